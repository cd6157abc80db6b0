"""The example robot: what ``protoduino ros2 --sim`` bridges when no ``--config`` is given.

It is the robot.yaml of docs/ros2.md (a test holds the two equal): the design notes' robot,
on pins an Uno can do all at once. The two servos take Timer1's pins 9 and 10, so the drive's
PWM is on Timer0's pins 5 and 6 (976 Hz, beside the device's clock), and the two encoders
have the counter pins 2 and 3.
"""

from __future__ import annotations

from .config import BridgeConfig, parse_config

ROBOT_YAML = """\
namespace: robot1            # topics are /robot1/...; one namespace per board
# domain_id: 0               # optional: else $ROS_DOMAIN_ID, else 0 (--domain-id overrides)
failsafe_timeout: 1.0        # s, 0.1..60: the device's failsafe (below)
diagnostics_period: 1.0      # s between /diagnostics reports
min_publish_rate: 1.0        # Hz, 0.01..100: each input published at least this often
servos:                      # a std_msgs/Float64 topic in degrees, a joint name, or both
  - {pin: 9, topic: servo/pan, joint: pan, safe: 90}
  - {pin: 10, joint: tilt, safe: 45, min_us: 544, max_us: 2400, zero: 90, max_speed: 120}
joint_topic: joint_commands  # the arm's sensor_msgs/JointState (every servo with a joint)
digital_outputs:             # std_msgs/Bool
  - {pin: 13, topic: led, safe: false}
stop: {topic: stop, type: Empty, resume_topic: resume}   # or type: Bool (true stops)
drive:                       # /cmd_vel (geometry_msgs/Twist) to a differential drive
  wheel_base: 0.20           # m between the wheels
  max_speed: 0.50            # m/s of a wheel at duty 255
  timeout: 0.5               # s without a Twist: motors stopped
  left: {pwm: 5, direction: 4}
  right: {pwm: 6, direction: 12, invert: true}
digital_inputs:              # std_msgs/Bool; interlock: low (or high) trips every output
  - {pin: 7, topic: bumper, pull_up: true, debounce_ms: 10, interlock: low}  # on the device
analog_inputs:               # std_msgs/Float32: counts * scale + offset, on each change
  - {pin: A0, topic: battery, scale: 0.0147, offset: 0.0, rate_hz: 10, threshold: 2}
counters:                    # std_msgs/Int32MultiArray, one value per pin in this order
  - {pins: [2, 3], topic: sensors/encoders}   # left, right
"""


def example_config() -> BridgeConfig:
    """The example robot, checked like any robot.yaml (it needs PyYAML, the ros2 extra)."""
    try:
        import yaml
    except ImportError:
        from ..errors import ExtraMissingError
        from .config import EXTRA_MISSING

        raise ExtraMissingError(EXTRA_MISSING.format(package="PyYAML")) from None
    return parse_config(yaml.safe_load(ROBOT_YAML))
