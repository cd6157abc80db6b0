"""The bridge's configuration: what a robot.yaml says, checked before anything opens.

The mapping from pins to ROS 2 topics is data (issue 25): this module turns
a YAML document (or the same structure as Python dicts and lists) into
frozen dataclasses, refusing anything it does not know with a
:class:`ConfigError` that names the key, so a typo never silently leaves a
servo unbridged. It checks what can be checked without a device (types,
ranges, duplicate pins and topics, ROS name syntax); the device's own
limits (which pins exist, PWM pins) are checked by the Board when the
bridge configures the outputs.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeVar

from ..errors import ConfigError, ExtraMissingError

#: ROS 2's defaults (the usual cmd_vel watchdog and the diagnostics rate).
CMD_VEL_TIMEOUT = 0.5
DIAGNOSTICS_PERIOD = 1.0
#: The device's failsafe under the bridge: short, since a robot is moving.
FAILSAFE_TIMEOUT = 1.0
#: An input that does not change is still published this often (Hz): a best-effort sample
#: lost on the network is repaired within one period.
MIN_PUBLISH_RATE = 1.0
#: The design notes' encoder rate (Hz): odometry is published this often by default.
ODOMETRY_RATE = 50.0
#: A Pose's most items (protoduino.options): one JointState is one pose.
MAX_JOINTS = 8
#: Uno analog pins by name (A0 is pin 14).
ANALOG_NAMES = {f"A{i}": 14 + i for i in range(8)}

StopType = Literal["Empty", "Bool"]
InterlockLevel = Literal["low", "high"]
T = TypeVar("T")

# A ROS 2 name token: letters, digits and underscores, not starting with a digit.
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


EXTRA_MISSING = "the ROS 2 bridge needs {package}: pip install 'protoduino[ros2]'"


@dataclass(frozen=True, slots=True)
class ServoConfig:
    pin: int
    #: std_msgs/Float64 in degrees (0..180); None: no topic of its own.
    topic: str | None = None
    #: Its name in a sensor_msgs/JointState (positions in radians); None: not a joint.
    joint: str | None = None
    safe: int = 90
    min_us: int = 544
    max_us: int = 2400
    #: The servo's angle (degrees) at joint position 0 rad.
    zero: float = 90.0
    #: Its speed limit on the device (degrees/s, Board.servo's max_speed); None: none.
    max_speed: float | None = None


@dataclass(frozen=True, slots=True)
class DigitalOutputConfig:
    pin: int
    topic: str
    safe: bool = False


@dataclass(frozen=True, slots=True)
class MotorConfig:
    #: The PWM pin setting the speed (duty 0..255) and the pin setting the direction.
    pwm: int
    direction: int
    #: Swap the direction pin's meaning (a motor wired the other way round).
    invert: bool = False
    #: The counter pin of this wheel's encoder (for odometry); None: no encoder.
    encoder: int | None = None


@dataclass(frozen=True, slots=True)
class DriveConfig:
    """``/cmd_vel`` (geometry_msgs/Twist) to a differential drive."""

    left: MotorConfig
    right: MotorConfig
    #: Distance between the wheels (m) and the wheel speed at duty 255 (m/s).
    wheel_base: float
    max_speed: float
    topic: str = "cmd_vel"
    #: No Twist for this long (s) stops the motors.
    timeout: float = CMD_VEL_TIMEOUT


@dataclass(frozen=True, slots=True)
class OdometryConfig:
    """Odometry from the drive's two wheel encoders (each motor's ``encoder``).

    The wheel base is the drive's; a wheel's direction is the one its direction pin gives
    (an encoder counts edges, not direction).
    """

    #: Encoder ticks per metre a wheel travels.
    ticks_per_metre: float
    #: Hz: Odometry, the transform and the ticks are published this often.
    rate_hz: float = ODOMETRY_RATE
    #: nav_msgs/Odometry.
    topic: str = "odom"
    #: tf2_msgs/TFMessage with the frame_id -> child_frame_id transform.
    tf_topic: str = "/tf"
    #: std_msgs/Int32MultiArray: the signed ticks (left, right) since the start.
    ticks_topic: str = "sensors/encoders"
    frame_id: str = "odom"
    child_frame_id: str = "base_link"


@dataclass(frozen=True, slots=True)
class StopConfig:
    topic: str = "stop"
    type: StopType = "Empty"
    #: std_msgs/Empty that releases a STOP (until then every command is held).
    resume_topic: str = "resume"


@dataclass(frozen=True, slots=True)
class ServicesConfig:
    """STOP, resume and the interlock's clear as ``std_srvs/srv/Trigger`` services.

    They are answered by a small rclpy node the bridge starts beside itself
    (:mod:`.services`), run by ``python``: an interpreter of a ROS 2 installation
    (one that imports rclpy and std_srvs). Service names resolve in the namespace,
    as topics do.
    """

    python: str = "python3"
    stop: str = "stop"
    resume: str = "resume"
    #: Only with an interlock input.
    clear_interlock: str = "clear_interlock"


@dataclass(frozen=True, slots=True)
class DigitalInputConfig:
    pin: int
    topic: str
    pull_up: bool = False
    debounce_ms: int = 0
    #: Trip every output safe on the device itself at this level (Board.digital_input's).
    interlock: InterlockLevel | None = None


@dataclass(frozen=True, slots=True)
class AnalogInputConfig:
    pin: int
    topic: str
    #: Published value = counts * scale + offset (e.g. volts behind a divider).
    scale: float = 1.0
    offset: float = 0.0
    rate_hz: float = 10.0
    threshold: int = 0


@dataclass(frozen=True, slots=True)
class CounterConfig:
    """Several counters on one std_msgs/Int32MultiArray, in the order of ``pins``."""

    pins: tuple[int, ...]
    topic: str = "sensors/encoders"


@dataclass(frozen=True, slots=True)
class BridgeConfig:
    #: The ROS namespace of this board's topics ("" for none).
    namespace: str = ""
    #: The DDS domain (ROS_DOMAIN_ID); None: the environment's ROS_DOMAIN_ID, else 0.
    domain_id: int | None = None
    failsafe_timeout: float = FAILSAFE_TIMEOUT
    diagnostics_period: float = DIAGNOSTICS_PERIOD
    #: Hz: each input topic is published at least this often, changed or not.
    min_publish_rate: float = MIN_PUBLISH_RATE
    diagnostics_topic: str = "/diagnostics"
    joint_topic: str = "joint_commands"
    #: std_msgs/Empty that clears a tripped interlock (only with an interlock input).
    clear_interlock_topic: str = "clear_interlock"
    servos: tuple[ServoConfig, ...] = ()
    digital_outputs: tuple[DigitalOutputConfig, ...] = ()
    stop: StopConfig = field(default_factory=StopConfig)
    drive: DriveConfig | None = None
    odometry: OdometryConfig | None = None
    digital_inputs: tuple[DigitalInputConfig, ...] = ()
    analog_inputs: tuple[AnalogInputConfig, ...] = ()
    counters: tuple[CounterConfig, ...] = ()
    #: Trigger services beside the topics; None: none.
    services: ServicesConfig | None = None

    @property
    def interlocks(self) -> tuple[DigitalInputConfig, ...]:
        """The digital inputs that are interlocks."""
        return tuple(d for d in self.digital_inputs if d.interlock is not None)

    @property
    def joints(self) -> dict[str, ServoConfig]:
        """The servos a JointState moves, by joint name."""
        return {s.joint: s for s in self.servos if s.joint is not None}

    def resolved_domain(self) -> int:
        """The DDS domain id: the config's, else ROS_DOMAIN_ID, else 0 (as ROS 2 does)."""
        if self.domain_id is not None:
            return self.domain_id
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if not text:
            return 0
        try:
            return _domain("ROS_DOMAIN_ID", int(text))
        except ValueError:
            raise ConfigError(f"ROS_DOMAIN_ID={text!r} is not a domain id (0..232)") from None


