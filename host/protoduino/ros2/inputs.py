"""Board inputs to ROS 2 topics: digital -> Bool, analog -> Float32, counters -> Int32MultiArray.

The values become messages here (pure functions, tested without a board).
The wiring configures each input on the board (``Board.digital_input``,
``analog_input``, ``counter``). Each input's changes arrive on the board's
event thread, newest value first (the board coalesces), and are published
from there: a DDS writer may be used from any thread.

A sensor topic is best effort and volatile (ROS 2's sensor-data QoS): a sample lost on the
network is never sent again, and DDS keeps no value for a subscriber that joins later. So each
topic keeps its last message (:class:`LastPublished`), which the bridge publishes again when a
subscriber matches (``ros2 topic echo`` shows a constant battery voltage at once) and whenever
the topic was quiet for a period (:meth:`LastPublished.refresh`, ``min_publish_rate``): a value
that stops changing is still published, and a lost sample is repaired within that period.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from .config import AnalogInputConfig, BridgeConfig, CounterConfig, DigitalInputConfig
from .msgs import Bool, Float32, Int32MultiArray, MultiArrayDimension, MultiArrayLayout


class Input(Protocol):
    """An input object of the board: its latest value and its changes."""

    def read(self) -> Any: ...

    def on_change(self, callback: Callable[[Any], None]) -> Callable[[], None]: ...


Publish = Callable[[object], None]


def bool_message(level: object) -> Bool:
    return Bool(data=bool(level))


def analog_message(counts: int, config: AnalogInputConfig) -> Float32:
    """Counts (0..1023) as ``counts * scale + offset``, e.g. a battery's volts."""
    return Float32(data=counts * config.scale + config.offset)


def int32(count: int) -> int:
    """A count that wraps at 2**32 (the device's) as the int32 it is in Int32MultiArray.

    It wraps the same way there, so a subscriber takes differences modulo 2**32.
    """
    count &= 0xFFFFFFFF
    return count - (1 << 32) if count & 0x80000000 else count


def counters_message(counts: Sequence[int], config: CounterConfig) -> Int32MultiArray:
    """The counts in the order of ``config.pins``, one labelled dimension ("pins")."""
    n = len(counts)
    layout = MultiArrayLayout(dim=[MultiArrayDimension(label="pins", size=n, stride=n)])
    return Int32MultiArray(layout=layout, data=[int32(c) for c in counts])


class LastPublished:
    """Publishes on one topic and keeps the last message (and when it went out, on ``clock``),
    to publish it :meth:`again` or :meth:`refresh` it.

    One lock around both, so that a message published again can never overtake a newer one
    published from the board's event thread meanwhile (the newest stays the last one out).
    """

    def __init__(self, publish: Publish, clock: Callable[[], float] = time.monotonic) -> None:
        self._publish = publish
        self._clock = clock
        self._lock = threading.Lock()
        self.message: object | None = None
        #: When a message last went out (``clock``'s time).
        self.at = -math.inf

    def __call__(self, message: object) -> None:
        with self._lock:
            self.message = message
            self._send()

    def _send(self) -> None:
        assert self.message is not None
        self._publish(self.message)
        self.at = self._clock()

    def again(self) -> bool:
        """Publish the last message again (False: nothing was published yet)."""
        with self._lock:
            if self.message is None:
                return False
            self._send()
            return True

    def refresh(self, period: float) -> float:
        """Publish the last message again if none went out for ``period``; return when the
        next refresh is due (``clock``'s time)."""
        with self._lock:
            if self.message is None:
                return self._clock() + period
            if self._clock() - self.at >= period:
                self._send()
            return self.at + period


@dataclass(frozen=True, slots=True)
class Wiring:
    """The inputs on their topics: what unsubscribes them, and each topic's last message."""

    undo: list[Callable[[], None]]
    topics: dict[str, LastPublished]


def wire(
    board: Any,
    config: BridgeConfig,
    publishers: dict[str, Publish],
    clock: Callable[[], float] = time.monotonic,
) -> Wiring:
    """Subscribe to every configured input and publish its first value.

    ``publishers`` maps each input topic to the function that publishes a message on it;
    ``clock`` dates what each topic published (for :meth:`LastPublished.refresh`).
    """
    last = {topic: LastPublished(publish, clock) for topic, publish in publishers.items()}
    undo: list[Callable[[], None]] = []
    for d in config.digital_inputs:
        undo.append(_digital(board, d, last[d.topic]))
    for a in config.analog_inputs:
        undo.append(_analog(board, a, last[a.topic]))
    for c in config.counters:
        undo += _counters(board, c, last[c.topic])
    return Wiring(undo, last)


def _digital(board: Any, config: DigitalInputConfig, publish: Publish) -> Callable[[], None]:
    pin: Input = board.digital_input(
        config.pin,
        pull_up=config.pull_up,
        debounce_ms=config.debounce_ms,
        interlock=config.interlock,
    )
    first = pin.read()
    if first is not None:
        publish(bool_message(first))
    return pin.on_change(lambda r: publish(bool_message(r.value)))


def _analog(board: Any, config: AnalogInputConfig, publish: Publish) -> Callable[[], None]:
    pin: Input = board.analog_input(config.pin, rate_hz=config.rate_hz, threshold=config.threshold)
    first = pin.read()
    if first is not None:
        publish(analog_message(int(first), config))
    return pin.on_change(lambda r: publish(analog_message(int(r.value), config)))


def _counters(board: Any, config: CounterConfig, publish: Publish) -> list[Callable[[], None]]:
    pins: list[Input] = [board.counter(p) for p in config.pins]
    lock = threading.Lock()
    counts = [int(p.read() or 0) for p in pins]

    def changed(index: int, reading: Any) -> None:
        with lock:
            counts[index] = int(reading.value)
            message = counters_message(counts, config)
        publish(message)

    publish(counters_message(counts, config))
    return [
        p.on_change(lambda r, i=i: changed(i, r))  # type: ignore[misc]
        for i, p in enumerate(pins)
    ]
