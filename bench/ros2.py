"""Benchmark part 8 (docs/performance.md): the ROS 2 bridge on the emulated Uno.

The bridge runs as a user runs it (``protoduino ros2 PORT --config robot.yaml`` in a process
of its own, with ``--capture``), on the emulated Uno (the real firmware on simavr, its pins
measured by the runner), and this process is the rest of the ROS 2 graph: a Cyclone DDS
participant on loopback only (the bridge's own message types: the encoding is tested
elsewhere, against rosbags, in tests/e2e/test_ros2.py). Three questions:

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
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import TYPE_CHECKING, Any

from protoduino.framing import StreamDecoder
from protoduino.messages import parse_in, parse_out
from protoduino.packets import Packet
from protoduino.simboard import SimBoard

from .boards import BoardUnavailableError, Percentiles, Trace, missing_tool
from .core import Context, Section, SectionResult, md_table, require
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
#: The drive's pins (Timer2's two PWM pins), the button, the pin that ties the clocks.
LEFT_PWM, LEFT_DIR, RIGHT_PWM, RIGHT_DIR = 3, 4, 11, 12
BUTTON_PIN = 2
CLOCK_PIN = 7
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
  left: {{pwm: {lp}, direction: {ld}}}
  right: {{pwm: {rp}, direction: {rd}}}
digital_inputs:
  - {{pin: {button}, topic: button, pull_up: true}}
"""
ANALOG_CONFIG = """\
analog_inputs:
{channels}
"""


def analog_topic(pin: int) -> str:
    return f"analog/a{pin - 14}"


def robot_yaml(streaming: bool) -> str:
    """The bridge's configuration: the drive and a button, and the six channels if streaming.

    The drive's watchdog is long (30 s): the trials leave the motors running between Twists,
    and a stop by the watchdog would be a command of its own among theirs.
    """
    text = CONFIG.format(
        ns=NAMESPACE,
        max_speed=MAX_SPEED,
        lp=LEFT_PWM,
        ld=LEFT_DIR,
        rp=RIGHT_PWM,
        rd=RIGHT_DIR,
        button=BUTTON_PIN,
    )
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


@dataclass(slots=True)
class Result:
    idle: Phase | None = None
    streaming: Phase | None = None
    error: str | None = None


@contextlib.contextmanager
def bridge_process(port: str, domain: int, tmp: Path, name: str, streaming: bool) -> Iterator[Path]:
    """``protoduino ros2 PORT`` running with this phase's configuration; yields its capture."""
    config = tmp / f"{name}.yaml"
    config.write_text(robot_yaml(streaming))
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


def measure_drive(
    peer: Peer, sim: SimBoard, trace: Trace, trials: int, *, rng: random.Random, phase: Phase
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
        published_at = time.time()
        published = time.monotonic()
        peer.twist(duty / 255 * MAX_SPEED)
        left = _pwm_time(trace, LEFT_PWM, duty, mark)
        right = _pwm_time(trace, RIGHT_PWM, duty, mark)
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


def measure_inputs(
    peer: Peer, sim: SimBoard, trials: int, rng: random.Random, phase: Phase
) -> None:
    level = 1  # the pull-up's level before the first edge
    peer.recording.add("button")
    for _ in range(trials):
        time.sleep(rng.uniform(0.0, 0.020))  # edges at every phase of the device's loop
        level ^= 1
        since = len(peer.arrivals["button"])
        sent = time.monotonic()
        sim.set_level(BUTTON_PIN, level)
        answered = time.monotonic()
        arrived = peer.wait_for("button", bool(level), since)
        if arrived is None:
            phase.inputs_lost += 1
            continue
        edge = (sent + answered) / 2
        phase.inputs.append(arrived - edge)
        phase.input_uncertainty.append((answered - sent) / 2)
    peer.recording.discard("button")


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


def attach_capture(phase: Phase, frames: list[Frame], window: tuple[float, float] | None) -> None:
    """The commands' sizes and send times, the reports' sizes, the device's analog rates."""
    pwm = [f for f in frames if f.tx and f.message.WhichOneof("data") == "pwm_control"]
    for trial in phase.drive:
        for f in pwm:
            control = f.message.pwm_control
            if f.t >= trial.published_at and control.pin == LEFT_PWM and control.duty == trial.duty:
                trial.to_sent = f.t - trial.published_at
                phase.command_bytes.append(f.size)
                break
    reports = [f for f in frames if not f.tx and f.message.WhichOneof("data") == "input_report"]
    phase.report_bytes = [
        f.size for f in reports if f.message.input_report.digital_pins >> BUTTON_PIN & 1
    ]
    if window is not None:
        start, end = window
        for pin in ANALOG_PINS:
            times = [
                f.message.input_report.time_ms / 1000
                for f in reports
                if start <= f.t <= end and f.message.input_report.analog_pins >> pin & 1
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

            peer = Peer(domain)
            stack.callback(peer.close)
            for name, streaming in (("idle", False), ("streaming", True)):
                phase = Phase()
                window = None
                with bridge_process(sim.port, domain, tmp, name, streaming) as capture:
                    peer.wait_matched(1 + (len(ANALOG_PINS) if streaming else 0))
                    if streaming:
                        with Wiggler(sim) as wiggler:
                            window = measure_stream(peer, wiggler, seconds, phase)
                            drive_trials = max(3, trials // 2)
                            measure_drive(peer, sim, trace, drive_trials, rng=rng, phase=phase)
                    else:
                        measure_inputs(peer, sim, trials, rng, phase)
                        measure_drive(peer, sim, trace, trials, rng=rng, phase=phase)
                attach_capture(phase, read_capture(capture), window)
                if streaming:
                    result.streaming = phase
                else:
                    result.idle = phase
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
    parts = [
        "The bridge runs as `protoduino ros2 PORT --config robot.yaml --capture FILE` in a "
        "process of its own, on the emulated Uno (the real firmware on simavr); this process "
        "is the rest of the ROS 2 graph, a Cyclone DDS participant on loopback only (multicast "
        f"off, the peer 127.0.0.1; Cyclone DDS {_version('cyclonedds')} from PyPI). There is "
        "no ROS 2 installation here: the publisher and the "
        "subscribers use the bridge's own message types, whose CDR tests/e2e/test_ros2.py "
        "checks against rosbags' independent codec. The drive is on pins "
        f"{LEFT_PWM} and {RIGHT_PWM} (PWM, Timer2) with direction pins {LEFT_DIR} and "
        f"{RIGHT_DIR}; the button on pin {BUTTON_PIN} (pull-up, no debounce).\n",
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
    return SectionResult("\n".join(parts), packages=["cyclonedds"], quotes=quotes)


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
    return quotes


SECTION = Section(8, "ros2", "ROS 2 bridge: /cmd_vel to the pins, inputs to DDS samples", run)