# --- reading ------------------------------------------------------------------------


def load_config(path: str | os.PathLike[str]) -> BridgeConfig:
    """Read a robot.yaml (see docs/ros2.md) and check it."""
    try:
        import yaml  # the ros2 extra; only the file form needs it
    except ImportError:
        raise ExtraMissingError(EXTRA_MISSING.format(package="PyYAML")) from None

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"cannot read {path}: {error.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML: {error}") from None
    return parse_config({} if data is None else data)


def parse_config(data: object) -> BridgeConfig:
    """Check a configuration given as plain data (what ``yaml.safe_load`` returns)."""
    top = _Section(data, "the configuration")
    config = BridgeConfig(
        namespace=top.namespace("namespace", ""),
        domain_id=top.optional_int("domain_id", _domain),
        failsafe_timeout=top.number("failsafe_timeout", FAILSAFE_TIMEOUT, low=0.1, high=60.0),
        diagnostics_period=top.number("diagnostics_period", DIAGNOSTICS_PERIOD, low=0.05),
        min_publish_rate=top.number("min_publish_rate", MIN_PUBLISH_RATE, low=0.01, high=100.0),
        diagnostics_topic=top.topic("diagnostics_topic", "/diagnostics"),
        joint_topic=top.topic("joint_topic", "joint_commands"),
        clear_interlock_topic=top.topic("clear_interlock_topic", "clear_interlock"),
        servos=top.each("servos", _servo),
        digital_outputs=top.each("digital_outputs", _digital_output),
        stop=top.optional("stop", _stop) or StopConfig(),
        drive=top.optional("drive", _drive),
        odometry=top.optional("odometry", _odometry),
        digital_inputs=top.each("digital_inputs", _digital_input),
        analog_inputs=top.each("analog_inputs", _analog_input),
        counters=top.each("counters", _counter),
        services=top.optional("services", _services),
    )
    top.done()
    _check_whole(config)
    return config


