"""The analog input mode: :class:`AnalogInput`, its AnalogInputInit (sample rate, threshold,
heartbeat) and its checks. Its values come in InputReports (:mod:`protoduino.inputs`)."""

from __future__ import annotations

from collections.abc import Callable

from ..arguments import Pin, check_int, interval_ms, period_ms, refused
from ..commands import ANALOG_INPUT
from ..constants import ANALOG_MAX
from ..inputs import Input, ValueCondition
from ..messages import ArduinoIn, InputKind, Status
from .base import Built, ModeBoard


def init(
    board: ModeBoard, pin: Pin, rate_hz: object, threshold: object, heartbeat: object
) -> Built[Callable[[], AnalogInput]]:
    """Check an analog input's configuration; its AnalogInputInit, what to record at the
    Ack, and what makes its object."""
    # The device's order (rules 11 and 14): the feature, the pin's number, the
    # arguments, a reserved pin, the pin's ADC, then whether it is free.
    pin = board._check_pin(pin, ANALOG_INPUT, reserved=False)
    interval = period_ms("rate_hz", rate_hz)
    beat = interval_ms("heartbeat", heartbeat)
    counts = check_int("threshold", threshold)
    if not 0 <= counts <= ANALOG_MAX:
        raise refused(
            Status.STATUS_INVALID_ARGUMENT, f"threshold {counts} is outside 0..{ANALOG_MAX}"
        )
    board._check_reserved(pin)
    board._check_capable(pin, ANALOG_INPUT)
    msg = ArduinoIn()
    ai = msg.analog_input_init
    ai.pin, ai.threshold, ai.interval_ms, ai.heartbeat_ms = pin, counts, interval, beat

    def make() -> AnalogInput:
        return AnalogInput(board.inputs, pin, board.release, board.call_timeout)

    return msg, board._input_recorder(pin, ANALOG_INPUT, msg, AnalogInput.kind), make


class AnalogInput(Input):
    """An analog input in 10-bit counts; get one from ``board.analog_input``."""

    kind: InputKind = "analog"

    def read(self) -> int | None:
        """The latest counts, 0..1023 (None before the first report)."""
        reading = self.reading()
        return None if reading is None else reading.value

    def wait_for(self, condition: ValueCondition, timeout: float | None = None) -> int:
        """Wait until ``condition(counts)`` holds (at once if it does now); return the counts."""
        return self._wait(lambda r: condition(r.value), timeout).value
