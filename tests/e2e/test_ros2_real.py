"""The ROS 2 bridge against a real ROS 2 node: rclpy on Fast DDS (issue 33).

The node is ROS 2's own Python client library, rclpy 9.1.2 (Kilted), on its
default middleware rmw_fastrtps_cpp (Fast DDS 3.2), from the pinned wheels that
``tools/dev.sh setup`` installs into ``.deps/ros2-venv``; it runs there as
``tests/ros2_node.py``, a subprocess this test drives through JSON lines. The
bridge runs as ``protoduino ros2 PORT --config`` (tests/e2e/test_ros2.py's
``BridgeProcess``, Cyclone DDS on loopback), on both boards. Every topic type and
QoS of the bridge is judged at the pin (commands) or at the node (samples); the
rosbags peer of test_ros2.py stays the second, independent peer.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from protoduino.simboard import SimBoard
from simfixtures import pin_values, wait_for_pin, wait_until

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # bench/ is a top-level folder of the checkout, not installed
    sys.path.insert(0, str(ROOT))

from bench.ros2_rclpy import RclpyNode  # noqa: E402  (the node bench part 8 drives too)

pytest.importorskip("cyclonedds", reason="cyclonedds (the ros2 extra) is missing")

from test_ros2 import (  # noqa: E402
    DOMAIN,
    FAILSAFE_TIMEOUT,
    SAFE_90_US,
    WAIT,
    BridgeProcess,
    _until,
    now_at,
    to_us,
)

#: The ROS 2 venv's interpreter (tools/dev.sh setup).
ROS2_PYTHON = RclpyNode.python

if not ROS2_PYTHON.exists():
    pytest.skip(
        f"rclpy is not installed ({ROS2_PYTHON}: ./tools/dev.sh setup installs it)",
        allow_module_level=True,
    )

#: The node tests/ros2_node.py in its subprocess (bench part 8 drives the same one).
RosNode = RclpyNode


@pytest.fixture(scope="module")
def ros_node(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RosNode]:
    node = RosNode(DOMAIN, tmp_path_factory.mktemp("rclpy") / "node.log")
    try:
        yield node
    finally:
        node.close()


@pytest.fixture
def bridge(sim_board: SimBoard, tmp_path: Path) -> Iterator[Callable[[str], BridgeProcess]]:
    started: list[BridgeProcess] = []

    def start(config: str) -> BridgeProcess:
        # The services' rclpy node discovers as the test's node does (loopback only).
        env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        started.append(BridgeProcess(sim_board, config, tmp_path, new_session=True, env=env))
        return started[-1]

    yield start
    for process in started:
        process.stop()


#: Every topic type and QoS the bridge has, on pins an Uno drives all at once.
ROBOT = """
namespace: {ns}
failsafe_timeout: {failsafe}
diagnostics_period: 0.5
servos:
  - {{pin: 9, topic: servo/pan, joint: pan, safe: 90}}
  - {{pin: 10, joint: tilt, safe: 45}}
digital_outputs:
  - {{pin: 13, topic: led}}
stop: {{topic: stop, type: Empty}}
drive:
  wheel_base: 0.2
  max_speed: 0.5
  timeout: 30.0
  left: {{pwm: 3, direction: 4}}
  right: {{pwm: 11, direction: 12, invert: true}}
digital_inputs:
  - {{pin: 7, topic: bumper, pull_up: true}}
analog_inputs:
  - {{pin: A0, topic: battery, scale: 0.01, threshold: 2}}
counters:
  - {{pins: [2], topic: sensors/encoders}}
"""


def _seen(node: RosNode, topic: str, ok: Callable[[Any], bool], box: list[Any]) -> bool:
    box += node.request("take", topic=topic)
    return any(ok(sample) for sample in box)


def _until_seen(node: RosNode, topic: str, ok: Callable[[Any], bool], what: str) -> None:
    box: list[Any] = []
    _until(lambda: _seen(node, topic, ok, box), f"{topic}: {what} at the rclpy node")


def _until_fed(
    node: RosNode, topic: str, feed: Callable[[int], Any], ok: Callable[[Any, int], bool]
) -> None:
    """Feed the board (``feed(i)``, i = 1, 2, ...) until the node saw, after a feed, the
    sample ``ok`` says that feed makes: a best-effort sample written before the bridge's
    writer matched the node's reader is lost by design (the QoS), a later one is not."""
    deadline = time.monotonic() + WAIT
    fed = 0
    while True:
        fed += 1
        node.request("take", topic=topic)  # what came before this feed does not count
        box: list[Any] = []
        feed(fed)

        def made(sample: Any, i: int = fed) -> bool:
            return ok(sample, i)

        if wait_until(lambda: _seen(node, topic, made, box), timeout=2.0):  # noqa: B023
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"{topic}: nothing that {fed} feeds make at the rclpy node")


