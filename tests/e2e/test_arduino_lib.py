"""The Arduino IDE library zip (``make -C firmware arduino-zip``), built as the IDE builds it.

"Add .ZIP Library" unpacks the zip's one top-level folder into the sketchbook's libraries; a
sketch then compiles against the Arduino core with the library's ``src/`` on the include path.
The test does the same with the Arduino core of Debian's arduino-core-avr and the compiler
flags of its platform.txt (the IDE's own recipe for the Uno): the example sketch must compile
and link into a program that fits the Uno's flash below the bootloader.
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import protoduino
import pytest

pytestmark = pytest.mark.avr

ROOT = Path(__file__).resolve().parents[2]
AVR_CORE = Path("/usr/share/arduino/hardware/arduino/avr")
#: The Uno's flash less Optiboot's 512 B (boards.txt: uno.upload.maximum_size).
UNO_MAX_SIZE = 32256
#: The parts of the Arduino core this sketch links against (main() calling setup() and loop(),
#: the Timer0 clock, the interrupt hooks). The IDE compiles the whole core into an archive the
#: linker picks from; Debian 12's core is newer than its avr-gcc 5.4 in places the sketch never
#: uses (WString.cpp needs C++ DECIMAL_DIG), so those are not compiled. A part missing from this
#: list fails the link with its undefined symbol.
CORE_PARTS = ("main.cpp", "wiring.c", "hooks.c")
MCU_FLAGS = ["-mmcu=atmega328p", "-DF_CPU=16000000L"]
# -DARDUINO as an IDE 1.8.19 defines it; the board and architecture as boards.txt says.
IDE_DEFINES = ["-DARDUINO=10819", "-DARDUINO_AVR_UNO", "-DARDUINO_ARCH_AVR"]
COMMON = ["-c", "-g", "-Os", "-ffunction-sections", "-fdata-sections", "-flto"]
C_FLAGS = [*COMMON, "-std=gnu11", "-fno-fat-lto-objects"]
CPP_FLAGS = [*COMMON, "-std=gnu++11", "-fpermissive", "-fno-exceptions", "-fno-threadsafe-statics"]


def _missing() -> str | None:
    for tool in ("make", "avr-gcc", "avr-g++", "avr-size"):
        if shutil.which(tool) is None:
            return tool
    if not (AVR_CORE / "cores" / "arduino" / "Arduino.h").exists():
        return "arduino-core-avr (the Arduino core)"
    if not (ROOT / ".deps" / "nanopb" / "pb_decode.c").exists():
        return "the nanopb C runtime (./tools/dev.sh setup fetches it)"
    return None


def _compile(source: Path, out: Path, includes: list[str]) -> Path:
    obj = out / (source.name + ".o")
    if source.suffix == ".c":
        cmd = ["avr-gcc", *C_FLAGS]
    elif source.suffix == ".S":
        cmd = ["avr-gcc", "-c", "-g", "-x", "assembler-with-cpp", "-flto"]
    else:
        cmd = ["avr-g++", *CPP_FLAGS]
    cmd += [*MCU_FLAGS, *IDE_DEFINES, *includes, str(source), "-o", str(obj)]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=120)
    assert result.returncode == 0, f"{' '.join(cmd)}\n{result.stderr}"
    return obj


def test_the_zip_installs_and_its_example_builds_as_in_the_ide(tmp_path: Path) -> None:
    missing = _missing()
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build = tmp_path / "build"
    subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), f"BUILD={build}", "arduino-zip"],
        check=True,
        capture_output=True,
        timeout=300,
    )
    with zipfile.ZipFile(build / "arduino" / "Protoduino.zip") as archive:
        names = archive.namelist()
        # One top-level folder, with library.properties at its root: what the IDE installs.
        assert {name.split("/", 1)[0] for name in names} == {"protoduino"}
        assert "protoduino/library.properties" in names
        libraries = tmp_path / "sketchbook" / "libraries"
        archive.extractall(libraries)
    library = libraries / "protoduino"
    properties = dict(
        line.split("=", 1)
        for line in (library / "library.properties").read_text().splitlines()
        if "=" in line
    )
    assert properties["name"] == "Protoduino"
    assert properties["architectures"] == "avr"
    assert properties["version"] == protoduino.__version__  # the one source (_version.py)

    # The IDE turns the .ino into C++ with Arduino.h included first.
    sketch = tmp_path / "sketch" / "Protoduino.ino.cpp"
    sketch.parent.mkdir()
    ino = library / "examples" / "Protoduino" / "Protoduino.ino"
    sketch.write_text('#include <Arduino.h>\n#line 1 "Protoduino.ino"\n' + ino.read_text())

    core = AVR_CORE / "cores" / "arduino"
    includes = [f"-I{core}", f"-I{AVR_CORE / 'variants' / 'standard'}", f"-I{library / 'src'}"]
    objects = tmp_path / "objects"
    objects.mkdir()
    sources = [sketch, *sorted((library / "src").glob("*.c"))]
    sources += [core / name for name in CORE_PARTS]
    objs = [_compile(source, objects, includes) for source in sources]

    elf = tmp_path / "Protoduino.ino.elf"
    link = [
        "avr-gcc",
        "-Os",
        "-g",
        "-flto",
        "-fuse-linker-plugin",
        "-Wl,--gc-sections",
        "-mmcu=atmega328p",
        "-o",
        str(elf),
        *map(str, objs),
        "-lm",
    ]
    result = subprocess.run(link, capture_output=True, text=True, check=False, timeout=300)
    assert result.returncode == 0, result.stderr
    sizes = subprocess.run(
        ["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    section = {
        parts[0]: int(parts[1])
        for parts in (line.split() for line in sizes.splitlines())
        if len(parts) >= 2 and parts[1].isdigit()
    }
    flash = section[".text"] + section.get(".data", 0)
    # The firmware is in (about 12 KB; setup() and loop() alone with the core are under 1 KB),
    # and the whole fits below the bootloader.
    assert 8 * 1024 < flash <= UNO_MAX_SIZE, sizes
