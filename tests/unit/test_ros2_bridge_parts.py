"""The ROS 2 bridge's pure parts: robot.yaml, the drive's kinematics and watchdog, the
messages (checked byte for byte against rosbags' independent CDR codec), inputs to
messages, /diagnostics."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("cyclonedds", reason="cyclonedds (the ros2 extra) is missing")
pytest.importorskip("rosbags", reason="rosbags is not installed")

import numpy as np
from protoduino.errors import AckTimeoutError, BadCommandError, ConfigError, StaleCommandError
from protoduino.events import Event, EventKind, Stats
from protoduino.ros2 import msgs
from protoduino.ros2.config import (
    BridgeConfig,
    DigitalInputConfig,
    DriveConfig,
    MotorConfig,
    ServicesConfig,
    ServoConfig,
    load_config,
    parse_config,
    service_names,
)
from protoduino.ros2.dds import dds_topic, ros_topic
from protoduino.ros2.diagnostics import ERROR, OK, STALE, WARN, Health
from protoduino.ros2.drive import (
    DiffDrive,
    Motor,
    WheelCommand,
    twist_to_wheels,
    wheel_command,
    wheel_speeds,
)
from protoduino.ros2.inputs import (
    LastPublished,
    analog_message,
    bool_message,
    counters_message,
    int32,
    wire,
)
from protoduino.ros2.services import Services
from protoduino.ros2.servos import joint_pose, servo_degrees
from rosbags.typesys import Stores, get_typestore

TYPES = get_typestore(Stores.ROS2_HUMBLE)

FULL: dict[str, Any] = {
    "namespace": "robot1",
    "domain_id": 7,
    "failsafe_timeout": 0.5,
    "servos": [
        {"pin": 9, "topic": "servo/pan", "joint": "pan", "safe": 80},
        {"pin": 10, "joint": "tilt", "zero": 45, "min_us": 600, "max_us": 2300},
    ],
    "digital_outputs": [{"pin": 13, "topic": "led", "safe": True}],
    "stop": {"topic": "estop", "type": "Bool"},
    "drive": {
        "wheel_base": 0.2,
        "max_speed": 0.5,
        "left": {"pwm": 3, "direction": 4},
        "right": {"pwm": 11, "direction": 12, "invert": True},
    },
    "digital_inputs": [{"pin": 2, "topic": "bumper", "pull_up": True, "debounce_ms": 5}],
    "analog_inputs": [{"pin": "A0", "topic": "battery", "scale": 0.01, "offset": 0.5}],
    "counters": [{"pins": [5, 6]}],
}


# --- robot.yaml ------------------------------------------------------------------------


def test_a_full_configuration() -> None:
    config = parse_config(FULL)
    assert config.namespace == "robot1" and config.resolved_domain() == 7
    assert config.servos[0] == ServoConfig(9, "servo/pan", "pan", 80)
    assert config.joints == {"pan": config.servos[0], "tilt": config.servos[1]}
    assert config.servos[1].zero == 45.0 and config.servos[1].min_us == 600
    assert config.stop.type == "Bool" and config.stop.topic == "estop"
    assert config.drive == DriveConfig(
        MotorConfig(3, 4), MotorConfig(11, 12, invert=True), 0.2, 0.5
    )
    assert config.drive.timeout == 0.5 and config.drive.topic == "cmd_vel"
    assert config.analog_inputs[0].pin == 14  # A0
    assert config.counters[0].pins == (5, 6) and config.counters[0].topic == "sensors/encoders"


def test_the_example_robot_is_the_one_docs_show() -> None:
    """``protoduino ros2 --sim`` bridges docs/ros2.md's robot.yaml, and it is valid."""
    from protoduino.ros2.example import ROBOT_YAML, example_config

    docs = (Path(__file__).resolve().parents[2] / "docs" / "ros2.md").read_text()
    assert f"```yaml\n{ROBOT_YAML}```" in docs
    config = example_config()
    assert config.drive is not None and config.counters[0].pins == (2, 3)  # left, right
    assert {s.pin for s in config.servos} == {9, 10}  # Timer1: no PWM on 9 and 10, so
    assert {config.drive.left.pwm, config.drive.right.pwm} == {5, 6}  # the drive is on Timer0
    # A copied robot stops on its bumper, on the device (issue 33).
    assert [(d.topic, d.interlock) for d in config.digital_inputs] == [("bumper", "low")]


def test_servo_speed_limits_input_rate_and_resume_topic() -> None:
    """robot.yaml takes a servo's max_speed (degrees/s, Board.servo's), the inputs' minimum
    publish rate (1 Hz by default) and the topic that releases a STOP (issue 33)."""
    config = parse_config(_with(servos=[{"pin": 9, "topic": "pan", "max_speed": 60}]))
    assert config.servos[0].max_speed == 60.0
    assert parse_config(FULL).servos[0].max_speed is None  # no limit unless given
    assert config.min_publish_rate == 1.0 and config.stop.resume_topic == "resume"
    config = parse_config(_with(min_publish_rate=5, stop={"resume_topic": "go"}))
    assert config.min_publish_rate == 5.0 and config.stop.resume_topic == "go"


