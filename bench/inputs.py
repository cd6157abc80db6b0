"""Benchmark part 7 (docs/performance.md): inputs.

Three questions about the inputs (docs/api.md, Pins), on both boards:

* Pin change to host callback: a digital input's level is changed through the board's
  control socket, and the time until its ``on_change`` callback runs on the host is set
  against the time its InputReport takes on the wire. The edge came after the control
  command was sent and before its answer arrived, so its host time is the midpoint of that
  round trip, within half of it (reported).
* Analog streaming: six analog inputs sampled at 200 Hz each while the host keeps sending
  Pings, one after another. The inputs are constant, so a heartbeat of one sampling period
  makes the device report every sample; the values the host receives per channel per second
  are counted from the frames, and the Ping round trip is set against the same Ping with no
  input configured. Commands go first, but a frame cannot be cut: the goal is that streaming
  adds at most one report frame's wire time to the round trip (issue 35; it was 1.5x the idle
  round trip, a share that grows as the idle round trip shrinks).
* Interlock reaction: a bumper (a digital input with ``interlock="low"``) closes while a
  motor's PWM runs; the time from the edge to the PWM at 0 at the pin, both on the board's
  clock (emulated time on the Uno, measured at the pin).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import random
import statistics
import threading
import time
from dataclasses import dataclass, field

from protoduino import Board, Event, EventKind
from protoduino.constants import PacketType
from protoduino.errors import InterlockActiveError, ProtoduinoError
from protoduino.inputs import Reading
from protoduino.messages import parse_out, pins_in
from protoduino.packets import Packet
from protoduino.simboard import SimBoard
from protoduino.transport import FrameRecord

from .boards import LABELS, Percentiles, Trace, on_each_board
from .core import Context, Section, SectionResult, Target, md_table
from .wire import board_byte_us, frame_bytes

log = logging.getLogger(__name__)

#: The button of the latency trials, the bumper and the motor of the interlock trials.
BUTTON_PIN = 2
BUMPER_PIN = 4
MOTOR_PIN = 3
MOTOR_DUTY = 200
#: Analog streaming: every channel at this rate, for this long, against this goal.
ANALOG_HZ = 200
STREAM_SECONDS = 3.0
TARGET_HZ = 200.0
#: The interlock's goal, on the emulated Uno's clock.
TARGET_REACTION = 0.001
#: How long one trial may take to show its result before it counts as lost.
SETTLE = 5.0


class ReportFrames:
    """The size on the wire of every InputReport frame received while ``counting`` (a frame
    monitor): the report of a low level is shorter (proto3 leaves a zero mask out), and
    ``time_ms`` grows a byte as the device's uptime does."""

    def __init__(self) -> None:
        self.counting = False
        self.sizes: list[int] = []

    def __call__(self, record: FrameRecord) -> None:  # the I/O thread: quick
        item = record.item
        if not self.counting or record.direction != "rx" or not isinstance(item, Packet):
            return
        if item.type is PacketType.DATA and item.payload[:1] == REPORT_TAG:
            self.sizes.append(frame_bytes(item))


#: The first byte of an ArduinoOut holding an InputReport (field 5, length-delimited).
REPORT_TAG = bytes([5 << 3 | 2])


@dataclass(slots=True)
class BoardResult:
    backend: str
    latency: list[float] = field(default_factory=list)  # edge -> callback (s)
    #: The wire sizes of the reports that carried the edges (bytes, framed).
    report_bytes: list[int] = field(default_factory=list)
    #: Half of each edge's control-socket round trip: how well its host time is known.
    edge_uncertainty: list[float] = field(default_factory=list)
    latency_lost: int = 0
    per_channel: dict[int, float] = field(default_factory=dict)  # values/s
    max_gap_ms: dict[int, int] = field(default_factory=dict)  # longest gap between reports
    coalesced: int = 0
    idle_rtt: list[float] = field(default_factory=list)
    stream_rtt: list[float] = field(default_factory=list)
    #: The wire sizes of the analog InputReport frames while streaming (bytes, framed).
    stream_report_bytes: list[int] = field(default_factory=list)
    reaction: list[float] = field(default_factory=list)  # edge -> PWM 0 at the pin (s)
    reaction_lost: int = 0
    error: str | None = None