def _publish_until(
    sim: SimBoard,
    node: RosNode,
    process: BridgeProcess,
    *done: tuple[int, int],
    topic: str,
    kind: str,
    msg: dict[str, Any],
) -> None:
    """Publish ``msg`` on ``topic`` (absolute) until the pins show ``done`` ((pin, value)...).

    A publisher that matched the bridge's subscription may still be unknown to it for a
    moment (discovery is not symmetric), and a volatile reader takes only what comes after
    it knows the writer: so a command (a state: the same again changes nothing) is
    published again until the pins show it."""

    def at_pins() -> bool:
        return all(pin_values(sim.trace(), pin)[-1:] == [value] for pin, value in done)

    deadline = time.monotonic() + WAIT
    while True:
        assert node.request("pub", topic=topic, type=kind, msg=msg) == 1
        if wait_until(at_pins, timeout=2.0):
            return
        if time.monotonic() > deadline:
            shown = {pin: pin_values(sim.trace(), pin)[-3:] for pin, _ in done}
            raise AssertionError(
                f"{topic}: the pins show no {done} but {shown}; the bridge printed:\n"
                + process.output()[-4000:]
            )


def test_a_real_rclpy_node_drives_and_reads_every_topic_type(
    sim_board: SimBoard, ros_node: RosNode, bridge: Callable[[str], BridgeProcess]
) -> None:
    """rclpy on Fast DDS: Float64, JointState, Bool, Twist, Empty to the pins (reliable);
    Bool, Float32, Int32MultiArray (sensor QoS) and /diagnostics' DiagnosticArray
    (reliable) at the node. JointState, Int32MultiArray and DiagnosticArray carry strings
    or sequences of structs: the types Cyclone refused Fast DDS's type objects for."""
    sim, node = sim_board, ros_node
    ns = f"real_{sim.backend}"
    sim.set_level(7, 1)  # the bumper released: the pull-up's level
    node.request("sub", topic=f"/{ns}/bumper", type="std_msgs/msg/Bool", qos="sensor")
    node.request("sub", topic=f"/{ns}/battery", type="std_msgs/msg/Float32", qos="sensor")
    encoders = f"/{ns}/sensors/encoders"
    node.request("sub", topic=encoders, type="std_msgs/msg/Int32MultiArray", qos="sensor")
    node.request("sub", topic="/diagnostics", type="diagnostic_msgs/msg/DiagnosticArray")
    process = bridge(ROBOT.format(ns=ns, failsafe=FAILSAFE_TIMEOUT))
    wait_for_pin(sim, 9, now_at(SAFE_90_US))

    # To the board, reliable, each command published until the pins show it.
    def pub(topic: str, kind: str, msg: dict[str, Any], *done: tuple[int, int]) -> None:
        _publish_until(sim, node, process, *done, topic=f"/{ns}/{topic}", kind=kind, msg=msg)

    pub("servo/pan", "std_msgs/msg/Float64", {"data": 45.0}, (9, to_us(45)))
    # pan 0.5 rad -> 90 + 28.6 -> 119 degrees; tilt -0.3 rad -> 90 - 17.2 -> 73 degrees.
    joints = {"name": ["pan", "tilt"], "position": [0.5, -0.3]}
    joints_type = "sensor_msgs/msg/JointState"
    pub("joint_commands", joints_type, joints, (9, to_us(119)), (10, to_us(73)))
    # Bad input from the node: counted on /diagnostics, nothing moves (the publisher
    # delivered before, so this one arrives too).
    before = {pin: len(pin_values(sim.trace(), pin)) for pin in (9, 10)}
    elbow = {"name": ["pan", "elbow"], "position": [0.0, 0.0]}
    node.request("pub", topic=f"/{ns}/joint_commands", type=joints_type, msg=elbow)
    _until_seen(
        node,
        "/diagnostics",
        lambda s: any(
            st["name"] == f"protoduino {ns}: bridge"
            and {"key": f"bad./{ns}/joint_commands: invalid", "value": "1"} in st["values"]
            for st in s["status"]
        ),
        "the bad JointState counted",
    )
    pub("led", "std_msgs/msg/Bool", {"data": True}, (13, 1))
    assert {pin: len(pin_values(sim.trace(), pin)) for pin in (9, 10)} == before
    twist = {"linear": {"x": 0.25}, "angular": {"z": 0.0}}
    pub("cmd_vel", "geometry_msgs/msg/Twist", twist, (3, 128), (11, 128))
    assert pin_values(sim.trace(), 4)[-1] == 1 and pin_values(sim.trace(), 12)[-1] == 0

    # From the board, best effort (sensor QoS), judged at the node.
    def to_level(level: bool) -> Callable[[int], None]:
        def feed(_: int) -> None:  # each feed makes ``level`` anew: the other one, then it
            sim.set_level(7, int(not level))
            sim.set_level(7, int(level))

        return feed

    bumper = f"/{ns}/bumper"
    _until_fed(node, bumper, to_level(False), lambda s, _: s["data"] is False)  # pressed
    _until_fed(node, bumper, to_level(True), lambda s, _: s["data"] is True)  # released
    _until_fed(
        node,
        f"/{ns}/battery",
        lambda i: sim.set_analog(14, 100 + 10 * i),
        lambda s, i: abs(s["data"] - (1.0 + 0.1 * i)) < 1e-5,
    )
    _until_fed(
        node,
        encoders,
        lambda i: sim.pulses(2, 5, 1000),
        lambda s, i: s["data"] == [5 * i],
    )
    # /diagnostics, reliable: the bridge's three statuses for this board.
    _until_seen(
        node,
        "/diagnostics",
        lambda s: any(
            st["name"] == f"protoduino {ns}: link"
            and {"key": "state", "value": "active"} in st["values"]
            for st in s["status"]
        ),
        "the link's status",
    )

    safe = ((9, SAFE_90_US), (10, to_us(45)), (13, 0), (3, 0), (11, 0))
    pub("stop", "std_msgs/msg/Empty", {}, *safe)
    _until_seen(
        node,
        "/diagnostics",
        lambda s: any(
            st["name"] == f"protoduino {ns}: failsafe"
            and {"key": "cause", "value": "stop"} in st["values"]
            for st in s["status"]
        ),
        "the failsafe's cause: stop",
    )