def test_trigger_services_are_asked_for_by_services() -> None:
    """``services:`` asks for STOP and resume as std_srvs/Trigger services, and the
    interlock's clear with an interlock input; names resolve in the namespace, one each."""
    assert parse_config(FULL).services is None and service_names(parse_config(FULL)) == {}
    config = parse_config(_with(services={"python": "/opt/ros/venv/bin/python"}))
    assert config.services == ServicesConfig(python="/opt/ros/venv/bin/python")
    assert service_names(config) == {"stop": "stop", "resume": "resume"}  # no interlock
    bumper = {"pin": 7, "topic": "bumper", "interlock": "low"}
    config = parse_config(_with(services={"stop": "halt"}, digital_inputs=[bumper]))
    assert config.services is not None and config.services.python == "python3"
    assert service_names(config) == {
        "stop": "halt",
        "resume": "resume",
        "clear_interlock": "clear_interlock",
    }
    with pytest.raises(ConfigError, match="services: unknown key"):
        parse_config(_with(services={"pyhton": "python3"}))
    with pytest.raises(ConfigError, match="services: resume and stop are both /robot1/halt"):
        parse_config(_with(services={"stop": "halt", "resume": "/robot1/halt"}))
    # docs/ros2.md's services: block is what the configuration reads.
    import yaml

    docs = (Path(__file__).resolve().parents[2] / "docs" / "ros2.md").read_text()
    snippet = docs.split("## Services", 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    shown = parse_config(yaml.safe_load(snippet)).services
    assert shown is not None and shown.python == "/usr/bin/python3"


def test_services_need_an_interpreter_that_imports_rclpy(tmp_path: Path) -> None:
    """The services' node is run by the configured interpreter; one without rclpy (this
    venv's) or none at all leaves the bridge without services, saying why."""
    missing = str(tmp_path / "no-python")
    for python, why in ((sys.executable, "cannot import rclpy"), (missing, "cannot run")):
        config = parse_config({"services": {"python": python}})
        services = Services(config, 0, lambda: None)
        services.start()
        deadline = time.monotonic() + 30.0  # bounds a failing run only
        while services.state == "starting" and time.monotonic() < deadline:
            time.sleep(0.01)
        state = services.state
        services.close()
        assert state.startswith("unavailable") and why in state, state


def test_the_yaml_file(tmp_path: Path) -> None:
    path = tmp_path / "robot.yaml"
    path.write_text("namespace: /r2/\nservos:\n  - {pin: 9, topic: pan}\n")
    config = load_config(path)
    assert config.namespace == "r2" and config.servos == (ServoConfig(9, "pan"),)
    path.write_text("servos: [pin: 9\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")


def test_an_empty_configuration_bridges_stop_and_diagnostics_only() -> None:
    config = parse_config({})
    assert config == BridgeConfig()
    assert config.stop.topic == "stop" and config.diagnostics_topic == "/diagnostics"


def test_domain_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert parse_config({}).resolved_domain() == 42
    assert parse_config({"domain_id": 3}).resolved_domain() == 3
    monkeypatch.setenv("ROS_DOMAIN_ID", "300")
    with pytest.raises(ConfigError, match=r"0\.\.232"):
        parse_config({}).resolved_domain()


def _with(**changes: Any) -> dict[str, Any]:
    return {**FULL, **changes}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"servo": []}, "unknown key"),  # a typo never silently bridges nothing
        (_with(servos=[{"pin": 9, "topic": "a", "speed": 3}]), r"servos\[0\]: unknown key"),
        (_with(servos=[{"pin": 9}]), "a topic .* or a joint"),
        (_with(servos=[{"pin": 9, "topic": "a", "safe": 181}]), "safe must be 0..180"),
        (_with(servos=[{"pin": 9, "topic": "a", "min_us": 2000, "max_us": 1000}]), "min_us"),
        (_with(servos=[{"pin": 13, "topic": "a"}]), "pin 13 is both"),
        (_with(servos=[{"pin": 9, "topic": "led"}]), "topic 'led' is both"),
        (_with(servos=[{"pin": 9, "topic": "9lives"}]), "not a ROS 2 topic name"),
        (_with(servos=[{"pin": 9, "topic": "a//b"}]), "not a ROS 2 topic name"),
        (_with(servos=[{"pin": True, "topic": "a"}]), "pin number"),
        (_with(servos=[{"pin": 9, "joint": "j"}, {"pin": 8, "joint": "j"}]), "joint name"),
        (_with(servos=[{"pin": p, "joint": f"j{p}"} for p in range(20, 29)]), "at most 8"),
        (_with(stop={"type": "String"}), "one of Empty, Bool"),
        (_with(servos=[{"pin": 9, "topic": "a", "max_speed": 0}]), "max_speed must be above 0"),
        (_with(servos=[{"pin": 9, "topic": "a", "max_speed": "fast"}]), "must be a number"),
        (_with(min_publish_rate=0), "min_publish_rate must be >= 0.01"),
        (_with(stop={"resume_topic": "led"}), "topic 'led' is both"),
        (_with(drive={**FULL["drive"], "wheel_base": None}), "wheel_base is required"),
        (_with(namespace="a b"), "not a ROS 2 topic name"),
        (_with(drive={**FULL["drive"], "max_speed": 0}), "max_speed must be above 0"),
        (_with(drive={**FULL["drive"], "timeout": float("nan")}), "finite"),
        (_with(drive={**FULL["drive"], "right": None}), "right is required"),
        (_with(failsafe_timeout=0.01), "failsafe_timeout must be >= 0.1"),
        (_with(domain_id=233), "0..232"),
        (_with(counters=[{"pins": []}]), "non-empty list"),
        (_with(analog_inputs=[{"pin": 14, "topic": "b", "threshold": 2000}]), "0..1023"),
        (_with(digital_inputs=[{"pin": 2, "topic": "b", "interlock": "on"}]), "one of low, high"),
        (
            _with(digital_inputs=[{"pin": 2, "topic": "estop", "interlock": "low"}]),
            "topic 'estop' is both",
        ),
        (
            _with(
                digital_inputs=[{"pin": 2, "topic": "b", "interlock": "low"}],
                clear_interlock_topic="led",
            ),
            "topic 'led' is both",
        ),
        ([1, 2], "must be a mapping"),
        # One topic named twice, relative and absolute: one Bool would drive both pins.
        (
            _with(
                digital_outputs=[{"pin": 13, "topic": "led"}, {"pin": 8, "topic": "/robot1/led"}]
            ),
            r"topic '/robot1/led' is both digital output 13 \(as 'led': both are /robot1/led\)",
        ),
        (
            _with(diagnostics_topic="/robot1/battery"),
            "topic 'battery' is both the diagnostics",
        ),
    ],
)
def test_bad_configurations_are_refused_naming_the_key(data: Any, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_config(data)


def test_an_interlock_input_and_its_clear_topic() -> None:
    config = parse_config(_with(digital_inputs=[{"pin": 2, "topic": "bumper", "interlock": "low"}]))
    assert config.interlocks == (DigitalInputConfig(2, "bumper", interlock="low"),)
    assert config.clear_interlock_topic == "clear_interlock"
    # Without an interlock, the clear topic is not the bridge's: another may use the name.
    plain = parse_config(_with(digital_outputs=[{"pin": 13, "topic": "clear_interlock"}]))
    assert plain.interlocks == ()


def test_topic_names() -> None:
    assert dds_topic("robot1", "servo/pan") == "rt/robot1/servo/pan"
    assert dds_topic("", "cmd_vel") == "rt/cmd_vel"
    assert dds_topic("robot1", "/diagnostics") == "rt/diagnostics"
    assert ros_topic("robot1", "led") == "/robot1/led"


# --- the drive -------------------------------------------------------------------------

DRIVE = DriveConfig(MotorConfig(3, 4), MotorConfig(11, 12), wheel_base=0.2, max_speed=0.5)


def test_kinematics() -> None:
    assert wheel_speeds(0.3, 0.0, 0.2) == (0.3, 0.3)
    assert wheel_speeds(0.0, 1.0, 0.2) == pytest.approx((-0.1, 0.1))  # left back, right ahead
    assert wheel_speeds(0.2, -1.0, 0.2) == pytest.approx((0.3, 0.1))  # a right turn
    assert twist_to_wheels(0.5, 0.0, DRIVE) == (WheelCommand(255, True), WheelCommand(255, True))
    assert twist_to_wheels(-0.25, 0.0, DRIVE) == (
        WheelCommand(128, False),  # 127.5 rounds to even
        WheelCommand(128, False),
    )
    assert twist_to_wheels(0.0, 2.5, DRIVE) == (WheelCommand(128, False), WheelCommand(128, True))
    assert twist_to_wheels(0.0, 0.0, DRIVE) == (WheelCommand(0, True), WheelCommand(0, True))
    assert wheel_command(0.001, 0.5) == WheelCommand(1, True)


@pytest.mark.parametrize(
    ("linear", "angular"),
    [(0.51, 0.0), (-0.6, 0.0), (0.4, 2.0), (0.0, 5.1), (math.nan, 0.0), (0.0, math.inf)],
)
def test_twists_the_drive_cannot_follow_are_refused_not_clamped(
    linear: float, angular: float
) -> None:
    with pytest.raises(BadCommandError):
        twist_to_wheels(linear, angular, DRIVE)


def test_direction_levels_and_invert() -> None:
    assert WheelCommand(10, True).level(MotorConfig(3, 4)) is True
    assert WheelCommand(10, True).level(MotorConfig(3, 4, invert=True)) is False
    assert WheelCommand(10, False).level(MotorConfig(3, 4, invert=True)) is True


class Pin:
    """A fake output recording what was written, in one log shared by both pins."""

    def __init__(self, name: str, log: list[tuple[str, object]]) -> None:
        self.name, self.log = name, log

    def write(self, value: Any) -> None:
        self.log.append((self.name, value))


def _motors(log: list[tuple[str, object]]) -> tuple[Motor, Motor]:
    return (
        Motor(DRIVE.left, Pin("lpwm", log), Pin("ldir", log)),
        Motor(DRIVE.right, Pin("rpwm", log), Pin("rdir", log)),
    )


def test_a_motor_never_runs_its_old_duty_the_other_way() -> None:
    log: list[tuple[str, object]] = []
    left, _ = _motors(log)
    left.apply(WheelCommand(200, True))
    left.apply(WheelCommand(100, True))
    left.apply(WheelCommand(100, True))  # the same: nothing written
    left.apply(WheelCommand(50, False))
    assert log == [
        ("ldir", True),
        ("lpwm", 200),
        ("lpwm", 100),
        ("lpwm", 0),  # stop before the direction flips
        ("ldir", False),
        ("lpwm", 50),
    ]


def test_the_cmd_vel_watchdog_stops_the_motors_once() -> None:
    log: list[tuple[str, object]] = []
    now = [100.0]
    drive = DiffDrive(DRIVE, *_motors(log), clock=lambda: now[0])
    assert drive.deadline() is None and not drive.check()
    drive.command(0.25, 0.0)
    assert drive.deadline() == 100.5
    log.clear()
    now[0] = 100.49
    assert not drive.check() and log == []
    now[0] = 100.5
    assert drive.check()
    assert log == [("lpwm", 0), ("rpwm", 0)] and drive.stale_stops == 1
    now[0] = 200.0
    assert not drive.check()  # once per silence
    with pytest.raises(BadCommandError):
        drive.command(1.0, 0.0)
    assert drive.deadline() is None  # a refused Twist does not feed the watchdog


def test_after_a_device_stop_the_next_twist_sets_the_direction_again() -> None:
    log: list[tuple[str, object]] = []
    drive = DiffDrive(DRIVE, *_motors(log), clock=lambda: 0.0)
    drive.command(0.25, 0.0)
    drive.forget()  # the device drove everything safe (direction pins low)
    log.clear()
    drive.command(0.25, 0.0)
    assert log == [("ldir", True), ("lpwm", 128), ("rdir", True), ("rpwm", 128)]


class LostAck(Pin):
    """A fake output whose writes of ``lost`` values run but raise (their Ack was lost)."""

    def __init__(self, name: str, log: list[tuple[str, object]], lost: set[object]) -> None:
        super().__init__(name, log)
        self.lost = lost

    def write(self, value: Any) -> None:
        super().write(value)
        if value in self.lost:
            raise AckTimeoutError(f"no Ack for {value}")


def test_a_twist_whose_outcome_is_unknown_arms_the_watchdog() -> None:
    """Issue 32: a Twist whose Ack was lost ran on the device; the watchdog stops it."""
    log: list[tuple[str, object]] = []
    now = [100.0]
    lost: set[object] = {153}
    left = Motor(DRIVE.left, LostAck("lpwm", log, lost), Pin("ldir", log))
    right = Motor(DRIVE.right, Pin("rpwm", log), Pin("rdir", log))
    drive = DiffDrive(DRIVE, left, right, clock=lambda: now[0])
    with pytest.raises(AckTimeoutError):
        drive.command(0.3, 0.0)  # 153 on both wheels; the left one's Ack is lost
    assert drive.deadline() == 100.5
    lost.clear()
    now[0] = 100.5
    assert drive.check()
    assert log[-2:] == [("lpwm", 0), ("rpwm", 0)] and drive.deadline() is None


def test_a_motor_whose_duty_is_unknown_stops_before_it_turns() -> None:
    log: list[tuple[str, object]] = []
    motor = Motor(DRIVE.left, LostAck("lpwm", log, {200}), Pin("ldir", log))
    with pytest.raises(AckTimeoutError):
        motor.apply(WheelCommand(200, True))
    motor.apply(WheelCommand(50, False))
    assert log == [("ldir", True), ("lpwm", 200), ("lpwm", 0), ("ldir", False), ("lpwm", 50)]


def test_a_stop_whose_outcome_is_unknown_is_tried_again() -> None:
    log: list[tuple[str, object]] = []
    now = [0.0]
    lost: set[object] = set()
    left = Motor(DRIVE.left, LostAck("lpwm", log, lost), Pin("ldir", log))
    drive = DiffDrive(DRIVE, left, _motors(log)[1], clock=lambda: now[0])
    drive.command(0.25, 0.0)
    lost.add(0)
    now[0] = 0.5
    with pytest.raises(AckTimeoutError):
        drive.check()
    assert drive.deadline() == 1.0  # armed again: one timeout later
    lost.clear()
    log.clear()
    now[0] = 1.0
    assert drive.check() and log == [("lpwm", 0), ("rpwm", 0)]
    assert drive.deadline() is None


def test_a_stop_the_device_refuses_disarms_the_watchdog() -> None:
    """A refusal means the device holds its outputs safe itself (failsafe, interlock)."""
    from protoduino.errors import CommandRejectedError
    from protoduino.messages import Status

    class Refusing(Pin):
        def write(self, value: Any) -> None:
            raise CommandRejectedError(Status.STATUS_FAILSAFE_EXPIRED, "safe")

    log: list[tuple[str, object]] = []
    now = [0.0]
    drive = DiffDrive(DRIVE, *_motors(log), clock=lambda: now[0])
    drive.command(0.25, 0.0)
    drive.left.pwm = Refusing("lpwm", log)
    now[0] = 0.5
    with pytest.raises(CommandRejectedError):
        drive.check()
    assert drive.deadline() is None


def test_a_twist_older_than_the_timeout_is_stale_on_arrival() -> None:
    """Issue 32: Twists queued by reliable DDS through a freeze are refused, by their DDS
    source timestamp against the bridge's wall clock (both injected here)."""
    log: list[tuple[str, object]] = []
    wall = [1_700_000_000.0]
    drive = DiffDrive(DRIVE, *_motors(log), clock=lambda: 0.0, wall_clock=lambda: wall[0])
    drive.check_fresh(wall[0] - 0.5)  # as old as the timeout: still fresh
    drive.check_fresh(wall[0] + 3.0)  # a publisher's clock ahead: fresh
    drive.check_fresh(None)  # no timestamp: fresh
    with pytest.raises(StaleCommandError, match="stale on arrival"):
        drive.check_fresh(wall[0] - 0.501)
    assert log == [] and drive.deadline() is None


def test_the_bridge_drops_a_stale_twist_and_counts_it() -> None:
    from types import SimpleNamespace

    from protoduino.ros2.bridge import Bridge, _Route

    config = parse_config({"drive": FULL["drive"]})
    bridge = Bridge("unused", config)
    log: list[tuple[str, object]] = []
    now = 1_700_000_000.0
    bridge.drive = DiffDrive(DRIVE, *_motors(log), clock=lambda: 0.0, wall_clock=lambda: now)

    def route(x: float, written: float) -> Any:
        message = msgs.Twist(msgs.Vector3(x, 0.0, 0.0), msgs.Vector3(0.0, 0.0, 0.0))
        info = SimpleNamespace(valid_data=True, source_timestamp=round(written * 1e9))
        message.sample_info = info  # type: ignore[attr-defined]  # as cyclonedds sets it
        return _Route("/cmd_vel", FakeReader([message]), bridge._on_twist)  # type: ignore[arg-type]

    bridge._take(route(0.2, now - 4.0))
    assert log == [] and dict(bridge.health.bad) == {"/cmd_vel: stale": 1}
    bridge._take(route(0.2, now - 0.01))
    assert ("lpwm", 102) in log and bridge.health.forwarded == 1


# --- servos and joints ---------------------------------------------------------------


def test_servo_degrees() -> None:
    assert servo_degrees(45.0) == 45
    assert servo_degrees(44.5) == 44  # half to even
    assert servo_degrees(180.0) == 180
    for bad in (-0.1, 180.01, math.nan, math.inf):
        with pytest.raises(BadCommandError):
            servo_degrees(bad)


def _joint_state(names: list[str], positions: list[float]) -> Any:
    return msgs.JointState(name=names, position=positions)


def test_a_joint_state_is_one_checked_pose() -> None:
    joints = {"pan": ServoConfig(9, joint="pan"), "tilt": ServoConfig(10, joint="tilt", zero=0)}
    assert joint_pose(_joint_state(["pan", "tilt"], [0.0, math.pi / 2]), joints) == {9: 90, 10: 90}
    assert joint_pose(_joint_state(["tilt"], [math.pi]), joints) == {10: 180}
    for names, positions, why in [
        (["pan", "elbow"], [0.0, 0.0], "unknown joint"),
        (["pan"], [0.0, 1.0], "1 names but 2 positions"),
        (["pan", "pan"], [0.0, 0.0], "named twice"),
        (["tilt"], [-0.1], "outside 0..180"),
        (["pan"], [math.nan], "finite"),
        ([], [], "no joints"),
    ]:
        with pytest.raises(BadCommandError, match=why):
            joint_pose(_joint_state(names, positions), joints)


# --- the messages against rosbags -------------------------------------------------------


def _header(sec: int = 5, nanosec: int = 6, frame: str = "base") -> Any:
    t = TYPES.types
    return t["std_msgs/msg/Header"](
        stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame
    )


def _rosbags(msgtype: str, /, **fields: Any) -> bytes:
    return bytes(TYPES.serialize_cdr(TYPES.types[msgtype](**fields), msgtype))


def _cases() -> list[tuple[Any, str, dict[str, Any]]]:
    t = TYPES.types
    f64 = np.float64
    return [
        (msgs.Bool(data=True), "std_msgs/msg/Bool", {"data": True}),
        (msgs.Empty(), "std_msgs/msg/Empty", {"structure_needs_at_least_one_member": 0}),
        (msgs.Float32(data=3.5), "std_msgs/msg/Float32", {"data": 3.5}),
        (msgs.Float64(data=-1.25), "std_msgs/msg/Float64", {"data": -1.25}),
        (
            counters_message([1, -2, 2**32 - 1], parse_config(FULL).counters[0]),
            "std_msgs/msg/Int32MultiArray",
            {
                "layout": t["std_msgs/msg/MultiArrayLayout"](
                    dim=[t["std_msgs/msg/MultiArrayDimension"](label="pins", size=3, stride=3)],
                    data_offset=0,
                ),
                "data": np.array([1, -2, -1], dtype=np.int32),
            },
        ),
        (
            msgs.Twist(linear=msgs.Vector3(0.1, 0.2, 0.3), angular=msgs.Vector3(z=-0.5)),
            "geometry_msgs/msg/Twist",
            {
                "linear": t["geometry_msgs/msg/Vector3"](x=0.1, y=0.2, z=0.3),
                "angular": t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=-0.5),
            },
        ),
        (
            msgs.JointState(
                header=msgs.Header(msgs.Time(5, 6), "base"), name=["a", "bc"], position=[1.0, 2.0]
            ),
            "sensor_msgs/msg/JointState",
            {
                "header": _header(),
                "name": ["a", "bc"],
                "position": np.array([1.0, 2.0], dtype=f64),
                "velocity": np.array([], dtype=f64),
                "effort": np.array([], dtype=f64),
            },
        ),
        (
            msgs.DiagnosticArray(
                header=msgs.Header(msgs.Time(5, 6), "base"),
                status=[
                    msgs.DiagnosticStatus(
                        level=2,
                        name="n",
                        message="msg",
                        hardware_id="hw",
                        values=[msgs.KeyValue("k", "v"), msgs.KeyValue("key2", "")],
                    )
                ],
            ),
            "diagnostic_msgs/msg/DiagnosticArray",
            {
                "header": _header(),
                "status": [
                    t["diagnostic_msgs/msg/DiagnosticStatus"](
                        level=2,
                        name="n",
                        message="msg",
                        hardware_id="hw",
                        values=[
                            t["diagnostic_msgs/msg/KeyValue"](key="k", value="v"),
                            t["diagnostic_msgs/msg/KeyValue"](key="key2", value=""),
                        ],
                    )
                ],
            },
        ),
    ]


