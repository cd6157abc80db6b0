"""Benchmark part 8 (docs/performance.md): the ROS 2 bridge on the emulated Uno.

The bridge runs as a user runs it (``protoduino ros2 PORT --config robot.yaml`` in a process
of its own, with ``--capture``), on the emulated Uno (the real firmware on simavr, its pins
measured by the runner), and this process is the rest of the ROS 2 graph: a Cyclone DDS
participant on loopback only (the bridge's own message types: the encoding is tested
elsewhere, against rosbags, in tests/e2e/test_ros2.py; :mod:`bench.ros2_peer`). Three
questions, then the first two and odometry again with a real ROS 2 node:

* ``/cmd_vel`` to the pins: a Twist published on DDS until both motors' PWM duty shows the new
  value at the pins (the runner's trace: a duty is dated to the rising edge of the first whole
  period at the new duty, so up to one PWM period, about 2 ms on pins 3 and 11, of each time is
  the period's phase). The board's clock is tied to the host's for each trial by one control
  command on a spare pin just before the Twist: its board time lies between sending and the
  answer, so the midpoint is used and half the round trip is the trial's uncertainty. The
  capture splits each time at the moment the bridge wrote the command to the port, and gives
  the command's size: its wire time is on the emulated line (simavr times a UART byte as 11
  bits: :data:`bench.wire.EMULATED_BYTE_US`).
* An input's level to a DDS sample: a digital input's level is changed through the board's
  control socket (its host time is the midpoint of that round trip, as in part 7) until a
  subscriber's listener has the Bool.
* Samples per second per topic with six analog channels streaming: each sampled at 200 Hz
  and reporting every change, while a thread of this process changes their values through
  the control socket as fast as it can (the bridge publishes an input when it changes), counted
  at the subscriber, against the values the device sent (from the capture); then the
  ``/cmd_vel`` trials again while they stream.
* A real ROS 2 node, rclpy on Fast DDS (:mod:`bench.ros2_rclpy`, when ``.deps/ros2-venv``
  is installed), against a bridge with odometry (the drive on pins 9 and 11, encoders on 2
  and 3): a Twist it publishes until both motor pins show the new duty (as above), an
  input's edge until its subscription's callback has the Bool, and one encoder pulse
  (made through the control socket, dated as an edge is) until its callback has an
  Odometry whose pose moved. The node stamps its publish and its callbacks with
  ``time.monotonic()`` (CLOCK_MONOTONIC, the same clock in this process).

Imports go one way: this module uses :mod:`bench.ros2_peer` and :mod:`bench.ros2_rclpy`,
which use nothing of the bench.

Every wait is bounded; nothing here asserts on time.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import random
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import TYPE_CHECKING, Any, Protocol

from protoduino.framing import StreamDecoder
from protoduino.messages import parse_in, parse_out, pins_in
from protoduino.packets import Packet
from protoduino.simboard import SimBoard

from .boards import BoardUnavailableError, Percentiles, Trace, missing_tool
from .core import Context, Section, SectionResult, md_table, require
from .ros2_rclpy import RclpyNode, rclpy_versions
from .wire import EMULATED_BYTE_US

if TYPE_CHECKING:
    from .ros2_peer import Peer

log = logging.getLogger(__name__)

#: Cyclone on loopback only (no multicast, the peer 127.0.0.1): the bench never reaches the
#: machine's network, and a fresh domain id keeps it apart from anything else running here.
LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    '<ParticipantIndex>auto</ParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers>'
    "</Discovery></Domain></CycloneDDS>"
)
NAMESPACE = "bench"
#: The real node's bridge: a namespace of its own.
RCLPY_NAMESPACE = "bench_rclpy"


@dataclass(frozen=True, slots=True)
class Wiring:
    """Where a phase's robot is wired."""

    left_pwm: int
    left_dir: int
    right_pwm: int
    right_dir: int
    button: int
    #: The wheel encoders (left, right) for odometry; None: no odometry.
    encoders: tuple[int, int] | None = None


#: The Cyclone peer's robot: the drive on Timer2's two PWM pins, the button on pin 2.
PEER_WIRING = Wiring(left_pwm=3, left_dir=4, right_pwm=11, right_dir=12, button=2)
#: The real node's: the encoders on INT0 and INT1's pins 2 and 3 (the external interrupts), so the
#: left motor moves to pin 9 (Timer1: no servo here), the button to pin 8.
RCLPY_WIRING = Wiring(9, 4, 11, 12, button=8, encoders=(2, 3))
#: The pin that ties the clocks.
CLOCK_PIN = 7
#: Encoder ticks per metre of the real node's robot (each tick moves the pose 0.5 mm).
TICKS_PER_METRE = 1000
#: One encoder pulse at this rate: the pin leaves its level for a quarter of a millisecond.
PULSE_HZ = 2000
MAX_SPEED = 0.5
ANALOG_PINS = (14, 15, 16, 17, 18, 19)
ANALOG_HZ = 200
STREAM_SECONDS = 3.0
#: How long one trial may take to show its result before it counts as lost.
SETTLE = 5.0
#: Bridge start-up (Cyclone's import, the handshake, discovery) may take this long.
START_TIMEOUT = 30.0

