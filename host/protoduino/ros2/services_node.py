"""The bridge's Trigger services on ROS 2: a small rclpy node that relays each call.

Run by the bridge (:mod:`.services`) with the interpreter ``services: python:`` of
robot.yaml names, as a script, never imported by protoduino: that interpreter is a ROS
2 installation's (it imports rclpy and std_srvs) and has no protoduino. It owns no
board and decides nothing: each call to one of its ``std_srvs/srv/Trigger`` services
goes to the bridge as one JSON line on stdout, and the bridge's loop (the board's one
owner) carries it out and answers with one JSON line on stdin, which becomes the
response. Why a process of its own: rmw_fastrtps, ROS 2's default middleware, pairs a
reply with its request by the request's sample identity, carried beside the payload in
the RTPS message, which Cyclone DDS (the bridge's DDS) can neither read nor write;
rclpy answers on whatever middleware its installation runs.

The lines (``argv[1]`` is the setup: ``{"node", "namespace", "services": {kind: name},
"timeout"}``):

* to the bridge: ``{"ready": [names]}`` once the services are up, or ``{"error": "..."}``
  (then it exits, status 1) when rclpy or std_srvs cannot be imported; ``{"call": id,
  "service": kind}`` for each call;
* from the bridge: ``{"answer": id, "success": bool, "message": "..."}``.

It exits when its stdin ends: the bridge closed it, or died (a killed bridge leaves no
services answering for it, and its device's failsafe acts as without them). A call the
bridge does not answer within ``timeout`` s is answered ``success: false``.
"""

from __future__ import annotations

import importlib
import itertools
import json
import queue
import sys
import threading
from typing import Any, TextIO


class Relay:
    """Calls out as lines, answers in: one line each way per call."""

    def __init__(self, out: TextIO, timeout: float) -> None:
        self.out = out
        self.timeout = timeout
        self.ids = itertools.count(1)
        self.lock = threading.Lock()
        self.pending: dict[int, queue.Queue[dict[str, Any]]] = {}
        self.gone = False

    def send(self, line: dict[str, Any]) -> None:
        with self.lock:
            self.out.write(json.dumps(line) + "\n")
            self.out.flush()

    def handler(self, kind: str) -> Any:
        """An rclpy service callback: Trigger's response from the bridge's answer."""

        def call(_request: Any, response: Any) -> Any:
            answer = self.ask(kind)
            response.success = bool(answer.get("success", False))
            response.message = str(answer.get("message", ""))
            return response

        return call

    def ask(self, kind: str) -> dict[str, Any]:
        box: queue.Queue[dict[str, Any]] = queue.Queue(maxsize=1)
        with self.lock:
            if self.gone:
                return {"success": False, "message": "the bridge is gone"}
            call = next(self.ids)
            self.pending[call] = box
        try:
            self.send({"call": call, "service": kind})
            return box.get(timeout=self.timeout)
        except queue.Empty:
            return {"success": False, "message": f"the bridge did not answer in {self.timeout} s"}
        except OSError as error:  # the bridge closed our stdout: it is going
            return {"success": False, "message": f"the bridge is gone: {error}"}
        finally:
            with self.lock:
                self.pending.pop(call, None)

    def read_answers(self, lines: TextIO) -> None:
        """Hand each answer to its call, until ``lines`` end (the bridge is gone)."""
        for line in lines:
            answer = json.loads(line)
            with self.lock:
                box = self.pending.get(int(answer["answer"]))
            if box is not None:
                box.put(answer)
        with self.lock:
            self.gone = True
            boxes = list(self.pending.values())
        for box in boxes:
            box.put({"success": False, "message": "the bridge is gone"})


def main() -> int:
    setup = json.loads(sys.argv[1])
    relay = Relay(sys.stdout, float(setup["timeout"]))
    try:
        rclpy: Any = importlib.import_module("rclpy")
        executors: Any = importlib.import_module("rclpy.executors")
        trigger: Any = importlib.import_module("std_srvs.srv").Trigger
    except ImportError as error:
        relay.send({"error": f"{sys.executable} cannot import {error.name}: {error}"})
        return 1
    rclpy.init()
    node = rclpy.create_node(
        setup["node"], namespace=setup["namespace"], start_parameter_services=False
    )
    for kind, name in setup["services"].items():
        node.create_service(trigger, name, relay.handler(kind))
    executor = executors.SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    relay.send({"ready": [node.resolve_service_name(n) for n in setup["services"].values()]})
    relay.read_answers(sys.stdin)
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