@pytest.mark.parametrize(("ours", "name", "fields"), _cases(), ids=lambda c: str(c)[:30])
def test_the_bridges_cdr_is_rosbags_cdr(ours: Any, name: str, fields: dict[str, Any]) -> None:
    """Byte for byte what a ROS 2 node (rosbags' Humble definitions) sends, and back."""
    theirs = _rosbags(name, **fields)
    assert ours.serialize() == theirs
    assert type(ours).deserialize(theirs) == ours
    assert type(ours).__idl_typename__ == "{}::{}::dds_::{}_".format(*name.split("/"))


# --- inputs to messages ---------------------------------------------------------------


def test_input_messages() -> None:
    assert bool_message(1) == msgs.Bool(True)
    battery = parse_config(FULL).analog_inputs[0]
    assert analog_message(500, battery).data == pytest.approx(5.5)
    assert [int32(c) for c in (0, 2**31 - 1, 2**31, 2**32 - 1, 2**32 + 5)] == [
        0,
        2**31 - 1,
        -(2**31),
        -1,
        5,
    ]


class FakeInput:
    def __init__(self, value: Any) -> None:
        self.value = value
        self.callbacks: list[Callable[[Any], None]] = []

    def read(self) -> Any:
        return self.value

    def on_change(self, callback: Callable[[Any], None]) -> Callable[[], None]:
        self.callbacks.append(callback)
        return lambda: self.callbacks.remove(callback)

    def change(self, value: Any) -> None:
        self.value = value
        for callback in list(self.callbacks):
            callback(type("Reading", (), {"value": value})())


