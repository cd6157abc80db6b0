"""A simulated board's lifetime, one rule (protoduino.simboard), judged by process state.

An OWNED board (a SimBoard: a test suite, ``protoduino demo``, a user's script)
never outlives its owner: killed outright (SIGKILL, an out-of-memory kill, a CI
job cancelled) or exiting without stopping it, the owner's pipe reads EOF and
the board exits, so boards (each with its pty, and on the emulated Uno a core
at work) do not pile up unseen. A board a user started on purpose (``protoduino
sim``) stays until it is stopped: under ``nohup`` from a script that exits, or
``--detach``ed with a pid file that ``--stop`` uses.
"""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from protoduino import Board
from simfixtures import SIM_BOARDS, sim_args

#: Each test runs on the emulated Mega too: its runner is another MCU's (tests/README.md).
pytestmark = pytest.mark.mega

#: Bounds a failing wait only: the board checks for its owner on every pass of
#: its main loop (at least every millisecond).
EXIT_TIMEOUT = 30.0

OWNER = """
import sys, time
from protoduino.simboard import SimBoard
board = SimBoard(sys.argv[1], board=sys.argv[2])
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


def test_a_board_exits_when_its_owner_is_killed(board_id: str) -> None:
    owner = subprocess.Popen(
        [sys.executable, "-c", OWNER, *SIM_BOARDS[board_id]],
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
            pytest.fail(f"the {board_id} board (pid {board}) outlived its killed owner")
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait()
        if owner.stdout is not None:
            owner.stdout.close()


OWNER_EXITS = """
import os, sys
from protoduino.simboard import SimBoard
board = SimBoard(sys.argv[1], board=sys.argv[2])
board.start()
print(board.pid, flush=True)
os._exit(0)  # no stop(), no cleanup at all: a script that forgot the board
"""


def _wait_gone(pid: int) -> bool:
    deadline = time.monotonic() + EXIT_TIMEOUT
    while not _gone(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    return _gone(pid)


def _kill(pid: int) -> None:
    if not _gone(pid):
        os.kill(pid, signal.SIGKILL)


def _serves(port: str) -> None:
    """The board answers: a handshake and a ping (takes far longer than an orphaned
    board needs to notice its owner is gone)."""
    with Board.open(port, ping=False) as board:
        assert board.ping() > 0


def test_an_owned_board_ends_when_its_owner_exits_without_stopping_it(board_id: str) -> None:
    done = subprocess.run(
        [sys.executable, "-c", OWNER_EXITS, *SIM_BOARDS[board_id]],
        capture_output=True,
        text=True,
        timeout=EXIT_TIMEOUT,
        check=True,
        stdin=subprocess.DEVNULL,
    )
    board = int(done.stdout)
    try:
        assert _wait_gone(board), f"the {board_id} board (pid {board}) outlived its owner"
    finally:
        _kill(board)


def _protoduino() -> list[str]:
    return [sys.executable, "-m", "protoduino.cli.main"]


def test_a_detached_board_survives_its_shell_and_stops_by_its_pid_file(
    board_id: str, tmp_path: Path
) -> None:
    pid_file = tmp_path / "board.pid"
    cli = shlex.join([*_protoduino(), "sim", *sim_args(board_id)])
    # The shell exits right after; run() returning at all shows the board holds none of
    # the caller's pipes (a daemon that kept stdout would make it wait forever).
    done = subprocess.run(
        ["sh", "-c", f"{cli} --detach --pid-file {shlex.quote(str(pid_file))}"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, done.stderr
    port = done.stdout.strip()
    pid = int(pid_file.read_text())
    try:
        assert "runs until stopped" in done.stderr
        _serves(port)  # after its shell is gone
        assert not _gone(pid)
        assert os.getsid(pid) == pid  # a session of its own: no terminal's SIGHUP reaches it
        stop = subprocess.run(
            [*_protoduino(), "sim", "--stop", str(pid_file)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert stop.returncode == 0, stop.stderr
        assert _gone(pid)
        assert not pid_file.exists()
        again = subprocess.run(
            [*_protoduino(), "sim", "--stop", str(pid_file)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert again.returncode == 1 and "cannot read the pid file" in again.stderr
    finally:
        _kill(pid)


@pytest.mark.skipif(shutil.which("nohup") is None, reason="nohup is not installed")
def test_a_board_started_under_nohup_outlives_the_script_that_started_it(
    board_id: str, tmp_path: Path
) -> None:
    """``nohup protoduino sim &`` in a script: the board was started on purpose, so it
    stays after the script exits (it used to exit silently with status 0 then)."""
    out = tmp_path / "sim.out"
    cli = shlex.join([*_protoduino(), "sim", *sim_args(board_id)])
    # The script stays until the board printed its port, then exits: its child is orphaned
    # while it runs (the old rule ended a board whose parent went away).
    script = (
        f"nohup {cli} > {shlex.quote(str(out))} 2>/dev/null & pid=$!\n"
        f"while ! [ -s {shlex.quote(str(out))} ]; do sleep 0.05; done\n"
        "echo $pid\n"
    )
    done = subprocess.run(
        ["sh", "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
        stdin=subprocess.DEVNULL,
    )
    pid = int(done.stdout)
    try:
        deadline = time.monotonic() + EXIT_TIMEOUT
        while not out.read_text().endswith("\n") and time.monotonic() < deadline:
            time.sleep(0.02)
        port = out.read_text().splitlines()[0]
        _serves(port)
        assert not _gone(pid), "the board exited when the script that started it did"
        os.kill(pid, signal.SIGTERM)  # stopped on purpose: it goes
        assert _wait_gone(pid)
    finally:
        _kill(pid)