def test_the_bridge_is_a_node_in_the_ros2_graph(
    sim_board: SimBoard, ros_node: RosNode, bridge: Callable[[str], BridgeProcess]
) -> None:
    """rclpy's get_node_names_and_namespaces() (``ros2 node list``) has the bridge under its
    namespace, and the per-node queries of ``ros2 node info`` list its subscriptions
    (commands) and publishers (inputs, /diagnostics) with their ROS 2 types."""
    sim, node = sim_board, ros_node
    ns = f"graph_{sim.backend}"
    bridge(ROBOT.format(ns=ns, failsafe=FAILSAFE_TIMEOUT))
    found: list[dict[str, Any]] = []

    def listed() -> bool:
        found[:] = [n for n in node.request("graph") if n["namespace"] == f"/{ns}"]
        return bool(found and found[0]["publishers"] and found[0]["subscriptions"])

    _until(listed, f"a node in /{ns}")
    assert [n["name"] for n in found] == ["protoduino"], found
    subscriptions = {name: types for name, types in found[0]["subscriptions"]}
    publishers = {name: types for name, types in found[0]["publishers"]}
    assert subscriptions == {
        f"/{ns}/servo/pan": ["std_msgs/msg/Float64"],
        f"/{ns}/joint_commands": ["sensor_msgs/msg/JointState"],
        f"/{ns}/led": ["std_msgs/msg/Bool"],
        f"/{ns}/stop": ["std_msgs/msg/Empty"],
        f"/{ns}/resume": ["std_msgs/msg/Empty"],  # releases a latched STOP
        f"/{ns}/cmd_vel": ["geometry_msgs/msg/Twist"],
    }
    assert publishers == {
        "/diagnostics": ["diagnostic_msgs/msg/DiagnosticArray"],
        f"/{ns}/bumper": ["std_msgs/msg/Bool"],
        f"/{ns}/battery": ["std_msgs/msg/Float32"],
        f"/{ns}/sensors/encoders": ["std_msgs/msg/Int32MultiArray"],
    }


#: A drive, an LED and a bumper interlock, with the Trigger services (issue 33, item 4)
#: answered by an rclpy node run by the ROS 2 venv's interpreter.
SERVICE_ROBOT = """
namespace: {ns}
failsafe_timeout: {failsafe}
diagnostics_period: 0.5
digital_outputs:
  - {{pin: 13, topic: led}}
drive:
  wheel_base: 0.2
  max_speed: 0.5
  timeout: 30.0
  left: {{pwm: 3, direction: 4}}
  right: {{pwm: 11, direction: 12, invert: true}}
digital_inputs:
  - {{pin: 7, topic: bumper, pull_up: true, interlock: low}}
services: {{python: {python}}}
"""

