"""Board inputs to ROS 2 topics: digital -> Bool, analog -> Float32, counters -> Int32MultiArray.

The values become messages here (pure functions, tested without a board).
The wiring configures each input on the board (``Board.digital_input``,
``analog_input``, ``counter``). Each input's changes arrive on the board's
event thread, newest value first (the board coalesces), and are published
from there: a DDS writer may be used from any thread.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
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


def wire(
    board: Any, config: BridgeConfig, publishers: dict[str, Publish]
) -> list[Callable[[], None]]:
    """Subscribe to every configured input; returns the functions that unsubscribe.

    ``publishers`` maps each input topic to the function that publishes a message on it.
    """
    undo: list[Callable[[], None]] = []
    for d in config.digital_inputs:
        undo.append(_digital(board, d, publishers[d.topic]))
    for a in config.analog_inputs:
        undo.append(_analog(board, a, publishers[a.topic]))
    for c in config.counters:
        undo += _counters(board, c, publishers[c.topic])
    return undo


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
