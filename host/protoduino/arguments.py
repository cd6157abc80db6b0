"""The checks of the board's arguments: types refused as ``ArgumentTypeError``, values as the
status the device would give (``CommandRejectedError``, ``sent=False``) or ``ArgumentError``.

Each says what it takes and why it refuses the rest (a bool is no number, NaN no angle); the
board and its outputs call them before anything is sent.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from decimal import Decimal
from fractions import Fraction
from numbers import Integral, Real

from .constants import FAILSAFE_MAX, FAILSAFE_MIN, INPUT_INTERVAL_MAX_MS
from .errors import ArgumentError, ArgumentTypeError, CommandRejectedError, rejection
from .messages import Status, status_name


def check_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ArgumentTypeError(f"{name} must be an int, not {type(value).__name__}")
    return int(value)


#: A pin as the board's methods and the command line take it: its number, or its name
#: on the board as Arduino writes it ("A0").
Pin = int | str

_ANALOG_NAME = re.compile(r"A(\d{1,3})", re.IGNORECASE)


def pin_number(value: object, analog_pins: Sequence[int]) -> int:
    """A pin's number: an int as it is, a board name as the device names it.

    ``"A0"`` is the first of the device's analog inputs in its own table
    (``DeviceInfo.analog_pins``: 14 on the Uno), ``"A5"`` the sixth (19): the names
    come from the device, not from a list kept here, so a board with other analog
    pins has them right. A name the device lacks (``"A6"`` on the Uno) is refused
    as a pin it does not have (STATUS_INVALID_PIN); any other string (``"9"``) is
    the wrong type, as it was.
    """
    if not isinstance(value, str):
        return check_int("pin", value)
    found = _ANALOG_NAME.fullmatch(value)
    if found is None:
        raise ArgumentTypeError(f"pin must be an int or a board name such as 'A0', not {value!r}")
    index = int(found[1])
    if index >= len(analog_pins):
        names = f"A0..A{len(analog_pins) - 1}" if analog_pins else "none"
        raise refused(
            Status.STATUS_INVALID_PIN,
            f"pin {value} does not exist (its analog pins by name: {names})",
        )
    return analog_pins[index]


#: Real numbers: numbers.Real (int, float, Fraction, numpy's) and Decimal, which the
#: numbers tower leaves out although its values are real.
_REAL = (Real, Decimal)


def whole_number(name: str, value: object) -> int:
    """A real number (int, float, Fraction, Decimal, a numpy float) rounded to a whole one.

    Inverse kinematics and filters produce floats; the wire carries whole degrees
    and microseconds. The rounding is ``round()``'s: to the nearest whole number, a
    half to the even one (44.5 -> 44, 45.5 -> 46), exact for a Fraction or a
    Decimal. NaN and infinities are refused (there is no nearest whole number), and
    so is a bool: ``True`` is no angle.
    """
    if isinstance(value, bool) or not isinstance(value, _REAL):
        raise ArgumentTypeError(f"{name} must be a real number, not {type(value).__name__}")
    if isinstance(value, Integral):
        return int(value)
    if not math.isfinite(value):
        raise refused(Status.STATUS_OUT_OF_RANGE, f"{name} {value!r} is not a finite number")
    return int(round(value))  # noqa: RUF046  (numpy < 2 rounds a float32 to a float32)


def check_session(value: object) -> int:
    """A host session id: an int 1..2**32-1 (a bool or a float is refused, not truncated)."""
    session = check_int("session", value)
    if not 0 < session <= 0xFFFFFFFF:
        raise ArgumentError(f"session must be 1..2**32-1, not {session}")
    return session


def check_failsafe_ms(value: object) -> int:
    """A failsafe timeout (seconds, any real number) as the whole milliseconds the device keeps.

    ``Decimal("0.1")`` is 100 ms like ``0.1``: the check is on the value rounded to the
    millisecond, which is what ConfigureFailsafe carries, so no binary float edge
    decides it. A bool is refused (``True`` is no duration), and so are NaN and infinities.
    """
    if isinstance(value, bool) or not isinstance(value, _REAL):
        raise ArgumentTypeError(
            f"failsafe_timeout must be a number of seconds, not {type(value).__name__}"
        )
    low, high = round(FAILSAFE_MIN * 1000), round(FAILSAFE_MAX * 1000)
    try:
        ms = round(float(value) * 1000)
    except (OverflowError, ValueError):  # an infinity, NaN
        ms = -1
    if not low <= ms <= high:
        raise ArgumentError(
            f"failsafe_timeout must be {FAILSAFE_MIN:g}..{FAILSAFE_MAX:g} s, not {value!r}"
        )
    return ms


def check_level(name: str, value: object) -> bool:
    """A digital level: True/False, or the ints 1/0; anything else is refused, never clamped.

    ``bool(2)`` is True, so accepting any int would turn a wrong value (a PWM
    duty, a pin number passed by mistake) into "on".
    """
    if isinstance(value, bool):
        return value
    if isinstance(value, Integral):
        if int(value) in (0, 1):
            return bool(value)
        raise refused(Status.STATUS_OUT_OF_RANGE, f"{name} {int(value)} is not a level (0 or 1)")
    raise ArgumentTypeError(f"{name} must be a bool, not {type(value).__name__}")


def refused(status: int, text: str) -> CommandRejectedError:
    return rejection(status, f"{text} ({status_name(status)})", sent=False)


#: The same for the type checker (an int is a float to it).
RealNumber = float | Fraction | Decimal


def interval_ms(name: str, seconds: object) -> int:
    """An input's interval in seconds as whole ms, 1..INPUT_INTERVAL_MAX_MS."""
    if isinstance(seconds, bool) or not isinstance(seconds, _REAL):
        raise ArgumentTypeError(f"{name} must be a number of seconds, not {type(seconds).__name__}")
    value = float(seconds)
    if not 0 < value <= INPUT_INTERVAL_MAX_MS / 1000:  # also NaN
        raise refused(
            Status.STATUS_INVALID_ARGUMENT,
            f"{name} {seconds} s is outside 0.001..{INPUT_INTERVAL_MAX_MS // 1000} s",
        )
    return max(1, round(value * 1000))


def period_ms(name: str, rate_hz: object) -> int:
    """A rate in Hz as the device's whole ms between samples (or reports), 1..60000."""
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, _REAL):
        raise ArgumentTypeError(f"{name} must be a number (Hz), not {type(rate_hz).__name__}")
    rate = float(rate_hz)
    slowest = 1000 / INPUT_INTERVAL_MAX_MS
    if not slowest <= rate <= 1000:  # also NaN
        raise refused(
            Status.STATUS_INVALID_ARGUMENT, f"{name} {rate_hz} is outside {slowest:g}..1000 Hz"
        )
    return min(INPUT_INTERVAL_MAX_MS, max(1, round(1000 / rate)))
