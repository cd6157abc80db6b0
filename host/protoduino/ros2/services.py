"""The bridge's ``std_srvs/srv/Trigger`` services: STOP, resume and the interlock's clear.

ROS 2 services do not cross from Cyclone DDS's Python binding to rmw_fastrtps (ROS 2's
default middleware): a Fast DDS client takes a reply only when the RTPS message carries
the request's sample identity (writer GUID and sequence number) as its related sample
identity, beside the payload; Cyclone DDS has no sample identity in its API (neither to
read a request's nor to write a reply's), and rmw_cyclonedds pairs them through a header
in the payload instead, which Fast DDS does not read. So the services are answered by
ROS 2 itself: :class:`Services` starts a small rclpy node (``services_node.py``, run by
the interpreter ``services: python:`` names, in a session of its own) that relays each
call here as one JSON line; the bridge's loop carries it out (the board has one owner:
the bridge) and :meth:`Services.answer` sends the outcome back as the response.

It is started only when robot.yaml has ``services:``, and only serves when that
interpreter imports rclpy and std_srvs; otherwise the bridge runs without services (a
warning, and ``services`` on /diagnostics says why). The node holds nothing of the
board: it exits when its stdin ends (the bridge closed or died), so a killed bridge
leaves its device's failsafe to act exactly as without services.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import subprocess
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from .config import BridgeConfig, ros_topic, service_names
from .graph import node_namespace

#: The node's script, run by the configured interpreter (it imports nothing of protoduino).
SCRIPT = Path(__file__).with_name("services_node.py")
#: The node's name, in the bridge's namespace (beside the bridge's own ``protoduino``).
NODE_NAME = "protoduino_services"
#: The services' ROS 2 type.
TRIGGER = "std_srvs/srv/Trigger"
#: How long (s) the node waits for the bridge's answer before it answers a failure.
ANSWER_TIMEOUT = 10.0
#: How long (s) closing waits for the node to exit before it is killed.
CLOSE_WAIT = 3.0

log = logging.getLogger(__name__)

__all__ = ["NODE_NAME", "TRIGGER", "Call", "Services"]


@dataclass(frozen=True, slots=True)
class Call:
    """One call of a service: ``kind`` is what it does (``stop``, ``resume``,
    ``clear_interlock``), ``name`` its ROS name."""

    id: int
    kind: str
    name: str


class Services:
    """The rclpy node beside the bridge, and the calls it relays; see the module docstring.

    ``wake`` is called (from this object's reader thread) when a call arrives, to wake the
    bridge's loop; :meth:`take` hands the loop the calls waiting, :meth:`answer` answers
    one (any thread). ``state`` is what /diagnostics says of them.
    """

    def __init__(self, config: BridgeConfig, domain: int, wake: Callable[[], None]) -> None:
        assert config.services is not None
        self.python = config.services.python
        self.names = {
            kind: ros_topic(config.namespace, name) for kind, name in service_names(config).items()
        }
        self.namespace = node_namespace(config.namespace)
        self.domain = domain
        self.wake = wake
        self.state = "starting"
        self._calls: queue.SimpleQueue[Call] = queue.SimpleQueue()
        self._proc: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None
        self._write_lock = threading.Lock()
        self._closing = False

    def start(self) -> None:
        """Start the node (not waiting for it: it says when it is up, or why not)."""
        setup = {
            "node": NODE_NAME,
            "namespace": self.namespace,
            "services": self.names,
            "timeout": ANSWER_TIMEOUT,
        }
        try:
            self._proc = subprocess.Popen(
                [self.python, str(SCRIPT), json.dumps(setup)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                bufsize=1,
                # The bridge's domain; everything else (RMW_IMPLEMENTATION, discovery) as the
                # user's environment says, as for any ROS 2 node they run.
                env=dict(os.environ, ROS_DOMAIN_ID=str(self.domain)),
                # Not in the bridge's process group: a Ctrl-C stops the bridge, which then
                # closes the node's stdin.
                start_new_session=True,
            )
        except OSError as error:
            self._unavailable(f"cannot run {self.python}: {error.strerror or error}")
            return
        self._reader = threading.Thread(
            target=self._read, args=(self._proc.stdout,), name="ros2-services", daemon=True
        )
        self._reader.start()

    def take(self) -> list[Call]:
        """The calls waiting (the loop's thread)."""
        calls = []
        while True:
            try:
                calls.append(self._calls.get_nowait())
            except queue.Empty:
                return calls

    def answer(self, call: Call, success: bool, message: str) -> None:
        """Send ``call``'s response (a node already gone gets none: nothing to do)."""
        line = json.dumps({"answer": call.id, "success": success, "message": message})
        proc = self._proc
        if proc is None or proc.stdin is None:
            return
        with self._write_lock:
            try:
                proc.stdin.write(line + "\n")
                proc.stdin.flush()
            except (OSError, ValueError) as error:  # the node exited, or we are closing
                log.debug("services: %s not answered: %s", call.name, error)

    def close(self) -> None:
        """Close the node's stdin (it exits), wait for it, kill it if it does not."""
        self._closing = True
        proc, self._proc = self._proc, None
        if proc is None:
            return
        with self._write_lock:
            try:
                if proc.stdin is not None:
                    proc.stdin.close()
            except OSError:
                pass
        try:
            proc.wait(CLOSE_WAIT)
        except subprocess.TimeoutExpired:
            log.warning("services: the node did not exit in %g s: killed", CLOSE_WAIT)
            proc.kill()
            proc.wait()
        if self._reader is not None:
            self._reader.join(CLOSE_WAIT)
        if proc.stdout is not None:
            proc.stdout.close()
        self.state = "closed"

    def _unavailable(self, why: str) -> None:
        self.state = f"unavailable: {why}"
        log.warning("services: none (%s); STOP, resume and clear_interlock stay topics", why)

    def _read(self, lines: IO[str]) -> None:
        """The node's lines (its own thread), until it exits."""
        for line in lines:
            try:
                message: dict[str, Any] = json.loads(line)
            except ValueError:
                log.warning("services: the node wrote %r", line.rstrip())
                continue
            if "call" in message:
                kind = str(message.get("service"))
                if kind in self.names:
                    self._calls.put(Call(int(message["call"]), kind, self.names[kind]))
                    self.wake()
            elif "ready" in message:
                self.state = "up: " + ", ".join(message["ready"])
                log.info("services up (%s): %s", self.python, ", ".join(message["ready"]))
            elif "error" in message:
                self._unavailable(str(message["error"]))
        if not self._closing and not self.state.startswith("unavailable"):
            self._unavailable("the node exited")