CONFIG = """\
namespace: {ns}
failsafe_timeout: 1.0
drive:
  wheel_base: 0.2
  max_speed: {max_speed}
  timeout: 30.0
  left: {{pwm: {lp}, direction: {ld}{left_encoder}}}
  right: {{pwm: {rp}, direction: {rd}{right_encoder}}}
digital_inputs:
  - {{pin: {button}, topic: button, pull_up: true}}
"""
ANALOG_CONFIG = """\
analog_inputs:
{channels}
"""
ODOMETRY_CONFIG = """\
odometry:
  ticks_per_metre: {ticks}
"""


def analog_topic(pin: int) -> str:
    return f"analog/a{pin - 14}"


def robot_yaml(wiring: Wiring, namespace: str, streaming: bool = False) -> str:
    """The bridge's configuration: the drive and a button, odometry if ``wiring`` has
    encoders, and the six channels if streaming.

    The drive's watchdog is long (30 s): the trials leave the motors running between Twists,
    and a stop by the watchdog would be a command of its own among theirs.
    """
    left, right = wiring.encoders or ("", "")
    text = CONFIG.format(
        ns=namespace,
        max_speed=MAX_SPEED,
        lp=wiring.left_pwm,
        ld=wiring.left_dir,
        rp=wiring.right_pwm,
        rd=wiring.right_dir,
        button=wiring.button,
        left_encoder=f", encoder: {left}" if left else "",
        right_encoder=f", encoder: {right}" if right else "",
    )
    if wiring.encoders is not None:
        text += ODOMETRY_CONFIG.format(ticks=TICKS_PER_METRE)
    if streaming:
        channels = "\n".join(
            f"  - {{pin: {pin}, topic: {analog_topic(pin)}, rate_hz: {ANALOG_HZ}, threshold: 0}}"
            for pin in ANALOG_PINS
        )
        text += ANALOG_CONFIG.format(channels=channels)
    return text


@dataclass(slots=True)
class DriveTrial:
    """One Twist: publish -> each motor pin at its duty (s), and where the time went."""

    to_left: float
    to_right: float
    #: Publish -> the bridge wrote the left motor's command (the capture's time).
    to_sent: float | None
    uncertainty: float  # half the clock-tying round trip
    #: The wall time the Twist was published (to find its commands in the capture).
    published_at: float
    duty: int


@dataclass(slots=True)
class Phase:
    """One run of the bridge: its trials and what the capture says about them."""

    drive: list[DriveTrial] = field(default_factory=list)
    drive_lost: int = 0
    #: Framed sizes (bytes, with the delimiter) of the PwmControl commands of the trials.
    command_bytes: list[int] = field(default_factory=list)
    inputs: list[float] = field(default_factory=list)  # edge -> Bool at the subscriber
    input_uncertainty: list[float] = field(default_factory=list)
    inputs_lost: int = 0
    report_bytes: list[int] = field(default_factory=list)  # the InputReports of the edges
    #: Streaming: topic -> samples/s at the subscriber; pin -> values/s the device sent.
    topic_rates: dict[str, float] = field(default_factory=dict)
    device_rates: dict[int, float] = field(default_factory=dict)
    stream_seconds: float = 0.0
    #: Values set per analog pin per second through the control socket while counting.
    changes_per_pin: float = 0.0
    #: Encoder pulse -> an Odometry that moved at the subscriber (s), as for the inputs.
    odometry: list[float] = field(default_factory=list)
    odometry_uncertainty: list[float] = field(default_factory=list)
    odometry_lost: int = 0


@dataclass(slots=True)
class Result:
    idle: Phase | None = None
    streaming: Phase | None = None
    #: The real ROS 2 node's phase, or why it was not run.
    rclpy: Phase | None = None
    rclpy_error: str | None = None
    rclpy_versions: str = ""
    error: str | None = None