class FakeBoard:
    """The input half of the Board API, as far as the bridge uses it."""

    def __init__(self) -> None:
        self.made: dict[int, FakeInput] = {}
        self.calls: list[tuple[str, int, dict[str, Any]]] = []

    def _make(self, kind: str, pin: int, first: Any, **options: Any) -> FakeInput:
        self.calls.append((kind, pin, options))
        self.made[pin] = FakeInput(first)
        return self.made[pin]

    def digital_input(self, pin: int, **options: Any) -> FakeInput:
        return self._make("digital", pin, True, **options)

    def analog_input(self, pin: int, **options: Any) -> FakeInput:
        return self._make("analog", pin, 100, **options)

    def counter(self, pin: int, **options: Any) -> FakeInput:
        return self._make("counter", pin, 0, **options)


def test_inputs_are_wired_to_their_topics() -> None:
    config = parse_config(FULL)
    board = FakeBoard()
    sent: dict[str, list[Any]] = {"bumper": [], "battery": [], "sensors/encoders": []}
    wiring = wire(board, config, {k: v.append for k, v in sent.items()})
    assert board.calls == [
        ("digital", 2, {"pull_up": True, "debounce_ms": 5, "interlock": None}),
        ("analog", 14, {"rate_hz": 10.0, "threshold": 0}),
        ("counter", 5, {}),
        ("counter", 6, {}),
    ]
    board.made[2].change(False)
    board.made[14].change(300)
    board.made[6].change(7)
    board.made[5].change(2**32 - 3)
    assert sent["bumper"] == [msgs.Bool(True), msgs.Bool(False)]  # the first level, then each
    assert [round(m.data, 3) for m in sent["battery"]] == [1.5, 3.5]
    assert [list(m.data) for m in sent["sensors/encoders"]] == [[0, 0], [0, 7], [-3, 7]]
    # A subscriber that joins now gets each topic's last message again.
    assert all(wiring.topics[topic].again() for topic in sent)
    assert sent["bumper"][-1] == msgs.Bool(False)
    assert [list(m.data) for m in sent["sensors/encoders"]][-1] == [-3, 7]
    for u in wiring.undo:
        u()
    board.made[2].change(True)
    assert len(sent["bumper"]) == 3


class ManualClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_an_unchanged_input_is_published_again_at_the_minimum_rate() -> None:
    """A best-effort sample lost on the network (here: the first message of the change, dropped
    on purpose) is repaired by the next refresh, one period after it went out (issue 33)."""
    clock = ManualClock()
    arrived: list[Any] = []
    lost = [msgs.Float32(7.0)]  # the sample the network loses

    def lossy(message: Any) -> None:
        if lost and message == lost[0]:
            lost.pop()
        else:
            arrived.append(message)

    last = LastPublished(lossy, clock)
    assert last.refresh(1.0) == 101.0 and arrived == []  # nothing to publish yet
    last(msgs.Float32(5.0))
    last(msgs.Float32(7.0))  # lost
    assert arrived == [msgs.Float32(5.0)]
    clock.now = 100.5
    assert last.refresh(1.0) == 101.0 and arrived == [msgs.Float32(5.0)]  # not yet due
    clock.now = 101.0
    assert last.refresh(1.0) == 102.0  # due: repaired
    assert arrived == [msgs.Float32(5.0), msgs.Float32(7.0)]
    clock.now = 101.5
    last.again()  # a new subscriber's copy counts as published: the next is a period later
    assert last.refresh(1.0) == 102.5 and len(arrived) == 3


def test_the_bridge_refreshes_every_input_at_its_configured_rate() -> None:
    from protoduino.ros2.bridge import Bridge
    from protoduino.ros2.inputs import Wiring

    clock = ManualClock()
    bridge = Bridge("unused", parse_config({"min_publish_rate": 4}), clock=clock)
    sent: dict[str, list[Any]] = {"a": [], "b": []}
    topics = {name: LastPublished(out.append, clock) for name, out in sent.items()}
    bridge._inputs = Wiring([], topics)
    topics["a"](msgs.Bool(True))
    clock.now += 0.125
    topics["b"](msgs.Bool(False))
    assert bridge._refresh_inputs() == 100.25  # a's is due first
    clock.now = 100.25
    assert bridge._refresh_inputs() == 100.375 and len(sent["a"]) == 2 and len(sent["b"]) == 1
    clock.now = 100.375
    assert bridge._refresh_inputs() == 100.5 and len(sent["b"]) == 2


# --- /diagnostics ---------------------------------------------------------------------


def _stats(**changes: Any) -> Stats:
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(Stats):
        fields[f.name] = {} if f.name in ("dropped", "events_dropped") else 0
    fields.update(state="active", connected=True, rtt=None, last_ping=None)
    fields.update(changes)
    return Stats(**fields)


def _by_name(report: msgs.DiagnosticArray) -> dict[str, tuple[int, dict[str, str]]]:
    return {s.name: (s.level, {kv.key: kv.value for kv in s.values}) for s in report.status}


def test_diagnostics() -> None:
    health = Health("protoduino r1", "/dev/ttyACM0")
    report = _by_name(health.report(_stats(acks=12, dropped={"crc": 2}, rtt=0.004), now=10.25))
    level, link = report["protoduino r1: link"]
    assert level == OK and link["acks"] == "12" and link["dropped.crc"] == "2"
    assert link["rtt"] == "0.004" and "last_ping" not in link
    assert report["protoduino r1: failsafe"][0] == OK
    assert report["protoduino r1: bridge"] == (
        OK,
        {
            "bad_messages": "0",
            "forwarded": "0",
            "superseded": "0",
            "refused_by_device": "0",
            "stops": "0",
            "stop_latched": "false",
            "held_by_stop": "0",
            "cmd_vel_stale_stops": "0",
            "interlock_clears": "0",
        },
    )

    health.bad_message("/r1/pan", "invalid")
    urgent = health.event(
        Event(EventKind.FAILSAFE, "failsafe", {"active": True, "cause": "ping_timeout"})
    )
    assert urgent and not health.event(Event(EventKind.DECODE_ERROR, "decode errors: 1"))
    report = _by_name(health.report(_stats(state="disconnected")))
    assert report["protoduino r1: link"][0] == ERROR
    level, failsafe = report["protoduino r1: failsafe"]
    assert level == ERROR and failsafe["cause"] == "ping_timeout" and failsafe["failsafes"] == "1"
    level, bridge = report["protoduino r1: bridge"]
    assert level == WARN and bridge["bad./r1/pan: invalid"] == "1"
    # WARN only for refusals since the previous report; the count stays.
    assert _by_name(health.report(_stats()))["protoduino r1: bridge"][0] == OK
    health.event(Event(EventKind.FAILSAFE, "over", {"active": False, "cause": "none"}))
    assert _by_name(health.report(_stats()))["protoduino r1: failsafe"][0] == OK


def test_a_latched_stop_and_a_shutdown_are_reported() -> None:
    health = Health("protoduino r1", "/dev/ttyACM0")
    health.latch(True)
    health.count("held", 2)
    level, bridge = _by_name(health.report(_stats()))["protoduino r1: bridge"]
    assert level == WARN and bridge["stop_latched"] == "true" and bridge["held_by_stop"] == "2"
    health.latch(False)
    assert _by_name(health.report(_stats()))["protoduino r1: bridge"][0] == OK
    health.shut_down(True)
    report = {s.name: s for s in health.report(_stats(state="closed")).status}
    assert report["protoduino r1: link"].level == STALE
    assert report["protoduino r1: bridge"].level == STALE
    assert report["protoduino r1: bridge"].message.startswith("shut down: every output")


