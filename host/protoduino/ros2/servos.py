"""Servo commands from ROS 2: a Float64 in degrees, a JointState in radians, checked.

Every conversion refuses what it cannot carry out exactly as asked
(:class:`BadCommandError`): a value out of range or not a number is never
clamped into a motion. A JointState is all or nothing, as the one pose it
becomes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..errors import BadCommandError
from .config import ServoConfig


def servo_degrees(value: float) -> int:
    """A Float64 in degrees as the whole degree the servo goes to (round half to even).

    Raises :class:`BadCommandError` when it is not a finite number within 0..180.
    """
    if not math.isfinite(value):
        raise BadCommandError(f"{value!r} degrees is not a finite number")
    if not 0.0 <= value <= 180.0:
        raise BadCommandError(f"{value:g} degrees is outside 0..180")
    return round(value)


def joint_degrees(position: float, servo: ServoConfig) -> int:
    """A joint position (radians, REP 103) as the servo's whole degree: zero + degrees(position)."""
    if not math.isfinite(position):
        raise BadCommandError(f"joint position {position!r} is not a finite number")
    degrees = servo.zero + math.degrees(position)
    if not -1e-9 <= degrees <= 180.0 + 1e-9:
        raise BadCommandError(
            f"joint position {position:g} rad is {degrees:g} degrees on the servo, outside 0..180"
        )
    return min(180, max(0, round(degrees)))


def joint_pose(message: Any, joints: Mapping[str, ServoConfig]) -> dict[int, int]:
    """A JointState's names and positions as servo pin -> degrees, all checked (all or nothing)."""
    names, positions = list(message.name), list(message.position)
    if not names:
        raise BadCommandError("a JointState with no joints")
    if len(names) != len(positions):
        raise BadCommandError(f"{len(names)} names but {len(positions)} positions")
    if len(set(names)) != len(names):
        raise BadCommandError(f"a joint named twice in {names}")
    unknown = [n for n in names if n not in joints]
    if unknown:
        raise BadCommandError(f"unknown joint(s) {unknown} (this board has {sorted(joints)})")
    return {
        joints[n].pin: joint_degrees(p, joints[n]) for n, p in zip(names, positions, strict=True)
    }
