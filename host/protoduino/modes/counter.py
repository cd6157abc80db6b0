"""The counter mode: :class:`Counter`, its CounterInit (edge, pull-up, report rate) and its
checks. Its counts come in InputReports (:mod:`protoduino.inputs`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

from .._generated import protoduino_pb2 as pb
from ..arguments import Pin, period_ms, refused
from ..commands import COUNTER
from ..errors import ArgumentTypeError
from ..inputs import Input, ValueCondition
from ..messages import ArduinoIn, InputKind, Status
from .base import Built, ModeBoard

#: Which edges a counter counts.
Edge = Literal["rising", "falling", "both"]

_EDGES = {"rising": pb.EDGE_RISING, "falling": pb.EDGE_FALLING, "both": pb.EDGE_BOTH}


def init(
    board: ModeBoard, pin: Pin, edge: object, pull_up: object, rate_hz: object
) -> Built[Callable[[], Counter]]:
    """Check a counter's configuration; its CounterInit, what to record at the Ack, and what
    makes its object."""
    # As an analog input's (rule 14), with the pin's interrupt.
    if not isinstance(pull_up, bool):
        raise ArgumentTypeError(f"pull_up must be a bool, not {type(pull_up).__name__}")
    pin = board._check_pin(pin, COUNTER, reserved=False)
    if edge not in _EDGES:
        raise refused(
            Status.STATUS_INVALID_ARGUMENT,
            f"edge must be 'rising', 'falling' or 'both', not {edge!r}",
        )
    interval = period_ms("rate_hz", rate_hz)
    board._check_reserved(pin)
    board._check_capable(pin, COUNTER)
    msg = ArduinoIn()
    ci = msg.counter_init
    ci.pin, ci.pull_up, ci.interval_ms = pin, pull_up, interval
    ci.edge = _EDGES[edge]

    def make() -> Counter:
        return Counter(board.inputs, pin, board.release, board.call_timeout)

    return msg, board._input_recorder(pin, COUNTER, msg, Counter.kind), make


class Counter(Input):
    """A pulse counter (a wheel encoder); get one from ``board.counter``."""

    kind: InputKind = "counter"

    def read(self) -> int | None:
        """Edges counted since the counter's Init (wraps at 2**32; None before the first report)."""
        reading = self.reading()
        return None if reading is None else reading.value

    def wait_for(self, condition: ValueCondition, timeout: float | None = None) -> int:
        """Wait until ``condition(count)`` holds (at once if it does now); return the count."""
        return self._wait(lambda r: condition(r.value), timeout).value
