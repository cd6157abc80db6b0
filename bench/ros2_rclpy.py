"""A real ROS 2 node for benchmark part 8 (:mod:`bench.ros2`): rclpy on Fast DDS.

The node is ``tests/ros2_node.py`` (the one tests/e2e/test_ros2_real.py drives), run by the
ROS 2 venv's interpreter (``.deps/ros2-venv``, installed by ``tools/dev.sh setup``: ROS 2
Kilted's wheels, rclpy on rmw_fastrtps_cpp) and driven through JSON lines. It stamps what it
publishes and what its callbacks receive with ``time.monotonic()``, which is
CLOCK_MONOTONIC, the same clock in this process: the bench subtracts the two directly.
A leaf: it imports nothing of the bench.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: The ROS 2 venv's interpreter (tools/dev.sh setup) and the node it runs.
PYTHON = ROOT / ".deps" / "ros2-venv" / "bin" / "python"
SCRIPT = ROOT / "tests" / "ros2_node.py"


def rclpy_versions() -> str:
    """The node's rclpy, rmw_fastrtps_cpp and Fast DDS versions, as the venv has them."""
    if not PYTHON.exists():
        raise NodeUnavailableError(f"{PYTHON} is missing (./tools/dev.sh setup installs it)")
    wheels = ("ros-rclpy", "ros-rmw-fastrtps-cpp", "ros-fastdds")
    code = "import importlib.metadata as m, sys; print(*(m.version(w) for w in sys.argv[1:]))"
    done = subprocess.run(
        [str(PYTHON), "-c", code, *wheels], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise NodeUnavailableError(f"{PYTHON}: {done.stderr.strip()[-300:]}")
    rclpy, rmw, fastdds = done.stdout.split()
    return f"rclpy {rclpy} on rmw_fastrtps_cpp {rmw} (Fast DDS {fastdds})"


class NodeUnavailableError(RuntimeError):
    """The ROS 2 venv is missing, or the node died."""


class RclpyNode:
    """The node in its subprocess, on DDS domain ``domain``, discovering over loopback only;
    its stderr goes to ``log``. tests/e2e/test_ros2_real.py drives it too."""

    #: The interpreter that runs it.
    python = PYTHON

    def __init__(self, domain: int, log: Path) -> None:
        if not PYTHON.exists():
            raise NodeUnavailableError(f"{PYTHON} is missing (./tools/dev.sh setup installs it)")
        env = dict(
            os.environ,
            ROS_DOMAIN_ID=str(domain),
            RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        )
        env.pop("CYCLONEDDS_URI", None)
        self.log = log
        self._stderr = log.open("w")
        self.proc = subprocess.Popen(
            [str(PYTHON), str(SCRIPT)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            env=env,
            text=True,
        )
        self._answer()  # "ready"

    def _answer(self) -> Any:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            raise NodeUnavailableError(f"the rclpy node died: {self.log.read_text()[-500:]}")
        answer = json.loads(line)
        if "error" in answer:
            raise NodeUnavailableError(f"the rclpy node: {answer['error']}")
        return answer["ok"]

    def request(self, op: str, **args: Any) -> Any:
        """One request (tests/ros2_node.py lists them) and its answer."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"op": op, **args}) + "\n")
        self.proc.stdin.flush()
        return self._answer()

    def publish(self, topic: str, kind: str, msg: dict[str, Any]) -> float:
        """Publish; returns the node's ``time.monotonic()`` just before it did."""
        _matched, at = self.request("pub", topic=topic, type=kind, msg=msg, stamped=True)
        return float(at)

    def take(self, topic: str) -> list[tuple[float, Any]]:
        """The samples received since the last take, each with its callback's time."""
        return [(float(t), sample) for t, sample in self.request("take", topic=topic, stamped=True)]

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._stderr.close()