def measure_latency(
    board: Board, sim: SimBoard, trials: int, rng: random.Random
) -> tuple[list[float], int, list[float], list[int]]:
    button = board.digital_input(BUTTON_PIN, pull_up=True)
    frames = ReportFrames()
    board.add_frame_monitor(frames)
    arrivals: list[tuple[bool, float]] = []
    got = threading.Event()

    def changed(reading: Reading) -> None:  # the board's event thread
        arrivals.append((bool(reading.value), time.monotonic()))
        got.set()

    button.on_change(changed)
    level = bool(button.read())
    samples: list[float] = []
    lost = 0
    half_widths: list[float] = []
    for _ in range(trials):
        time.sleep(rng.uniform(0.0, 0.020))  # edges at every phase of the device's loop
        level = not level
        mark = len(arrivals)
        got.clear()
        frames.counting = True
        sent = time.monotonic()
        sim.set_level(BUTTON_PIN, int(level))
        answered = time.monotonic()
        edge = (sent + answered) / 2
        half_widths.append((answered - sent) / 2)
        deadline = time.monotonic() + SETTLE
        while len(arrivals) <= mark and time.monotonic() < deadline:
            got.wait(0.1)
        if len(arrivals) <= mark or arrivals[mark][0] != level:
            lost += 1
            continue
        frames.counting = False
        samples.append(arrivals[mark][1] - edge)
    frames.counting = False
    button.release()
    return samples, lost, half_widths, frames.sizes


class AnalogCounter:
    """Analog values received per pin, counted from the frames (a frame monitor), with the
    device times (InputReport.time_ms) of the first and the last report that carried one."""

    def __init__(self) -> None:
        self.counting = False
        self.values: collections.Counter[int] = collections.Counter()
        self.first_ms: dict[int, int] = {}
        self.last_ms: dict[int, int] = {}
        #: The longest time between two reports of a pin's value (device ms).
        self.max_gap_ms: collections.Counter[int] = collections.Counter()
        #: The wire size of each analog InputReport frame (bytes, framed).
        self.frame_bytes: list[int] = []

    def rate(self, pin: int) -> float:
        """Values per second of the device's clock: (n - 1) over the span of their times."""
        n = self.values[pin]
        span = (self.last_ms.get(pin, 0) - self.first_ms.get(pin, 0)) / 1000
        return (n - 1) / span if n > 1 and span > 0 else 0.0

    def __call__(self, record: FrameRecord) -> None:  # the I/O thread: quick
        item = record.item
        if not self.counting or record.direction != "rx" or not isinstance(item, Packet):
            return
        if item.type is not PacketType.DATA:
            return
        with contextlib.suppress(ProtoduinoError):
            msg = parse_out(item.payload)
            if msg.WhichOneof("data") == "input_report":
                report = msg.input_report
                if report.analog_pins:
                    self.frame_bytes.append(frame_bytes(item))
                for pin in pins_in(report.analog_pins):
                    self.values[pin] += 1
                    if pin in self.last_ms:
                        gap = report.time_ms - self.last_ms[pin]
                        self.max_gap_ms[pin] = max(self.max_gap_ms[pin], gap)
                    self.first_ms.setdefault(pin, report.time_ms)
                    self.last_ms[pin] = report.time_ms


def measure_streaming(
    board: Board, seconds: float, pings: int
) -> tuple[dict[int, float], dict[int, int], int, list[float], list[float], list[int]]:
    idle = [board.ping() for _ in range(pings)]
    counter = AnalogCounter()
    board.add_frame_monitor(counter)
    pots = [
        board.analog_input(pin, rate_hz=ANALOG_HZ, heartbeat=1 / ANALOG_HZ)
        for pin in board.info.analog_pins
    ]
    coalesced = board.stats.inputs_coalesced
    streaming: list[float] = []
    counter.counting = True
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        streaming.append(board.ping())  # commands keep flowing
    elapsed = time.monotonic() - start
    counter.counting = False
    coalesced = board.stats.inputs_coalesced - coalesced
    for pot in pots:
        pot.release()
    log.debug("analog values received in %.3f s of the host's clock: %s", elapsed, counter.values)
    rates = {pin: counter.rate(pin) for pin in board.info.analog_pins}
    gaps = {pin: counter.max_gap_ms[pin] for pin in board.info.analog_pins}
    return rates, gaps, coalesced, idle, streaming, counter.frame_bytes


def _report_wire(result: BoardResult) -> float | None:
    """A report frame's wire time in seconds (the median frame's), None if none came."""
    if not result.stream_report_bytes:
        return None
    return statistics.median(result.stream_report_bytes) * board_byte_us(result.backend) / 1e6


def _preempt_text(result: BoardResult, idle: float, busy: float) -> str:
    """What streaming adds to a Ping's round trip, against the report frame it waits behind.

    The device builds a report only when its send ring has room to spare and no command is
    arriving (control preempts data), but an Ack still goes after the report bytes already
    in the ring: a COBS frame cannot be cut. An Ack that finds the line busy waits for the
    rest of such a frame, so the extra wait is an absolute time set by the report's size,
    not a share of the idle round trip.
    """
    frame = _report_wire(result)
    if frame is None or busy <= idle:
        return ""
    size = statistics.median(result.stream_report_bytes)
    return (
        f" Streaming adds {_ms(busy - idle)} ms to the round trip; a report frame of the six "
        f"channels is {size:.0f} B, {_ms(frame)} ms on the wire. The device builds a report "
        "only while no command is arriving and its send ring has room to spare, but an Ack "
        "goes after the report bytes already in the ring (a frame cannot be cut): the added "
        "wait is set by that frame's wire time, not by the idle round trip, so the ratio "
        "grows as the idle round trip shrinks."
    )


