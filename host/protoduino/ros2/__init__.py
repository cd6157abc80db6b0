"""protoduino on ROS 2: a bridge that puts a board's pins on DDS topics (issue 25).

``protoduino ros2 PORT --config robot.yaml`` runs it; the same as an API::

    from protoduino.ros2 import Bridge, load_config

    with Bridge("/dev/ttyACM0", load_config("robot.yaml")) as bridge:
        bridge.run()          # until bridge.stop() from another thread or a signal

It needs the ``ros2`` extra (``pip install protoduino[ros2]``: Cyclone DDS and
PyYAML). Modules: :mod:`.config` (robot.yaml), :mod:`.msgs` (the ROS 2 types
on DDS), :mod:`.dds` (names, QoS, the domain's configuration), :mod:`.drive`
(``/cmd_vel`` kinematics), :mod:`.servos` (servo commands), :mod:`.inputs`
(inputs to topics), :mod:`.odometry` (two encoders to Odometry and /tf),
:mod:`.diagnostics`, :mod:`.graph` (the node in ROS 2's graph), :mod:`.services`
(the Trigger services, answered by an rclpy node beside the bridge), :mod:`.bridge`
(the loop). docs/ros2.md says how to run it next to a ROS 2 installation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import ConfigError, ExtraMissingError
from .config import EXTRA_MISSING, BridgeConfig, load_config, parse_config

if TYPE_CHECKING:
    from .bridge import Bridge

__all__ = [
    "Bridge",
    "BridgeConfig",
    "ConfigError",
    "ExtraMissingError",
    "load_config",
    "parse_config",
]


def __getattr__(name: str) -> Any:
    # Bridge imports cyclonedds: only on use, so that the configuration checks (and a
    # clear error) need nothing more.
    if name == "Bridge":
        try:
            from .bridge import Bridge
        except ImportError as error:
            if error.name is None or not error.name.startswith("cyclonedds"):
                raise
            raise ExtraMissingError(EXTRA_MISSING.format(package="cyclonedds")) from error
        return Bridge
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
