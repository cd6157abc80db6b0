"""``/cmd_vel`` to a differential drive: the kinematics, and the motors behind a small interface.

The kinematics are pure functions (a Twist in, two wheel commands out), so
they are tested without a board. The motors are written against
:class:`PwmOutput` and :class:`DirectionOutput`, the two calls the drive
needs, so that it does not depend on how the board provides them.

A Twist the drive cannot carry out as asked (a wheel faster than
``max_speed``, a value that is not a finite number) is refused whole with
:class:`BadCommandError`: it is never scaled or clamped into a motion nobody
asked for. Only ``linear.x`` and ``angular.z`` mean anything to a
differential drive; the other components are ignored, as ROS 2's
diff_drive_controller does.

A Twist that was already older than the drive's timeout when it arrived (its
DDS source timestamp against the bridge's wall clock: queued by reliable DDS
through a freeze of the bridge or of the network) is refused as stale with
:class:`StaleCommandError`: the watchdog would have stopped the motors for
want of it, and nobody gives that command any more.

A write whose outcome is unknown (no Ack after every retry, the link down:
the device may have run it) counts as done for the watchdog's sake: a Twist
that raised arms the watchdog as one that was acknowledged does, and the
motor's duty or direction is unknown until a write of it is acknowledged.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from ..errors import BadCommandError, CommandRejectedError, StaleCommandError
from .config import DriveConfig, MotorConfig

#: A PWM duty's range (analogWrite's).
MAX_DUTY = 255


class PwmOutput(Protocol):
    """A PWM output: the only call the drive makes on it."""

    def write(self, duty: int) -> None: ...


class DirectionOutput(Protocol):
    """The digital pin that sets a motor's direction."""

    def write(self, level: bool) -> None: ...


@dataclass(frozen=True, slots=True)
class WheelCommand:
    duty: int  # 0..255
    forward: bool

    def level(self, motor: MotorConfig) -> bool:
        """The direction pin's level for this command on ``motor`` (high = forward)."""
        return self.forward != motor.invert


def wheel_speeds(linear_x: float, angular_z: float, wheel_base: float) -> tuple[float, float]:
    """Left and right wheel speeds (m/s) for a body speed (m/s) and turn rate (rad/s)."""
    half = angular_z * wheel_base / 2
    return linear_x - half, linear_x + half


def wheel_command(speed: float, max_speed: float) -> WheelCommand:
    """One wheel's speed (m/s) as a duty 0..255 (rounded to nearest) and a direction.

    Raises :class:`BadCommandError` for a speed beyond ``max_speed`` or not finite.
    """
    if not math.isfinite(speed):
        raise BadCommandError(f"wheel speed {speed!r} is not a finite number")
    if abs(speed) > max_speed * (1 + 1e-9):  # rounding of v +- w*b/2 must not refuse max_speed
        raise BadCommandError(f"wheel speed {speed:g} m/s exceeds max_speed {max_speed:g} m/s")
    duty = min(MAX_DUTY, round(abs(speed) / max_speed * MAX_DUTY))
    return WheelCommand(duty, speed >= 0)


def twist_to_wheels(
    linear_x: float, angular_z: float, drive: DriveConfig
) -> tuple[WheelCommand, WheelCommand]:
    """A Twist's ``linear.x`` and ``angular.z`` as the left and right wheel commands.

    Raises :class:`BadCommandError` (nothing to move) when either is not finite or
    either wheel would exceed ``drive.max_speed``.
    """
    for name, value in (("linear.x", linear_x), ("angular.z", angular_z)):
        if not math.isfinite(value):
            raise BadCommandError(f"{name} = {value!r} is not a finite number")
    left, right = wheel_speeds(linear_x, angular_z, drive.wheel_base)
    return wheel_command(left, drive.max_speed), wheel_command(right, drive.max_speed)


