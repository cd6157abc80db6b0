"""A simulated board outlives no owner.

``protoduino sim``, a test suite or a user's script starts the board as a child
process and stops it when done; killed outright (SIGKILL, an out-of-memory kill,
a CI job cancelled), the owner cannot. The board then notices that its parent
is gone and exits, so boards (each with its pty, and on the emulated Uno a core
at work) do not pile up unseen.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from simfixtures import SIM_BACKENDS

#: Bounds a failing wait only: the board checks for its owner on every pass of
#: its main loop (at least every millisecond).
EXIT_TIMEOUT = 30.0

OWNER = """
import sys, time
from protoduino.simboard import SimBoard
board = SimBoard(sys.argv[1])
board.start()
print(board.pid, flush=True)
time.sleep(600)
"""


def _gone(pid: int) -> bool:
    """Exited: no such process, or a zombie waiting for init to reap it."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return True
    return state in ("Z", "X")


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_a_board_exits_when_its_owner_is_killed(backend: str) -> None:
    owner = subprocess.Popen(
        [sys.executable, "-c", OWNER, backend],
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert owner.stdout is not None
        line = owner.stdout.readline()
        assert line.strip().isdigit(), f"the owner printed no board pid: {line!r}"
        board = int(line)
        assert not _gone(board)
        owner.send_signal(signal.SIGKILL)
        owner.wait()
        deadline = time.monotonic() + EXIT_TIMEOUT
        while not _gone(board) and time.monotonic() < deadline:
            time.sleep(0.02)
        if not _gone(board):
            os.kill(board, signal.SIGKILL)
            pytest.fail(f"the {backend} board (pid {board}) outlived its killed owner")
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait()
        if owner.stdout is not None:
            owner.stdout.close()