def test_the_report_is_stamped_with_the_wall_clock() -> None:
    report = Health("x", "y").report(_stats(), now=1700000000.25)
    assert (report.header.stamp.sec, report.header.stamp.nanosec) == (1700000000, 250000000)


# --- the loop's handling of one topic -------------------------------------------------


class FakeReader:
    """Hands out queued samples one at a time; an exception in the queue is raised by take."""

    def __init__(self, queue: list[Any]) -> None:
        self.queue = queue

    def take(self, N: int = 1) -> list[Any]:  # noqa: N803  (cyclonedds' name)
        if not self.queue:
            return []
        item = self.queue.pop(0)
        if isinstance(item, Exception):
            raise item
        return [item]


def test_the_newest_valid_command_of_a_topic_wins_and_bad_ones_are_counted() -> None:
    from protoduino.ros2.bridge import Bridge, _Route

    bridge = Bridge("unused", parse_config({}))  # nothing opens before start()
    done: list[float] = []

    def prepare(message: msgs.Float64) -> Callable[[], None]:
        value = servo_degrees(message.data)
        return lambda: done.append(value)

    samples: list[Any] = [msgs.Float64(d) for d in (10.0, 20.0, 500.0, 30.0)]
    samples.insert(1, UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"))
    samples.append(msgs.Float64(math.nan))
    bridge._take(_Route("/pan", FakeReader(samples), prepare))  # type: ignore[arg-type]
    assert done == [30]  # one command sent: the newest valid one
    assert bridge.health.forwarded == 1 and bridge.health.superseded == 2
    assert dict(bridge.health.bad) == {"/pan: undecodable": 1, "/pan: invalid": 2}
    bridge._take(_Route("/pan", FakeReader([]), prepare))  # type: ignore[arg-type]
    assert done == [30]  # nothing waiting: nothing sent


class StopBoard:
    def __init__(self) -> None:
        self.stops = 0

    def stop(self) -> None:
        self.stops += 1


def test_stop_latches_until_resume() -> None:
    """After a STOP every command is held (counted, nothing sent) until a resume; a resume
    moves nothing itself (issue 33: a 10 Hz node's next Twist must not drive again)."""
    from protoduino.ros2.bridge import Bridge, _Route

    bridge = Bridge("unused", parse_config({}))
    board = StopBoard()
    bridge.board = board  # type: ignore[assignment]
    done: list[float] = []

    def servo(degrees: float) -> _Route:
        def prepare(message: msgs.Float64) -> Callable[[], None]:
            value = servo_degrees(message.data)
            return lambda: done.append(value)

        return _Route("/pan", FakeReader([msgs.Float64(degrees)]), prepare)  # type: ignore[arg-type]

    def control(prepare: Any) -> _Route:
        return _Route("/c", FakeReader([msgs.Empty()]), prepare, held=False)  # type: ignore[arg-type]

    bridge._take(servo(10.0))
    bridge._take(control(bridge._on_stop))
    assert board.stops == 1 and done == [10]
    bridge._take(servo(20.0))
    bridge._take(servo(30.0))
    assert done == [10] and bridge.health.held == 2 and bridge.health.stop_latched
    bridge._take(control(bridge._on_resume))
    assert done == [10] and board.stops == 1 and not bridge.health.stop_latched
    bridge._take(servo(40.0))
    assert done == [10, 40]

    class DeafBoard(StopBoard):
        def stop(self) -> None:
            raise AckTimeoutError("no Ack")

    bridge.board = DeafBoard()
    bridge._take(control(bridge._on_stop))  # its outcome unknown: latched all the same
    bridge._take(servo(50.0))
    assert done == [10, 40] and bridge.health.stop_latched


# --- the command line -----------------------------------------------------------------


def test_the_command_refuses_a_bad_config_before_any_port(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from protoduino.cli.main import main

    path = tmp_path / "robot.yaml"
    path.write_text("servos: [{pin: 9}]\n")
    with pytest.raises(SystemExit) as exited:
        main(["ros2", "/dev/no-such-port", "--config", str(path)])
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "servos[0]: give it a topic" in err and err.count("\n") == 1


def test_without_cyclonedds_the_command_says_what_to_install(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import sys

    from protoduino.cli.main import main

    path = tmp_path / "robot.yaml"
    path.write_text("servos: [{pin: 9, topic: pan}]\n")
    for name in [m for m in sys.modules if m.startswith("cyclonedds")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.delitem(sys.modules, "protoduino.ros2.bridge", raising=False)
    monkeypatch.setitem(sys.modules, "cyclonedds", None)  # as if not installed
    assert main(["ros2", "/dev/no-such-port", "--config", str(path)]) == 1
    assert "needs cyclonedds: pip install 'protoduino[ros2]'" in capsys.readouterr().err


def test_a_clean_close_stops_the_outputs_before_closing_the_board() -> None:
    from protoduino.errors import AckTimeoutError
    from protoduino.ros2.bridge import Bridge

    calls: list[str] = []

    class Board:
        closed = False

        def __init__(self, stop_fails: bool = False) -> None:
            self.stop_fails = stop_fails

        def stop(self) -> None:
            calls.append("stop")
            if self.stop_fails:
                raise AckTimeoutError("the link is down")

        def close(self) -> None:
            calls.append("close")

        stats = _stats(state="closed")

    class Writer:
        def write(self, report: msgs.DiagnosticArray) -> None:
            calls.append("report: " + report.status[2].message)

        def wait_for_acks(self, timeout: int) -> bool:
            calls.append("acked")
            return True

        def set_listener(self, listener: Any) -> None:
            pass

    for fails in (False, True):  # a stop that fails still closes (the failsafe takes over)
        calls.clear()
        bridge = Bridge("unused", parse_config({}))
        bridge.board = Board(fails)  # type: ignore[assignment]
        bridge._writers["/diagnostics"] = Writer()  # type: ignore[assignment]
        bridge.close()
        # The last word on /diagnostics says so (issue 33: it was "link active").
        outcome = "the outputs left to the device's failsafe" if fails else "every output driven"
        assert calls[:2] == ["stop", "close"] and calls[3] == "acked", calls
        assert calls[2].startswith(f"report: shut down: {outcome}"), calls


def test_a_bridge_stops_only_what_it_inherits() -> None:
    """Outputs the device already drives at the start (a resumed session) are stopped; a
    device that drives nothing gets no Stop."""
    from protoduino.board import OutputState
    from protoduino.ros2.bridge import _start_safe

    class Board:
        def __init__(self, outputs: dict[int, OutputState]) -> None:
            self.outputs, self.stops = outputs, 0

        def read_outputs(self) -> dict[int, OutputState]:
            return self.outputs

        def stop(self) -> None:
            self.stops += 1

    fresh = Board({})
    _start_safe(fresh)  # type: ignore[arg-type]
    assert fresh.stops == 0
    resumed = Board({3: OutputState(3, "pwm", 102, 102)})
    _start_safe(resumed)  # type: ignore[arg-type]
    assert resumed.stops == 1


# --- odometry (issue 33 item 5) ---------------------------------------------------------

ODOM_DRIVE: dict[str, Any] = {
    "wheel_base": 0.2,
    "max_speed": 0.5,
    "left": {"pwm": 9, "direction": 4, "encoder": 2},
    "right": {"pwm": 11, "direction": 12, "invert": True, "encoder": 3},
}


def _odometry_config(**odometry: Any) -> BridgeConfig:
    return parse_config({"drive": ODOM_DRIVE, "odometry": {"ticks_per_metre": 1000, **odometry}})


def test_odometry_configuration() -> None:
    """Each wheel's encoder is a key of its motor; the geometry and rate of the odometry's."""
    from protoduino.ros2.config import OdometryConfig

    config = _odometry_config()
    assert config.drive is not None
    assert (config.drive.left.encoder, config.drive.right.encoder) == (2, 3)
    assert config.odometry == OdometryConfig(1000.0)
    odometry = config.odometry
    assert (odometry.rate_hz, odometry.topic, odometry.tf_topic) == (50.0, "odom", "/tf")
    assert odometry.ticks_topic == "sensors/encoders"  # the design notes' topic
    assert (odometry.frame_id, odometry.child_frame_id) == ("odom", "base_link")
    custom = _odometry_config(rate_hz=20, topic="wheel_odom", frame_id="odom2").odometry
    assert custom is not None and (custom.rate_hz, custom.topic) == (20.0, "wheel_odom")
    assert parse_config(FULL).odometry is None and parse_config(FULL).drive.left.encoder is None  # type: ignore[union-attr]


def _no_encoder(side: str) -> dict[str, Any]:
    return {**ODOM_DRIVE, side: {k: v for k, v in ODOM_DRIVE[side].items() if k != "encoder"}}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"odometry": {"ticks_per_metre": 1000}}, "odometry: needs a drive with an encoder"),
        (
            {"drive": _no_encoder("right"), "odometry": {"ticks_per_metre": 1000}},
            "needs a drive with an encoder on each wheel",
        ),
        ({"drive": ODOM_DRIVE}, "an encoder is given without odometry"),
        ({"drive": ODOM_DRIVE, "odometry": {}}, "ticks_per_metre is required"),
        ({"drive": ODOM_DRIVE, "odometry": {"ticks_per_metre": 0}}, "must be above 0"),
        (
            {"drive": ODOM_DRIVE, "odometry": {"ticks_per_metre": 1, "rate_hz": 0}},
            "rate_hz must be >= 0.1",
        ),
        (
            {"drive": ODOM_DRIVE, "odometry": {"ticks_per_metre": 1, "wheel_base": 1}},
            "unknown key",  # the drive's wheel base is the one
        ),
        (
            {
                "drive": ODOM_DRIVE,
                "odometry": {"ticks_per_metre": 1},
                "counters": [{"pins": [3], "topic": "c"}],
            },
            "pin 3 is both the drive's right encoder and a counter",
        ),
        (
            {
                "drive": ODOM_DRIVE,
                "odometry": {"ticks_per_metre": 1},
                "counters": [{"pins": [5]}],
            },
            "topic 'sensors/encoders' is both the odometry's ticks",
        ),
        (
            {"drive": ODOM_DRIVE, "odometry": {"ticks_per_metre": 1, "child_frame_id": "odom"}},
            "frame_id and child_frame_id are both",
        ),
        (
            {"drive": ODOM_DRIVE, "odometry": {"ticks_per_metre": 1, "frame_id": "a b"}},
            "frame id",
        ),
    ],
)
def test_bad_odometry_configurations_are_refused(data: Any, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_config(data)


def test_the_pose_is_the_exact_arc_of_a_differential_drive() -> None:
    from protoduino.ros2.odometry import Pose2D, integrate

    start = Pose2D()
    assert integrate(start, 0.5, 0.5, 0.2) == Pose2D(0.5, 0.0, 0.0)
    turned = integrate(start, -0.1 * math.pi / 2, 0.1 * math.pi / 2, 0.2)  # in place, 90 deg
    assert turned.x == pytest.approx(0.0, abs=1e-12) and turned.y == pytest.approx(0.0, abs=1e-12)
    assert turned.theta == pytest.approx(math.pi / 2)
    ahead = integrate(turned, 0.3, 0.3, 0.2)  # now along +y
    assert (ahead.x, ahead.y) == pytest.approx((0.0, 0.3), abs=1e-12)
    # A quarter circle of radius 1 m to the left (left wheel on radius 0.9, right on 1.1).
    quarter = integrate(start, 0.9 * math.pi / 2, 1.1 * math.pi / 2, 0.2)
    assert (quarter.x, quarter.y, quarter.theta) == pytest.approx((1.0, 1.0, math.pi / 2))
    # Exact: the same arc in 1000 samples ends where one sample does.
    pose = start
    for _ in range(1000):
        pose = integrate(pose, 0.9 * math.pi / 2000, 1.1 * math.pi / 2000, 0.2)
    assert (pose.x, pose.y, pose.theta) == pytest.approx((quarter.x, quarter.y, quarter.theta))
    # Backwards, and the heading stays in (-pi, pi].
    assert integrate(start, -0.2, -0.2, 0.2) == Pose2D(-0.2, 0.0, 0.0)
    around = integrate(Pose2D(theta=3.0), -0.05, 0.05, 0.2)  # +0.5 rad past pi
    assert around.theta == pytest.approx(3.5 - 2 * math.pi)


def test_tick_increments_wrap_with_the_counter() -> None:
    from protoduino.ros2.odometry import tick_increment

    assert tick_increment(25, 20) == 5
    assert tick_increment(3, 2**32 - 2) == 5  # across the device's wrap


class FakeWheel:
    """A wheel whose count and direction the test sets."""

    def __init__(self) -> None:
        self.count: int | None = None
        self.forward: bool | None = None

    def wheel(self) -> Any:
        from protoduino.ros2.odometry import Wheel

        return Wheel(lambda: self.count, lambda: self.forward)


def test_the_tracker_signs_ticks_by_the_direction_pins_on_a_manual_clock() -> None:
    from protoduino.ros2.odometry import Tracker

    clock = ManualClock()
    config = _odometry_config().odometry
    assert config is not None
    left, right = FakeWheel(), FakeWheel()
    tracker = Tracker(config, 0.2, left.wheel(), right.wheel(), clock)
    first = tracker.sample()  # no count yet: at the origin, still
    assert (first.pose.x, first.linear, first.ticks) == (0.0, 0.0, (0, 0))
    # Unknown direction at the start: forward (the counter counts up).
    left.count = right.count = 100
    clock.now += 0.02
    sample = tracker.sample()
    assert sample.ticks == (100, 100) and sample.pose.x == pytest.approx(0.1)
    assert sample.linear == pytest.approx(0.1 / 0.02) and sample.angular == 0.0
    # The left pin backwards: its ticks count down; a turn to the left in place.
    left.forward, right.forward = False, True
    left.count, right.count = 150, 150
    clock.now += 0.02
    sample = tracker.sample()
    assert sample.ticks == (50, 150)
    assert sample.pose.theta == pytest.approx(0.1 / 0.2)
    assert sample.linear == pytest.approx(0.0) and sample.angular == pytest.approx(0.5 / 0.02)
    # Direction unknown again (the device drove the motors safe): the last one holds.
    left.forward = right.forward = None
    left.count, right.count = 160, 160
    clock.now += 0.02
    assert tracker.sample().ticks == (40, 160)
    # No new ticks: the pose stays, the velocity is 0.
    clock.now += 0.02
    still = tracker.sample()
    assert still.pose == tracker.pose and still.linear == 0.0 and still.angular == 0.0


def test_odometry_messages() -> None:
    from protoduino.ros2.odometry import (
        Pose2D,
        Sample,
        odometry_message,
        tf_message,
        ticks_message,
    )

    config = _odometry_config().odometry
    assert config is not None
    sample = Sample(Pose2D(1.0, 2.0, math.pi / 2), 0.3, -0.4, (-5, 2**32 + 7))
    odom = odometry_message(sample, config, 1700000000.25)
    assert odom.header == msgs.Header(msgs.Time(1700000000, 250000000), "odom")
    assert odom.child_frame_id == "base_link"
    assert odom.pose.pose.position == msgs.Point(1.0, 2.0, 0.0)
    q = odom.pose.pose.orientation
    assert (q.z, q.w) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))
    assert (odom.twist.twist.linear.x, odom.twist.twist.angular.z) == (0.3, -0.4)
    (transform,) = tf_message(sample, config, 1700000000.25).transforms
    assert transform.header == odom.header and transform.child_frame_id == "base_link"
    assert transform.transform.translation == msgs.Vector3(1.0, 2.0, 0.0)
    assert transform.transform.rotation == q
    assert ticks_message(sample.ticks).data == [-5, 7]  # int32, wrapping


