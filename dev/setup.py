"""protoduino-dev's version is protoduino's: read from host/protoduino/_version.py, where it is
written once (pyproject.toml declares it dynamic). This distribution is built only from the
checkout (its pyproject.toml says why), so the file is always there."""

from __future__ import annotations

import runpy
from pathlib import Path

from setuptools import setup

VERSION_FILE = Path(__file__).resolve().parents[1] / "host" / "protoduino" / "_version.py"

setup(version=str(runpy.run_path(str(VERSION_FILE))["__version__"]))
