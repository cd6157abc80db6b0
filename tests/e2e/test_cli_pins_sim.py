"""``protoduino pwm``, ``read`` and ``watch`` against both simulated boards (the real firmware)."""

from __future__ import annotations

import json
import threading
import time

import pytest
from protoduino.cli.main import main
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin

#: Bounds a failing test's wait only.
BOUND = 30.0


def test_pwm_read_and_watch(sim_board: SimBoard, capsys: pytest.CaptureFixture[str]) -> None:
    sim = sim_board
    assert main(["pwm", sim.port, "11", "77"]) == 0
    deadline = time.monotonic() + BOUND
    while not any(e["pin"] == 11 and e["value"] == 77 for e in sim.trace()):
        assert time.monotonic() < deadline, sim.trace()
        time.sleep(0.02)
    capsys.readouterr()  # what came before

    codes: list[int] = []
    watcher = threading.Thread(
        target=lambda: codes.append(main(["watch", sim.port, "2", "--json", "--count", "1"]))
    )
    watcher.start()
    level = 0
    while watcher.is_alive() and time.monotonic() < deadline:  # until it saw a change
        level ^= 1
        sim.set_level(2, level)
        watcher.join(0.05)
    watcher.join(BOUND)
    assert codes == [0]
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(lines) == 2 and all(x["pin"] == 2 and x["kind"] == "digital" for x in lines)
    assert lines[0]["value"] != lines[1]["value"]  # its level, then a change


def test_read_prints_what_the_firmware_reads(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = sim_board
    sim.set_analog(15, 321)
    sim.set_level(2, 0)
    assert main(["read", sim.port, "15", "--analog", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["value"] == 321
    assert main(["read", sim.port, "2", "--pull-up"]) == 0
    assert capsys.readouterr().out.startswith("pin 2 digital: 0 (")


def test_servo_takes_a_real_angle(sim_board: SimBoard) -> None:
    assert main(["servo", sim_board.port, "9", "89.6"]) == 0  # 90 degrees: 1472 us
    wait_for_pin(sim_board, 9, lambda v: bool(v) and abs(v[-1] - 1472) <= PULSE_TOLERANCE_US)


def test_an_analog_pin_by_its_board_name(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    sim_board.set_analog(15, 456)  # A1
    assert main(["read", sim_board.port, "A1", "--analog", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert (got["pin"], got["value"]) == (15, 456)
