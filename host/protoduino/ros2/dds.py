"""ROS 2's conventions on DDS: topic names and QoS profiles.

ROS 2 puts topic ``/ns/name`` on DDS as ``rt/ns/name`` ("rt" for ROS
topic). Its QoS presets, as rclcpp defines them: sensor data is best effort,
keep last 5, volatile (a late sample is worth nothing; the newest wins);
everything else (commands, /diagnostics) is reliable, keep last 10,
volatile. A reliable subscriber does not match a best-effort publisher, so
the bridge's command subscriptions being reliable is what ``ros2 topic pub``
(reliable by default) expects.

:func:`participant` joins the domain as rmw_cyclonedds_cpp matches a ROS 2
graph: on type names. Fast DDS (rmw_fastrtps_cpp, ROS 2's default middleware)
announces XTypes type information with every endpoint; Cyclone, which attaches
its own to every topic the Python binding creates, sees that the two differ
for every type with a string or a sequence of structs and asks Fast DDS for its
type objects to check assignability, refuses them as invalid
(``ddsi_xt_type_add_typeobj with invalid type object``) and leaves the
endpoints matched in name only: no sample ever flows either way. rmw_cyclonedds
attaches no type information, so Cyclone matches Fast DDS's endpoints on the
type name and never resolves those objects. The binding cannot create a topic
without type information, so the bridge's domain ignores the type information
of eProsima's participants (Cyclone's ``Compatibility/IgnoreTypeInformation``
for vendor id 1.15): their endpoints match on the type name, as they do with
rmw_cyclonedds; Cyclone peers (rmw_cyclonedds, Cyclone's Python) are matched
as before.
"""

from __future__ import annotations

import logging
import os

from cyclonedds.core import DDSException, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
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


#: eProsima's DDSI vendor id: Fast DDS, rmw_fastrtps_cpp's middleware.
EPROSIMA = "1.15"
#: The bridge's part of its Cyclone configuration, after the user's ``CYCLONEDDS_URI``.
TYPE_NAME_MATCHING = (
    '<CycloneDDS><Domain id="any"><Compatibility>'
    f"<IgnoreTypeInformation>{EPROSIMA}</IgnoreTypeInformation>"
    "</Compatibility></Domain></CycloneDDS>"
)

log = logging.getLogger(__name__)

__all__ = [
    "DEFAULT_QOS",
    "SENSOR_QOS",
    "TYPE_NAME_MATCHING",
    "dds_topic",
    "domain_config",
    "participant",
    "ros_topic",
]


def domain_config(user: str | None = None) -> str:
    """The bridge's Cyclone configuration: ``user``'s (by default ``$CYCLONEDDS_URI``), which
    chooses interfaces and peers, then :data:`TYPE_NAME_MATCHING`."""
    if user is None:
        user = os.environ.get("CYCLONEDDS_URI", "")
    user = user.strip()
    return f"{user},{TYPE_NAME_MATCHING}" if user else TYPE_NAME_MATCHING


#: The domains this process configured, kept for its lifetime: deleting one would delete
#: every participant in it, other code's too.
_DOMAINS: dict[int, Domain] = {}


def participant(domain_id: int) -> DomainParticipant:
    """A participant in ``domain_id``, whose domain :func:`domain_config` configures (unless
    this process created it before, with the configuration it was given then, kept)."""
    if domain_id not in _DOMAINS:
        try:
            _DOMAINS[domain_id] = Domain(domain_id, domain_config())
        except DDSException:
            # Created earlier in this process (e.g. by a participant of its own): one
            # configuration per domain and process.
            log.info("DDS domain %d exists in this process: its configuration stays", domain_id)
    return DomainParticipant(domain_id)


def dds_topic(namespace: str, name: str) -> str:
    """The DDS topic of ROS topic ``name`` in ``namespace`` (an absolute name ignores it)."""
    return "rt" + ros_topic(namespace, name)
