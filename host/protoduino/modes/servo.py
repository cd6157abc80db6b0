"""The servo mode: :class:`Servo`, its ServoInit (limits, safe position, speed limit) and
its checks.

Servo pulses come from the servos' timer (``info.timer_pins("servos")``), which a PWM output
on the same timer rules out: the board's :func:`~protoduino.board.conflict`, which spans the
modes, says so.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any, Literal, SupportsFloat

from ..arguments import Pin, check_int, refused, whole_number
from ..commands import SERVO
from ..constants import (
    SERVO_DEFAULT_MAX_US,
    SERVO_DEFAULT_MIN_US,
    SERVO_FRAME,
    SERVO_LIMIT_MAX_US,
    SERVO_LIMIT_MIN_US,
    SERVO_MAX_DEGREES,
    SERVO_MAX_SPEED,
)
from ..errors import ArgumentTypeError
from ..messages import ArduinoIn, Status
from .base import Built, ModeBoard, OutputBoard, PinRecord

#: Servo speed limits step once per 20 ms servo frame: a limit is a whole
#: number of us per frame, 1 .. 255 (ServoInit.max_speed, docs/protocol.md).
FRAMES_PER_SECOND = round(1 / SERVO_FRAME)
MAX_SPEED_US = SERVO_MAX_SPEED


def effective_speed(us_per_second: int) -> int:
    """The speed the device keeps for a requested ``max_speed`` (us/s): whole us per frame."""
    if us_per_second <= 0:
        return 0
    step = max(1, (us_per_second + FRAMES_PER_SECOND // 2) // FRAMES_PER_SECOND)
    return step * FRAMES_PER_SECOND


def init(  # noqa: PLR0917  (Board.servo()'s arguments, checked in one place)
    board: ModeBoard,
    pin: Pin,
    safe: int | Literal["detach"] | None,
    safe_us: int | None,
    min_us: int,
    max_us: int,
    max_speed: float | None,
    max_speed_us: int | None,
) -> Built[Servo]:
    """Check a servo's configuration; its ServoInit, what to record at the Ack, its object."""
    pin = board._check_pin(pin, SERVO)
    min_us = check_int("min_us", min_us) or SERVO_DEFAULT_MIN_US
    max_us = check_int("max_us", max_us) or SERVO_DEFAULT_MAX_US
    if safe is not None and safe_us is not None:
        raise ArgumentTypeError("give safe (degrees) or safe_us, not both")
    if min_us < SERVO_LIMIT_MIN_US or max_us > SERVO_LIMIT_MAX_US or min_us >= max_us:
        raise refused(
            Status.STATUS_INVALID_ARGUMENT,
            f"servo limits [{min_us}, {max_us}] us must satisfy "
            f"{SERVO_LIMIT_MIN_US} <= min_us < max_us <= {SERVO_LIMIT_MAX_US}",
        )
    speed = speed_limit(max_speed, max_speed_us, max_us - min_us)
    msg = ArduinoIn()
    servo_init = msg.servo_init
    servo_init.pin, servo_init.min_us, servo_init.max_us = pin, min_us, max_us
    servo_init.max_speed = speed
    if safe_us is not None:
        safe_us = check_int("safe_us", safe_us)
        if not min_us <= safe_us <= max_us:
            raise refused(
                Status.STATUS_OUT_OF_RANGE, f"safe_us {safe_us} is outside [{min_us}, {max_us}]"
            )
        servo_init.safe_us = safe_us
    elif safe == "detach":
        servo_init.safe_detach = True
    else:
        safe = 90 if safe is None else check_int("safe", safe)
        if not 0 <= safe <= SERVO_MAX_DEGREES:
            raise refused(Status.STATUS_OUT_OF_RANGE, f"safe {safe} degrees is outside 0..180")
        servo_init.safe_degrees = safe
    with board._lock:
        board._check_free(pin, SERVO)
        current = board._outputs.get(pin)
        servos = sum(1 for o in board._outputs.values() if o.mode is SERVO)
        if current is None and servos >= board.info.max_servos:
            raise refused(
                Status.STATUS_NO_FREE_RESOURCE,
                f"all {board.info.max_servos} servo slots are in use",
            )
    servo = Servo(board, pin, min_us, max_us, effective_speed(speed))
    which = servo_init.WhichOneof("safe")
    if which == "safe_detach":
        width = 0  # no pulses
    else:
        width = servo_init.safe_us if which == "safe_us" else servo.to_us(servo_init.safe_degrees)
    state = PinRecord(SERVO, msg.SerializeToString(), width, min_us, max_us)
    return msg, lambda: board._set_output(pin, state), servo