class Motor:
    """One wheel's motor: a PWM output for the speed and a digital output for the direction."""

    def __init__(self, config: MotorConfig, pwm: PwmOutput, direction: DirectionOutput) -> None:
        self.config = config
        self.pwm = pwm
        self.direction = direction
        #: The duty and direction level the device acknowledged; None: unknown (a write
        #: that raised may or may not have run, or the level was never set).
        self.duty: int | None = 0
        self.level: bool | None = None
        #: Called once the duty is 0, just before the direction pin turns (the odometry
        #: counts the wheel's ticks so far the old way).
        self.before_turn: Callable[[], None] | None = None

    @property
    def forward(self) -> bool | None:
        """The way the direction pin drives the wheel (True: forward); None: not known."""
        return None if self.level is None else self.level != self.config.invert

    def apply(self, command: WheelCommand) -> None:
        level = command.level(self.config)
        if level != self.level:
            if self.duty != 0:
                # Never drive the old duty (or an unknown one) the other way round while
                # the pin turns.
                self._write_duty(0)
            if self.before_turn is not None:
                self.before_turn()
            self.level = None  # unknown until acknowledged
            self.direction.write(level)
            self.level = level
        if command.duty != self.duty:
            self._write_duty(command.duty)

    def stop(self) -> None:
        """Duty 0, the PWM output's safe value (the direction pin stays as it is)."""
        self._write_duty(0)

    def _write_duty(self, duty: int) -> None:
        self.duty = None  # unknown until acknowledged
        self.pwm.write(duty)
        self.duty = duty

    def forget(self) -> None:
        """The device drove this motor safe itself (Stop, failsafe): duty 0, direction unknown."""
        self.duty = 0
        self.level = None


class DiffDrive:
    """Twists to the two motors, and the ``cmd_vel`` watchdog.

    :meth:`command` applies a Twist; :meth:`check` (called from the bridge's
    loop with the time) stops both motors once no Twist came for
    ``config.timeout`` seconds since the last one, once per silence.
    A Twist arms the watchdog whatever the outcome of its writes (one that
    raised may have run); a stop whose outcome is unknown leaves it armed, to
    try again a timeout later. :meth:`check_fresh` refuses a Twist that was
    older than the timeout when it arrived. ``clock`` (monotonic, for the
    watchdog) and ``wall_clock`` (Unix seconds, what DDS source timestamps are
    in) are injected so that both rules are tested without waiting.
    """

    def __init__(
        self,
        config: DriveConfig,
        left: Motor,
        right: Motor,
        clock: Callable[[], float],
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.config = config
        self.left = left
        self.right = right
        self.clock = clock
        self.wall_clock = wall_clock
        self.last: float | None = None  # when the last Twist was applied; None: stopped
        self.stale_stops = 0

    def check_fresh(self, written: float | None) -> None:
        """Refuse (:class:`StaleCommandError`) a Twist written at ``written`` (Unix seconds:
        its DDS source timestamp; None: not known, taken as fresh) that is already older
        than the timeout. The publisher's clock and the bridge's must agree well within
        the timeout (NTP, as ROS 2 expects anyway); one that lags refuses every Twist,
        which stops the robot rather than driving it on old commands."""
        if written is None:
            return
        age = self.wall_clock() - written
        if age > self.config.timeout:
            raise StaleCommandError(
                f"a Twist written {age:.3f} s ago, more than the {self.config.timeout:g} s "
                "timeout: stale on arrival (queued through a freeze, or the publisher's "
                "clock is behind the bridge's)"
            )

    def command(self, linear_x: float, angular_z: float) -> None:
        """Apply one Twist; :class:`BadCommandError` leaves the motors as they were."""
        self.apply(*twist_to_wheels(linear_x, angular_z, self.config))

    def apply(self, left: WheelCommand, right: WheelCommand) -> None:
        """Apply a Twist already converted (:func:`twist_to_wheels`); feeds the watchdog,
        even when a write raised: its outcome is unknown (no Ack: the device may have run
        it), or the other motor's write ran, so the motors may be running."""
        try:
            self.left.apply(left)
            self.right.apply(right)
        finally:
            self.last = self.clock()

    def deadline(self) -> float | None:
        """When the watchdog fires if no Twist comes (None: the motors are stopped)."""
        return None if self.last is None else self.last + self.config.timeout

    def check(self) -> bool:
        """Stop the motors if the last Twist is older than the timeout; True if it did."""
        due = self.deadline()
        if due is None or self.clock() < due:
            return False
        self.stop()
        self.stale_stops += 1
        return True

    def stop(self) -> None:
        """Both motors at duty 0; the watchdog disarmed once that is done, or refused (the
        device refuses a value only while it holds every output safe itself). A write
        whose outcome is unknown re-arms it: the stop is tried again a timeout later."""
        self.last = self.clock()
        try:
            self.left.stop()
            self.right.stop()
        except CommandRejectedError:
            self.last = None
            raise
        self.last = None

    def forget(self) -> None:
        """The device drove the motors safe itself: nothing to stop until the next Twist."""
        self.last = None
        self.left.forget()
        self.right.forget()
