"""The emulated Uno runner's counters (``tools/avrsim --stats FILE``), for the bench and the tests.

SIGUSR2 makes the runner append one JSON line to FILE at the next pass of its
main loop (tools/avrsim/README.md lists the fields).
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

#: Bounds a failing wait only: the runner writes within a fraction of a millisecond.
STATS_TIMEOUT = 10.0


def _complete_lines(path: Path) -> list[str]:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return []
    return [line for line in text.splitlines(keepends=True) if line.endswith("\n")]


def snapshot(pid: int, path: Path, timeout: float = STATS_TIMEOUT) -> dict[str, Any]:
    """The counters of the runner ``pid`` now (its --stats file is ``path``).

    Raises TimeoutError if no line comes within ``timeout`` seconds.
    """
    before = len(_complete_lines(path))
    os.kill(pid, signal.SIGUSR2)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        lines = _complete_lines(path)
        if len(lines) > before:
            row: dict[str, Any] = json.loads(lines[-1])
            return row
        time.sleep(0.002)
    raise TimeoutError(f"the runner wrote no statistics to {path}")
