"""The command line's one session per port, and the commands that must not take a device over.

Issue 20, items 5, 6 and 14, on both boards, judged at the pin: ``--new-session`` releases
what earlier commands configured, and what it then configures is not released by the next
plain command, not even a read-only ``info``, ``ping`` or ``outputs``, nor by a command the
host refuses; ``protoduino outputs`` shows what the device drives; ``protoduino flash``
refuses a port that a running board holds, before avrdude could reset the board under it.
"""

from __future__ import annotations

import json
import os
from typing import Any

import protoduino.flashing
import pytest
from protoduino import Board
from protoduino.cli.main import main
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, pin_values, wait_for_pin

#: Servo widths with the CLI's defaults (544..2400 us).
SAFE_90_US = 1472
NEAR = PULSE_TOLERANCE_US


def _near(target: int) -> Any:
    return lambda v: bool(v) and abs(v[-1] - target) <= NEAR


def test_a_new_sessions_outputs_survive_read_only_and_refused_commands(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    port = sim_board.port
    assert main(["servo", port, "10", "30"]) == 0
    wait_for_pin(sim_board, 10, _near(544 + 30 * 1856 // 180))
    # --new-session starts afresh: what earlier commands configured is released ...
    assert main(["servo", port, "9", "45", "--new-session"]) == 0
    width = 544 + 45 * 1856 // 180
    wait_for_pin(sim_board, 10, lambda v: v[-1:] == [0])  # pulses stopped
    wait_for_pin(sim_board, 9, _near(width))
    start = len(pin_values(sim_board.trace(), 9))
    # ... and what it configured is not released by the commands that follow it.
    assert main(["info", port]) == 0
    assert main(["ping", port, "-c", "1", "-q"]) == 0
    assert main(["servo", port, "1", "45"]) == 2  # a reserved pin: refused (exit status 2)
    assert "STATUS_RESERVED_PIN" in capsys.readouterr().err
    assert main(["outputs", port, "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert [o["pin"] for o in shown["outputs"]] == [9]
    servo = shown["outputs"][0]
    assert servo["mode"] == "servo" and servo["target"] == width
    assert abs(servo["value"] - width) <= NEAR
    assert main(["outputs", port]) == 0
    text = capsys.readouterr().out.splitlines()
    assert text[0].split() == ["pin", "mode", "value", "target"]
    assert text[1].split()[:2] == ["9", "servo"] and text[1].split()[-2:] == [str(width), "us"]
    # The verdict at the pin: the next thing pin 9 does is its failsafe (the safe 90
    # degrees, 10 s after the last command's sign of life), never a release (no pulses).
    values = wait_for_pin(sim_board, 9, lambda v: abs(v[-1] - width) > NEAR, timeout=60.0)
    assert 0 not in values[start:], values[start:]
    assert abs(values[-1] - SAFE_90_US) <= NEAR, values[start:]


def test_outputs_on_a_fresh_board_shows_none(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["outputs", sim_board.port]) == 0
    assert "no output configured" in capsys.readouterr().out
    assert main(["pin", sim_board.port, "13", "on"]) == 0
    capsys.readouterr()
    assert main(["outputs", sim_board.port, "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["outputs"] == [{"pin": 13, "mode": "digital", "value": 1, "target": 1}]


def test_flash_refuses_a_port_a_running_board_holds(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    uploads: list[str] = []
    monkeypatch.setattr(protoduino.flashing, "flash", lambda port, *a, **k: uploads.append(port))
    port = sim_board.port
    with Board.open(port) as board:
        servo = board.servo(9, safe=90)
        servo.write(10)
        wait_for_pin(sim_board, 9, _near(servo.to_us(10)))
        lines = len(pin_values(sim_board.trace(), 9))
        assert main(["flash", port, "--hex", os.devnull]) == 1
        err = capsys.readouterr().err
        assert "port in use" in err and "nothing flashed" in err
        assert uploads == []  # avrdude never ran
        assert board.ping() > 0  # the running board was not disturbed
        servo.write(20)
        wait_for_pin(sim_board, 9, _near(servo.to_us(20)))
        # At the pin: 10 degrees, then 20, and nothing between (no reset, no release).
        after = pin_values(sim_board.trace(), 9)[lines - 1 :]
        ends = (servo.to_us(10), servo.to_us(20))
        assert all(min(abs(v - end) for end in ends) <= NEAR for v in after), after
    # Once the board let go, flash goes ahead (here to the stand-in for avrdude).
    assert main(["flash", port, "--hex", os.devnull]) == 0
    assert uploads == [port]


def test_a_pin_or_timer_an_earlier_command_holds_is_said_as_the_api_says_it(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    """The device refuses (its board did not configure the pin: an earlier command did), and
    the command says why as Board's own check does, not only the status: exit status 1."""
    port = sim_board.port
    assert main(["pwm", port, "10", "100"]) == 0
    capsys.readouterr()
    cases = [
        (["servo", port, "9", "45"], "pin 10 does PWM on Timer1, the timer the servos need"),
        (["pin", port, "10", "on"], "pin 10 is a pwm pin (STATUS_PIN_IN_USE)"),
        (["read", port, "10"], "pin 10 is a pwm pin (STATUS_PIN_IN_USE)"),
    ]
    for argv, why in cases:
        assert main(argv) == 1, argv
        assert why in capsys.readouterr().err, argv
    assert main(["servo", port, "9", "45", "--new-session"]) == 0
    assert main(["pwm", port, "10", "100"]) == 1
    err = capsys.readouterr().err
    assert "pin 10's PWM needs Timer1, which makes the servo pulses while a servo runs" in err
    assert "(STATUS_TIMER_IN_USE)" in err


def test_the_same_port_under_another_name_is_the_same_session(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str], tmp_path: Any
) -> None:
    # A /dev/serial/by-id link to the port: the same device, so the same session; a new
    # one would release pin 13 (issue 32: the session id came from the port's string).
    link = tmp_path / "usb-Arduino_Uno-if00"
    link.symlink_to(sim_board.port)
    assert main(["pin", sim_board.port, "13", "on"]) == 0
    wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])
    capsys.readouterr()
    assert main(["outputs", str(link), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["outputs"] == [{"pin": 13, "mode": "digital", "value": 1, "target": 1}]
    assert pin_values(sim_board.trace(), 13)[-1] == 1
