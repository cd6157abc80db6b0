"""The emulated Uno runner's counters (``tools/avrsim --stats FILE``), read by the tests.

SIGUSR2 makes the runner append one JSON line to FILE at the next pass of its
main loop (tools/avrsim/README.md lists the fields).
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

#: Bounds a failing wait only: the runner writes within a fraction of a millisecond.
STATS_TIMEOUT = 10.0


def _complete_lines(path: Path) -> list[str]:
    if not path.exists():
        return []
    return [line for line in path.read_text().splitlines(keepends=True) if line.endswith("\n")]


def snapshot(proc: subprocess.Popen[bytes], path: Path) -> dict[str, Any]:
    """The counters of the runner ``proc`` now (its --stats file is ``path``)."""
    before = len(_complete_lines(path))
    proc.send_signal(signal.SIGUSR2)
    deadline = time.monotonic() + STATS_TIMEOUT
    while time.monotonic() < deadline:
        lines = _complete_lines(path)
        if len(lines) > before:
            row: dict[str, Any] = json.loads(lines[-1])
            return row
        time.sleep(0.01)
    raise AssertionError(f"the runner wrote no statistics to {path}")