TRIGGER = "std_srvs/srv/Trigger"


def test_stop_resume_and_clear_interlock_as_trigger_services(
    sim_board: SimBoard, ros_node: RosNode, bridge: Callable[[str], BridgeProcess]
) -> None:
    """rclpy's client calls ``stop``, ``resume`` and ``clear_interlock`` (std_srvs/Trigger)
    on Fast DDS: STOP takes the motors and the LED safe at the pins and answers success;
    a clear while the bumper is still pressed answers success false with the device's
    reason, and the device then still refuses a Twist; once the bumper is released a clear
    succeeds and a Twist drives. A SIGKILLed bridge takes its services' node with it and
    the device's failsafe takes the motors safe."""
    sim, node = sim_board, ros_node
    ns = f"svc_{sim.backend}"
    sim.set_level(7, 1)  # the bumper released: the pull-up's level
    node.request("sub", topic="/diagnostics", type="diagnostic_msgs/msg/DiagnosticArray")
    process = bridge(SERVICE_ROBOT.format(ns=ns, failsafe=FAILSAFE_TIMEOUT, python=ROS2_PYTHON))
    printed = [f"  /{ns}/{name}  {TRIGGER}\n" for name in ("stop", "resume", "clear_interlock")]
    _until(lambda: all(line in process.output() for line in printed), "the services printed")

    def call(service: str) -> dict[str, Any]:
        answer: dict[str, Any] = node.request("call", service=f"/{ns}/{service}", type=TRIGGER)
        return answer

    def drive() -> None:
        twist = {"linear": {"x": 0.25}, "angular": {"z": 0.0}}
        kind = "geometry_msgs/msg/Twist"
        _publish_until(
            sim, node, process, (3, 128), (11, 128), topic=f"/{ns}/cmd_vel", kind=kind, msg=twist
        )

    seen: list[int] = []

    def refused() -> int:
        """The bridge's count of commands the device refused, in its latest report (-1:
        none yet)."""
        for array in node.request("take", topic="/diagnostics"):
            for status in array["status"]:
                if status["name"] == f"protoduino {ns}: bridge":
                    values = {kv["key"]: kv["value"] for kv in status["values"]}
                    seen.append(int(values["refused_by_device"]))
        return seen[-1] if seen else -1

    drive()
    led = f"/{ns}/led"
    _publish_until(
        sim, node, process, (13, 1), topic=led, kind="std_msgs/msg/Bool", msg={"data": True}
    )

    stopped = call("stop")
    assert stopped["success"] is True, stopped
    for pin in (3, 11, 13):
        wait_for_pin(sim, pin, now_at(0))
    resumed = call("resume")
    assert resumed["success"] is True, resumed
    drive()  # released: a Twist drives again

    sim.set_level(7, 0)  # the bumper pressed: the device's interlock stops the motors
    for pin in (3, 11):
        wait_for_pin(sim, pin, now_at(0))
    early = call("clear_interlock")
    assert early["success"] is False, early
    assert early["message"].endswith("rejected by the device: STATUS_INTERLOCK_ACTIVE"), early
    # Released, but not cleared: the device still refuses a Twist (counted), nothing moves.
    sim.set_level(7, 1)
    # The refused clear is the first refusal of this bridge: once a report counts it, the
    # next count is the Twist's.
    _until(lambda: refused() >= 1, "the refused clear counted on /diagnostics")
    before = refused()
    twist = {"linear": {"x": 0.25}, "angular": {"z": 0.0}}
    assert node.request("pub", topic=f"/{ns}/cmd_vel", type="geometry_msgs/msg/Twist", msg=twist)
    _until(lambda: refused() > before, "the Twist refused by the device")
    assert pin_values(sim.trace(), 3)[-1] == 0 and pin_values(sim.trace(), 11)[-1] == 0
    cleared = call("clear_interlock")
    assert cleared["success"] is True, cleared
    drive()

    # The services' node is in the graph; a killed bridge takes it along, and the device's
    # failsafe (not the bridge) takes the motors safe.
    def services_node() -> list[dict[str, Any]]:
        return [
            n
            for n in node.request("graph")
            if (n["name"], n["namespace"]) == ("protoduino_services", f"/{ns}")
        ]

    listed = services_node()
    assert len(listed) == 1, listed
    triggers = sorted(name for name, types in listed[0]["services"] if types == [TRIGGER])
    assert triggers == [f"/{ns}/{s}" for s in ("clear_interlock", "resume", "stop")]
    process.kill()
    for pin in (3, 11):
        wait_for_pin(sim, pin, now_at(0))
    _until(lambda: not services_node(), "the services' node gone with the bridge")
