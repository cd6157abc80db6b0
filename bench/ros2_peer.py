"""This process's side of the ROS 2 graph in benchmark part 8 (:mod:`bench.ros2`).

A module of its own so that :mod:`bench.ros2` imports cyclonedds only once its section runs
(a missing ``cyclonedds`` is then reported as "not run", not an import error of the bench).
A leaf: :mod:`bench.ros2` gives it the namespace, the topics and the waits, and it imports
nothing of the bench (the import goes one way).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from cyclonedds.core import Listener
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from protoduino.ros2.dds import DEFAULT_QOS, SENSOR_QOS, dds_topic
from protoduino.ros2.msgs import Bool, Float32, Twist, Vector3


def _matched(status: Callable[..., Any]) -> int:
    """How many remote endpoints an endpoint matched (cyclonedds leaves it untyped)."""
    return int(status().current_count)


class Peer:
    """This process's side of the graph: a Twist publisher on ``cmd_vel`` and listening
    subscribers (a Bool on each of ``bools``, a Float32 on each of ``floats``), in
    ``namespace`` on DDS domain ``domain``. ``settle``: how long (s) :meth:`wait_for` waits
    for a sample; ``start_timeout``: how long :meth:`wait_matched` waits for discovery."""

    def __init__(
        self,
        domain: int,
        namespace: str,
        *,
        bools: Iterable[str],
        floats: Iterable[str],
        settle: float,
        start_timeout: float,
    ) -> None:
        self.dp = DomainParticipant(domain)
        self.namespace = namespace
        self.settle = settle
        self.start_timeout = start_timeout
        twist = Topic(self.dp, dds_topic(namespace, "cmd_vel"), Twist, qos=DEFAULT_QOS)
        self.cmd_vel = DataWriter(self.dp, twist, qos=DEFAULT_QOS)
        self.readers: list[DataReader[Any]] = []
        #: topic -> (arrival, sample) of every sample received while ``recording``.
        self.arrivals: dict[str, list[tuple[float, Any]]] = {}
        self.recording: set[str] = set()
        self.arrived = threading.Condition()
        for name in bools:
            self.subscribe(name, Bool)
        for name in floats:
            self.subscribe(name, Float32)

    def subscribe(self, name: str, kind: type[Any]) -> None:
        self.arrivals[name] = []

        def on_data_available(reader: Any) -> None:  # Cyclone's thread: quick
            now = time.monotonic()
            samples = reader.take(N=64)
            if name in self.recording:
                with self.arrived:
                    self.arrivals[name] += [(now, s) for s in samples]
                    self.arrived.notify_all()

        topic = Topic(self.dp, dds_topic(self.namespace, name), kind, qos=SENSOR_QOS)
        listener: Any = Listener  # untyped in cyclonedds
        reader: DataReader[Any] = DataReader(
            self.dp, topic, qos=SENSOR_QOS, listener=listener(on_data_available=on_data_available)
        )
        self.readers.append(reader)

    def close(self) -> None:
        """Delete the DDS entities now, children first, their listeners detached.

        Left to the garbage collector, the participant went at some later moment while
        Cyclone's threads could still call a listener's Python closure: the bench
        process crashed (SIGSEGV) in the part after this one, now and then.
        """
        for reader in self.readers:
            reader.set_listener(None)
        entities: list[Any] = [*self.readers, self.cmd_vel, self.dp]
        self.readers.clear()
        for entity in entities:
            entity.__del__()  # cyclonedds deletes an entity in __del__; a second call is a no-op

    def wait_matched(self, readers: int) -> None:
        """Until the bridge's cmd_vel reader and ``readers`` of its writers are matched."""
        deadline = time.monotonic() + self.start_timeout
        while True:
            writer = _matched(self.cmd_vel.get_publication_matched_status)
            matched = sum(1 for r in self.readers if _matched(r.get_subscription_matched_status))
            if writer and matched >= readers:
                return
            if time.monotonic() > deadline:
                raise RuntimeError("the bridge's DDS topics were not discovered")
            time.sleep(0.02)

    def twist(self, linear: float) -> float:
        """Publish a Twist; returns the ``time.monotonic()`` just before it was written."""
        now = time.monotonic()
        self.cmd_vel.write(Twist(linear=Vector3(x=linear), angular=Vector3()))
        return now

    def wait_for(self, name: str, data: object, since: int) -> float | None:
        """The arrival time of the first sample from index ``since`` on carrying ``data``."""
        deadline = time.monotonic() + self.settle
        with self.arrived:
            while True:
                for when, sample in self.arrivals[name][since:]:
                    if sample.data == data:
                        return when
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self.arrived.wait(left)
