"""Wheel odometry: two encoders and the drive's direction pins to Odometry, /tf and ticks.

An encoder is a pulse counter (``Board.counter``): it counts edges, never
direction, and only ever counts up (wrapping at 2**32). The direction of
each wheel is the one the bridge itself drives on that motor's direction pin
(:attr:`.drive.Motor.forward`), so the ticks a wheel made since the last
sample are taken as forward or backward by that pin. While the direction is
unknown (before the first Twist, or after the device drove the motors safe
and forgot it) the wheel keeps the last direction it had, forward at the
start: a wheel coasting after a stop still turns the way it went.

Every ``1 / rate_hz`` (the bridge's loop, on its monotonic clock) :class:`Tracker`
takes both counts, turns their increments into signed distances
(``ticks / ticks_per_metre``) and integrates the pose (:func:`integrate`:
the exact arc of a differential drive, so a sample's size does not bend the
path). The bridge then publishes nav_msgs/Odometry (pose in ``frame_id``,
velocity in ``child_frame_id``), the same pose as the ``frame_id ->
child_frame_id`` transform on /tf (tf2_msgs/TFMessage), and the signed ticks
since the start as std_msgs/Int32MultiArray in the design notes' form
(left, right). The covariances are zero: the bridge has no model of the
wheels' slip.

The ticks of one sample get the direction the pin has when it is taken, and
the bridge takes one more just before it turns a direction pin (after the
drive set that motor's duty to 0: :class:`.drive.Motor`), so the ticks
reported until then count the old way. The device reports a count at most
``rate_hz`` times a second, so ticks made in the last moments before a
reversal and reported after it count the new way: the few ticks of a wheel
slowing down. The two counters are reported independently, so a sample may
hold one wheel's newest report and not yet the other's: the heading catches
up at the next sample, the position keeps a small offset (docs/ros2.md has
the measured cost); the heading and the ticks stay exact.

Everything but :class:`Tracker`'s inputs (a count and a direction per wheel,
and a clock) is a pure function, tested on a manual clock.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from .config import OdometryConfig
from .diagnostics import stamp
from .inputs import int32
from .msgs import (
    Header,
    Int32MultiArray,
    MultiArrayDimension,
    MultiArrayLayout,
    Odometry,
    Point,
    Pose,
    PoseWithCovariance,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Twist,
    TwistWithCovariance,
    Vector3,
)

#: A counter wraps at 2**32 (the device's uint32).
COUNT_MODULO = 1 << 32


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A pose on the floor: position (m) in the odometry frame, heading (rad, -pi..pi]."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


@dataclass(frozen=True, slots=True)
class Wheel:
    """What the odometry reads of one wheel: its encoder's count (None before the first
    report) and its direction (True forward; None unknown)."""

    count: Callable[[], int | None]
    forward: Callable[[], bool | None]


def tick_increment(new: int, old: int) -> int:
    """The ticks a counter made from ``old`` to ``new``, across its wrap at 2**32."""
    return (new - old) % COUNT_MODULO


def normalize_angle(theta: float) -> float:
    """``theta`` in (-pi, pi]."""
    wrapped = math.remainder(theta, math.tau)
    return math.pi if wrapped == -math.pi else wrapped


def integrate(pose: Pose2D, left: float, right: float, wheel_base: float) -> Pose2D:
    """The pose after the wheels travelled ``left`` and ``right`` metres (signed).

    The exact arc of a differential drive whose wheel speeds were constant meanwhile: the
    body moves ``(left + right) / 2`` along a circle and turns ``(right - left) /
    wheel_base`` radians (counter-clockwise positive, REP 103).
    """
    distance = (left + right) / 2
    turn = (right - left) / wheel_base
    theta = pose.theta
    if abs(turn) < 1e-12:
        dx, dy = distance * math.cos(theta), distance * math.sin(theta)
    else:
        radius = distance / turn
        dx = radius * (math.sin(theta + turn) - math.sin(theta))
        dy = -radius * (math.cos(theta + turn) - math.cos(theta))
    return Pose2D(pose.x + dx, pose.y + dy, normalize_angle(theta + turn))


def yaw_quaternion(theta: float) -> Quaternion:
    """The rotation by ``theta`` about z."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


