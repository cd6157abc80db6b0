"""argparse types that refuse bad values while parsing (exit status 2, one line, no traceback).

A value the command could never use (a negative interval, a zero timeout, a
count of -1) is refused here, before anything opens a port, rather than deep
inside the library as an exception the user was never meant to see.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from ..arguments import Pin


def _bounds(low: float | None, high: float | None, low_open: bool) -> str:
    if low is not None and high is not None:
        return f"{low:g}..{high:g}"
    if low is not None:
        return f"> {low:g}" if low_open else f">= {low:g}"
    return f"<= {high:g}" if high is not None else "any"


def integer(
    low: int | None = None, high: int | None = None, *, name: str = "integer"
) -> Callable[[str], int]:
    """An int within [low, high] (either bound may be absent)."""

    def parse(text: str) -> int:
        try:
            value = int(text, 0) if text.strip().lower().startswith("0x") else int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(
                f"{value} is out of range (want {_bounds(low, high, False)})"
            )
        return value

    parse.__name__ = name
    return parse


def number(
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    name: str = "number",
) -> Callable[[str], float]:
    """A finite float within [low, high], or (low, high] with ``low_open``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        too_low = low is not None and (value <= low if low_open else value < low)
        if not math.isfinite(value) or too_low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(
                f"{text} is out of range (want {_bounds(low, high, low_open)})"
            )
        return value

    parse.__name__ = name
    return parse


#: Seconds that must be more than zero (timeouts).
positive_seconds = number(0.0, low_open=True, name="seconds")
#: Seconds that may be zero (intervals, "0: never").
seconds = number(0.0, name="seconds")
#: Counts and sizes.
count = integer(0, name="count")
positive_count = integer(1, name="count")
_pin_number = integer(0, 255, name="pin")


def pin(text: str) -> Pin:
    """A pin: its number, or its name on the board as Arduino writes it ("A0"); the board
    resolves the name from the device's own table and checks either against its
    DeviceInfo (:meth:`protoduino.Board.pin_number`)."""
    if text[:1] in "aA" and text[1:].isdigit():
        return text.upper()
    if not text.strip().lstrip("+-").isdigit():
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a pin (want a number 0..255 or a name such as A0)"
        )
    return _pin_number(text)


#: Serial baud rates.
baud = integer(1, name="baud rate")
