"""The bridge: one board on a ROS 2 graph over Cyclone DDS.

:class:`Bridge` opens the board with ``liveness="heartbeat"``, configures
the outputs the configuration names, creates the DDS topics (ROS 2 names,
types and QoS: :mod:`.dds`, :mod:`.msgs`) and runs one loop
(:meth:`Bridge.run`) that

* waits for commands on the subscribed topics and carries out the newest
  valid one of each (a servo's Float64, an arm's JointState as one pose, a
  digital output's Bool, STOP, resume, ``/cmd_vel``), refusing bad ones and Twists
  stale on arrival (logged, counted on /diagnostics, nothing moves);
* holds every command after a STOP until ``resume`` (counted as ``held_by_stop``);
* carries out the calls of the Trigger services (STOP, resume, clear_interlock) that
  its rclpy node relays (:mod:`.services`), and answers each with the outcome;
* sends the device's heartbeat every ``failsafe_timeout / 4``: only this loop
  keeps the outputs alive, so a bridge that hangs or dies lets the device's
  failsafe drive them safe (the board's automatic Ping only keeps the link up);
* stops the motors when ``/cmd_vel`` went quiet for its timeout;
* publishes /diagnostics every ``diagnostics_period``, and at once from the
  board's event thread when a failsafe, reboot or link change happens;
* publishes again each input that was quiet for ``1 / min_publish_rate``;
* publishes the wheel odometry (Odometry, /tf, ticks) every ``1 / odometry.rate_hz``
  (:mod:`.odometry`).

Inputs are published from the board's event thread as they change
(:mod:`.inputs`). The bridge starts from every output safe: what the device
already drives when it starts (a resumed session) is stopped first.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Self

from cyclonedds.core import (
    GuardCondition,
    InstanceState,
    Listener,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ..board import Board, DigitalOutput, Servo
from ..closing import ClosedOnExit
from ..errors import (
    BadCommandError,
    CommandRejectedError,
    ConfigError,
    ProtoduinoError,
    StaleCommandError,
)
from ..events import Event, EventKind
from . import dds, graph, inputs, odometry, services
from .config import BridgeConfig, ServoConfig, service_names
from .dds import DEFAULT_QOS, SENSOR_QOS, dds_topic, ros_topic
from .diagnostics import Health
from .drive import DiffDrive, Motor, twist_to_wheels
from .msgs import (
    Bool,
    DiagnosticArray,
    Empty,
    Float32,
    Float64,
    Int32MultiArray,
    JointState,
    Odometry,
    TFMessage,
    Twist,
)
from .servos import joint_pose, servo_degrees

log = logging.getLogger(__name__)

#: Heartbeats per failsafe timeout: one or two lost to a slow moment must not trip it.
BEATS_PER_TIMEOUT = 4
#: At most this long (s) a clean shutdown waits for its last /diagnostics to be acknowledged.
LAST_REPORT_WAIT = 1.0
#: Samples taken from one topic per pass, so that a flood on one cannot starve the others.
TAKE_PER_PASS = 64

#: What a valid command does, once it is the newest of its topic.
Action = Callable[[], None]
#: Checks one sample (raising BadCommandError) and returns its action (None: nothing to do).
Prepare = Callable[[Any], Action | None]


@dataclass
class _Route:
    """One subscribed topic: its reader and how a sample becomes an action."""

    topic: str  # the ROS name, for logs and /diagnostics
    reader: DataReader[Any]
    prepare: Prepare
    #: A command that moves something: held while a STOP is latched.
    held: bool = True


class Bridge(ClosedOnExit):
    """One board on ROS 2; see the module docstring.

    ``Bridge(port, config)`` takes a checked configuration (:func:`.load_config`);
    :meth:`start` (or ``with``) opens the board and the DDS entities;
    :meth:`run` loops until :meth:`stop` (from another thread or a signal
    handler); :meth:`close` drives every output safe and releases everything.
    ``board_options`` go to :meth:`Board.open` (``liveness`` and
    ``failsafe_timeout`` are the bridge's own); ``on_open`` is called with the
    board as soon as it is open, before anything else (the command line's
    ``--new-session`` releases every output there).
    """

    def __init__(
        self,
        port: str,
        config: BridgeConfig,
        *,
        board_options: Mapping[str, Any] | None = None,
        clock: Callable[[], float] = time.monotonic,
        on_open: Callable[[Board], None] | None = None,
    ) -> None:
        self.port = port
        self._on_open = on_open
        self.config = config
        self.clock = clock
        self._board_options = dict(board_options or {})
        for key in ("liveness", "failsafe_timeout"):
            if key in self._board_options:
                raise ConfigError(f"board_options: {key} is the bridge's own setting")
        self.name = f"protoduino {config.namespace or port}"
        self.health = Health(self.name, port)
        self.board: Board | None = None
        self.drive: DiffDrive | None = None
        self._servos: dict[int, Servo] = {}
        self._routes: list[_Route] = []
        self._writers: dict[str, DataWriter[Any]] = {}
        self._participant: DomainParticipant | None = None
        self._node: DataWriter[Any] | None = None  # the node's entry in ROS 2's graph
        self._waitset: WaitSet | None = None
        self._wake: GuardCondition | None = None
        self._stopping = threading.Event()
        #: Set from the event thread when the device drove its outputs safe on its own.
        self._device_safe = threading.Event()
        #: A STOP holds every command until a resume (only the loop's thread changes it).
        self._stop_latched = False
        self._diag_lock = threading.Lock()
        #: Input topics whose writer matched a new subscriber (Cyclone's thread adds them).
        self._joined: set[str] = set()
        self._joined_lock = threading.Lock()
        self._inputs: inputs.Wiring | None = None
        self._odometry: odometry.Tracker | None = None
        self._services: services.Services | None = None
        self._next_beat = 0.0
        self._undo: list[Callable[[], None]] = []

    # --- life cycle ----------------------------------------------------------------

    def __enter__(self) -> Self:
        """Start the bridge; leaving the block closes it (closing.ClosedOnExit)."""
        self.start()
        return super().__enter__()

    def start(self) -> None:
        """Open the board, configure every output, create the DDS topics."""
        config = self.config
        try:
            self.board = Board.open(
                self.port,
                liveness="heartbeat",
                failsafe_timeout=config.failsafe_timeout,
                **self._board_options,
            )
            # Events from the start: the Stop of _start_safe is reported on /diagnostics.
            self._undo.append(self.board.on_event(self._on_event))
            if self._on_open is not None:
                self._on_open(self.board)
            _start_safe(self.board)
            self._participant = dds.participant(config.resolved_domain())
            self._waitset = WaitSet(self._participant)
            self._wake = GuardCondition(self._participant)
            self._waitset.attach(self._wake)
            self._writers[config.diagnostics_topic] = self._writer(
                config.diagnostics_topic, DiagnosticArray, DEFAULT_QOS
            )
            self._configure_outputs(self.board)
            self._configure_inputs(self.board)
            self._configure_odometry(self.board)
            # In ROS 2's node graph (ros2 node list / info), with every endpoint above.
            self._node = graph.announce(
                self._participant,
                config.namespace,
                [route.reader for route in self._routes],
                self._writers.values(),
            )
            self._start_services()
        except BaseException:
            self.close()
            raise
        log.info(
            "bridge up: %s on DDS domain %d, topics %s",
            self.port,
            config.resolved_domain(),
            ", ".join(sorted(self.topics())),
        )

    def topics(self) -> dict[str, str]:
        """Every ROS topic of the bridge -> its ROS 2 type (``pkg/msg/Type``)."""
        found: dict[str, str] = {}
        for route in self._routes:
            found[route.topic] = _ros_type(route.reader.topic.data_type)
        for name, writer in self._writers.items():
            found[ros_topic(self.config.namespace, name)] = _ros_type(writer.topic.data_type)
        return found

    def services(self) -> dict[str, str]:
        """Every ROS service of the bridge -> its ROS 2 type (answered once its rclpy node is
        up: :mod:`.services`)."""
        if self._services is None:
            return {}
        return {name: services.TRIGGER for name in self._services.names.values()}

    def stop(self) -> None:
        """Make :meth:`run` return (thread-safe; callable from a signal handler)."""
        self._stopping.set()
        if self._wake is not None:
            self._wake.set(True)

    def close(self) -> None:
        """Stop subscriptions, drive every output safe (the device's Stop), close the board.

        A bridge that shuts down cleanly stops the robot at once rather than a failsafe
        timeout later; one that cannot (the link is down) leaves it to the failsafe. The
        DDS entities go with the object.
        """
        self.stop()
        if self._services is not None:  # first: no call reaches a board being closed
            self._services.close()
            self.health.services = self._services.state
            self._services = None
        for undo in self._undo:
            undo()
        self._undo.clear()
        if self.board is not None:
            stopped = False
            if not self.board.closed:
                try:
                    self.board.stop()
                    stopped = True
                except ProtoduinoError as error:
                    log.warning("outputs not stopped on close (the failsafe will): %s", error)
            self.board.close()
            self._last_diagnostics(stopped)
        self._routes.clear()
        # Cyclone calls a writer's listener on its own thread: detached first, no callback
        # runs into a bridge being torn down while the entities are deleted (the bench's
        # DDS peer, which did not, crashed its process now and then after its part).
        for writer in self._writers.values():
            writer.set_listener(None)
        self._writers.clear()
        self._waitset = None
        self._wake = None
        self._node = None
        self._participant = None

    # --- setup ---------------------------------------------------------------------

    def _writer(
        self, name: str, kind: type[Any], qos: Any, listener: Any = None
    ) -> DataWriter[Any]:
        assert self._participant is not None
        topic = Topic(self._participant, dds_topic(self.config.namespace, name), kind, qos=qos)
        return DataWriter(self._participant, topic, qos=qos, listener=listener)

    def _subscribe(
        self, name: str, kind: type[Any], prepare: Prepare, *, held: bool = True
    ) -> None:
        assert self._participant is not None and self._waitset is not None
        topic = Topic(
            self._participant, dds_topic(self.config.namespace, name), kind, qos=DEFAULT_QOS
        )
        reader: DataReader[Any] = DataReader(self._participant, topic, qos=DEFAULT_QOS)
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        self._waitset.attach(ReadCondition(reader, mask))
        route = _Route(ros_topic(self.config.namespace, name), reader, prepare, held)
        self._routes.append(route)

    def _configure_outputs(self, board: Board) -> None:
        config = self.config
        for s in config.servos:
            self._servos[s.pin] = board.servo(
                s.pin, safe=s.safe, min_us=s.min_us, max_us=s.max_us, max_speed=s.max_speed
            )
            if s.topic is not None:
                self._subscribe(s.topic, Float64, self._servo_handler(s))
        if config.joints:
            self._subscribe(config.joint_topic, JointState, self._on_joints)
        for d in config.digital_outputs:
            out = board.digital_output(d.pin, safe=d.safe)
            self._subscribe(d.topic, Bool, self._digital_handler(out))
        stop_type = Empty if config.stop.type == "Empty" else Bool
        # Neither a STOP, its resume nor a clear moves anything: never held.
        self._subscribe(config.stop.topic, stop_type, self._on_stop, held=False)
        self._subscribe(config.stop.resume_topic, Empty, self._on_resume, held=False)
        if config.interlocks:
            self._subscribe(
                config.clear_interlock_topic, Empty, self._on_clear_interlock, held=False
            )
        if config.drive is not None:
            drive = config.drive
            motors = [
                Motor(
                    m,
                    board.pwm_output(m.pwm, safe=0),
                    board.digital_output(m.direction, safe=False),
                )
                for m in (drive.left, drive.right)
            ]
            self.drive = DiffDrive(drive, motors[0], motors[1], self.clock)
            self._subscribe(drive.topic, Twist, self._on_twist)

    def _configure_inputs(self, board: Board) -> None:
        config = self.config
        kinds: list[tuple[str, type[Any]]] = [(d.topic, Bool) for d in config.digital_inputs]
        kinds += [(a.topic, Float32) for a in config.analog_inputs]
        kinds += [(c.topic, Int32MultiArray) for c in config.counters]
        publishers: dict[str, inputs.Publish] = {}
        for topic, kind in kinds:
            # Kept in _writers too: topics() lists them, and they live as long as the bridge.
            listener: Any = Listener  # untyped in cyclonedds
            matched = listener(on_publication_matched=self._subscriber_joined(topic))
            self._writers[topic] = self._writer(topic, kind, SENSOR_QOS, matched)
            publishers[topic] = self._writers[topic].write
        if publishers:
            self._inputs = inputs.wire(board, config, publishers, self.clock)
            self._undo += self._inputs.undo

    def _configure_odometry(self, board: Board) -> None:
        config = self.config.odometry
        if config is None:
            return
        assert self.drive is not None  # the configuration checked it has one
        wheels = []
        for motor in (self.drive.left, self.drive.right):
            assert motor.config.encoder is not None  # checked too
            counter = board.counter(motor.config.encoder, rate_hz=config.rate_hz)
            wheels.append(odometry.Wheel(counter.read, lambda m=motor: m.forward))  # type: ignore[misc]
        tracker = odometry.Tracker(
            config, self.drive.config.wheel_base, wheels[0], wheels[1], self.clock
        )
        self.drive.left.before_turn = self.drive.right.before_turn = tracker.update
        self._odometry = tracker
        for name, kind, qos in (
            (config.topic, Odometry, DEFAULT_QOS),
            (config.tf_topic, TFMessage, DEFAULT_QOS),
            (config.ticks_topic, Int32MultiArray, SENSOR_QOS),
        ):
            self._writers[name] = self._writer(name, kind, qos)

    def _start_services(self) -> None:
        """The Trigger services' rclpy node, when robot.yaml asks for services."""
        if not service_names(self.config):
            return
        wake = self._wake
        assert wake is not None
        self._services = services.Services(
            self.config, self.config.resolved_domain(), lambda: wake.set(True)
        )
        self._services.start()
        self.health.services = self._services.state

    def _publish_odometry(self, due: float) -> float:
        """Sample the wheels, publish Odometry, /tf and the ticks (this sample was ``due``);
        return when the next one is due: a period later, or a period from now when late."""
        assert self._odometry is not None
        config = self._odometry.config
        sample = self._odometry.sample()
        at = time.time()  # ROS stamps are wall-clock time
        try:
            self._writers[config.topic].write(odometry.odometry_message(sample, config, at))
            self._writers[config.tf_topic].write(odometry.tf_message(sample, config, at))
            self._writers[config.ticks_topic].write(odometry.ticks_message(sample.ticks))
        except Exception:  # DDS refused it; the next sample carries the pose anyway
            log.exception("publishing the odometry failed")
        period = 1.0 / config.rate_hz
        now = self.clock()
        return due + period if due + period > now else now + period

    def _subscriber_joined(self, topic: str) -> Callable[[Any, Any], None]:
        """A writer's publication-matched listener (Cyclone's thread): a new subscriber gets
        the topic's last value from the loop (volatile QoS kept none for it)."""

        def matched(_writer: Any, status: Any) -> None:
            if status.current_count_change > 0:
                with self._joined_lock:
                    self._joined.add(topic)
                if self._wake is not None:
                    self._wake.set(True)

        return matched

    def _publish_again_for_new_subscribers(self) -> None:
        with self._joined_lock:
            joined, self._joined = self._joined, set()
        if self._inputs is None:
            return
        for topic in sorted(joined):
            try:
                self._inputs.topics[topic].again()
            except Exception:  # DDS refused it; the next change publishes anyway
                log.exception("%s: publishing the last value again failed", topic)

    def _refresh_inputs(self) -> float:
        """Publish again each input quiet for ``1 / min_publish_rate`` (a best-effort sample
        lost on the network is repaired so); return when the next one is due."""
        period = 1.0 / self.config.min_publish_rate
        due = self.clock() + period
        if self._inputs is None:
            return due
        for topic, last in self._inputs.topics.items():
            try:
                due = min(due, last.refresh(period))
            except Exception:  # DDS refused it; tried again a period later
                log.exception("%s: publishing the last value again failed", topic)
        return due

    # --- the loop ------------------------------------------------------------------

    def run(self) -> None:
        """Carry out commands, heartbeat, watch /cmd_vel, report, until :meth:`stop`."""
        if self.board is None or self._waitset is None or self._wake is None:
            raise RuntimeError("start() the bridge first")
        # Locals: close() from another thread drops the attributes, not these.
        waitset, wake = self._waitset, self._wake
        self._next_beat = self.clock()
        next_report = next_refresh = next_odometry = self.clock()
        while not self._stopping.is_set():
            self._beat_if_due()
            now = self.clock()
            if now >= next_report:
                self.publish_diagnostics()
                next_report = now + self.config.diagnostics_period
            if now >= next_refresh:
                next_refresh = self._refresh_inputs()
            if self._odometry is not None and now >= next_odometry:
                next_odometry = self._publish_odometry(next_odometry)
            due = min(self._next_beat, next_report, next_refresh)
            if self._odometry is not None:
                due = min(due, next_odometry)
            if self.drive is not None and (stale := self.drive.deadline()) is not None:
                due = min(due, stale)
            wait = max(0.0, due - self.clock())
            waitset.wait(duration(seconds=wait) if wait > 0 else 0)
            wake.set(False)
            self._publish_again_for_new_subscribers()
            self._serve_calls()
            if self._device_safe.is_set():
                self._device_safe.clear()
                if self.drive is not None:
                    self.drive.forget()
            for route in self._routes:
                if self._stopping.is_set():
                    break
                self._take(route)
                self._beat_if_due()  # a slow device must not starve the heartbeat
            self._check_drive()

    def _beat_if_due(self) -> None:
        """Send the heartbeat when it is due (every failsafe_timeout / 4)."""
        now = self.clock()
        if now < self._next_beat:
            return
        self._next_beat = now + self.config.failsafe_timeout / BEATS_PER_TIMEOUT
        assert self.board is not None
        try:
            self.board.heartbeat()
        except ProtoduinoError as error:
            # The link is down or the device stopped answering: its failsafe will act.
            log.warning("heartbeat failed: %s", error)

    def _take(self, route: _Route) -> None:
        """Every sample waiting on one topic checked (bad ones counted); the newest valid one
        carried out. The others are superseded: a servo, a level or a Twist is a state, and
        only the latest matters (the newest wins, as for the sensors), so a publisher faster
        than the device never builds a backlog of stale commands."""
        action: Action | None = None
        valid = 0
        for _ in range(TAKE_PER_PASS):
            try:
                samples = route.reader.take(N=1)  # one at a time: a bad one costs only itself
            except Exception as error:  # bytes that are no such message
                self._bad(route.topic, "undecodable", error)
                continue
            if not samples:
                break
            sample = samples[0]
            info = getattr(sample, "sample_info", None)
            if info is not None and not info.valid_data:
                continue  # an instance's state change, no data
            try:
                prepared = route.prepare(sample)
            except StaleCommandError as error:
                self._bad(route.topic, "stale", error)
                continue
            except BadCommandError as error:
                self._bad(route.topic, "invalid", error)
                continue
            if prepared is not None:
                action = prepared
                valid += 1
        if valid > 1:
            self.health.count("superseded", valid - 1)
        if action is None:
            return
        if route.held and self._stop_latched:
            self.health.count("held")
            log.warning("%s: held: STOP is latched until a resume", route.topic)
            return
        self._carry_out(route.topic, action)

    def _carry_out(self, topic: str, action: Action) -> str | None:
        """Carry out one command of ``topic`` (a topic or a service); None when it was, else
        why not (the device's refusal, the link's error), logged and counted."""
        try:
            action()
        except BadCommandError as error:
            self._bad(topic, "invalid", error)
            return str(error)
        except CommandRejectedError as error:
            self.health.count("refused")
            log.warning("%s: the device refused it: %s", topic, error)
            return str(error)  # "... rejected by the device: STATUS_..."
        except ProtoduinoError as error:
            self.health.count("refused")
            log.warning("%s: not carried out: %s", topic, error)
            return f"not carried out: {error}"
        self.health.count("forwarded")
        return None

    def _serve_calls(self) -> None:
        """Carry out the service calls waiting, as their topics' messages are (never held by
        a STOP: none moves anything), and answer each: success, or why not."""
        if self._services is None:
            return
        self.health.services = self._services.state
        for call in self._services.take():
            latched = self._stop_latched
            action, done = {
                "stop": (self._stop, "every output driven safe; commands held until a resume"),
                "resume": (
                    self._resume,
                    "resumed: the outputs stay safe until the next command"
                    if latched
                    else "no STOP was latched",
                ),
                "clear_interlock": (
                    self._clear_interlock,
                    "interlock cleared: the outputs stay safe until commanded again",
                ),
            }[call.kind]
            failed = self._carry_out(call.name, action)
            self._services.answer(call, failed is None, done if failed is None else failed)

    def _bad(self, topic: str, reason: str, error: BaseException) -> None:
        first = not self.health.bad[f"{topic}: {reason}"]
        self.health.bad_message(topic, reason)
        (log.warning if first else log.debug)("%s: dropped (%s): %s", topic, reason, error)

    def _check_drive(self) -> None:
        if self.drive is None:
            return
        try:
            if self.drive.check():
                self.health.count("stale_stops")
                log.info("cmd_vel: no Twist for %g s: motors stopped", self.drive.config.timeout)
        except ProtoduinoError as error:
            log.warning("cmd_vel: stopping the motors failed: %s", error)

    # --- handlers ------------------------------------------------------------------

    def _servo_handler(self, config: ServoConfig) -> Prepare:
        servo = self._servos[config.pin]

        def prepare(message: Float64) -> Action:
            degrees = servo_degrees(message.data)
            return lambda: servo.write(degrees)

        return prepare

    def _on_joints(self, message: JointState) -> Action:
        pose = joint_pose(message, self.config.joints)
        # Keys typed loosely: Board.pose's mapping type grows with each output kind.
        targets: dict[Any, int] = {self._servos[pin]: degrees for pin, degrees in pose.items()}

        def move() -> None:
            assert self.board is not None
            self.board.pose(targets)

        return move

    @staticmethod
    def _digital_handler(out: DigitalOutput) -> Prepare:
        def prepare(message: Bool) -> Action:
            level = bool(message.data)
            return lambda: out.write(level)

        return prepare

    def _on_stop(self, message: Empty | Bool) -> Action | None:
        if isinstance(message, Bool) and not message.data:
            return None  # Bool false: not a stop
        return self._stop

    def _stop(self) -> None:
        """Every output safe, and held there: latched before the device's Stop is sent, so
        that no command follows it even when its outcome is unknown."""
        assert self.board is not None
        self._latch(True)
        self.board.stop()
        self.health.count("stops")
        if self.drive is not None:
            self.drive.forget()
        log.warning("STOP: every output driven safe, commands held until a resume")

    def _on_resume(self, _message: Empty) -> Action:
        return self._resume

    def _resume(self) -> None:
        """Release a latched STOP: nothing moves until the next command."""
        if self._stop_latched:
            self._latch(False)
            log.warning("resumed: commands are carried out again")

    def _latch(self, latched: bool) -> None:
        self._stop_latched = latched
        self.health.latch(latched)
        self.publish_diagnostics()

    def _on_clear_interlock(self, _message: Empty) -> Action:
        return self._clear_interlock

    def _clear_interlock(self) -> None:
        """Clear a tripped interlock (refused while its input is still at the trip level, which
        :meth:`_carry_out` logs and counts). The outputs stay safe until commanded again."""
        assert self.board is not None
        self.board.clear_interlock()
        self.health.count("interlock_clears")
        log.warning("interlock cleared: the outputs stay safe until commanded again")

    def _on_twist(self, message: Twist) -> Action:
        assert self.drive is not None
        drive = self.drive
        drive.check_fresh(_written(message))
        left, right = twist_to_wheels(message.linear.x, message.angular.z, drive.config)
        return lambda: drive.apply(left, right)

    # --- events and diagnostics ----------------------------------------------------

    def _on_event(self, event: Event) -> None:
        if event.kind is EventKind.FAILSAFE and event.details.get("active"):
            self._device_safe.set()
        if self.health.event(event):
            self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """Publish the /diagnostics report now (any thread)."""
        board = self.board
        writer = self._writers.get(self.config.diagnostics_topic)
        if board is None or writer is None:
            return
        with self._diag_lock:
            try:
                writer.write(self.health.report(board.stats))
            except Exception:  # DDS refused it; the next period tries again
                log.exception("publishing /diagnostics failed")

    def _last_diagnostics(self, stopped: bool) -> None:
        """The last report, once the board is closed: the bridge is gone (STALE), and whether
        its Stop drove the outputs safe. Waits (bounded) until the reliable subscribers have
        it, so that it is not lost with the process."""
        self.health.shut_down(stopped)
        self.publish_diagnostics()
        writer = self._writers.get(self.config.diagnostics_topic)
        if writer is not None:
            try:
                writer.wait_for_acks(duration(seconds=LAST_REPORT_WAIT))
            except Exception:  # nobody to wait for, or DDS is going: nothing more to do
                log.debug("the last /diagnostics may not have reached every subscriber")


def _written(sample: Any) -> float | None:
    """When a sample was written (Unix seconds): its DDS source timestamp, if it has one."""
    info = getattr(sample, "sample_info", None)
    stamp = getattr(info, "source_timestamp", None)
    return stamp / 1e9 if isinstance(stamp, int) and stamp > 0 else None


def _start_safe(board: Board) -> None:
    """Start from a safe state the bridge knows: no output driven by anyone else.

    Outputs the device already drives belong to a session this board resumed (the
    command line's: a bridge killed less than a failsafe timeout ago, whose motors still
    run, or an earlier ``protoduino pin``); nobody commands them now, and the bridge's
    heartbeat would keep them alive for good. So they are driven safe by the device's
    Stop before the bridge configures its own outputs (a new session has none: the
    device released them).
    """
    inherited = board.read_outputs()
    if inherited:
        log.warning(
            "the device already drives pin(s) %s (a resumed session): Stop, every output "
            "safe, before the bridge commands anything",
            ", ".join(str(pin) for pin in inherited),
        )
        board.stop()


def _ros_type(kind: type[Any]) -> str:
    """``pkg::msg::dds_::Type_`` -> ``pkg/msg/Type``."""
    pkg, sub, _, name = kind.__idl_typename__.replace(".", "::").split("::")
    return f"{pkg}/{sub}/{name.rstrip('_')}"