def speed_limit(degrees_per_s: float | None, us_per_s: int | None, span_us: int) -> int:
    """A speed limit as ServoInit.max_speed (us per second, 0: none), checked."""
    if degrees_per_s is not None and us_per_s is not None:
        raise ArgumentTypeError("give max_speed (degrees/s) or max_speed_us, not both")
    if degrees_per_s is not None:
        if isinstance(degrees_per_s, bool) or not isinstance(degrees_per_s, int | float):
            raise ArgumentTypeError(
                f"max_speed must be a number, not {type(degrees_per_s).__name__}"
            )
        if not degrees_per_s > 0:  # also NaN
            raise refused(Status.STATUS_INVALID_ARGUMENT, "max_speed must be above 0")
        us_per_s = max(1, round(degrees_per_s * span_us / SERVO_MAX_DEGREES))
    elif us_per_s is None:
        return 0
    else:
        us_per_s = check_int("max_speed_us", us_per_s)
        if us_per_s <= 0:
            raise refused(Status.STATUS_INVALID_ARGUMENT, "max_speed_us must be above 0")
    if us_per_s > MAX_SPEED_US:
        raise refused(
            Status.STATUS_INVALID_ARGUMENT,
            f"a speed limit of {us_per_s} us/s is above the device's {MAX_SPEED_US}",
        )
    return us_per_s


class Servo:
    """A servo output; get one from :meth:`Board.servo`."""

    def __init__(
        self, board: OutputBoard, pin: int, min_us: int, max_us: int, max_speed_us: int = 0
    ) -> None:
        self.board = board
        self.pin = pin
        self.min_us = min_us
        self.max_us = max_us
        #: The speed limit the device keeps (us per second; 0: none, values jump).
        self.max_speed_us = max_speed_us

    @property
    def value(self) -> int | None:
        """The pulse width (us) the device last acknowledged for this servo.

        Its safe width after the Init, a Stop or a failsafe (0 for ``safe="detach"``:
        no pulses); None once the pin was released or configured anew as
        something else (or for a servo object that stands for a configuration
        since replaced).
        """
        return self.board._value(self.pin, SERVO)

    def _pose_item(self, item: Any, value: object) -> tuple[bytes, int]:
        """Fill a pose's item with ``value``; return this output's own Control (as bytes,
        for a restore) and the value it sets."""
        msg, us = self._degrees(value)
        item.servo.CopyFrom(msg.servo_control)
        return msg.SerializeToString(), us

    def to_us(self, degrees: int) -> int:
        """The pulse width the device makes for ``degrees`` (its own integer formula)."""
        return self.min_us + degrees * (self.max_us - self.min_us) // SERVO_MAX_DEGREES

    def write(self, degrees: SupportsFloat) -> None:
        """Move to ``degrees`` (0..180, mapped linearly onto [min_us, max_us]).

        Any real number: it is rounded to the nearest whole degree first, a half to
        the even one (``round()``), which must then be within 0..180.
        """
        self.board._control(self.pin, *self._degrees(degrees))

    def write_us(self, us: SupportsFloat) -> None:
        """Set the pulse width in microseconds (within [min_us, max_us]).

        Any real number, rounded to the nearest whole microsecond as :meth:`write` rounds.
        """
        self.board._control(self.pin, *self._us(us))

    def submit(self, degrees: SupportsFloat) -> Future[None]:
        """:meth:`write` without waiting: a future resolved by the Ack."""
        return self.board._control_future(self.pin, *self._degrees(degrees))

    def submit_us(self, us: SupportsFloat) -> Future[None]:
        """:meth:`write_us` without waiting: a future resolved by the Ack."""
        return self.board._control_future(self.pin, *self._us(us))

    def _degrees(self, value: object) -> tuple[ArduinoIn, int]:
        degrees = whole_number("degrees", value)
        if not 0 <= degrees <= SERVO_MAX_DEGREES:
            raise refused(Status.STATUS_OUT_OF_RANGE, f"{degrees} degrees is outside 0..180")
        msg = ArduinoIn()
        msg.servo_control.pin = self.pin
        msg.servo_control.degrees = degrees
        return msg, self.to_us(degrees)

    def _us(self, value: object) -> tuple[ArduinoIn, int]:
        us = whole_number("us", value)
        if not self.min_us <= us <= self.max_us:
            raise refused(
                Status.STATUS_OUT_OF_RANGE,
                f"{us} us is outside this servo's [{self.min_us}, {self.max_us}]",
            )
        msg = ArduinoIn()
        msg.servo_control.pin = self.pin
        msg.servo_control.us = us
        return msg, us

    def release(self) -> None:
        """Release the servo: its pulses stop (limp) and the pin is free for any mode."""
        self.board.release(self.pin)

    def submit_release(self) -> Future[None]:
        """:meth:`release` without waiting: a future resolved by the Ack."""
        return self.board.submit_release(self.pin)

    def __repr__(self) -> str:
        return f"Servo(pin={self.pin}, min_us={self.min_us}, max_us={self.max_us})"
