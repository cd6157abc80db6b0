"""``protoduino flash``: upload the firmware through the board's bootloader with avrdude.

The board (``--board``: uno, nano or mega) picks avrdude's part, programmer and rate and the
firmware this installation carries for it (:data:`protoduino.flashing.BOARDS`). Without
``--board`` it is the Uno, unless ``--hex`` is an ELF built for the ATmega2560, which only the
Mega of the three has; an ELF built for the other chip than ``--board``'s is refused.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from . import argtypes

HELP = (
    "upload the firmware (this version's for the board, or --hex) with avrdude through the "
    "bootloader"
)

#: An AVR ELF's machine (e_flags & EF_AVR_MACH) -> the board of the three that has that core.
_ELF_MACH_BOARD = {5: "uno", 6: "mega"}
_EM_AVR = 83


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("port", help="serial port of the board, e.g. /dev/ttyACM0")
    parser.add_argument(
        "--board",
        choices=("uno", "nano", "mega"),
        default=None,
        help="the board: uno (default; Optiboot), nano (Optiboot at 115200, the IDE's "
        "'ATmega328P'; an old-bootloader Nano: --baud 57600) or mega (the Mega 2560's stk500v2 "
        "bootloader); an ATmega2560 ELF given as --hex means mega",
    )
    parser.add_argument(
        "--hex",
        type=Path,
        default=None,
        help="flash this Intel hex (or ELF, converted) instead of this version's firmware",
    )
    parser.add_argument(
        "--baud",
        type=argtypes.baud,
        default=None,
        help="bootloader baud rate (default the board's: 115200 for all three)",
    )


def _is_elf(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return f.read(4) == b"\x7fELF"
    except OSError:
        return False  # flash() says why it cannot read it


def _elf_board(path: Path) -> str | None:
    """The board whose chip ``path`` (an ELF) was built for, by its AVR core; None if unknown.

    avr-gcc records the core in the ELF header's flags: avr5 for the ATmega328P (Uno, Nano),
    avr6 for the ATmega2560 (Mega).
    """
    try:
        with path.open("rb") as f:
            header = f.read(52)
    except OSError:
        return None
    # 32-bit little-endian ELF: e_machine at 18, e_flags at 36.
    if len(header) < 52 or header[4] != 1 or header[5] != 1:
        return None
    if int.from_bytes(header[18:20], "little") != _EM_AVR:
        return None
    return _ELF_MACH_BOARD.get(int.from_bytes(header[36:40], "little") & 0x7F)


def run(args: argparse.Namespace) -> int:
    from .. import programs
    from ..errors import BuildError, FlashError, PortInUseError, TransportError
    from ..flashing import BOARDS, flash, strip_to_hex
    from ..transport import check_port_free

    is_elf = args.hex is not None and (args.hex.suffix == ".elf" or _is_elf(args.hex))
    built_for = _elf_board(args.hex) if is_elf else None
    board = args.board or ("mega" if built_for == "mega" else "uno")
    if built_for is not None and BOARDS[built_for].chip != BOARDS[board].chip:
        print(
            f"protoduino flash: {args.hex} is built for the {BOARDS[built_for].chip}, the "
            f"{board}'s chip is the {BOARDS[board].chip}; nothing flashed",
            file=sys.stderr,
        )
        return 1
    target = BOARDS[board]
    baud = target.baud if args.baud is None else args.baud
    try:
        # Before anything else: avrdude takes no lock, and resetting the board under a
        # running program (a robot mid-move) is what the lock is there to prevent.
        check_port_free(args.port, baudrate=baud)
    except PortInUseError as error:
        print(f"protoduino flash: {error}; nothing flashed", file=sys.stderr)
        return 1
    except TransportError:
        pass  # a port that cannot open at all: flash() says why, in avrdude's terms
    try:
        with tempfile.TemporaryDirectory(prefix="protoduino-flash-") as tmp:
            if args.hex is None:
                # In a source checkout this builds it first (make -C firmware avr).
                hex_file = programs.locate(target.firmware)
            elif is_elf:
                # An ELF may carry .eeprom or simavr's .mmcu: convert without them.
                hex_file = strip_to_hex(args.hex, Path(tmp) / "firmware.hex")
            else:
                hex_file = args.hex
            print(
                f"protoduino flash: uploading {hex_file} to the {board} on {args.port}",
                file=sys.stderr,
            )
            flash(args.port, hex_file, board=board, baud=baud, progress=sys.stderr)
    except (BuildError, FlashError) as error:
        print(f"protoduino flash: {error}", file=sys.stderr)
        return 1
    print(f"protoduino flash: done, {args.port} runs the new firmware", file=sys.stderr)
    return 0
