"""Build, from this source checkout, the programs protoduino runs or flashes.

Everything goes through ``make`` (so repeated calls cost a few milliseconds) into ``build/``:

- the simulated board ``build/sim/pd_sim`` (``make -C firmware sim``),
- the firmware's Uno build (``make -C firmware avr``: ``build/avr/protoduino.{elf,hex}``),
- the simavr runner ``build/avrsim/avrsim`` and its test program (``tools/avrsim/``),
- Optiboot in a 1 KB boot section at 0x7C00 (``build/optiboot/optiboot.hex``) and the Mega
  2560's stk500v2 bootloader at 0x3E000 (``build/stk500v2/stk500v2.hex``), for the flashing
  tests.

:func:`build_program` is the program source this distribution declares (entry point group
``protoduino.programs``, dev/pyproject.toml), which the runtime's
:func:`protoduino.programs.locate` calls when this package is installed: in a checkout every
run uses programs built from the current sources, never a copy bundled into some earlier wheel.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import subprocess
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from protoduino import programs
from protoduino._generated import tables
from protoduino.errors import BuildError

logger = logging.getLogger(__name__)

#: The source checkout this package lives in (dev/protoduino_dev/build.py): the development
#: tools exist only there.
ROOT = Path(__file__).resolve().parents[2]
FIRMWARE_DIR = ROOT / "firmware"
AVRSIM_DIR = ROOT / "tools" / "avrsim"
BUILD = ROOT / "build"
#: make's cache is per file; this lock keeps two processes from building at once.
BUILD_LOCK = BUILD / ".build.lock"
MAKE_TIMEOUT = 300.0
_TAIL_CHARS = 4000

NATIVE_SIM = BUILD / "sim" / "pd_sim"
RUNNER = BUILD / "avrsim" / "avrsim"
TEST_PROGRAM = BUILD / "avrsim" / "testprog.elf"
OPTIBOOT_HEX = BUILD / "optiboot" / "optiboot.hex"
#: Start of the 1 KB boot section (hfuse BOOTSZ = 10) where Optiboot is linked.
OPTIBOOT_ADDRESS = 0x7C00
#: The Mega 2560's stk500v2 bootloader (Debian's Arduino core) and the start of its 8 KB boot
#: section (hfuse 0xD8: BOOTSZ = 00, BOOTRST).
STK500V2_HEX = BUILD / "stk500v2" / "stk500v2.hex"
STK500V2_ADDRESS = 0x3E000
FIRMWARE_ELF = BUILD / "avr" / "protoduino.elf"
FIRMWARE_HEX = BUILD / "avr" / "protoduino.hex"


@contextlib.contextmanager
def _build_lock() -> Iterator[None]:
    BUILD.mkdir(parents=True, exist_ok=True)
    with BUILD_LOCK.open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def make(directory: Path, *targets: str) -> None:
    """Run make quietly; raise :class:`BuildError` with the tail of its output on failure."""
    if not (directory / "Makefile").is_file():
        raise BuildError(f"{directory / 'Makefile'} not found: is this a complete source checkout?")
    cmd = ["make", "-s", "-C", str(directory), *targets]
    with _build_lock():
        try:
            result = subprocess.run(
                cmd, capture_output=True, text=True, check=False, timeout=MAKE_TIMEOUT
            )
        except FileNotFoundError as error:
            raise BuildError("`make` is not installed (run ./tools/dev.sh setup)") from error
        except subprocess.TimeoutExpired as error:
            raise BuildError(f"`{' '.join(cmd)}` did not finish in {MAKE_TIMEOUT:.0f} s") from error
    if result.returncode != 0:
        output = (result.stdout + result.stderr).strip()[-_TAIL_CHARS:]
        raise BuildError(f"`{' '.join(cmd)}` failed (exit {result.returncode}):\n{output}")
    logger.debug("%s: ok", " ".join(cmd))


def build_native_sim() -> Path:
    """Build the simulated board (the firmware core with a POSIX HAL) and return its path."""
    make(FIRMWARE_DIR, "sim")
    return NATIVE_SIM


def build_runner() -> Path:
    """Build the simavr runner and return its path."""
    make(AVRSIM_DIR, "runner")
    return RUNNER


def build_test_program() -> Path:
    """Build the runner's own AVR test program and return its ELF."""
    make(AVRSIM_DIR, "testprog")
    return TEST_PROGRAM


def build_optiboot() -> Path:
    """Build Optiboot for the 1 KB boot section and return its hex."""
    make(AVRSIM_DIR, "optiboot")
    return OPTIBOOT_HEX


def build_stk500v2() -> Path:
    """The Mega 2560's stk500v2 bootloader as simavr reads it; its hex."""
    make(AVRSIM_DIR, "stk500v2")
    return STK500V2_HEX


def build_firmware() -> Path:
    """Build the firmware's Uno target and return its ELF."""
    make(FIRMWARE_DIR, "avr")
    return FIRMWARE_ELF


#: The Uno firmware's build-time features: every Feature of the schema (`protoduino gen` writes
#: them for the Makefile's ALL_FEATURES and core/pd_features.h too).
FEATURES = tables.FEATURES


def build_firmware_features(features: Iterable[str]) -> Path:
    """Build the Uno firmware with only ``features`` (``make avr FEATURES=...``); its ELF.

    Such a build goes to ``build/avr-<features, sorted, joined by ->/``; the default one (every
    feature) is ``build/avr/``, as :func:`build_firmware` builds it.
    """
    chosen = sorted(set(features))
    unknown = set(chosen) - set(FEATURES)
    if unknown:
        raise ValueError(f"unknown features {sorted(unknown)} (known: {', '.join(FEATURES)})")
    if set(chosen) == set(FEATURES):
        return build_firmware()
    make(FIRMWARE_DIR, "avr", "FEATURES=" + " ".join(chosen))
    return BUILD / ("avr-" + "-".join(chosen)) / "protoduino.elf"


def build_firmware_board(board: str) -> Path:
    """Build the firmware for a board (``make avr BOARD=...``: "uno", "nano", "mega");
    its ELF."""
    make(FIRMWARE_DIR, "avr", f"BOARD={board}")
    return BUILD / ("avr" if board == "uno" else f"avr-{board}") / "protoduino.elf"


def build_firmware_board_hex(board: str) -> Path:
    """Build the firmware for a board (``make avr BOARD=...``); its flashable hex."""
    return build_firmware_board(board).with_suffix(".hex")


def build_firmware_hex() -> Path:
    """Build the firmware's Uno target and return its flashable hex."""
    make(FIRMWARE_DIR, "avr")
    return FIRMWARE_HEX


#: Runtime program name (protoduino.programs) -> how this checkout builds it.
PROGRAMS: dict[str, Callable[[], Path]] = {
    programs.NATIVE_SIM: build_native_sim,
    programs.RUNNER: build_runner,
    programs.FIRMWARE_ELF: build_firmware,
    programs.FIRMWARE_HEX: build_firmware_hex,
    programs.MEGA_FIRMWARE_ELF: lambda: build_firmware_board("mega"),
    programs.MEGA_FIRMWARE_HEX: lambda: build_firmware_board_hex("mega"),
    programs.NANO_FIRMWARE_HEX: lambda: build_firmware_board_hex("nano"),
}


def build_program(name: str) -> Path:
    """Build one of the runtime's programs from this checkout (cached by make)."""
    try:
        builder = PROGRAMS[name]
    except KeyError:
        raise ValueError(f"no build rule for program {name!r}") from None
    return builder()