@contextlib.contextmanager
def bridge_process(
    port: str, domain: int, tmp: Path, name: str, config_text: str
) -> Iterator[Path]:
    """``protoduino ros2 PORT`` running with this phase's configuration; yields its capture."""
    config = tmp / f"{name}.yaml"
    config.write_text(config_text)
    capture = tmp / f"{name}.capture.jsonl"
    out = tmp / f"{name}.log"
    command = [
        *(sys.executable, "-m", "protoduino.cli.main", "ros2", port, "--config", str(config)),
        *("--domain-id", str(domain), "--new-session", "--capture", str(capture)),
        *("--baud", "115200"),  # this part's figures are at 115200, as its text says
    ]
    with out.open("w") as log_file:
        proc = subprocess.Popen(command, stdout=log_file, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while "topics:" not in out.read_text():
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the bridge did not start: {out.read_text()[-500:]}")
            time.sleep(0.05)
        yield capture
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _pwm_time(trace: Trace, pin: int, duty: int, since: int) -> float | None:
    """Board time of the first trace line from index ``since`` on with ``pin`` at ``duty``."""
    deadline = time.monotonic() + SETTLE
    while time.monotonic() < deadline:
        events = trace.update()
        for e in events[since:]:
            if e["pin"] == pin and e.get("mode") == "pwm" and int(e["value"]) == duty:
                return float(e["t"])
        time.sleep(0.002)
    return None


#: Publishes a Twist of this linear speed (m/s); returns the time.monotonic() it did.
PublishTwist = Callable[[float], float]


def measure_drive(
    publish: PublishTwist,
    sim: SimBoard,
    trace: Trace,
    wiring: Wiring,
    trials: int,
    *,
    rng: random.Random,
    phase: Phase,
) -> None:
    """Twists at duties that always change (never 0 or 255: the trace dates those later)."""
    level = 0
    duty = 0
    for i in range(trials + 1):  # the first one sets the direction pins: not timed
        duty = 30 + (duty + 61 + 7 * i) % 190
        time.sleep(rng.uniform(0.0, 0.020))  # Twists at every phase of the PWM period
        mark = len(trace.update())
        level ^= 1
        sent = time.monotonic()
        board_t = sim.set_level(CLOCK_PIN, level)
        answered = time.monotonic()
        published = publish(duty / 255 * MAX_SPEED)
        published_at = time.time() - (time.monotonic() - published)  # the capture's clock
        left = _pwm_time(trace, wiring.left_pwm, duty, mark)
        right = _pwm_time(trace, wiring.right_pwm, duty, mark)
        if i == 0:
            continue
        if left is None or right is None:
            phase.drive_lost += 1
            continue
        host_at_board_t = (sent + answered) / 2
        lag = published - host_at_board_t
        phase.drive.append(
            DriveTrial(
                to_left=left - board_t - lag,
                to_right=right - board_t - lag,
                to_sent=None,
                uncertainty=(answered - sent) / 2,
                published_at=published_at,
                duty=duty,
            )
        )


class ButtonProbe(Protocol):
    """Where the button's samples arrive: :meth:`mark` before an edge, then :meth:`arrival`
    of the first sample after the mark with ``level`` (None: none within SETTLE)."""

    def mark(self) -> None: ...

    def arrival(self, level: bool) -> float | None: ...


class PeerButton:
    """The button at the Cyclone peer's listener."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self.since = 0
        peer.recording.add("button")

    def mark(self) -> None:
        self.since = len(self.peer.arrivals["button"])

    def arrival(self, level: bool) -> float | None:
        return self.peer.wait_for("button", level, self.since)


def measure_inputs(
    probe: ButtonProbe,
    sim: SimBoard,
    wiring: Wiring,
    *,
    trials: int,
    rng: random.Random,
    phase: Phase,
) -> None:
    level = 1  # the pull-up's level before the first edge
    for _ in range(trials):
        time.sleep(rng.uniform(0.0, 0.020))  # edges at every phase of the device's loop
        level ^= 1
        probe.mark()
        sent = time.monotonic()
        sim.set_level(wiring.button, level)
        answered = time.monotonic()
        arrived = probe.arrival(bool(level))
        if arrived is None:
            phase.inputs_lost += 1
            continue
        edge = (sent + answered) / 2
        phase.inputs.append(arrived - edge)
        phase.input_uncertainty.append((answered - sent) / 2)


# --- the real ROS 2 node ------------------------------------------------------------


class NodeTopic:
    """One subscription of the rclpy node: its samples, each with its callback's time."""

    def __init__(self, node: RclpyNode, topic: str, kind: str, qos: str | None) -> None:
        self.node = node
        self.topic = topic
        node.request("sub", topic=topic, type=kind, qos=qos)
        self.last: Any = None

    def first(self, timeout: float) -> bool:
        """Until a first sample arrived (the bridge's writer and this reader matched)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.drain():
                return True
            time.sleep(0.02)
        return False

    def drain(self) -> bool:
        """Take what arrived; keep the newest. True if anything did."""
        taken = self.node.take(self.topic)
        if taken:
            self.last = taken[-1][1]
        return bool(taken)

    def arrival(self, ok: Callable[[Any], bool]) -> float | None:
        """The callback time of the first sample from now on for which ``ok`` holds."""
        deadline = time.monotonic() + SETTLE
        while time.monotonic() < deadline:
            for when, sample in self.node.take(self.topic):
                self.last = sample
                if ok(sample):
                    return when
            time.sleep(0.001)
        return None


class NodeButton:
    """The button at the rclpy node's callback."""

    def __init__(self, topic: NodeTopic) -> None:
        self.topic = topic

    def mark(self) -> None:
        self.topic.drain()

    def arrival(self, level: bool) -> float | None:
        return self.topic.arrival(lambda sample: sample["data"] is level)


def _x(odometry: Any) -> float:
    return float(odometry["pose"]["pose"]["position"]["x"])


def measure_odometry(
    odom: NodeTopic,
    sim: SimBoard,
    wiring: Wiring,
    *,
    trials: int,
    rng: random.Random,
    phase: Phase,
) -> None:
    """One pulse on each encoder in turn (the heading stays near 0, so each moves the pose
    0.5 mm ahead) until an Odometry at the node shows the pose moved."""
    assert wiring.encoders is not None
    step = 1.0 / TICKS_PER_METRE / 2  # one wheel's tick moves the middle half as far
    for i in range(trials):
        time.sleep(rng.uniform(0.0, 0.020))  # pulses at every phase of the reports
        odom.drain()
        before = _x(odom.last)
        sent = time.monotonic()
        sim.pulses(wiring.encoders[i % 2], 1, PULSE_HZ)
        answered = time.monotonic()

        def moved(sample: Any, x: float = before) -> bool:
            return _x(sample) > x + step / 2

        arrived = odom.arrival(moved)
        if arrived is None:
            phase.odometry_lost += 1
            continue
        phase.odometry.append(arrived - (sent + answered) / 2)
        phase.odometry_uncertainty.append((answered - sent) / 2)


def _drive_until_shown(publish: PublishTwist, trace: Trace, wiring: Wiring) -> None:
    """Publish a Twist until the left pin shows it: the bridge knows the node's writer (a
    reliable reader takes only what comes after it discovered the writer)."""
    duty = 100
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        mark = len(trace.update())
        publish(duty / 255 * MAX_SPEED)
        if _pwm_time(trace, wiring.left_pwm, duty, mark) is not None:
            return
    raise RuntimeError("the rclpy node's Twists never reached the pins")


def measure_rclpy(
    sim: SimBoard, trace: Trace, *, domain: int, tmp: Path, trials: int, rng: random.Random
) -> Phase:
    """The real node's phase: inputs, odometry, then the Twists."""
    phase = Phase()
    wiring = RCLPY_WIRING
    node = RclpyNode(domain, tmp / "rclpy.log")
    try:
        ns = RCLPY_NAMESPACE
        # The bridge's QoS: an input is sensor data, the odometry reliable (docs/ros2.md).
        button = NodeTopic(node, f"/{ns}/button", "std_msgs/msg/Bool", "sensor")
        odom = NodeTopic(node, f"/{ns}/odom", "nav_msgs/msg/Odometry", None)
        config = robot_yaml(wiring, ns)
        with bridge_process(sim.port, domain, tmp, "rclpy", config) as capture:
            sim.set_level(wiring.button, 1)  # the pull-up's level
            if not (button.first(START_TIMEOUT) and odom.first(START_TIMEOUT)):
                raise RuntimeError("the bridge's topics never reached the rclpy node")
            measure_inputs(NodeButton(button), sim, wiring, trials=trials, rng=rng, phase=phase)
            measure_odometry(odom, sim, wiring, trials=trials, rng=rng, phase=phase)

            def publish(linear: float) -> float:
                twist = {"linear": {"x": linear}, "angular": {"z": 0.0}}
                return node.publish(f"/{ns}/cmd_vel", "geometry_msgs/msg/Twist", twist)

            _drive_until_shown(publish, trace, wiring)
            measure_drive(publish, sim, trace, wiring, trials, rng=rng, phase=phase)
        attach_capture(phase, read_capture(capture), None, wiring)
    finally:
        node.close()
    return phase


class Wiggler:
    """Changes the six analog inputs, one after another, as fast as the control socket takes
    it (a new value each time, so that two samples never see the same one if a change came
    between them), in a thread of its own while it is entered."""

    def __init__(self, sim: SimBoard) -> None:
        self.sim = sim
        self.changes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-ros2-analog", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            pin = ANALOG_PINS[self.changes % len(ANALOG_PINS)]
            self.sim.set_analog(pin, 100 + (self.changes // len(ANALOG_PINS)) % 800)
            self.changes += 1

    def __enter__(self) -> Wiggler:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join(SETTLE)


def measure_stream(
    peer: Peer, wiggler: Wiggler, seconds: float, phase: Phase
) -> tuple[float, float]:
    """Count the six topics' samples for ``seconds``; returns the window in wall time."""
    names = [analog_topic(pin) for pin in ANALOG_PINS]
    for name in names:
        peer.arrivals[name].clear()
    start = time.time()
    changes = wiggler.changes
    peer.recording.update(names)
    time.sleep(seconds)
    peer.recording.difference_update(names)
    end = time.time()
    phase.changes_per_pin = (wiggler.changes - changes) / len(ANALOG_PINS) / (end - start)
    with peer.arrived:
        for name in names:
            times = [when for when, _sample in peer.arrivals[name]]
            span = times[-1] - times[0] if len(times) > 1 else 0.0
            phase.topic_rates[name] = (len(times) - 1) / span if span > 0 else 0.0
    phase.stream_seconds = seconds
    return start, end


# --- the capture -----------------------------------------------------------------------


@dataclass(slots=True)
class Frame:
    t: float  # wall time the bridge wrote or read it
    tx: bool
    size: int  # on the wire, with the delimiter
    message: Any


def read_capture(path: Path) -> list[Frame]:
    frames: list[Frame] = []
    decoder = StreamDecoder()
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue  # a torn last line
        if "frame" not in record or "error" in record:
            continue
        data = bytes.fromhex(record["frame"]) + b"\0"
        for item in decoder.feed(data):
            if not isinstance(item, Packet) or not item.payload:
                continue
            tx = record["dir"] == "tx"
            with contextlib.suppress(Exception):
                message = parse_in(item.payload) if tx else parse_out(item.payload)
                frames.append(Frame(float(record["t"]), tx, len(data), message))
    return frames


def attach_capture(
    phase: Phase, frames: list[Frame], window: tuple[float, float] | None, wiring: Wiring
) -> None:
    """The commands' sizes and send times, the reports' sizes, the device's analog rates."""
    pwm = [f for f in frames if f.tx and f.message.WhichOneof("data") == "pwm_control"]
    for trial in phase.drive:
        for f in pwm:
            control = f.message.pwm_control
            left = control.pin == wiring.left_pwm
            if f.t >= trial.published_at and left and control.duty == trial.duty:
                trial.to_sent = f.t - trial.published_at
                phase.command_bytes.append(f.size)
                break
    reports = [f for f in frames if not f.tx and f.message.WhichOneof("data") == "input_report"]
    phase.report_bytes = [
        f.size for f in reports if wiring.button in pins_in(f.message.input_report.digital_pins)
    ]
    if window is not None:
        start, end = window
        for pin in ANALOG_PINS:
            times = [
                f.message.input_report.time_ms / 1000
                for f in reports
                if start <= f.t <= end and pin in pins_in(f.message.input_report.analog_pins)
            ]
            span = times[-1] - times[0] if len(times) > 1 else 0.0
            phase.device_rates[pin] = (len(times) - 1) / span if span > 0 else 0.0


# --- running it ------------------------------------------------------------------------


@contextlib.contextmanager
def loopback_only() -> Iterator[None]:
    """CYCLONEDDS_URI set to loopback for this process and the bridges it starts."""
    old = os.environ.get("CYCLONEDDS_URI")
    os.environ["CYCLONEDDS_URI"] = LOOPBACK
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("CYCLONEDDS_URI", None)
        else:
            os.environ["CYCLONEDDS_URI"] = old


def collect(trials: int, seconds: float, seed: int = 7) -> Result:
    result = Result()
    tool = missing_tool("avr")
    if tool is not None:
        result.error = f"`{tool}` is not installed"
        return result
    rng = random.Random(seed)
    domain = random.SystemRandom().randint(1, 200)
    with (
        TemporaryDirectory(prefix="bench-ros2-") as tmp_name,
        loopback_only(),
        contextlib.ExitStack() as stack,
    ):
        tmp = Path(tmp_name)
        sim = SimBoard("avr", trace=tmp / "trace.jsonl")
        try:
            sim.start()
            trace = Trace(tmp / "trace.jsonl")
            from .ros2_peer import Peer  # cyclonedds: only once run() found it

            peer = Peer(
                domain,
                NAMESPACE,
                bools=["button"],
                floats=[analog_topic(pin) for pin in ANALOG_PINS],
                settle=SETTLE,
                start_timeout=START_TIMEOUT,
            )
            stack.callback(peer.close)
            wiring = PEER_WIRING
            for name, streaming in (("idle", False), ("streaming", True)):
                phase = Phase()
                window = None
                config = robot_yaml(wiring, NAMESPACE, streaming)
                with bridge_process(sim.port, domain, tmp, name, config) as capture:
                    peer.wait_matched(1 + (len(ANALOG_PINS) if streaming else 0))
                    if streaming:
                        with Wiggler(sim) as wiggler:
                            window = measure_stream(peer, wiggler, seconds, phase)
                            drive_trials = max(3, trials // 2)
                            measure_drive(
                                peer.twist, sim, trace, wiring, drive_trials, rng=rng, phase=phase
                            )
                    else:
                        button = PeerButton(peer)
                        measure_inputs(button, sim, wiring, trials=trials, rng=rng, phase=phase)
                        peer.recording.discard("button")
                        measure_drive(peer.twist, sim, trace, wiring, trials, rng=rng, phase=phase)
                attach_capture(phase, read_capture(capture), window, wiring)
                if streaming:
                    result.streaming = phase
                else:
                    result.idle = phase
            try:
                result.rclpy_versions = rclpy_versions()
                result.rclpy = measure_rclpy(
                    sim, trace, domain=domain, tmp=tmp, trials=trials, rng=rng
                )
            except RuntimeError as error:  # NodeUnavailableError too
                log.warning("ros2: the real node not run: %s", error)
                result.rclpy_error = str(error).splitlines()[0]
        except (BoardUnavailableError, RuntimeError, OSError) as error:
            log.warning("ros2: not run: %s", error)
            result.error = str(error).splitlines()[0]
        finally:
            sim.stop()
    return result


# --- the report ------------------------------------------------------------------------


def _span(values: Iterable[float]) -> str:
    """``lo to hi`` with one decimal, or one figure when they agree."""
    ordered = sorted(values) or [0.0]
    lo, hi = f"{ordered[0]:.1f}", f"{ordered[-1]:.1f}"
    return lo if lo == hi else f"{lo} to {hi}"


def _version(package: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return "(version unknown)"


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:.2f}"


def _drive_rows(label: str, phase: Phase) -> list[list[str]]:
    if not phase.drive:
        return [[label, "-", "-", "-", "-", "-", str(phase.drive_lost)]]
    size = statistics.median(phase.command_bytes) if phase.command_bytes else 0
    wire = size * EMULATED_BYTE_US / 1e6
    left = Percentiles.of([t.to_left for t in phase.drive])
    right = Percentiles.of([t.to_right for t in phase.drive])
    sent = [t.to_sent for t in phase.drive if t.to_sent is not None]
    rows = [
        [
            f"{label}: to the left motor's pin (1st PwmControl, {size:g} B)",
            _ms(left.p50),
            _ms(left.p99),
            _ms(wire),
            f"{left.p50 / wire:.1f}x" if wire else "-",
            str(len(phase.drive)),
            str(phase.drive_lost),
        ],
        [
            f"{label}: to the right motor's pin (2nd PwmControl)",
            _ms(right.p50),
            _ms(right.p99),
            _ms(2 * wire),
            f"{right.p50 / (2 * wire):.1f}x" if wire else "-",
            str(len(phase.drive)),
            str(phase.drive_lost),
        ],
    ]
    if sent:
        to_sent = Percentiles.of(sent)
        rows.append(
            [
                f"{label}: until the bridge wrote the 1st command (DDS and the bridge)",
                _ms(to_sent.p50),
                _ms(to_sent.p99),
                "-",
                "-",
                str(len(sent)),
                "-",
            ]
        )
    return rows


def run(ctx: Context) -> SectionResult:
    require("cyclonedds", "cyclonedds")
    require("yaml", "PyYAML")
    trials = max(10, min(100, ctx.samples // 3))
    seconds = STREAM_SECONDS if ctx.samples >= 100 else 1.0
    result = collect(trials, seconds, ctx.seed)
    w = PEER_WIRING
    parts = [
        "The bridge runs as `protoduino ros2 PORT --config robot.yaml --capture FILE` in a "
        "process of its own, on the emulated Uno (the real firmware on simavr); this process "
        "is the rest of the ROS 2 graph, a Cyclone DDS participant on loopback only (multicast "
        f"off, the peer 127.0.0.1; Cyclone DDS {_version('cyclonedds')} from PyPI). In the "
        "first three questions that participant is no ROS 2 installation: the publisher and "
        "the subscribers use the bridge's own message types, whose CDR tests/e2e/test_ros2.py "
        "checks against rosbags' independent codec. The drive is on pins "
        f"{w.left_pwm} and {w.right_pwm} (PWM, Timer2) with direction pins {w.left_dir} and "
        f"{w.right_dir}; the button on pin {w.button} (pull-up, no debounce).\n",
        f"**/cmd_vel to the pins.** {trials} Twists (the first, which sets the direction pins, "
        "not counted), each after a random pause of 0-20 ms, each at a new speed, so that both "
        "wheels get a new duty (never 0 or 255): from the Twist written on DDS until each "
        "motor's pin shows its new duty in the runner's trace. A duty is dated to the rising "
        "edge of its first whole PWM period, so up to one period (about 2 ms at the pins' 490 "
        "Hz) of each time is the period's phase. The bridge writes the two motors one after "
        "the other (each a PwmControl command awaiting its Ack), so the right motor's time "
        "holds two commands. The board's clock (emulated time) is tied to the host's for each "
        f"Twist by a control command on pin {CLOCK_PIN} just before it: its board time lies "
        "between sending and the answer, so the midpoint is used and half that round trip is "
        "the trial's uncertainty (below). *Wire*: the PwmControl frame's size (from the "
        "bridge's capture) at the emulated line's 11 bits a byte (simavr times a UART byte "
        f"as 11 bits: {EMULATED_BYTE_US:.1f} us a byte, not 10 at 115200 baud); for the right "
        "motor, two such frames. The last row is the DDS and bridge share: from the Twist "
        "written until the bridge wrote the left motor's command to the port (the capture's "
        "time of that frame). The same Twists again, fewer, while six analog channels stream "
        "(below); the thread that changes their values runs in this process, next to the "
        "publisher and the subscribers, and the machine's two cores are shared, so the tail of "
        "those times is partly this bench's own load. With n below 100, p99 is the slowest "
        "trial.\n",
        f"**Input to a DDS sample.** {trials} edges on the button, each after a random pause "
        "of 0-20 ms, made through the board's control socket: from the edge until the "
        "subscriber's listener has the Bool (the host time of the edge is the midpoint of the "
        "control command's round trip; half of it is the uncertainty), against the wire time "
        "of the InputReport that carried it (its median framed size, from the capture).\n",
        f"**Samples per second with six analog channels.** A0..A5 at {ANALOG_HZ} Hz each "
        f"(`rate_hz: {ANALOG_HZ}`, `threshold: 0`: every sample that changed is reported), "
        "each its own std_msgs/Float32 topic. The bridge publishes an input when it changes, "
        "so a thread of this process changes the six values one after another through the "
        "board's control socket, as fast as it answers (the rate per pin is given), a new "
        f"value each time. For {seconds:g} s: the samples each topic's subscriber received per "
        "second (their number less one over the span of their arrivals), against the values "
        "the device sent for that pin in the same window (the capture's InputReports, over "
        "the span of their device times). Then the /cmd_vel trials above ran again while "
        "they streamed.\n",
        f"**A real ROS 2 node.** Then ROS 2's own client library, rclpy on its default "
        "middleware Fast DDS (ROS 2 Kilted's wheels from PyPI in `.deps/ros2-venv`, which "
        "`./tools/dev.sh setup` installs; the node is tests/ros2_node.py, the one "
        "tests/e2e/test_ros2_real.py drives, discovering over loopback only), against the "
        "bridge with odometry: the encoders on INT0 and INT1's pins 2 and 3 (the external "
        "interrupts), "
        f"the left motor moves to pin {RCLPY_WIRING.left_pwm} (Timer1; no servo here) and the "
        f"button to pin {RCLPY_WIRING.button}; `ticks_per_metre: {TICKS_PER_METRE}`, the "
        "odometry at its default 50 Hz (the device reports a counter at most that often too). "
        "The node stamps its publish call and its subscription callbacks with "
        "`time.monotonic()`, the clock this process reads (CLOCK_MONOTONIC). Three questions, "
        f"{trials} trials each, each after a random pause of 0-20 ms: a Twist published by "
        "rclpy until each motor pin shows its new duty (as above, the clocks tied the same "
        "way); a button edge until the node's callback has the Bool (sensor QoS); one encoder "
        f"pulse (a quarter of a millisecond: {PULSE_HZ} Hz, on each encoder in turn, made "
        "through the control socket and dated as an edge is) until the node's callback has an "
        "Odometry whose pose moved by it (reliable QoS). That last time holds up to one "
        "counter report period and one odometry period (20 ms each) by design.\n",
    ]
    if result.error is not None:
        parts.append(f"The emulated Uno was not run: {result.error}.\n")
        return SectionResult("\n".join(parts), packages=["cyclonedds"])
    rows: list[list[str]] = []
    for label, phase in (("idle", result.idle), ("6 channels streaming", result.streaming)):
        if phase is not None:
            rows += _drive_rows(label, phase)
    parts.append("### /cmd_vel to the motor pins (emulated Uno)\n")
    parts.append(md_table(["what", "p50 ms", "p99 ms", "wire ms", "p50 / wire", "n", "lost"], rows))
    uncertainty = [t.uncertainty for p in (result.idle, result.streaming) if p for t in p.drive]
    if uncertainty:
        parts.append(
            "The clocks tied within +-"
            f"{statistics.median(uncertainty) * 1000:.2f} ms (median; at most "
            f"+-{max(uncertainty) * 1000:.2f} ms).\n"
        )
    idle = result.idle
    if idle is not None:
        parts.append("### Input to a DDS sample (emulated Uno)\n")
        if idle.inputs:
            lat = Percentiles.of(idle.inputs)
            size = statistics.median(idle.report_bytes) if idle.report_bytes else 0
            wire = size * EMULATED_BYTE_US / 1e6
            parts.append(
                md_table(
                    ["what", "p50 ms", "p99 ms", "wire ms", "p50 / wire", "n", "lost"],
                    [
                        [
                            f"button edge to the Bool at the subscriber ({size:g} B report)",
                            _ms(lat.p50),
                            _ms(lat.p99),
                            _ms(wire),
                            f"{lat.p50 / wire:.1f}x" if wire else "-",
                            str(len(idle.inputs)),
                            str(idle.inputs_lost),
                        ]
                    ],
                )
            )
            parts.append(
                "Each edge's host time known within +-"
                f"{statistics.median(idle.input_uncertainty) * 1000:.2f} ms (median; at most "
                f"+-{max(idle.input_uncertainty) * 1000:.2f} ms).\n"
            )
        else:
            parts.append(f"No edge arrived ({idle.inputs_lost} lost).\n")
    stream = result.streaming
    quotes = _quotes(result)
    if stream is not None:
        parts.append("### Six analog channels streaming (emulated Uno)\n")
        stream_rows = [
            [
                f"/{NAMESPACE}/{analog_topic(pin)} (A{pin - 14})",
                f"{stream.topic_rates.get(analog_topic(pin), 0.0):.1f}",
                f"{stream.device_rates.get(pin, 0.0):.1f}",
            ]
            for pin in ANALOG_PINS
        ]
        parts.append(
            md_table(
                ["topic", "samples/s at the subscriber", "values/s from the device"], stream_rows
            )
        )
        parts.append(
            f"Values set per pin through the control socket: {stream.changes_per_pin:.0f}/s.\n"
        )
    parts += _rclpy_parts(result)
    return SectionResult("\n".join(parts), packages=["cyclonedds"], quotes=quotes)


def _latency_row(what: str, times: list[float], lost: int) -> list[str]:
    if not times:
        return [what, "-", "-", "0", str(lost)]
    lat = Percentiles.of(times)
    return [what, _ms(lat.p50), _ms(lat.p99), str(len(times)), str(lost)]


def _rclpy_parts(result: Result) -> list[str]:
    parts = ["### A real ROS 2 node: rclpy on Fast DDS (emulated Uno)\n"]
    phase = result.rclpy
    if phase is None:
        parts.append(f"Not run: {result.rclpy_error or 'the emulated Uno was not run'}.\n")
        return parts
    w = RCLPY_WIRING
    drive_lost = phase.drive_lost
    rows = [
        _latency_row(
            f"Twist published by rclpy to the left motor's pin ({w.left_pwm})",
            [t.to_left for t in phase.drive],
            drive_lost,
        ),
        _latency_row(
            f"Twist published by rclpy to the right motor's pin ({w.right_pwm})",
            [t.to_right for t in phase.drive],
            drive_lost,
        ),
        _latency_row(
            f"button edge (pin {w.button}) to the rclpy callback's Bool",
            phase.inputs,
            phase.inputs_lost,
        ),
        _latency_row(
            "encoder pulse to the rclpy callback's Odometry that moved",
            phase.odometry,
            phase.odometry_lost,
        ),
    ]
    parts.append(md_table(["what", "p50 ms", "p99 ms", "n", "lost"], rows))
    sent = [t.to_sent for t in phase.drive if t.to_sent is not None]
    uncertainty = [t.uncertainty for t in phase.drive] + phase.input_uncertainty
    uncertainty += phase.odometry_uncertainty
    notes = []
    if sent:
        to_sent = Percentiles.of(sent)
        notes.append(
            "From the Twist published until the bridge wrote the left motor's command: "
            f"{_ms(to_sent.p50)} ms at the median, {_ms(to_sent.p99)} ms at the 99th "
            "percentile (Fast DDS, Cyclone DDS and the bridge)."
        )
    if uncertainty:
        notes.append(
            f"The clocks tied within +-{statistics.median(uncertainty) * 1000:.2f} ms "
            f"(median; at most +-{max(uncertainty) * 1000:.2f} ms)."
        )
    notes.append(f"{result.rclpy_versions}.")
    parts.append(" ".join(notes) + "\n")
    return parts


def _quotes(result: Result) -> dict[str, str]:
    """The figures docs/ros2.md quotes from this run (bench.report.quote)."""
    quotes: dict[str, str] = {}
    idle, stream = result.idle, result.streaming
    if idle is not None and idle.drive and idle.command_bytes:
        left = Percentiles.of([t.to_left for t in idle.drive])
        right = Percentiles.of([t.to_right for t in idle.drive])
        wire = statistics.median(idle.command_bytes) * EMULATED_BYTE_US / 1e6
        quotes["ros2_cmd_vel"] = (
            f"{_ms(left.p50)} ms at the median, {_ms(left.p99)} ms at the 99th percentile to "
            f"the first motor's pin (its command's wire time: {_ms(wire)} ms), "
            f"{_ms(right.p50)} and {_ms(right.p99)} ms to the second"
        )
    if idle is not None and idle.inputs:
        lat = Percentiles.of(idle.inputs)
        quotes["ros2_input"] = f"{_ms(lat.p50)} ms at the median, {_ms(lat.p99)} ms at the 99th"
    if stream is not None and stream.topic_rates:
        topics = _span(stream.topic_rates.values())
        device = _span(stream.device_rates.values())
        quotes["ros2_stream"] = (
            f"{topics} samples/s per topic at the subscriber (the device sent {device} values/s "
            "per channel)"
        )
    real = result.rclpy
    if real is not None and real.drive and real.inputs and real.odometry:
        left = Percentiles.of([t.to_left for t in real.drive])
        right = Percentiles.of([t.to_right for t in real.drive])
        edge = Percentiles.of(real.inputs)
        odom = Percentiles.of(real.odometry)
        quotes["ros2_rclpy"] = (
            f"a Twist published by rclpy reaches the first motor's pin in {_ms(left.p50)} ms at "
            f"the median, {_ms(left.p99)} ms at the 99th percentile ({_ms(right.p50)} and "
            f"{_ms(right.p99)} ms the second); an input's edge reaches the rclpy callback in "
            f"{_ms(edge.p50)} and {_ms(edge.p99)} ms; an encoder pulse an Odometry at the "
            f"callback in {_ms(odom.p50)} and {_ms(odom.p99)} ms"
        )
    return quotes


SECTION = Section(8, "ros2", "ROS 2 bridge: /cmd_vel to the pins, inputs to DDS samples", run)
