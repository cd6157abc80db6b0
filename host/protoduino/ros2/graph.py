"""The bridge as a ROS 2 node: its entry in ROS 2's node graph (issue 33).

A ROS 2 node is no DDS entity: every rmw publishes, per participant, which nodes
it holds and which of its readers and writers belong to each, as a
``rmw_dds_common/msg/ParticipantEntitiesInfo`` on the DDS topic
``ros_discovery_info`` (reliable, transient local, keep last 1, so that a
participant that joins later gets it too). ``ros2 node list`` (rclpy's
``get_node_names()``) and ``ros2 node info`` read that topic and match the GUIDs
with the endpoints DDS discovery found. :func:`announce` publishes the bridge's:
one node, ``protoduino`` in the bridge's namespace, with its readers (commands)
and writers (inputs, /diagnostics). The endpoint GUIDs are the 16 bytes of
``char[16] data`` of Jazzy's and Kilted's ``Gid`` (Humble's has 24: not supported).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from cyclonedds.core import Entity, Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from .msgs import Gid, NodeEntitiesInfo, ParticipantEntitiesInfo

#: The DDS topic of ROS 2's node graph (no "rt/": it is no ROS topic).
TOPIC = "ros_discovery_info"
#: The node name the bridge appears under, in its namespace.
NODE_NAME = "protoduino"
#: rmw_dds_common's QoS for it.
QOS = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
    Policy.Durability.TransientLocal,
    Policy.History.KeepLast(1),
)

__all__ = ["NODE_NAME", "QOS", "TOPIC", "announce", "node_namespace"]


def node_namespace(namespace: str) -> str:
    """The bridge's namespace as ROS 2 writes a node's: ``robot1`` -> ``/robot1``, none: ``/``."""
    return "/" + namespace.strip("/")


def _gid(entity: Entity) -> Gid:
    return Gid(data=list(entity.guid.bytes))


def announce(
    participant: DomainParticipant,
    namespace: str,
    readers: Iterable[Entity],
    writers: Iterable[Entity],
) -> DataWriter[Any]:
    """Publish the bridge's node with its ``readers`` and ``writers`` on ros_discovery_info;
    the writer returned keeps it there (transient local) as long as it lives."""
    topic = Topic(participant, TOPIC, ParticipantEntitiesInfo, qos=QOS)
    writer: DataWriter[Any] = DataWriter(participant, topic, qos=QOS)
    node = NodeEntitiesInfo(
        node_namespace=node_namespace(namespace),
        node_name=NODE_NAME,
        reader_gid_seq=[_gid(r) for r in readers],
        writer_gid_seq=[_gid(w) for w in writers],
    )
    writer.write(ParticipantEntitiesInfo(gid=_gid(participant), node_entities_info_seq=[node]))
    return writer
