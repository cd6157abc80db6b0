"""Builds the optional C accelerator ``protoduino._speedups``; everything else is in pyproject.toml.

The extension is optional (``optional=True``): where there is no C compiler or no Python headers,
``pip install`` still succeeds, and ``protoduino.framing`` logs one warning and uses the
pure-Python decoder. ``tests/test_framing_props.py`` fails when a compiler and the headers are
present but the module was not built (a build broken by a warning must not pass as a skip).

It compiles the firmware's own COBS and CRC (``firmware/core``), so both ends of the link check
frames with the same code. Source paths are relative, as setuptools requires.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent

#: Everything the module is compiled from. Their digest is compiled in as
#: ``_speedups.SOURCE_DIGEST``, so a test can tell a stale in-place build from a fresh one.
SOURCES = ["host/protoduino/_speedups.c", "firmware/core/pd_cobs.c", "firmware/core/pd_crc.c"]
HEADERS = ["firmware/core/pd_cobs.h", "firmware/core/pd_crc.h", "firmware/core/pd_protocol.h"]


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


# Guarded so that tests can import source_digest(); setuptools runs this file as __main__.
if __name__ == "__main__":
    setup(
        ext_modules=[
            Extension(
                "protoduino._speedups",
                sources=SOURCES,
                depends=HEADERS,
                include_dirs=["firmware/core"],
                define_macros=[("PD_SPEEDUPS_DIGEST", f'"{source_digest()}"')],
                optional=True,
            )
        ],
        cmdclass={"build_ext": StrictBuildExt},
    )
