"""ROS 2's conventions on DDS: topic names and QoS profiles.

ROS 2 puts topic ``/ns/name`` on DDS as ``rt/ns/name`` ("rt" for ROS
topic). Its QoS presets, as rclcpp defines them: sensor data is best effort,
keep last 5, volatile (a late sample is worth nothing; the newest wins);
everything else (commands, /diagnostics) is reliable, keep last 10,
volatile. A reliable subscriber does not match a best-effort publisher, so
the bridge's command subscriptions being reliable is what ``ros2 topic pub``
(reliable by default) expects.
"""

from __future__ import annotations

from cyclonedds.core import Policy, Qos
from cyclonedds.util import duration

from .config import ros_topic

#: rmw_qos_profile_sensor_data.
SENSOR_QOS = Qos(
    Policy.Reliability.BestEffort,
    Policy.History.KeepLast(5),
    Policy.Durability.Volatile,
)

#: rmw_qos_profile_default: commands and /diagnostics.
DEFAULT_QOS = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
    Policy.History.KeepLast(10),
    Policy.Durability.Volatile,
)


__all__ = ["DEFAULT_QOS", "SENSOR_QOS", "dds_topic", "ros_topic"]


def dds_topic(namespace: str, name: str) -> str:
    """The DDS topic of ROS topic ``name`` in ``namespace`` (an absolute name ignores it)."""
    return "rt" + ros_topic(namespace, name)