def _digital_output(s: _Section) -> DigitalOutputConfig:
    return DigitalOutputConfig(s.pin("pin"), s.topic("topic"), s.flag("safe", False))


def _digital_input(s: _Section) -> DigitalInputConfig:
    return DigitalInputConfig(
        s.pin("pin"),
        s.topic("topic"),
        s.flag("pull_up", False),
        s.integer("debounce_ms", 0, 0, 255),
        s.optional_choice("interlock", ("low", "high")),  # type: ignore[arg-type]
    )


def _analog_input(s: _Section) -> AnalogInputConfig:
    return AnalogInputConfig(
        s.pin("pin"),
        s.topic("topic"),
        s.number("scale", 1.0),
        s.number("offset", 0.0),
        s.number("rate_hz", 10.0, low=0.001, high=1000.0),
        s.integer("threshold", 0, 0, 1023),
    )


def _counter(s: _Section) -> CounterConfig:
    return CounterConfig(s.pins("pins"), s.topic("topic", "sensors/encoders"))


def _servo(s: _Section) -> ServoConfig:
    servo = ServoConfig(
        pin=s.pin("pin"),
        topic=s.optional_topic("topic"),
        joint=s.optional_token("joint"),
        safe=s.integer("safe", 90, 0, 180),
        min_us=s.integer("min_us", 544, 400, 2600),
        max_us=s.integer("max_us", 2400, 400, 2600),
        zero=s.number("zero", 90.0, low=0.0, high=180.0),
        max_speed=s.optional_number("max_speed", low=0.0),
    )
    if servo.min_us >= servo.max_us:
        raise ConfigError(f"{s.where}: min_us {servo.min_us} must be below max_us {servo.max_us}")
    if servo.topic is None and servo.joint is None:
        raise ConfigError(f"{s.where}: give it a topic (Float64 degrees) or a joint name, or both")
    return servo


def _stop(s: _Section) -> StopConfig:
    kind = s.choice("type", ("Empty", "Bool"), "Empty")
    return StopConfig(
        s.topic("topic", "stop"),
        kind,  # type: ignore[arg-type]
        s.topic("resume_topic", "resume"),
    )


def _services(s: _Section) -> ServicesConfig:
    return ServicesConfig(
        s.optional_token("python") or "python3",
        s.topic("stop", "stop"),
        s.topic("resume", "resume"),
        s.topic("clear_interlock", "clear_interlock"),
    )


def _drive(s: _Section) -> DriveConfig:
    return DriveConfig(
        left=s.required("left", _motor),
        right=s.required("right", _motor),
        wheel_base=s.number("wheel_base", None, low=0.0, low_open=True),
        max_speed=s.number("max_speed", None, low=0.0, low_open=True),
        topic=s.topic("topic", "cmd_vel"),
        timeout=s.number("timeout", CMD_VEL_TIMEOUT, low=0.0, low_open=True),
    )


