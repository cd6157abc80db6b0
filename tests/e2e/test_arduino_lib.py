"""The Arduino IDE library zip (``make -C firmware arduino-zip``), built as the IDE builds it,
for each board the library serves, then run.

"Add .ZIP Library" unpacks the zip's one top-level folder into the sketchbook's libraries; a
sketch then compiles against the Arduino core with the library's ``src/`` on the include path.
The test does the same with Debian's ``arduino-builder`` (the Arduino IDE 1.8's own builder)
and the Arduino core of its arduino-core-avr, for the Uno, the Nano and the Mega 2560 (the
board's FQBN, as the IDE's Tools > Board menu sets it): the example sketch must compile and
link into a program that fits the board's flash below its bootloader, and run: on the
emulated board (the Nano's chip is the Uno's) it answers ``protoduino info`` as that board.
The IDE passes no per-library flags: the library tells the board from the MCU and board
macros the IDE compiles with (its src/pd_config.h).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import protoduino
import pytest
from boardprocess import missing_tool
from protoduino.simboard import SimBoard

pytestmark = pytest.mark.avr

ROOT = Path(__file__).resolve().parents[2]
HARDWARE = Path("/usr/share/arduino/hardware")
BUILDER_DIR = Path("/usr/share/arduino-builder")
#: Upper bound only (a build, a command): nothing is judged by it.
TIMEOUT = 300.0


@dataclass(frozen=True)
class IdeBoard:
    """A board as the IDE builds for it, and the emulated board that runs the result."""

    fqbn: str
    #: boards.txt's upload.maximum_size: the flash below the bootloader.
    max_size: int
    emulated: str


BOARDS = {
    "uno": IdeBoard("arduino:avr:uno", 32256, "uno"),
    # Debian's boards.txt keeps the old bootloader's 30,720 B for the Optiboot Nano too.
    "nano": IdeBoard("arduino:avr:nano:cpu=atmega328", 30720, "uno"),
    "mega": IdeBoard("arduino:avr:mega:cpu=atmega2560", 253952, "mega"),
}


def missing_ide() -> str | None:
    """What building the library as the IDE does needs and this machine lacks."""
    missing = missing_tool("make", "avr-gcc", "avr-size", "arduino-builder", simavr=True)
    if missing is not None:
        return missing
    if not (HARDWARE / "arduino" / "avr" / "cores" / "arduino" / "Arduino.h").exists():
        return "arduino-core-avr (the Arduino core)"
    if not (ROOT / ".deps" / "nanopb" / "pb_decode.c").exists():
        return "the nanopb C runtime (./tools/dev.sh setup fetches it)"
    return None


def arduino_build(sketch: Path, libraries: Path, build: Path, fqbn: str) -> Path:
    """Compile ``sketch`` (its .ino) with arduino-builder for ``fqbn``; the ELF it made."""
    build.mkdir(parents=True, exist_ok=True)
    result = subprocess.run(
        [
            "arduino-builder",
            "-compile",
            "-fqbn",
            fqbn,
            "-hardware",
            str(HARDWARE),
            "-hardware",
            str(BUILDER_DIR),
            "-tools",
            str(BUILDER_DIR),
            "-tools",
            "/usr/bin",
            "-libraries",
            str(libraries),
            "-build-path",
            str(build),
            # Debian's core is newer than its avr-gcc 5.4 (WString.cpp wants DECIMAL_DIG;
            # AVR doubles are 32-bit): ../shared/TOOLCHAIN.md.
            "-prefs=compiler.cpp.extra_flags=-DDECIMAL_DIG=9",
            str(sketch),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=TIMEOUT,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return build / f"{sketch.name}.elf"


def flash_size(elf: Path) -> int:
    """.text + .data: what the program takes of the flash."""
    sizes = subprocess.run(
        ["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    section = {
        parts[0]: int(parts[1])
        for parts in (line.split() for line in sizes.splitlines())
        if len(parts) >= 2 and parts[1].isdigit()
    }
    return section[".text"] + section.get(".data", 0)


@pytest.fixture(scope="module")
def libraries(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The zip, made and installed into a sketchbook's libraries as "Add .ZIP Library" does."""
    missing = missing_ide()
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    tmp = tmp_path_factory.mktemp("arduino")
    build = tmp / "build"
    subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), f"BUILD={build}", "arduino-zip"],
        check=True,
        capture_output=True,
        timeout=TIMEOUT,
    )
    with zipfile.ZipFile(build / "arduino" / "Protoduino.zip") as archive:
        names = archive.namelist()
        # One top-level folder, with library.properties at its root: what the IDE installs.
        assert {name.split("/", 1)[0] for name in names} == {"protoduino"}
        assert "protoduino/library.properties" in names
        archive.extractall(tmp / "libraries")
    return tmp / "libraries"


def test_the_zip_is_a_library_the_ide_installs(libraries: Path) -> None:
    properties = dict(
        line.split("=", 1)
        for line in (libraries / "protoduino" / "library.properties").read_text().splitlines()
        if "=" in line
    )
    assert properties["name"] == "Protoduino"
    assert properties["architectures"] == "avr"
    assert properties["version"] == protoduino.__version__  # the one source (_version.py)


@pytest.mark.parametrize("board", list(BOARDS))
def test_the_example_builds_as_in_the_ide_and_runs_as_the_board(
    libraries: Path, tmp_path: Path, board: str
) -> None:
    ide = BOARDS[board]
    sketch = tmp_path / "Protoduino"
    shutil.copytree(libraries / "protoduino" / "examples" / "Protoduino", sketch)
    elf = arduino_build(sketch / "Protoduino.ino", libraries, tmp_path / "build", ide.fqbn)
    # The firmware is in (about 25 KB; setup() and loop() alone with the core are under 1 KB),
    # and the whole fits below the bootloader.
    assert 8 * 1024 < flash_size(elf) <= ide.max_size

    with SimBoard("avr", board=ide.emulated, firmware=elf) as sim:
        sim.start()
        info = subprocess.run(
            [sys.executable, "-m", "protoduino.cli.main", "info", sim.port, "--json"],
            capture_output=True,
            text=True,
            check=False,
            timeout=TIMEOUT,
            stdin=subprocess.DEVNULL,
        )
    assert info.returncode == 0, info.stdout + info.stderr
    found = json.loads(info.stdout)["info"]
    assert found["board"] == board
    assert found["schema_id"] == f"0x{protoduino.SCHEMA_ID:08X}"
