"""docs/services.md's tutorial, run as written: its files, its commands, its Python, on both boards.

Each step is a fenced block after a ``<!-- services step: KIND -->`` marker: ``file PATH``
writes the block to PATH, ``shell`` runs it with sh, ``python`` runs it (with the backend as
its argument) and ``output`` is what that script must print. They run in order, in an empty
folder, with ``$PROTODUINO`` the checkout and this environment's ``protoduino`` on the PATH.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SERVICES_MD = ROOT / "docs" / "services.md"
STEP = re.compile(r"<!-- services step: (\w+)(?: (\S+))? -->\n```\w*\n(.*?)```", re.S)


def steps() -> list[tuple[str, str | None, str]]:
    found = [(m.group(1), m.group(2), m.group(3)) for m in STEP.finditer(SERVICES_MD.read_text())]
    kinds = [kind for kind, _, _ in found]
    assert kinds.count("python") == 1 and kinds.count("output") == 1, kinds
    assert "file" in kinds and "shell" in kinds, kinds
    return found


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, str]:
    """The tutorial's folder after its file and shell steps; its script and expected output."""
    for tool in ("make", "gcc", "avr-gcc"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (the tutorial builds for both boards)")
    work = tmp_path_factory.mktemp("tutorial")
    env = {
        **os.environ,
        "PROTODUINO": str(ROOT),
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
    }
    script = expected = ""
    for kind, arg, body in steps():
        if kind == "file":
            assert arg is not None
            (work / arg).parent.mkdir(parents=True, exist_ok=True)
            (work / arg).write_text(body)
        elif kind == "shell":
            result = subprocess.run(
                ["sh", "-e", "-c", body],
                check=False,
                cwd=work,
                env=env,
                capture_output=True,
                text=True,
            )
            assert result.returncode == 0, f"{body}\n{result.stdout}{result.stderr}"
        elif kind == "python":
            script = body
        elif kind == "output":
            expected = body
    (work / "call.py").write_text(script)
    return work, "call.py", expected


@pytest.mark.parametrize("backend", ["native", "avr"])
def test_the_tutorial_runs_as_written(tutorial: tuple[Path, str, str], backend: str) -> None:
    work, script, expected = tutorial
    result = subprocess.run(
        [sys.executable, script, backend],
        check=False,
        cwd=work,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout == expected