def _pwm_line(trace: Trace, duty: int, since: int) -> tuple[int, float] | None:
    """The first trace line (index, board time) from index ``since`` on where the motor pin
    shows ``duty``.

    Lines, not times: the emulated Uno dates a PWM that stopped at the pin's last edge (the
    end of its last pulse), which comes before the bumper's edge when the edge falls between
    two pulses; the pin then never went high again after the edge.
    """
    deadline = time.monotonic() + SETTLE
    while time.monotonic() < deadline:
        events = trace.update()
        for i in range(since, len(events)):
            e = events[i]
            if e["pin"] == MOTOR_PIN and e.get("mode") == "pwm" and int(e["value"]) == duty:
                return i, float(e["t"])
        time.sleep(0.002)
    return None


def measure_reaction(
    board: Board, sim: SimBoard, trace: Trace, trials: int, rng: random.Random
) -> tuple[list[float], int]:
    motor = board.pwm_output(MOTOR_PIN, safe=0)
    sim.set_level(BUMPER_PIN, 1)
    bumper = board.digital_input(BUMPER_PIN, pull_up=True, interlock="low")
    # Only a host that has heard of a trip may clear it (ClearInterlock carries the trip's
    # failsafe epoch): each trip's FAILSAFE event is waited for before the next clear.
    trips = threading.Semaphore(0)

    def on_trip(event: Event) -> None:
        details = event.details
        if (
            event.kind is EventKind.FAILSAFE
            and details["active"]
            and details["cause"] == "interlock"
        ):
            trips.release()

    board.on_event(on_trip)
    samples: list[float] = []
    lost = 0
    for _ in range(trials):
        sim.set_level(BUMPER_PIN, 1)
        bumper.wait_for(True, timeout=SETTLE)
        with contextlib.suppress(InterlockActiveError):  # none latched on the first trial
            board.clear_interlock()
        mark = len(trace.update())
        motor.write(MOTOR_DUTY)
        running = _pwm_line(trace, MOTOR_DUTY, mark)
        if running is None:
            lost += 1
            continue
        time.sleep(rng.uniform(0.0, 0.020))  # edges at every phase of the PWM period
        hit = sim.set_level(BUMPER_PIN, 0)
        stopped = _pwm_line(trace, 0, running[0] + 1)
        if stopped is None:
            lost += 1
            continue
        # Low for good from stopped[1]: at the edge already (0), or this long after it.
        samples.append(max(0.0, stopped[1] - hit))
        trips.acquire(timeout=SETTLE)
    sim.set_level(BUMPER_PIN, 1)
    return samples, lost


def collect(trials: int, seconds: float, pings: int, seed: int = 7) -> list[BoardResult]:
    rng = random.Random(seed)

    def measure(result: BoardResult, sim: SimBoard, trace: Trace, board: Board) -> None:
        (
            result.latency,
            result.latency_lost,
            result.edge_uncertainty,
            result.report_bytes,
        ) = measure_latency(board, sim, trials, rng)
        (
            result.per_channel,
            result.max_gap_ms,
            result.coalesced,
            result.idle_rtt,
            result.stream_rtt,
            result.stream_report_bytes,
        ) = measure_streaming(board, seconds, pings)
        result.reaction, result.reaction_lost = measure_reaction(board, sim, trace, trials, rng)

    return on_each_board("inputs", BoardResult, measure)


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:.2f}"