def _odometry_cases() -> list[tuple[Any, str, dict[str, Any]]]:
    from protoduino.ros2.odometry import Pose2D, Sample, odometry_message, tf_message

    t = TYPES.types
    config = _odometry_config().odometry
    assert config is not None
    sample = Sample(Pose2D(1.0, -2.0, 0.5), 0.25, -0.5, (1, 2))
    quaternion = t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(0.25), w=math.cos(0.25))
    header = _header(5, 250000000, "odom")
    zeros = np.zeros(36, dtype=np.float64)
    vector = t["geometry_msgs/msg/Vector3"]
    return [
        (
            odometry_message(sample, config, 5.25),
            "nav_msgs/msg/Odometry",
            {
                "header": header,
                "child_frame_id": "base_link",
                "pose": t["geometry_msgs/msg/PoseWithCovariance"](
                    pose=t["geometry_msgs/msg/Pose"](
                        position=t["geometry_msgs/msg/Point"](x=1.0, y=-2.0, z=0.0),
                        orientation=quaternion,
                    ),
                    covariance=zeros,
                ),
                "twist": t["geometry_msgs/msg/TwistWithCovariance"](
                    twist=t["geometry_msgs/msg/Twist"](
                        linear=vector(x=0.25, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=-0.5)
                    ),
                    covariance=zeros,
                ),
            },
        ),
        (
            tf_message(sample, config, 5.25),
            "tf2_msgs/msg/TFMessage",
            {
                "transforms": [
                    t["geometry_msgs/msg/TransformStamped"](
                        header=header,
                        child_frame_id="base_link",
                        transform=t["geometry_msgs/msg/Transform"](
                            translation=vector(x=1.0, y=-2.0, z=0.0), rotation=quaternion
                        ),
                    )
                ]
            },
        ),
    ]