def _motor(s: _Section) -> MotorConfig:
    return MotorConfig(
        s.pin("pwm"), s.pin("direction"), s.flag("invert", False), s.optional_pin("encoder")
    )


def _odometry(s: _Section) -> OdometryConfig:
    return OdometryConfig(
        ticks_per_metre=s.number("ticks_per_metre", None, low=0.0, low_open=True),
        rate_hz=s.number("rate_hz", ODOMETRY_RATE, low=0.1, high=200.0),
        topic=s.topic("topic", "odom"),
        tf_topic=s.topic("tf_topic", "/tf"),
        ticks_topic=s.topic("ticks_topic", "sensors/encoders"),
        frame_id=s.frame("frame_id", "odom"),
        child_frame_id=s.frame("child_frame_id", "base_link"),
    )


def _check_whole(config: BridgeConfig) -> None:
    """What no single entry shows: a pin or topic used twice, too many joints."""
    pins: dict[int, str] = {}

    def claim(pin: int, what: str) -> None:
        if pin in pins:
            raise ConfigError(f"pin {pin} is both {pins[pin]} and {what}")
        pins[pin] = what

    for servo in config.servos:
        claim(servo.pin, f"servo {servo.pin}")
    for out in config.digital_outputs:
        claim(out.pin, f"digital output {out.topic}")
    if config.drive is not None:
        for side, motor in (("left", config.drive.left), ("right", config.drive.right)):
            claim(motor.pwm, f"the drive's {side} PWM pin")
            claim(motor.direction, f"the drive's {side} direction pin")
            if motor.encoder is not None:
                claim(motor.encoder, f"the drive's {side} encoder")
    for din in config.digital_inputs:
        claim(din.pin, f"digital input {din.topic}")
    for ain in config.analog_inputs:
        claim(ain.pin, f"analog input {ain.topic}")
    for counter in config.counters:
        for pin in counter.pins:
            claim(pin, f"a counter of {counter.topic}")

    # Compared as ROS resolves them: "led" in namespace robot1 is "/robot1/led".
    topics: dict[str, tuple[str, str]] = {}
    for topic, what in _topics(config):
        name = ros_topic(config.namespace, topic)
        if name in topics:
            first, first_what = topics[name]
            same = "" if first == topic else f" (as {first!r}: both are {name})"
            raise ConfigError(f"topic {topic!r} is both {first_what}{same} and {what}")
        topics[name] = (topic, what)

    _check_services(config)
    _check_odometry(config)
    joints = [s.joint for s in config.servos if s.joint is not None]
    if len(set(joints)) != len(joints):
        raise ConfigError(f"a joint name is given twice: {joints}")
    if len(joints) > MAX_JOINTS:
        raise ConfigError(f"{len(joints)} joints: one JointState is one pose of at most 8")


def _check_services(config: BridgeConfig) -> None:
    """Each service a name of its own (a service may share its name with a topic, as ROS 2
    allows: they are apart on DDS)."""
    names: dict[str, str] = {}
    for key, name in service_names(config).items():
        resolved = ros_topic(config.namespace, name)
        if resolved in names:
            raise ConfigError(f"services: {key} and {names[resolved]} are both {resolved}")
        names[resolved] = key


def service_names(config: BridgeConfig) -> dict[str, str]:
    """The Trigger services the configuration asks for: what each does -> its name as given
    (clear_interlock only with an interlock input); none without ``services:``."""
    services = config.services
    if services is None:
        return {}
    names = {"stop": services.stop, "resume": services.resume}
    if config.interlocks:
        names["clear_interlock"] = services.clear_interlock
    return names


def _check_odometry(config: BridgeConfig) -> None:
    """Odometry needs the drive (its wheel base, its direction pins) and both encoders."""
    odometry, drive = config.odometry, config.drive
    encoders = drive is not None and (drive.left.encoder, drive.right.encoder) != (None, None)
    if odometry is None:
        if encoders:
            raise ConfigError("drive: an encoder is given without odometry: (ticks_per_metre)")
        return
    if drive is None or drive.left.encoder is None or drive.right.encoder is None:
        raise ConfigError(
            "odometry: needs a drive with an encoder on each wheel (drive: left: {encoder: PIN}"
            " and right: {encoder: PIN})"
        )
    if odometry.frame_id == odometry.child_frame_id:
        raise ConfigError(f"odometry: frame_id and child_frame_id are both {odometry.frame_id!r}")


