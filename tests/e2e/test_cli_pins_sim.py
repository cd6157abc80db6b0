"""``protoduino pwm``, ``read`` and ``watch`` against the simulated boards (the real firmware),
the emulated Mega too: the pins come from the board's DeviceInfo."""

from __future__ import annotations

import json
import threading
import time

import pytest
from protoduino.cli.main import main
from protoduino.commands import ANALOG_INPUT, DIGITAL_INPUT, PWM
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, device_info, pins_for, wait_for_pin

pytestmark = pytest.mark.mega

#: Bounds a failing test's wait only.
BOUND = 30.0


def test_pwm_read_and_watch(sim_board: SimBoard, capsys: pytest.CaptureFixture[str]) -> None:
    sim = sim_board
    info = device_info(sim)
    (pwm,) = pins_for(info, PWM)
    (pin,) = pins_for(info, DIGITAL_INPUT, avoid=(pwm,))
    assert main(["pwm", sim.port, str(pwm), "77"]) == 0
    deadline = time.monotonic() + BOUND
    while not any(e["pin"] == pwm and e["value"] == 77 for e in sim.trace()):
        assert time.monotonic() < deadline, sim.trace()
        time.sleep(0.02)
    capsys.readouterr()  # what came before

    codes: list[int] = []
    watcher = threading.Thread(
        target=lambda: codes.append(main(["watch", sim.port, str(pin), "--json", "--count", "1"]))
    )
    watcher.start()
    level = 0
    while watcher.is_alive() and time.monotonic() < deadline:  # until it saw a change
        level ^= 1
        sim.set_level(pin, level)
        watcher.join(0.05)
    watcher.join(BOUND)
    assert codes == [0]
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(lines) == 2 and all(x["pin"] == pin and x["kind"] == "digital" for x in lines)
    assert lines[0]["value"] != lines[1]["value"]  # its level, then a change


def test_read_prints_what_the_firmware_reads(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = sim_board
    info = device_info(sim)
    analog = pins_for(info, ANALOG_INPUT, 2)[1]
    (pin,) = pins_for(info, DIGITAL_INPUT, avoid=(analog,))
    sim.set_analog(analog, 321)
    sim.set_level(pin, 0)
    assert main(["read", sim.port, str(analog), "--analog", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["value"] == 321
    assert main(["read", sim.port, str(pin), "--pull-up"]) == 0
    assert capsys.readouterr().out.startswith(f"pin {pin} digital: 0 (")


def test_servo_takes_a_real_angle(sim_board: SimBoard) -> None:
    assert main(["servo", sim_board.port, "9", "89.6"]) == 0  # 90 degrees: 1472 us
    wait_for_pin(sim_board, 9, lambda v: bool(v) and abs(v[-1] - 1472) <= PULSE_TOLERANCE_US)


def test_an_analog_pin_by_its_board_name(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    a1 = pins_for(device_info(sim_board), ANALOG_INPUT, 2)[1]  # the analog inputs, A0 first
    sim_board.set_analog(a1, 456)
    assert main(["read", sim_board.port, "A1", "--analog", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert (got["pin"], got["value"]) == (a1, 456)
