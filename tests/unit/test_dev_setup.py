"""``tools/dev.sh``: the demo's setup is the demo's; the test path still sets up everything.

dev.sh runs from a copy of the checkout whose setup steps are stand-ins that write down
how they were called: the fetch scripts, the bench's setup, the virtual environment's
python (pip) and ``protoduino``, and ``dpkg-query``/``apt-get``/``sudo`` on the PATH. Nothing
is installed or fetched; what each path would do is read from that log.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: Each stand-in appends "NAME ARGS" to $SETUP_LOG; dpkg-query says every package is there.
RECORD = '#!/bin/sh\necho "$(basename "$0") $*" >>"$SETUP_LOG"\n'
INSTALLED = RECORD + "echo 'install ok installed'\n"


def _stand_in(path: Path, text: str = RECORD) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    path.chmod(0o755)


def _run(tmp_path: Path, command: str) -> list[str]:
    """What ``./tools/dev.sh COMMAND`` did, one line per step, in a checkout of stand-ins."""
    root = tmp_path / "checkout"
    root.mkdir()
    for entry in ROOT.iterdir():  # the real files it reads (its stamp's inputs)
        if entry.name not in {"tools", ".venv", ".deps"}:
            (root / entry.name).symlink_to(entry)
    (root / "tools").mkdir()
    shutil.copy(ROOT / "tools" / "dev.sh", root / "tools" / "dev.sh")
    for script in ("fetch_nanopb.sh", "fetch_firmata.sh", "fetch_uplot.sh", "bench_setup.sh"):
        _stand_in(root / "tools" / script)
    for program in ("python", "protoduino"):
        _stand_in(root / ".venv" / "bin" / program)
    _stand_in(root / ".deps" / "ros2-venv" / "bin" / "python")  # the real ROS 2 node's venv
    shims = tmp_path / "bin"
    _stand_in(shims / "dpkg-query", INSTALLED)
    for program in ("apt-get", "sudo"):
        _stand_in(shims / program)
    log = tmp_path / "setup.log"
    log.touch()
    env = dict(os.environ, PATH=f"{shims}:{os.environ['PATH']}", SETUP_LOG=str(log))
    done = subprocess.run(
        [str(root / "tools" / "dev.sh"), command],
        env=env,
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    return log.read_text().splitlines()


def _queried(steps: list[str]) -> set[str]:
    return {s.split()[-1] for s in steps if s.startswith("dpkg-query")}


def test_the_demo_sets_up_only_what_the_demo_needs(tmp_path: Path) -> None:
    steps = _run(tmp_path, "demo")
    assert "fetch_nanopb.sh " in steps  # the native board is built against nanopb's runtime
    assert steps[-1] == "protoduino demo"
    assert not [
        s
        for s in steps
        if "firmata" in s or "bench" in s or "npm" in s or "ros-" in s or "uplot" in s
    ], steps
    installs = [s for s in steps if s.startswith("python -m pip install")]
    assert installs and installs[-1].endswith(" -e . -e ./dev"), installs
    assert {"build-essential", "libjansson-dev"} <= _queried(steps)
    assert not {"gcc-avr", "simavr", "clang", "arduino-builder"} & _queried(steps)


def test_the_test_path_still_sets_up_everything(tmp_path: Path) -> None:
    steps = _run(tmp_path, "setup")
    assert "fetch_nanopb.sh " in steps and "fetch_firmata.sh " in steps
    assert "bench_setup.sh " in steps
    assert "fetch_uplot.sh " in steps  # the live console's plots, for its browser tests
    installs = [s for s in steps if s.startswith("python -m pip install")]
    assert any(s.endswith(" -e .[dev] -e ./dev") for s in installs), installs
    # ROS 2's rclpy on Fast DDS, pinned, for tests/e2e/test_ros2_real.py.
    assert any(" -c constraints.txt " in s and " ros-rclpy " in s for s in installs), installs
    assert {"build-essential", "gcc-avr", "simavr", "clang", "libjansson-dev"} <= _queried(steps)
    assert {"chromium", "chromium-driver"} <= _queried(steps)
