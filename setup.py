"""The build steps pyproject.toml cannot declare: the C accelerator and the bundled programs.

``protoduino._speedups`` (optional C accelerator, on Python's limited API of 3.11: one build
serves every CPython from 3.11 on, so a wheel is cp311-abi3): where there is no C compiler or
no Python headers, ``pip install`` still succeeds, and ``protoduino.framing`` logs one warning
and uses the pure-Python decoder. ``tests/unit/test_framing_props.py`` fails when a compiler
and the headers are present but the module was not built (a build broken by a warning must not
pass as a skip). It compiles the firmware's own COBS and CRC (``firmware/core``), so both ends
of the link check frames with the same code. Source paths are relative, as setuptools requires.

The programs (``protoduino/_programs/``, see ``protoduino.programs``): a wheel carries the
firmware as a ready hex for the Uno, the Nano and the Mega 2560 (and the Uno's and the Mega's
ELF, which the emulated boards run), the simulated board ``pd_sim`` and the emulated boards'
runner ``avrsim``, built here with make, avr-gcc and gcc, so that ``pip install protoduino`` is
enough to flash any of the three (``protoduino flash --board``; avrdude then is the only tool)
or to try a robot on the simulated board. They are not optional: a wheel without the firmware is
not protoduino, so a missing tool fails the build with its name. An editable install
(``pip install -e .``, the checkout's own) skips them: there, ``protoduino_dev`` builds each
program from the current sources when it is used.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import tempfile
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent

#: Everything the module is compiled from. Their digest is compiled in as
#: ``_speedups.SOURCE_DIGEST``, so a test can tell a stale in-place build from a fresh one.
SOURCES = ["host/protoduino/_speedups.c", "firmware/core/pd_cobs.c", "firmware/core/pd_crc.c"]
HEADERS = [
    "firmware/core/pd_cobs.h",
    "firmware/core/pd_crc.h",
    "firmware/core/pd_rom.h",
    "firmware/generated/pd_protocol.h",
]


def source_digest(root: Path = ROOT) -> str:
    """SHA-256 over the sources and headers, in the order listed."""
    digest = hashlib.sha256()
    for name in SOURCES + HEADERS:
        digest.update(name.encode() + b"\0" + (root / name).read_bytes())
    return digest.hexdigest()


class StrictBuildExt(build_ext):
    """The project's C rules (C99, every warning an error) where the compiler takes GCC flags."""

    def build_extensions(self) -> None:
        if self.compiler.compiler_type == "unix":
            for ext in self.extensions:
                ext.extra_compile_args += ["-std=c99", "-Wall", "-Wextra", "-Werror"]
        super().build_extensions()
        # A checkout's older in-place build per Python version (_speedups.cpython-311-*.so)
        # would be imported before the abi3 one: remove it.
        for stale in (ROOT / "host" / "protoduino").glob("_speedups.cpython-*.so"):
            stale.unlink()


#: What a wheel's protoduino/_programs/ holds: name -> (make directory, make arguments, the
#: file below the build folder). The simulated board is built without the sanitizers that the
#: checkout's build uses (they need their runtime libraries and slow it down).
PROGRAMS = {
    "protoduino.hex": ("firmware", ["avr"], "avr/protoduino.hex"),
    "protoduino.elf": ("firmware", ["avr"], "avr/protoduino.elf"),
    "protoduino-mega.elf": ("firmware", ["avr", "BOARD=mega"], "avr-mega/protoduino.elf"),
    "protoduino-mega.hex": ("firmware", ["avr", "BOARD=mega"], "avr-mega/protoduino.hex"),
    "protoduino-nano.hex": ("firmware", ["avr", "BOARD=nano"], "avr-nano/protoduino.hex"),
    "pd_sim": ("firmware", ["sim", "SIM_CFLAGS=-O2"], "sim/pd_sim"),
    "avrsim": ("tools/avrsim", ["runner"], "avrsim/avrsim"),
}
#: Tools the programs' builds need, with the Debian package that has each.
BUILD_TOOLS = {
    "make": "make",
    "gcc": "build-essential",
    "avr-gcc": "gcc-avr",
    "avr-objcopy": "binutils-avr",
}


def build_programs(build_dir: Path, out_dir: Path, root: Path = ROOT) -> list[Path]:
    """Build every program of :data:`PROGRAMS` below ``build_dir``; copy them to ``out_dir``."""
    for tool, package in BUILD_TOOLS.items():
        if shutil.which(tool) is None:
            raise SystemExit(
                f"building protoduino's wheel needs {tool} (Debian package {package}): it "
                "compiles the Uno firmware and the simulated board that the wheel carries"
            )
    out_dir.mkdir(parents=True, exist_ok=True)
    copied = []
    for name, (directory, args, built) in PROGRAMS.items():
        cmd = ["make", "-s", "-C", str(root / directory), f"BUILD={build_dir}", *args]
        result = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if result.returncode != 0:
            raise SystemExit(
                f"`{' '.join(cmd)}` failed (exit {result.returncode}):\n"
                + (result.stdout + result.stderr)[-4000:]
            )
        # copy2 keeps the executable bit, which the wheel records for pip to restore.
        copied.append(Path(shutil.copy2(build_dir / built, out_dir / name)))
    return copied


#: The live console's plotting library (``protoduino console``), fetched from npm by
#: tools/fetch_uplot.sh into .deps/uplot (an sdist carries it: MANIFEST.in); the wheel serves
#: it from its package data. An editable install serves it from .deps/uplot itself.
VENDOR_FILES = ("uPlot.iife.min.js", "uPlot.min.css", "LICENSE")


def copy_vendor_assets(out_dir: Path, root: Path = ROOT) -> None:
    """Copy uPlot's files from ``.deps/uplot`` into ``out_dir``; a missing one fails the build."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in VENDOR_FILES:
        source = root / ".deps" / "uplot" / name
        if not source.is_file():
            raise SystemExit(
                f"building protoduino's wheel needs {source} (the live console's plots): "
                "run ./tools/fetch_uplot.sh (./tools/dev.sh setup does)"
            )
        shutil.copy2(source, out_dir / name)


class BuildPyWithPrograms(build_py):
    """build_py, plus the programs in protoduino/_programs/ and the console's vendored
    assets (not for an editable install)."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        copy_vendor_assets(Path(self.build_lib) / "protoduino" / "console" / "static" / "vendor")
        with tempfile.TemporaryDirectory(prefix="protoduino-programs-") as tmp:
            build_programs(Path(tmp), Path(self.build_lib) / "protoduino" / "_programs")


# Guarded so that tests can import source_digest(); setuptools runs this file as __main__.
if __name__ == "__main__":
    setup(
        ext_modules=[
            Extension(
                "protoduino._speedups",
                sources=SOURCES,
                depends=HEADERS,
                include_dirs=["firmware/core", "firmware/generated"],
                define_macros=[("PD_SPEEDUPS_DIGEST", f'"{source_digest()}"')],
                optional=True,
                py_limited_api=True,  # _speedups.abi3.so: the C defines Py_LIMITED_API 3.11
            )
        ],
        cmdclass={"build_ext": StrictBuildExt, "build_py": BuildPyWithPrograms},
        # One wheel per machine kind for every CPython from 3.11 (cp311-abi3).
        options={"bdist_wheel": {"py_limited_api": "cp311"}},
    )
