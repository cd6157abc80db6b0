"""``protoduino flash``: upload the Uno firmware through the bootloader with avrdude."""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from . import argtypes

HELP = "upload the Uno firmware (this version's, or --hex) with avrdude through the bootloader"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("port", help="serial port of the Uno, e.g. /dev/ttyACM0")
    parser.add_argument(
        "--hex",
        type=Path,
        default=None,
        help="flash this Intel hex (or ELF, converted) instead of this version's firmware",
    )
    parser.add_argument(
        "--baud", type=argtypes.baud, default=115200, help="bootloader baud rate (Optiboot: 115200)"
    )


def _is_elf(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return f.read(4) == b"\x7fELF"
    except OSError:
        return False  # flash() says why it cannot read it


def run(args: argparse.Namespace) -> int:
    from .. import programs
    from ..errors import BuildError, FlashError, PortInUseError, TransportError
    from ..flashing import flash, strip_to_hex
    from ..transport import check_port_free

    try:
        # Before anything else: avrdude takes no lock, and resetting the board under a
        # running program (a robot mid-move) is what the lock is there to prevent.
        check_port_free(args.port, baudrate=args.baud)
    except PortInUseError as error:
        print(f"protoduino flash: {error}; nothing flashed", file=sys.stderr)
        return 1
    except TransportError:
        pass  # a port that cannot open at all: flash() says why, in avrdude's terms
    try:
        with tempfile.TemporaryDirectory(prefix="protoduino-flash-") as tmp:
            if args.hex is None:
                # In a source checkout this builds it first (make -C firmware avr).
                hex_file = programs.locate(programs.FIRMWARE_HEX)
            elif args.hex.suffix == ".elf" or _is_elf(args.hex):
                # An ELF may carry .eeprom or simavr's .mmcu: convert without them.
                hex_file = strip_to_hex(args.hex, Path(tmp) / "firmware.hex")
            else:
                hex_file = args.hex
            print(f"protoduino flash: uploading {hex_file} to {args.port}", file=sys.stderr)
            flash(args.port, hex_file, baud=args.baud, progress=sys.stderr)
    except (BuildError, FlashError) as error:
        print(f"protoduino flash: {error}", file=sys.stderr)
        return 1
    print(f"protoduino flash: done, {args.port} runs the new firmware", file=sys.stderr)
    return 0
