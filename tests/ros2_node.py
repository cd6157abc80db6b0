"""A real ROS 2 node for the tests: rclpy on Fast DDS, driven through JSON lines.

Run by the ROS 2 venv's interpreter (``.deps/ros2-venv``, installed by
``tools/dev.sh setup``), never imported by the suite's: ``bench/ros2_rclpy.py``'s
``RclpyNode`` (which tests/e2e/test_ros2_real.py and the bench's part 8 use) starts it as a
subprocess and sends one JSON request per line on its stdin; each gets one JSON line on
stdout, ``{"ok": ...}`` or ``{"error": "..."}``.
Requests (``type`` is a ROS 2 name, ``std_msgs/msg/Bool``; ``qos`` is ``sensor``
for rclpy's ``qos_profile_sensor_data``, else the default profile, reliable, keep
last 10):

* ``{"op": "sub", "topic", "type", "qos"}``: subscribe; samples are kept;
* ``{"op": "take", "topic"}``: the samples received since the last take (dicts);
  ``"stamped": true``: each as ``[t, dict]``, ``t`` the ``time.monotonic()`` at which the
  subscription's callback began (CLOCK_MONOTONIC: one clock for every process here);
* ``{"op": "pub", "topic", "type", "msg": {...}}``: publish (a publisher is made on
  first use and waits until it matched a subscription, up to ``timeout`` s); answers
  how many subscriptions it matched, or with ``"stamped": true`` ``[matched, t]``, ``t``
  the ``time.monotonic()`` just before the message was handed to rclpy;
* ``{"op": "publishers", "topic"}``: how many publishers the graph has on it;
* ``{"op": "graph"}``: every node (name, namespace) with its publishers, subscriptions
  and services, as ``ros2 node list`` / ``ros2 node info`` show them (a node that leaves
  while it is read is left out);
* ``{"op": "call", "service", "type", "request": {...}}``: call a service once it is
  there, up to ``timeout`` s.

Message and service classes come from the installed ROS 2 packages, fields are set
and read through rosidl's introspection (``get_fields_and_field_types``). The
modules are imported by name (importlib) so that the suite's mypy, which has no
ROS 2, checks this file too.
"""

from __future__ import annotations

import importlib
import json
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

rclpy: Any = importlib.import_module("rclpy")
rclpy_qos: Any = importlib.import_module("rclpy.qos")
executors: Any = importlib.import_module("rclpy.executors")
#: rclpy's error for a node that is not (or no longer) in the graph.
NodeGone: Any = importlib.import_module("rclpy._rclpy_pybind11").NodeNameNonExistentError


def ros_class(name: str) -> Any:
    """``pkg/msg/Type`` (or ``pkg/srv/Type``) -> its Python class."""
    pkg, kind, type_name = name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), type_name)


def to_dict(message: Any) -> Any:
    """A message as plain JSON values, through its introspection."""
    if hasattr(message, "get_fields_and_field_types"):
        return {f: to_dict(getattr(message, f)) for f in message.get_fields_and_field_types()}
    if isinstance(message, (list, tuple)) or hasattr(message, "tolist"):
        return [to_dict(v) for v in (message.tolist() if hasattr(message, "tolist") else message)]
    if isinstance(message, bytes):
        return message[0] if len(message) == 1 else list(message)
    return message


def fill(message: Any, values: dict[str, Any]) -> Any:
    """``message`` with ``values`` set, nested messages filled recursively."""
    for name, value in values.items():
        current = getattr(message, name)
        if isinstance(value, dict):
            fill(current, value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            kind = type(current[0]) if current else None
            if kind is None:
                types = message.get_fields_and_field_types()
                element = types[name].split("<", 1)[1].rstrip(">").split(",")[0]
                kind = ros_class(element.replace("/", "/msg/", 1))
            setattr(message, name, [fill(kind(), v) for v in value])
        else:
            setattr(message, name, value)
    return message


class Node:
    def __init__(self) -> None:
        rclpy.init()
        self.node = rclpy.create_node("ros2real_probe")
        self.lock = threading.Lock()
        #: topic -> (callback time, sample as a dict) since the last take.
        self.samples: dict[str, list[tuple[float, Any]]] = {}
        self.subscriptions: dict[str, Any] = {}
        self.publishers: dict[str, Any] = {}
        self.executor = executors.SingleThreadedExecutor()
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    @staticmethod
    def qos(name: str | None) -> Any:
        return rclpy_qos.qos_profile_sensor_data if name == "sensor" else 10

    def sub(self, topic: str, type: str, qos: str | None = None) -> bool:
        def received(message: Any) -> None:
            now = time.monotonic()
            sample = to_dict(message)
            with self.lock:
                self.samples[topic].append((now, sample))

        self.samples.setdefault(topic, [])
        self.subscriptions[topic] = self.node.create_subscription(
            ros_class(type), topic, received, self.qos(qos)
        )
        return True

    def take(self, topic: str, stamped: bool = False) -> list[Any]:
        with self.lock:
            taken, self.samples[topic] = self.samples[topic], []
        return [[t, s] for t, s in taken] if stamped else [s for _, s in taken]

    def pub(
        self,
        topic: str,
        type: str,
        msg: dict[str, Any],
        timeout: float = 30.0,
        stamped: bool = False,
    ) -> Any:
        if topic not in self.publishers:
            self.publishers[topic] = self.node.create_publisher(ros_class(type), topic, 10)
        publisher = self.publishers[topic]
        deadline = time.monotonic() + timeout
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        message = fill(ros_class(type)(), msg)
        now = time.monotonic()
        publisher.publish(message)
        matched = int(publisher.get_subscription_count())
        return [matched, now] if stamped else matched

    def count_publishers(self, topic: str) -> int:
        return int(self.node.count_publishers(topic))

    def graph(self) -> list[dict[str, Any]]:
        found = []
        for name, namespace in self.node.get_node_names_and_namespaces():
            node = self.node
            try:
                found.append(
                    {
                        "name": name,
                        "namespace": namespace,
                        "publishers": node.get_publisher_names_and_types_by_node(name, namespace),
                        "subscriptions": node.get_subscriber_names_and_types_by_node(
                            name, namespace
                        ),
                        "services": node.get_service_names_and_types_by_node(name, namespace),
                    }
                )
            except NodeGone:
                # It left the graph between the listing and its queries (a killed bridge's
                # node, as the test that waits for that saw on CI): it is not in the graph.
                continue
        return found

    def call(
        self, service: str, type: str, request: dict[str, Any] | None = None, timeout: float = 30.0
    ) -> Any:
        kind = ros_class(type)
        client = self.node.create_client(kind, service)
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                raise TimeoutError(f"{service}: no such service after {timeout} s")
            future = client.call_async(fill(kind.Request(), request or {}))
            deadline = time.monotonic() + timeout
            while not future.done():
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{service}: no response after {timeout} s")
                time.sleep(0.01)
            return to_dict(future.result())
        finally:
            self.node.destroy_client(client)


def main() -> None:
    node = Node()
    handlers: dict[str, Callable[..., Any]] = {
        "sub": node.sub,
        "take": node.take,
        "pub": node.pub,
        "publishers": node.count_publishers,
        "graph": node.graph,
        "call": node.call,
    }
    print(json.dumps({"ok": "ready"}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        op = request.pop("op")
        try:
            answer: dict[str, Any] = {"ok": handlers[op](**request)}
        except Exception as error:  # reported to the test, which fails on it
            answer = {"error": f"{type(error).__name__}: {error}"}
        print(json.dumps(answer), flush=True)
    node.executor.shutdown()
    node.node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
