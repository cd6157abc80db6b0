"""The version is written once, in host/protoduino/_version.py (issue 34).

Everything else takes it from there: the package, both distributions' metadata, the firmware's
``DeviceInfo.firmware_version`` (through the generated pd_protocol.h, whose staleness
tests/contract/test_codegen.py catches) and the Arduino library's library.properties
(tests/e2e/test_arduino_lib.py). A second place written by hand would drift from it, as five
did: so no file the checkout tracks writes the version but the source and what is generated
from it.
"""

from __future__ import annotations

import importlib.metadata
import re
import shutil
import subprocess
from pathlib import Path

import protoduino
import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCE = "host/protoduino/_version.py"
#: Where the version may stand besides its source: generated from it, or a run's record.
DERIVED = {
    "firmware/generated/pd_protocol.h",  # protoduino gen
    "docs/performance.md",  # the versions bench measured (bench/machine.py reads them)
}


def _tracked() -> list[str]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("git is not installed, or this is not a git checkout (an sdist)")
    out = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60
    ).stdout
    return [name for name in out.decode().split("\0") if name]


def test_the_version_is_written_once() -> None:
    version = protoduino.__version__
    assert re.fullmatch(r"\d+\.\d+\.\d+\S*", version), version
    token = re.compile(rf"(?<![\w.]){re.escape(version)}(?![\w.])")
    written = set()
    for name in _tracked():
        path = ROOT / name
        if not path.is_file() or path.is_symlink():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue  # binary
        if token.search(text):
            written.add(name)
    assert SOURCE in written  # the search reads the files it must
    assert written - DERIVED == {SOURCE}


def test_every_distribution_carries_the_version() -> None:
    version = protoduino.__version__
    assert importlib.metadata.version("protoduino") == version
    assert importlib.metadata.version("protoduino-dev") == version
    header = (ROOT / "firmware/generated/pd_protocol.h").read_text()
    assert f'#define PD_FIRMWARE_VERSION "{version}"' in header