def run(ctx: Context) -> SectionResult:
    trials = max(10, min(200, ctx.samples // 2))
    pings = max(20, ctx.samples // 5)
    seconds = STREAM_SECONDS if ctx.samples >= 100 else 1.0
    results = collect(trials, seconds, pings, ctx.seed)
    parts = [
        f"**Pin change to callback.** {trials} edges on a digital input (pull-up, no "
        "debounce), each after a random pause of 0-20 ms: from the edge (made "
        "through the control socket) to the host's `on_change` callback (the board's event "
        "thread), against the wire time of the InputReports that carried them (the median "
        "of their framed sizes, which the table gives). The edge's host time is the midpoint "
        "of the control command's round trip (it took effect between sending and answer): "
        "half that round trip bounds its error (median and largest given per board).\n",
        f"**Analog streaming.** Six analog inputs at {ANALOG_HZ} Hz each (`rate_hz="
        f"{ANALOG_HZ}`, a heartbeat of one period so that every sample of the constant "
        f"inputs is reported) for {seconds:g} s while the host sends Pings one after "
        "another; the values received per channel per second (their number less one over "
        "the span of their reports' device times, `InputReport.time_ms`, so that where the "
        "window cuts the 5 ms grid does not count), the reports the device coalesced "
        "(replaced before it could send them), and the Ping round trip against "
        f"{pings} Pings with no input configured. The samples are {1000 / ANALOG_HZ:g} ms "
        "apart and a report's time is when it was built, so consecutive reports of a channel "
        "come 4 to 6 ms apart; a longer gap is a sample that never reached the host (the next "
        "one replaced it before its report could go out).\n",
        f"**Interlock.** {trials} times: a motor's PWM at {MOTOR_DUTY} on pin {MOTOR_PIN}, "
        f'then a bumper on pin {BUMPER_PIN} (`interlock="low"`, pull-up) closes; the time '
        "from its edge until the pin is low for good, both on the board's clock (on the "
        "emulated Uno: emulated time, measured at the pin; 0 when the edge fell between two "
        "pulses and no pulse followed it).\n",
    ]
    targets: list[Target] = []
    for result in results:
        label = LABELS[result.backend]
        if result.error is not None:
            parts.append(f"The {label} was not run: {result.error}.\n")
            continue
        parts.append(f"### {label[0].upper()}{label[1:]}\n")
        size = statistics.median(result.report_bytes) if result.report_bytes else 0
        wire = size * board_byte_us(result.backend) / 1e6
        rows = []
        if result.latency:
            lat = Percentiles.of(result.latency)
            rows.append(
                [
                    f"pin change to callback ({size:g} B report)",
                    _ms(lat.p50),
                    _ms(lat.p99),
                    _ms(wire),
                    f"{lat.p50 / wire:.1f}x" if wire else "-",
                    str(result.latency_lost),
                ]
            )
        if result.reaction:
            rea = Percentiles.of(result.reaction)
            rows.append(
                [
                    "bumper edge to PWM 0 at the pin",
                    _ms(rea.p50),
                    _ms(rea.p99),
                    "-",
                    "-",
                    str(result.reaction_lost),
                ]
            )
        if result.edge_uncertainty:
            parts.append(
                "Each edge's host time known within +-"
                f"{statistics.median(result.edge_uncertainty) * 1000:.2f} ms (median; at "
                f"most +-{max(result.edge_uncertainty) * 1000:.2f} ms).\n"
            )
        parts.append(md_table(["what", "p50 ms", "p99 ms", "wire ms", "p50 / wire", "lost"], rows))
        slowest = min(result.per_channel.values(), default=0.0)
        idle = statistics.median(result.idle_rtt) if result.idle_rtt else 0.0
        busy = statistics.median(result.stream_rtt) if result.stream_rtt else 0.0
        ratio = busy / idle if idle > 0 else 0.0
        frame = _report_wire(result)
        channel_rows = [
            [f"pin {pin}", f"{rate:.1f}", str(result.max_gap_ms.get(pin, 0))]
            for pin, rate in sorted(result.per_channel.items())
        ]
        parts.append(
            md_table(
                ["analog channel", "values/s received", "longest gap between reports, ms"],
                channel_rows,
            )
        )
        parts.append(
            f"Reports coalesced by the device while streaming: {result.coalesced}. Ping round "
            f"trip p50: {_ms(idle)} ms idle, {_ms(busy)} ms while streaming ({ratio:.2f}x, "
            f"{len(result.stream_rtt)} Pings).{_preempt_text(result, idle, busy)}\n"
        )
        if result.backend == "avr":
            targets += [
                Target(
                    "analog values/s per channel, 6 channels, commands flowing (emulated Uno)",
                    f">= {TARGET_HZ:.0f}",
                    f"{slowest:.1f}",
                    slowest >= TARGET_HZ,
                ),
                Target(
                    "Ping round trip while 6 channels stream (emulated Uno)",
                    "adds <= one report frame's wire time to the idle round trip (issue 35)",
                    "no report frame"
                    if frame is None
                    else f"+{_ms(busy - idle)} ms against {_ms(frame)} ms ({ratio:.2f}x idle)",
                    frame is not None and busy > 0 and busy - idle <= frame,
                ),
            ]
            if result.reaction:
                worst = max(result.reaction)
                targets.append(
                    Target(
                        "interlock: bumper edge to motor PWM 0 at the pin (emulated Uno)",
                        f"<= {TARGET_REACTION * 1000:g} ms emulated time",
                        f"{_ms(worst)} ms at most",
                        worst <= TARGET_REACTION,
                    )
                )
    return SectionResult("\n".join(parts), targets=targets)


SECTION = Section(7, "inputs", "Inputs: change to callback, analog streaming, interlocks", run)