def _topics(config: BridgeConfig) -> list[tuple[str, str]]:
    found = [(config.diagnostics_topic, "the diagnostics"), (config.stop.topic, "the stop")]
    found.append((config.stop.resume_topic, "the stop's resume"))
    found += [(s.topic, f"servo {s.pin}") for s in config.servos if s.topic is not None]
    if config.joints:
        found.append((config.joint_topic, "the joint commands"))
    found += [(o.topic, f"digital output {o.pin}") for o in config.digital_outputs]
    if config.drive is not None:
        found.append((config.drive.topic, "the drive"))
    if config.odometry is not None:
        found.append((config.odometry.topic, "the odometry"))
        found.append((config.odometry.tf_topic, "the odometry's transform"))
        found.append((config.odometry.ticks_topic, "the odometry's ticks"))
    found += [(i.topic, f"digital input {i.pin}") for i in config.digital_inputs]
    if config.interlocks:
        found.append((config.clear_interlock_topic, "the interlock's clear"))
    found += [(i.topic, f"analog input {i.pin}") for i in config.analog_inputs]
    found += [(c.topic, f"counters {list(c.pins)}") for c in config.counters]
    return found


def ros_topic(namespace: str, name: str) -> str:
    """The ROS name of topic ``name`` in ``namespace``, as ``ros2 topic list`` shows it (an
    absolute name ignores the namespace)."""
    if name.startswith("/"):
        return name
    return f"/{namespace}/{name}" if namespace else f"/{name}"


def _domain(where: str, value: int) -> int:
    # Cyclone's default port mapping (7400 + 250 * domain) fits below 65536 up to 232.
    if not 0 <= value <= 232:
        raise ConfigError(f"{where}: a DDS domain id is 0..232, not {value}")
    return value


def check_topic(where: str, name: object, *, absolute_ok: bool = True) -> str:
    """A ROS 2 topic name (relative ``a/b`` or absolute ``/a/b``), checked; returned as given."""
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{where}: a topic name is a non-empty string, not {name!r}")
    body = name[1:] if name.startswith("/") and absolute_ok else name
    parts = body.split("/")
    if not all(_TOKEN.fullmatch(p) for p in parts) or "__" in body:
        raise ConfigError(
            f"{where}: {name!r} is not a ROS 2 topic name (tokens of letters, digits and "
            "'_' separated by '/', none starting with a digit)"
        )
    return name


