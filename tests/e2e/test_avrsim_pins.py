"""Issue 21 on the emulated Uno (the real firmware in simavr), judged at the pins and by the Acks.

- A build without a feature (``make -C firmware avr FEATURES=...``) lists it nowhere in
  DeviceInfo and answers its commands STATUS_NOT_SUPPORTED.
- PWM outputs: the duty a PwmControl sets is the duty the trace measures at the pin (the
  runner reads the timers' compare outputs), and Stop puts the safe duty there.

Raw ArduinoIn requests go through ``Board.request``, so the device's own checks are what is
tested (the host's Board API refuses a missing feature before sending; tests/unit test that).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino import Board, CommandRejectedError
from protoduino.messages import ArduinoIn, Status
from protoduino.simboard import runner_command
from protoduino_dev import build

pytestmark = pytest.mark.avr

STARTUP_TIMEOUT = 10.0
#: Bounds a failing wait only: the trace line comes within a few emulated PWM periods.
TRACE_TIMEOUT = 20.0
ROOT = Path(__file__).resolve().parents[2]


def _runner(elf: Path, trace: Path | None = None) -> BoardProcess:
    return BoardProcess(runner_command(elf, trace=trace), startup=STARTUP_TIMEOUT)


@pytest.fixture
def tools() -> None:
    missing = missing_tool("make", "cc", "avr-gcc", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build.build_runner()


def _info() -> ArduinoIn:
    msg = ArduinoIn()
    msg.get_info.SetInParent()
    return msg


def _servo_init(pin: int) -> ArduinoIn:
    msg = ArduinoIn()
    msg.servo_init.pin = pin
    msg.servo_init.safe_degrees = 90
    return msg


def _pwm_init(pin: int, safe: int) -> ArduinoIn:
    msg = ArduinoIn()
    msg.pwm_init.pin = pin
    msg.pwm_init.safe_duty = safe
    return msg


def _pwm(pin: int, duty: int) -> ArduinoIn:
    msg = ArduinoIn()
    msg.pwm_control.pin = pin
    msg.pwm_control.duty = duty
    return msg


def test_a_build_without_servo_refuses_servos(tools: None) -> None:
    build.make(ROOT / "firmware", "avr", "FEATURES=digital_output pwm")
    elf = ROOT / "build" / "avr-digital_output-pwm" / "protoduino.elf"
    runner = _runner(elf)
    try:
        with Board.open(runner.port) as board:
            info = board.request(_info()).info
            assert not (info.features >> 1) & 1  # FEATURE_SERVO
            assert (info.features >> 5) & 1  # FEATURE_PWM
            assert info.pwm_pins == (1 << 3) | (1 << 9) | (1 << 10) | (1 << 11)
            with pytest.raises(CommandRejectedError) as refused:
                board.request(_servo_init(9))
            assert refused.value.status == Status.STATUS_NOT_SUPPORTED
            # What it has still works.
            board.request(_pwm_init(9, 0))
    finally:
        runner.stop(strict=False)


def _wait_for(trace: Path, match: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
    deadline = time.monotonic() + TRACE_TIMEOUT
    while time.monotonic() < deadline:
        if trace.exists():
            for line in trace.read_text().splitlines():
                row: dict[str, Any] = json.loads(line)
                if match(row):
                    return row
        time.sleep(0.02)
    raise AssertionError(f"no trace line matched in {TRACE_TIMEOUT} s:\n{trace.read_text()}")


def _is_pwm(pin: int, duty: int) -> Callable[[dict[str, Any]], bool]:
    def match(row: dict[str, Any]) -> bool:
        return bool(row["pin"] == pin and row["mode"] == "pwm" and row["value"] == duty)

    return match


@pytest.mark.parametrize("pin", [3, 9, 10, 11])
def test_pwm_duty_measured_at_the_pin(tools: None, tmp_path: Path, pin: int) -> None:
    elf = build.build_firmware()
    trace = tmp_path / "trace.jsonl"
    runner = _runner(elf, trace)
    try:
        with Board.open(runner.port) as board:
            board.request(_pwm_init(pin, 0))
            for duty in (1, 128, 254):
                board.request(_pwm(pin, duty))
                _wait_for(trace, _is_pwm(pin, duty))
            board.request(_pwm(pin, 200))
            at_200 = _wait_for(trace, lambda r: r["pin"] == pin and r["value"] == 200)
            stop = ArduinoIn()
            stop.stop.SetInParent()
            board.request(stop)
            safe = _wait_for(
                trace, lambda r: r["pin"] == pin and r["value"] == 0 and r["t"] > at_200["t"]
            )
            assert safe["mode"] == "pwm"
    finally:
        runner.stop(strict=False)


def test_pwm_on_9_refused_while_a_servo_runs(tools: None) -> None:
    runner = _runner(build.build_firmware())
    try:
        with Board.open(runner.port) as board:
            board.request(_servo_init(2))
            with pytest.raises(CommandRejectedError) as refused:
                board.request(_pwm_init(9, 0))
            assert refused.value.status == Status.STATUS_TIMER_IN_USE
            with pytest.raises(CommandRejectedError) as refused:
                board.request(_pwm_init(5, 0))
            assert refused.value.status == Status.STATUS_TIMER_IN_USE
    finally:
        runner.stop(strict=False)