@pytest.mark.parametrize(("ours", "name", "fields"), _odometry_cases(), ids=["odom", "tf"])
def test_the_odometry_cdr_is_rosbags_cdr(ours: Any, name: str, fields: dict[str, Any]) -> None:
    """Byte for byte what rosbags' Humble nav_msgs/Odometry and tf2_msgs/TFMessage are."""
    test_the_bridges_cdr_is_rosbags_cdr(ours, name, fields)


def test_the_bridge_publishes_odometry_each_period() -> None:
    """Odometry, /tf and the ticks go out together, every 1 / rate_hz of the bridge's clock
    (a late sample is not followed by a burst)."""
    from protoduino.ros2.bridge import Bridge
    from protoduino.ros2.odometry import Tracker

    clock = ManualClock()
    config = _odometry_config(rate_hz=25)
    assert config.odometry is not None
    bridge = Bridge("unused", config, clock=clock)
    left, right = FakeWheel(), FakeWheel()
    bridge._odometry = Tracker(config.odometry, 0.2, left.wheel(), right.wheel(), clock)
    sent: dict[str, list[Any]] = {"odom": [], "/tf": [], "sensors/encoders": []}

    class Writer:
        def __init__(self, out: list[Any]) -> None:
            self.write = out.append

    bridge._writers.update({name: Writer(out) for name, out in sent.items()})  # type: ignore[misc]
    left.count = right.count = 40
    assert bridge._publish_odometry(100.0) == 100.04
    assert [len(out) for out in sent.values()] == [1, 1, 1]
    assert sent["odom"][0].pose.pose.position.x == pytest.approx(0.04)
    assert sent["sensors/encoders"][0].data == [40, 40]
    clock.now = 100.5  # late: the next is a period from now
    assert bridge._publish_odometry(100.04) == pytest.approx(100.54)


def test_the_odometry_example_in_the_docs_is_valid() -> None:
    """docs/ros2.md's odometry robot.yaml is what the configuration reads."""
    import yaml

    docs = (Path(__file__).resolve().parents[2] / "docs" / "ros2.md").read_text()
    section = docs.split("**Odometry** (issue 33)", 1)[1]
    snippet = section.split("```yaml\n", 1)[1].split("```", 1)[0]
    config = parse_config(yaml.safe_load(snippet))
    assert config.odometry is not None and config.drive is not None
    assert config.odometry.ticks_per_metre == 1000 and config.odometry.rate_hz == 50
    assert (config.drive.left.encoder, config.drive.right.encoder) == (2, 3)


def test_ticks_reported_before_a_reversal_count_the_old_way() -> None:
    """The drive calls the odometry's update once the duty is 0, just before the direction pin
    turns: the ticks reported until then count the way the wheel was going."""
    from protoduino.ros2.odometry import Tracker, Wheel

    clock = ManualClock()
    config = _odometry_config().odometry
    assert config is not None
    log: list[tuple[str, object]] = []
    left, right = _motors(log)
    counts = [0, 0]
    tracker = Tracker(
        config,
        0.2,
        Wheel(lambda: counts[0], lambda: left.forward),
        Wheel(lambda: counts[1], lambda: right.forward),
        clock,
    )
    for motor in (left, right):
        motor.before_turn = tracker.update
    left.apply(WheelCommand(100, True))
    right.apply(WheelCommand(100, True))
    tracker.sample()
    counts[:] = [50, 50]  # reported while both go ahead
    log.clear()

    def turning() -> None:
        log.append(("turn", tracker.ticks[0]))
        tracker.update()

    left.before_turn = turning
    left.apply(WheelCommand(100, False))  # the left wheel reverses
    assert log == [("lpwm", 0), ("turn", 0), ("ldir", False), ("lpwm", 100)]
    assert tracker.ticks == [50, 50]  # counted ahead, before the pin turned
    counts[:] = [70, 70]
    clock.now += 0.02
    sample = tracker.sample()
    assert sample.ticks == (30, 70)
    # The velocity is over the whole period, both updates in it.
    assert sample.linear == pytest.approx((0.03 + 0.07) / 2 / 0.02)
