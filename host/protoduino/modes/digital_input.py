"""The digital input mode: :class:`DigitalInput`, its DigitalInputInit (pull-up, debounce,
interlock) and its checks. Its values come in InputReports (:mod:`protoduino.inputs`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

from .._generated import protoduino_pb2 as pb
from ..arguments import Pin, check_int, refused
from ..commands import DIGITAL_INPUT
from ..constants import DEBOUNCE_MAX_MS
from ..errors import ArgumentTypeError
from ..inputs import Input, InputTable, LevelCondition, _level_test
from ..messages import ArduinoIn, InputKind, Status
from .base import Built, ModeBoard

#: An interlock's trip level, as ``digital_input(interlock=...)`` takes it.
Interlock = Literal["low", "high"]

_TRIPS = {None: pb.TRIP_NONE, "low": pb.TRIP_LOW, "high": pb.TRIP_HIGH}


def init(
    board: ModeBoard, pin: Pin, pull_up: object, debounce_ms: object, interlock: object
) -> Built[Callable[[], DigitalInput]]:
    """Check a digital input's configuration; its DigitalInputInit, what to record at the
    Ack, and what makes its object."""
    # The device's order (docs/protocol.md section 7, rules 11 and 14): the feature,
    # the arguments, the pin, then whether it is free.
    if not isinstance(pull_up, bool):
        raise ArgumentTypeError(f"pull_up must be a bool, not {type(pull_up).__name__}")
    pin = board.pin_number(pin)
    board._check_feature(DIGITAL_INPUT)
    debounce = check_int("debounce_ms", debounce_ms)
    if not 0 <= debounce <= DEBOUNCE_MAX_MS:
        raise refused(
            Status.STATUS_INVALID_ARGUMENT,
            f"debounce_ms {debounce} is outside 0..{DEBOUNCE_MAX_MS}",
        )
    if interlock not in _TRIPS:
        raise refused(
            Status.STATUS_INVALID_ARGUMENT,
            f"interlock must be None, 'low' or 'high', not {interlock!r}",
        )
    pin = board._check_pin(pin)
    board._check_capable(pin, DIGITAL_INPUT)
    msg = ArduinoIn()
    di = msg.digital_input_init
    di.pin, di.pull_up, di.debounce_ms = pin, pull_up, debounce
    di.interlock = _TRIPS[interlock]
    trip: Interlock | None = interlock  # type: ignore[assignment]

    def make() -> DigitalInput:
        return DigitalInput(board.inputs, pin, board.release, board.call_timeout, trip)

    return msg, board._input_recorder(pin, DIGITAL_INPUT, msg, DigitalInput.kind), make


class DigitalInput(Input):
    """A digital input (debounced on the device); get one from ``board.digital_input``."""

    kind: InputKind = "digital"

    def __init__(
        self,
        table: InputTable,
        pin: int,
        release: Callable[[int], None],
        timeout: float,
        interlock: Literal["low", "high"] | None = None,
    ) -> None:
        super().__init__(table, pin, release, timeout)
        #: The level that trips this input's interlock (None: not an interlock).
        self.interlock = interlock

    def read(self) -> bool | None:
        """The latest debounced level (None before the first report)."""
        reading = self.reading()
        return None if reading is None else bool(reading.value)

    def wait_for(self, level: LevelCondition, timeout: float | None = None) -> bool:
        """Wait until the level is ``level`` (or ``level(value)`` holds); return it.

        Returns at once if it already is. Raises :class:`InputTimeoutError` after
        ``timeout`` seconds (default: the board's call timeout).
        """
        test = _level_test(level)
        return bool(self._wait(lambda r: test(bool(r.value)), timeout).value)