class _Section:
    """One mapping of the configuration; every key it has must be read, or it is refused."""

    def __init__(self, data: object, where: str) -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{where} must be a mapping, not {type(data).__name__}")
        self.data: Mapping[str, Any] = data
        self.where = where
        self.used: set[str] = set()

    def _get(self, key: str) -> Any:
        self.used.add(key)
        return self.data.get(key)

    def done(self) -> None:
        unknown = sorted(str(k) for k in self.data if k not in self.used)
        if unknown:
            raise ConfigError(f"{self.where}: unknown key(s) {', '.join(unknown)}")

    def _at(self, key: str) -> str:
        return f"{self.where}: {key}"

    def integer(self, key: str, default: int, low: int, high: int) -> int:
        value = self._get(key)
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{self._at(key)} must be an integer, not {value!r}")
        if not low <= value <= high:
            raise ConfigError(f"{self._at(key)} must be {low}..{high}, not {value}")
        return value

    def optional_int(self, key: str, check: Any) -> int | None:
        value = self._get(key)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{self._at(key)} must be an integer, not {value!r}")
        result: int = check(self._at(key), value)
        return result

    def number(
        self,
        key: str,
        default: float | None,
        *,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
    ) -> float:
        value = self._get(key)
        if value is None:
            if default is None:
                raise ConfigError(f"{self._at(key)} is required")
            return default
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{self._at(key)} must be a number, not {value!r}")
        number = float(value)
        if not math.isfinite(number):
            raise ConfigError(f"{self._at(key)} must be finite, not {value!r}")
        if low is not None and (number <= low if low_open else number < low):
            raise ConfigError(f"{self._at(key)} must be {'above' if low_open else '>='} {low:g}")
        if high is not None and number > high:
            raise ConfigError(f"{self._at(key)} must be <= {high:g}")
        return number

    def optional_number(self, key: str, *, low: float) -> float | None:
        """A number above ``low``, or None when the key is not given."""
        if self.data.get(key) is None:
            self.used.add(key)
            return None
        return self.number(key, None, low=low, low_open=True)

    def flag(self, key: str, default: bool) -> bool:
        value = self._get(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise ConfigError(f"{self._at(key)} must be true or false, not {value!r}")
        return value

    def optional_choice(self, key: str, options: Sequence[str]) -> str | None:
        value = self._get(key)
        if value is None:
            return None
        if value not in options:
            raise ConfigError(f"{self._at(key)} must be one of {', '.join(options)}")
        return str(value)

    def choice(self, key: str, options: Sequence[str], default: str) -> str:
        value = self._get(key)
        if value is None:
            return default
        if value not in options:
            raise ConfigError(f"{self._at(key)} must be one of {', '.join(options)}")
        return str(value)

    def pin(self, key: str) -> int:
        value = self._get(key)
        if isinstance(value, str) and value.upper() in ANALOG_NAMES:
            return ANALOG_NAMES[value.upper()]
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
            raise ConfigError(f"{self._at(key)} must be a pin number (or A0..A7), not {value!r}")
        return value

    def optional_pin(self, key: str) -> int | None:
        return None if self._get(key) is None else self.pin(key)

    def frame(self, key: str, default: str) -> str:
        """A tf frame id: a ROS name token (``odom``, ``base_link``)."""
        value = self._get(key)
        if value is None:
            return default
        if not isinstance(value, str) or not _TOKEN.fullmatch(value):
            raise ConfigError(f"{self._at(key)} must be a frame id like base_link, not {value!r}")
        return value

    def pins(self, key: str) -> tuple[int, ...]:
        value = self._get(key)
        if not isinstance(value, list) or not value:
            raise ConfigError(f"{self._at(key)} must be a non-empty list of pins")
        return tuple(_Section({key: v}, self._at(key)).pin(key) for v in value)

    def topic(self, key: str, default: str | None = None) -> str:
        value = self._get(key)
        if value is None:
            if default is None:
                raise ConfigError(f"{self._at(key)} is required")
            return default
        return check_topic(self._at(key), value)

    def optional_topic(self, key: str) -> str | None:
        value = self._get(key)
        return None if value is None else check_topic(self._at(key), value)

    def optional_token(self, key: str) -> str | None:
        value = self._get(key)
        if value is None:
            return None
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{self._at(key)} must be a non-empty string, not {value!r}")
        return value

    def namespace(self, key: str, default: str) -> str:
        value = self._get(key)
        if value is None or value in ("", "/"):
            return default
        if not isinstance(value, str):
            raise ConfigError(f"{self._at(key)} must be a string, not {value!r}")
        return check_topic(self._at(key), value.strip("/"), absolute_ok=False)

    def optional(self, key: str, build: Callable[[_Section], T]) -> T | None:
        """The sub-mapping ``key`` built by ``build`` (every key of it read), or None."""
        value = self._get(key)
        if value is None:
            return None
        section = _Section(value, self._at(key))
        result = build(section)
        section.done()
        return result

    def required(self, key: str, build: Callable[[_Section], T]) -> T:
        result = self.optional(key, build)
        if result is None:
            raise ConfigError(f"{self._at(key)} is required")
        return result

    def each(self, key: str, build: Callable[[_Section], T]) -> tuple[T, ...]:
        """The list ``key``, each entry built by ``build`` (every key of it read)."""
        value = self._get(key)
        if value is None:
            return ()
        if not isinstance(value, list):
            raise ConfigError(f"{self._at(key)} must be a list, not {type(value).__name__}")
        results = []
        for i, entry in enumerate(value):
            section = _Section(entry, f"{self._at(key)}[{i}]")
            results.append(build(section))
            section.done()
        return tuple(results)
