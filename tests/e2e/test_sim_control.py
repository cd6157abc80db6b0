"""The simulated boards' input-control socket, the same on both backends.

What the firmware then makes of the inputs is tested with each pin mode; here
the socket itself: the Python API, the CLI option, the answers and refusals
(checked by the board, so both backends must give the same words).
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from protoduino.errors import SimControlError
from protoduino.simboard import SimBoard


def test_inputs_are_accepted_with_the_board_time(sim_board: SimBoard) -> None:
    t1 = sim_board.set_level(2, 0)
    t2 = sim_board.set_analog(14, 512)
    t3 = sim_board.pulses(3, 100, 2000)
    t4 = sim_board.set_level(3, True)  # ends the train at once
    assert 0 < t1 <= t2 <= t3 <= t4


@pytest.mark.parametrize(
    ("command", "message"),
    [
        ({"pin": 1, "level": 0}, "pins 0 and 1 carry the serial link"),
        ({"pin": 20, "level": 0}, "no such pin on this board"),
        ({"pin": 13, "analog": 5}, "analog inputs are pins 14..19"),
        ({"pin": 14, "analog": 1024}, '"analog" must be 0..1023, not 1024'),
        ({"pin": 2, "level": 2}, '"level" must be 0..1, not 2'),
        ({"pin": 2, "level": True}, '"level" must be an integer'),
        ({"pin": 3, "pulses": 10}, '"pulses" needs "hz"'),
        ({"pin": 3, "pulses": 0, "hz": 10}, '"pulses" must be 1..1000000'),
        ({"pin": 3, "pulses": 5, "hz": 100001}, '"hz" must be 1..100000'),
        ({"pin": 2, "level": 0, "analog": 3}, 'exactly one of "level", "analog", "pulses"'),
        ({"pin": 2, "level": 0, "hz": 3}, '"hz" goes with "pulses"'),
        ({"level": 0}, '"pin" must be an integer'),
        ({"pin": 2, "volts": 1}, 'unknown key "volts"'),
    ],
)
def test_refusals_name_the_problem(
    sim_board: SimBoard, command: dict[str, object], message: str
) -> None:
    with pytest.raises(SimControlError, match=re.escape(message)):
        sim_board.control.send(command)


def test_raw_lines_on_the_socket(sim_board: SimBoard) -> None:
    """Any client may speak the protocol: not JSON, not an object, a blank line, a long line."""
    with socket.socket(socket.AF_UNIX) as sock:
        sock.settimeout(5.0)
        sock.connect(str(sim_board.control_path))
        stream = sock.makefile("rwb")
        answers = []
        for line in (b"junk", b"[1, 2]", b"", b"x" * 600, b'{"pin": 2, "level": 1}'):
            stream.write(line + b"\n")
            stream.flush()
            if line:  # a blank line is allowed and gets no answer
                answers.append(json.loads(stream.readline()))
    assert answers[0]["ok"] is False and answers[0]["error"].startswith("not JSON")
    assert answers[1] == {"ok": False, "error": "expected one JSON object per line"}
    assert answers[2] == {"ok": False, "error": "line too long"}
    assert answers[3]["ok"] is True and answers[3]["t"] > 0


def test_cli_sim_control_option(sim_board: SimBoard) -> None:
    """``protoduino sim --control PATH`` (both backends) answers on PATH, removed at exit."""
    folder = Path(tempfile.mkdtemp(prefix="pd-cli-"))
    path = folder / "ctl"
    cmd = [sys.executable, "-m", "protoduino.cli.main", "sim", "--backend", sim_board.backend]
    proc = subprocess.Popen([*cmd, "--control", str(path)], stdout=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        port = proc.stdout.readline().decode().strip()
        assert os.path.exists(port)
        deadline = time.monotonic() + 10.0
        while not path.exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        with socket.socket(socket.AF_UNIX) as sock:
            sock.settimeout(5.0)
            sock.connect(str(path))
            sock.sendall(b'{"pin": 14, "analog": 512}\n')
            assert json.loads(sock.makefile("rb").readline())["ok"] is True
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        assert proc.stdout is not None
        proc.stdout.close()
    assert not path.exists()
    folder.rmdir()


def test_paths_given_as_str_work_like_paths(tmp_path: Path) -> None:
    """``SimBoard(trace="file.jsonl")``: a str names the trace (issue 20, item 13)."""
    from protoduino import Board

    trace = str(tmp_path / "trace.jsonl")
    short = tempfile.mkdtemp(prefix="pd-")  # a socket path must stay under 108 bytes
    with SimBoard("native", trace=trace, control=os.path.join(short, "c.sock")) as sim:
        sim.start()
        assert sim.trace_path == Path(trace)
        with Board.open(sim.port) as board:
            board.digital_output(13, safe=True)
        deadline = time.monotonic() + 30.0
        while not any(c["pin"] == 13 and c["value"] == 1 for c in sim.trace()):
            assert time.monotonic() < deadline, f"the trace shows {sim.trace()}"
            time.sleep(0.02)
        assert sim.set_level(2, 1) > 0  # the control socket at the str path answers
    os.rmdir(short)