@dataclass(frozen=True, slots=True)
class Sample:
    """One odometry sample: the pose, the body's velocity over the last interval (m/s
    along its heading, rad/s), and the signed ticks (left, right) since the start."""

    pose: Pose2D
    linear: float
    angular: float
    ticks: tuple[int, int]


def _header(config: OdometryConfig, at: float) -> Header:
    """Stamped ``at`` (Unix seconds: ROS time), in the odometry's frame."""
    return Header(stamp=stamp(at).stamp, frame_id=config.frame_id)


def odometry_message(sample: Sample, config: OdometryConfig, at: float) -> Odometry:
    """nav_msgs/Odometry: the pose in ``frame_id``, the velocity in ``child_frame_id``."""
    pose = sample.pose
    return Odometry(
        header=_header(config, at),
        child_frame_id=config.child_frame_id,
        pose=PoseWithCovariance(
            pose=Pose(position=Point(pose.x, pose.y, 0.0), orientation=yaw_quaternion(pose.theta))
        ),
        twist=TwistWithCovariance(
            twist=Twist(linear=Vector3(x=sample.linear), angular=Vector3(z=sample.angular))
        ),
    )


def tf_message(sample: Sample, config: OdometryConfig, at: float) -> TFMessage:
    """tf2_msgs/TFMessage with the one transform ``frame_id -> child_frame_id``."""
    pose = sample.pose
    transform = TransformStamped(
        header=_header(config, at),
        child_frame_id=config.child_frame_id,
        transform=Transform(
            translation=Vector3(pose.x, pose.y, 0.0), rotation=yaw_quaternion(pose.theta)
        ),
    )
    return TFMessage(transforms=[transform])


def ticks_message(ticks: Sequence[int]) -> Int32MultiArray:
    """The signed ticks (left, right) as the design notes have them (``left_ticks,right_ticks``),
    each wrapping as an int32."""
    layout = MultiArrayLayout(dim=[MultiArrayDimension(label="left_right", size=2, stride=2)])
    return Int32MultiArray(layout=layout, data=[int32(t) for t in ticks])


class Tracker:
    """The pose, integrated from both wheels' counts each time :meth:`update` or
    :meth:`sample` is called.

    The bridge calls :meth:`update` also just before the drive turns a direction pin
    (:attr:`.drive.Motor.before_turn`), so that the ticks already reported are counted the
    way the wheel was going.

    ``clock`` (monotonic seconds) times the velocity; it is injected so that the tracker is
    tested on a manual clock.
    """

    def __init__(
        self,
        config: OdometryConfig,
        wheel_base: float,
        left: Wheel,
        right: Wheel,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        self.wheel_base = wheel_base
        self.wheels = (left, right)
        self.clock = clock
        self.pose = Pose2D()
        self.ticks = [0, 0]
        #: Each wheel's last count (0 at the counter's Init, which the bridge made) and its
        #: last known direction.
        self._counts = [0, 0]
        self._forward = [True, True]
        self._at: float | None = None
        #: Metres each wheel travelled (signed) since the last sample: its velocity.
        self._travel = [0.0, 0.0]

    def update(self) -> None:
        """Take both counts, integrate what the wheels travelled since the last update."""
        step = [self._signed_ticks(i) for i in range(2)]
        for i in range(2):
            self.ticks[i] += step[i]
        left, right = (t / self.config.ticks_per_metre for t in step)
        self._travel = [self._travel[0] + left, self._travel[1] + right]
        self.pose = integrate(self.pose, left, right, self.wheel_base)

    def sample(self) -> Sample:
        """:meth:`update`, then the pose, the velocity since the last sample and the ticks."""
        self.update()
        now = self.clock()
        left, right = self._travel
        self._travel = [0.0, 0.0]
        linear = angular = 0.0
        if self._at is not None and now > self._at:
            dt = now - self._at
            linear = (left + right) / 2 / dt
            angular = (right - left) / self.wheel_base / dt
        self._at = now
        return Sample(self.pose, linear, angular, (self.ticks[0], self.ticks[1]))

    def _signed_ticks(self, index: int) -> int:
        wheel = self.wheels[index]
        forward = wheel.forward()
        if forward is not None:
            self._forward[index] = forward
        count = wheel.count()
        if count is None:
            return 0
        old, self._counts[index] = self._counts[index], count
        ticks = tick_increment(count, old)
        return ticks if self._forward[index] else -ticks
