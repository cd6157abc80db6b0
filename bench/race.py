"""Benchmark part 9 (docs/performance.md): the race against StandardFirmata (issue 23).

StandardFirmata 2.4, the Uno hex that the npm package avrgirl-arduino 5.0.1 ships (fetched at
setup by tools/fetch_firmata.sh, pinned by sha256; nothing is fetched here), runs unmodified on
the same emulated Uno runner (tools/avrsim ``--hex``) as protoduino's firmware, one after the
other in one run, and the same questions are asked of both:

* the bytes of a digital write on the wire, and of its answer;
* digital write -> pin, and servo write -> new pulse width at the pin (p50 / p99), the digital
  one also less the command's own line time;
* output changes per second delivered at the pin flat out, and how far behind the host's last
  write the pin's last change comes; poses of six digital outputs at window 4 (protoduino);
* servo write -> its Ack, less the wire time of the command and of the Ack (each call's own
  frames at the line's byte times): the p50 of each of 5 runs on a fresh emulated Uno, at
  115200 and at the agreed rate, and their median and spread;
* host CPU per command, per call kind: ``time.process_time`` around each call, so the host
  library's own threads count (protoduino's I/O thread; pyFirmata2 runs none while writing);
  and for protoduino alone the same per acked command, every call kind, on both boards (the
  simulated native one and the emulated Uno), the median of 5 runs on fresh boards (issue 35);
* analog samples per second per channel, every channel at its fastest;
* flash, static RAM and the deepest stack (the runner's lowest stack pointer in this run).

Pin times are the trace's (emulated seconds since the runner started, measured at the pins)
plus the runner's time zero on CLOCK_MONOTONIC, which its --stats line gives: the host's
``time.monotonic()`` of the change, within the pacing's 50 us while the runner keeps up (its
lag at the end of each board's run is reported). Each line's byte time is the runner's: simavr
sends a byte in 11 bit times at the rate the firmware set, and the runner feeds host bytes in
10 bit times at that rate.

Firmata is driven by pyFirmata2, the bench's Firmata library already (bench/peers/firmata.py).
"""

from __future__ import annotations

import functools
import logging
import random
import statistics
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any, TypeVar

from protoduino import Board, programs
from protoduino.constants import PacketType
from protoduino.errors import ProtoduinoError
from protoduino.messages import ArduinoIn, parse_out
from protoduino.packets import Packet
from protoduino.simboard import SimBoard
from protoduino.transport import FrameRecord
from protoduino_dev import runnerstats

from . import firmware, inputs, roundtrip
from .boards import LABELS as BOARD_LABELS
from .boards import (
    UNO_HZ,
    BoardUnavailableError,
    Percentiles,
    Trace,
    missing_tool,
    started,
    started_hex,
)
from .core import Context, Section, SectionResult, Target, md_table, require
from .motion import us, wait_changes
from .peers import firmata_board
from .wire import frame_bytes

log = logging.getLogger(__name__)

_V = TypeVar("_V")

ROOT = firmata_board.ROOT
FIRMATA_HEX = firmata_board.HEX
FETCH_STEP = firmata_board.FETCH_STEP

DIGITAL_PIN = 13
SERVO_PIN = 9
#: The pose's six digital outputs (13 is the digital write's pin).
POSE_PINS: tuple[int, ...] = (2, 4, 7, 8, 12, 13)
WINDOW = 4
#: Random pause before a timed digital call (s): samples every phase of the boards' 1 ms tick.
DIGITAL_GAP = 0.002
#: ... and before a servo write: every phase of the 20 ms servo frame.
SERVO_GAP = 0.020
#: Analog streaming per board (s), and protoduino's sampling rate per channel (its inputs part).
ANALOG_SECONDS = 2.0
ANALOG_HZ = inputs.ANALOG_HZ
#: Bounds a failing wait for the pins to show a flat-out run's last change (s).
SETTLE = 10.0
#: How far a trace time mapped to the host's clock may be off (the runner's pacing).
MAPPING_ERROR = 0.001

#: Servo round trips (issue 23): this many runs per rate, each on a fresh emulated Uno; the
#: report gives the median and the spread of their p50s, not one run's.
ROUND_TRIP_RUNS = 5
#: The goal: a servo write's round trip p50 at most this far beyond its own wire time (s).
ROUND_TRIP_OVERHEAD = 0.5e-3

#: Host CPU per acked command (issue 35): this many runs on each board, each on a fresh one;
#: the report gives the median and the spread of the runs' figures.
HOST_CPU_RUNS = 5
#: The boards it runs on (bench.boards' backends), and issue 35's goal for it (s).
HOST_CPU_BOARDS = ("native", "avr")
HOST_CPU_GOAL = 60e-6
#: Its call kinds, in the report's order: the blocking ones, then the flat-out ones.
HOST_CPU_KINDS = (
    "digital write",
    "servo write",
    "servo write, no pause",
    "pose (6 outputs)",
    "digital flat out",
)

LABELS = ("protoduino", "StandardFirmata")
#: The rate protoduino's Board agrees on with the Uno firmware (docs/protocol.md 5, *Line rate*).
FAST_BAUD = 1_000_000


@dataclass(frozen=True, slots=True)
class Line:
    """A board's serial line as the runner times it (from simavr's byte time, in cycles)."""

    byte_cycles: int  # a byte the UART sends: 11 bit times in simavr 1.6

    @property
    def baud(self) -> float:
        return UNO_HZ * 11 / self.byte_cycles

    @property
    def board_byte_us(self) -> float:
        return self.byte_cycles / UNO_HZ * 1e6

    @property
    def host_byte_us(self) -> float:
        """A host byte into the UART: 10 bit times at the same rate (tools/avrsim)."""
        return self.byte_cycles * 10 / 11 / UNO_HZ * 1e6

    def wire_seconds(self, to_board: float, from_board: float) -> float:
        """``to_board`` bytes into the board (10 bits each) and ``from_board`` out of it
        (simavr's 11) on this line, in seconds."""
        return (to_board * self.host_byte_us + from_board * self.board_byte_us) / 1e6

    def describe(self, nominal: int) -> str:
        return (
            f"{nominal} ({self.baud:,.0f} from UBRR): {self.host_byte_us:.1f} us a byte "
            f"to the board (10 bits), {self.board_byte_us:.1f} us from it (simavr's 11 bits)"
        )


@dataclass(slots=True)
class Flat:
    """A flat-out run: ``changes`` output changes, from the first call to the last change."""

    changes: int = 0
    seconds: float = 0.0  # first call -> last change at the pins (host clock)
    behind: float = 0.0  # the host's last write to the line -> the last change at the pins
    returned: float = 0.0  # the host's last call returned -> the last change at the pins
    cpu: float = 0.0  # process CPU of the whole run
    calls: int = 0
    acked: float | None = None  # the last Ack arrived -> last change (negative: before it)
    line_share: float | None = None  # host -> board bytes over the line's capacity

    @property
    def rate(self) -> float:
        return self.changes / self.seconds if self.seconds > 0 else 0.0


@dataclass(slots=True)
class BoardRun:
    label: str
    nominal_baud: int
    line: Line | None = None
    command_bytes: list[int] = field(default_factory=list)
    answer_bytes: list[int] = field(default_factory=list)
    digital: list[float] = field(default_factory=list)  # call -> pin (s)
    servo: list[float] = field(default_factory=list)
    cpu: dict[str, list[float]] = field(default_factory=dict)  # per call kind (s)
    lost: int = 0
    flat: Flat | None = None
    poses: Flat | None = None
    analog: dict[int, float] = field(default_factory=dict)
    flash: int = 0
    static_ram: int = 0
    stack: int = 0
    lag: float = 0.0  # wall clock minus the runner's emulated clock at the end (s)
    error: str | None = None


class RunnerClock:
    """The runner's --stats counters, and its time zero: trace time + ``zero`` is host time."""

    def __init__(self, sim: SimBoard, stats: Path) -> None:
        self.sim = sim
        self.stats = stats
        self.row = runnerstats.snapshot(sim.pid, stats)
        self.zero = int(self.row["start_ns"]) / 1e9

    def snapshot(self) -> dict[str, Any]:
        row: dict[str, Any] = runnerstats.snapshot(self.sim.pid, self.stats)
        self.row = row
        return row

    def line(self) -> Line:
        cycles = int(self.snapshot()["uart_byte_cycles"])
        if cycles <= 0:
            raise RuntimeError("the firmware never set up its UART")
        return Line(cycles)

    def lag(self) -> float:
        """How far the emulated clock is behind the host's now (s); ~0 when it keeps up."""
        seen = time.monotonic()
        row = self.snapshot()
        return seen - (self.zero + float(row["t"]))


def _to_pin(
    clock: RunnerClock,
    trace: Trace,
    pin: int,
    want: int,
    call: Callable[[], object],
) -> tuple[float, float] | None:
    """(call -> the pin shows ``want``, process CPU of the call) in seconds; None if lost."""
    events = trace.update()
    after = float(events[-1]["t"]) if events else 0.0
    c0 = time.process_time()
    t0 = time.monotonic()
    call()
    cpu = time.process_time() - c0
    changed = wait_changes(trace, {pin: want}, after)
    if changed is None:
        return None
    return clock.zero + changed[pin] - t0, cpu


def _time_writes(
    run: BoardRun,
    clock: RunnerClock,
    trace: Trace,
    *,
    kind: str,
    pin: int,
    targets: Sequence[tuple[_V, int]],
    write: Callable[[_V], object],
    gap: float,
    rng: random.Random,
) -> list[float]:
    """``write(value)`` for each (value, what ``pin`` then shows) of ``targets``, one at a time
    after a random pause of up to ``gap``: the call -> pin times (s). Each call's CPU goes to
    ``run.cpu[kind]``; a change that never shows counts in ``run.lost``."""
    out: list[float] = []
    for value, want in targets:
        time.sleep(rng.uniform(0.0, gap))
        got = _to_pin(clock, trace, pin, want, functools.partial(write, value))
        if got is None:
            run.lost += 1
            continue
        out.append(got[0])
        run.cpu.setdefault(kind, []).append(got[1])
    return out


def _levels(samples: int) -> list[tuple[bool, int]]:
    """Digital writes toggling a pin that starts low: (level, what the pin shows)."""
    return [(i % 2 == 0, int(i % 2 == 0)) for i in range(samples)]


def _angles(samples: int) -> list[tuple[int, int]]:
    """Servo writes, each to a new angle: (degrees, the pulse width the pin shows, us)."""
    out: list[tuple[int, int]] = []
    degrees = 0
    for i in range(samples):
        degrees = (degrees + 37 + i % 7) % 171 + 5
        out.append((degrees, us(degrees)))
    return out


def _poses(commands: int) -> int:
    """Poses of the flat-out run: a third of the commands, even (see _flat_out)."""
    return max(20, commands // 3) // 2 * 2


def _servo_samples(samples: int) -> int:
    """Servo samples: a quarter of the digital ones (each waits for a 20 ms frame)."""
    return max(5, samples // 4)


def _flat_out(
    clock: RunnerClock,
    trace: Trace,
    line: Line,
    *,
    pins: Sequence[int],
    calls: int,
    issue: Callable[[int], object],
    finish: Callable[[], object],
    acked: bool,
    last_write: Callable[[], float] | None = None,
) -> Flat:
    """``calls`` calls as fast as the host makes them, call i setting every pin of ``pins`` to
    level i % 2 == 0 (they start low, ``calls`` is even: they end low).

    The trace lists every edge of a digital output on both boards (the emulated Uno's runner
    reads which pins the firmware drives as servos or PWM: tools/avrsim/pd_pins.c; a program
    that does not say, such as StandardFirmata, has its fast highs read as pulses, whose
    train ends in a value-0 line dated to its last fall), so the last fall of each pin is
    dated exactly: the time the last call took effect. Changes per second are those of all
    the calls over the time from the first call to that moment. ``finish`` waits for the
    calls' Acks where there are any (``acked``); ``last_write`` says when the host wrote its
    last frame to the line, where a library holds calls back (protoduino's window); otherwise
    that is when the last call returned."""
    if calls % 2:
        raise ValueError("an even number of calls, so that the pins end low")
    mark = len(trace.update())
    rx0 = int(clock.snapshot()["uart_rx_bytes"])
    c0 = time.process_time()
    t0 = time.monotonic()
    for i in range(calls):
        issue(i)
    t_last = time.monotonic()
    finish()
    t_done = time.monotonic()
    cpu = time.process_time() - c0
    deadline = time.monotonic() + SETTLE + calls * 0.002
    while True:
        ends = _last_falls(trace.update()[mark:], pins)
        # A fall the last call made: after its write, and quiet since for longer than a
        # pulse train's period (a later pulse would have been reported by then).
        if (
            len(ends) == len(pins)
            and time.monotonic() > clock.zero + max(ends.values()) + 0.1
            and clock.zero + min(ends.values()) >= t_last - MAPPING_ERROR
        ):
            break
        if time.monotonic() > deadline:
            raise RuntimeError(f"pins {list(pins)} did not show the last of {calls} calls")
        time.sleep(0.01)
    rx = int(clock.snapshot()["uart_rx_bytes"]) - rx0
    end = clock.zero + max(ends.values())
    wrote = last_write() if last_write is not None else t_last
    flat = Flat(calls * len(pins), end - t0, end - wrote, end - t_last, cpu, calls)
    if acked:
        flat.acked = end - t_done
    flat.line_share = rx * line.host_byte_us / 1e6 / max(end - t0, 1e-9)
    return flat


def _last_falls(events: Sequence[dict[str, Any]], pins: Sequence[int]) -> dict[int, float]:
    """Each pin's last trace time, if its last line says 0 (the pin is low since then)."""
    last: dict[int, dict[str, Any]] = {}
    for e in events:
        if int(e["pin"]) in pins:
            last[int(e["pin"])] = e
    return {pin: float(e["t"]) for pin, e in last.items() if int(e["value"]) == 0}


class _Frames:
    """Frame monitor that only keeps what it sees: the I/O thread appends each packet's
    record, and the sizes are worked out afterwards, so that the bench's own bookkeeping
    (a protobuf parse per frame) neither delays an Ack nor counts in the host CPU it
    measures."""

    def __init__(self) -> None:
        self.counting = False
        #: (counting when seen, direction, packet, time) of every packet, in the order shown.
        self.records: list[tuple[bool, str, Packet, float]] = []

    def __call__(self, record: FrameRecord) -> None:  # the I/O thread: quick
        if isinstance(record.item, Packet):
            self.records.append((self.counting, record.direction, record.item, record.t))

    def packets(self) -> list[tuple[bool, str, Packet, float]]:
        """The records so far (a copy: the I/O thread may still append)."""
        return list(self.records)


class WireSizes(_Frames):
    """The wire size of every command of one ``kind`` (the ArduinoIn field: digital writes
    by default) the host sends while counting and of its Ack (not the automatic Ping's
    frames, nor reports); when the last COMMAND other than a Ping was written."""

    def __init__(self, kind: str = "digital_control") -> None:
        super().__init__()
        self.kind = kind

    @property
    def last_command(self) -> float:
        """time.monotonic() of the last COMMAND written that is not the automatic Ping: a
        Ping sent while the pins settled made the pose run's pins look 70 ms ahead of it."""
        last = 0.0
        for _counting, direction, item, t in self.packets():
            if (
                direction == "tx"
                and item.type is PacketType.COMMAND
                and ArduinoIn.FromString(item.payload).WhichOneof("data") != "ping"
            ):
                last = t
        return last

    def sizes(self) -> tuple[list[int], list[int]]:
        """(the commands' frame bytes, their Acks' frame bytes), in the order seen."""
        commands: list[int] = []
        answers: list[int] = []
        awaiting: set[int] = set()  # message ids of those commands not yet answered
        for counting, direction, item, _t in self.packets():
            if not counting:
                continue
            if direction == "tx" and item.type is PacketType.COMMAND:
                msg = ArduinoIn.FromString(item.payload)
                if msg.WhichOneof("data") == self.kind:
                    commands.append(frame_bytes(item))
                    awaiting.add(msg.message_id)
            elif direction == "rx" and item.type is PacketType.DATA:
                out = parse_out(item.payload)
                if out.WhichOneof("data") == "ack" and out.ack.message_id in awaiting:
                    awaiting.discard(out.ack.message_id)
                    answers.append(frame_bytes(item))
        return commands, answers


class _CallFrames(_Frames):
    """Each COMMAND's wire size, in the order sent (a retransmission is not a new command),
    and the wire size of the first Ack of each. Message ids come round again after 127
    (protocol version 5), so an Ack goes to the latest command of its id."""

    def sizes(self, skip: int) -> list[tuple[int, int]]:
        """(command bytes, Ack bytes) of each command after the first ``skip``."""
        commands: list[tuple[int, int]] = []  # (message id, bytes)
        acks: dict[int, int] = {}  # position in commands -> the Ack's bytes
        latest: dict[int, int] = {}  # message id -> its latest command's position
        for _counting, direction, item, _t in self.packets():
            if direction == "tx" and item.type is PacketType.COMMAND:
                message_id = ArduinoIn.FromString(item.payload).message_id
                known = latest.get(message_id)
                if known is not None and known not in acks:
                    continue  # sent again, not answered yet: the same command
                latest[message_id] = len(commands)
                commands.append((message_id, frame_bytes(item)))
            elif direction == "rx" and item.type is PacketType.DATA:
                out = parse_out(item.payload)
                if out.WhichOneof("data") == "ack":
                    position = latest.get(out.ack.message_id)
                    if position is not None:
                        acks.setdefault(position, frame_bytes(item))
        sent = list(enumerate(commands))[skip:]
        missing = [mid for position, (mid, _size) in sent if position not in acks]
        if missing:
            raise RuntimeError(f"no Ack seen for message ids {missing[:5]}")
        return [(size, acks[position]) for position, (_mid, size) in sent]


@dataclass(slots=True)
class RoundTripRun:
    """One run of servo writes on a fresh emulated Uno, each awaiting its Ack."""

    baud: int  # nominal: the rate pinned or agreed
    line: Line | None = None
    #: Per call: the round trip less the wire time of its command and its Ack (s).
    overheads: list[float] = field(default_factory=list)
    #: Per call: (command bytes, Ack bytes) as the frame monitor saw them.
    sizes: list[tuple[int, int]] = field(default_factory=list)
    error: str | None = None

    @property
    def p50(self) -> float:
        return Percentiles.of(self.overheads).p50


def beyond_wire(
    round_trips: Sequence[float], sizes: Sequence[tuple[int, int]], line: Line
) -> list[float]:
    """Each round trip less the time its command's bytes (to the board) and its Ack's (from
    it) take on ``line``, in seconds."""
    pairs = zip(round_trips, sizes, strict=True)  # ValueError: a call without its frames
    return [t - line.wire_seconds(cmd, ack) for t, (cmd, ack) in pairs]


def servo_round_trips(samples: int, seed: int, baudrate: int | None) -> RoundTripRun:
    """``samples`` servo writes (after roundtrip.WARMUP untimed ones), each awaiting its Ack
    after a random pause (bench/roundtrip.py's, part 2), on a fresh emulated Uno at
    ``baudrate`` (pinned), or (None) at the rate its Board agrees on; no automatic Ping."""
    run = RoundTripRun(baudrate or 0)
    rng = random.Random(seed)
    with TemporaryDirectory(prefix="bench-race-") as tmp:
        stats = Path(tmp) / "stats.jsonl"
        with (
            started("avr", stats=stats) as sim,
            Board.open(sim.port, ping=False, baudrate=baudrate) as board,
        ):
            run.baud = board.baudrate
            servo = board.servo(SERVO_PIN)
            run.line = line = RunnerClock(sim, stats).line()
            frames = _CallFrames()
            board.add_frame_monitor(frames)  # after the ServoInit: servo writes only
            times = roundtrip.timed(roundtrip.library_ops(board, servo)["servo"], samples, rng)
    run.sizes = frames.sizes(roundtrip.WARMUP)
    run.overheads = beyond_wire(times, run.sizes, line)
    return run


def collect_round_trips(
    samples: int, seed: int, runs: int = ROUND_TRIP_RUNS
) -> dict[int, list[RoundTripRun]]:
    """``runs`` runs of :func:`servo_round_trips` at 115200 and at the agreed rate, by nominal
    rate; a run that cannot run carries its ``error``."""
    out: dict[int, list[RoundTripRun]] = {}
    for nominal, baudrate in ((115_200, 115_200), (FAST_BAUD, None)):
        for i in range(runs):
            try:
                one = servo_round_trips(samples, seed + i, baudrate)
            except (
                ProtoduinoError,
                BoardUnavailableError,
                RuntimeError,
                ValueError,
                OSError,
            ) as error:
                log.warning("race: servo round trips at %s not run: %s", nominal, error)
                one = RoundTripRun(nominal, error=str(error).splitlines()[0])
            out.setdefault(nominal, []).append(one)
    return out


@dataclass(slots=True)
class HostCpuRun:
    """One run of :func:`host_cpu_run` on a fresh board: host CPU per acked command (s)."""

    backend: str
    baud: int = 0  # the rate its Board agreed on
    #: Per call kind (HOST_CPU_KINDS): the median over the blocking calls, or the whole
    #: flat-out run's CPU over its calls.
    cpu: dict[str, float] = field(default_factory=dict)
    error: str | None = None


def _cpu_per_call(
    calls: int, call: Callable[[int], object], gap: float, rng: random.Random
) -> float:
    """Median process CPU of ``call(i)`` for i < ``calls``, each after a random pause of up to
    ``gap`` (every phase of the board's tick or servo frame, as the race's timed writes)."""
    cpus: list[float] = []
    for i in range(calls):
        time.sleep(rng.uniform(0.0, gap))
        c0 = time.process_time()
        call(i)
        cpus.append(time.process_time() - c0)
    return statistics.median(cpus)


def _cpu_flat_out(calls: int, issue: Callable[[int], Future[None]]) -> float:
    """Process CPU per call of ``calls`` submits as fast as the host makes them, up to the
    last Ack (the race's flat-out runs measure their CPU so)."""
    c0 = time.process_time()
    futures = [issue(i) for i in range(calls)]
    for future in wait(futures).done:
        future.result()
    return (time.process_time() - c0) / calls


def host_cpu_run(backend: str, samples: int, commands: int, seed: int) -> HostCpuRun:
    """Host CPU per acked command of every call kind on a fresh ``backend`` board at the rate
    its Board agrees on, window WINDOW, the automatic Ping on: ``samples`` digital writes and
    a quarter as many servo writes, one at a time after the race's random pauses, the servo
    writes again back to back, then ``commands`` digital writes and a third as many poses of
    six outputs flat out."""
    run = HostCpuRun(backend)
    rng = random.Random(seed)
    with started(backend) as sim, Board.open(sim.port, window=WINDOW, baudrate=None) as board:
        run.baud = board.baudrate
        led = board.digital_output(DIGITAL_PIN)
        servo = board.servo(SERVO_PIN)
        outs = [led, *(board.digital_output(p) for p in POSE_PINS if p != DIGITAL_PIN)]
        angles = _angles(_servo_samples(samples))
        run.cpu["digital write"] = _cpu_per_call(
            samples, lambda i: led.write(i % 2 == 0), DIGITAL_GAP, rng
        )
        run.cpu["servo write"] = _cpu_per_call(
            len(angles), lambda i: servo.write(angles[i][0]), SERVO_GAP, rng
        )
        # The same calls back to back: what a pause before each call adds to its CPU.
        run.cpu["servo write, no pause"] = _cpu_per_call(
            len(angles), lambda i: servo.write(angles[i][0]), 0.0, rng
        )
        run.cpu["pose (6 outputs)"] = _cpu_flat_out(
            _poses(commands), lambda i: board.submit_pose(dict.fromkeys(outs, i % 2 == 0))
        )
        run.cpu["digital flat out"] = _cpu_flat_out(
            commands // 2 * 2, lambda i: led.submit(i % 2 == 0)
        )
    return run


def collect_host_cpu(
    samples: int, commands: int, seed: int, runs: int = HOST_CPU_RUNS
) -> dict[str, list[HostCpuRun]]:
    """``runs`` runs of :func:`host_cpu_run` on each board of HOST_CPU_BOARDS, by backend; a
    run that cannot run carries its ``error``."""
    out: dict[str, list[HostCpuRun]] = {}
    for backend in HOST_CPU_BOARDS:
        for i in range(runs):
            try:
                one = host_cpu_run(backend, samples, commands, seed + i)
            except (ProtoduinoError, BoardUnavailableError, RuntimeError, OSError) as error:
                log.warning("race: host CPU on %s not run: %s", backend, error)
                one = HostCpuRun(backend, error=str(error).splitlines()[0])
            out.setdefault(backend, []).append(one)
    return out


def _cpu_medians(runs: Sequence[HostCpuRun]) -> dict[str, list[float]]:
    """Per call kind, each complete run's figure (s), in run order."""
    done = [r for r in runs if r.error is None]
    return {kind: [r.cpu[kind] for r in done if kind in r.cpu] for kind in HOST_CPU_KINDS}


def _host_cpu_table(cpu: dict[str, list[HostCpuRun]]) -> str:
    """Per call kind, per board: the median of the runs' figures and their spread (us)."""
    header = ["call kind"]
    columns: list[dict[str, list[float]]] = []
    for backend, runs in cpu.items():
        done = [r for r in runs if r.error is None]
        baud = f", {done[0].baud:,} baud" if done else ""
        count = f"{len(runs)} run{'s' if len(runs) > 1 else ''}"
        if len(done) < len(runs):
            count = f"{len(done)} of {count}"
        header.append(f"{BOARD_LABELS.get(backend, backend).split(' (')[0]} ({count}{baud})")
        columns.append(_cpu_medians(runs))
    rows: list[list[str]] = []
    for kind in HOST_CPU_KINDS:
        row = [kind]
        for col in columns:
            values = col[kind]
            row.append(
                f"**{statistics.median(values) * 1e6:,.0f}** "
                f"({min(values) * 1e6:,.0f}-{max(values) * 1e6:,.0f})"
                if values
                else "not run"
            )
        rows.append(row)
    return md_table(header, rows, "l" + "r" * len(columns))


def _host_cpu_target(cpu: dict[str, list[HostCpuRun]]) -> Target:
    """Issue 35's host CPU goal: every call kind's median of the runs, on every board; not
    judged while a run is missing."""
    measured: list[str] = []
    met: bool | None = True
    for backend, runs in cpu.items():
        medians = [statistics.median(v) for v in _cpu_medians(runs).values() if v]
        missing = sum(r.error is not None for r in runs)
        if missing or len(medians) < len(HOST_CPU_KINDS):
            met = None
            measured.append(f"{len(runs) - missing} of {len(runs)} runs on {backend}")
        if medians:
            if met is not None:
                met = met and max(medians) <= HOST_CPU_GOAL
            measured.append(f"{min(medians) * 1e6:,.0f}-{max(medians) * 1e6:,.0f} us on {backend}")
    return Target(
        "host CPU per acked command",
        f"<= {HOST_CPU_GOAL * 1e6:g} us, every call kind, both boards, median of "
        f"{HOST_CPU_RUNS} runs",
        "; ".join(measured) or "not run",
        met if measured else None,
        "the range over the call kinds of each kind's median of the runs",
    )


def run_protoduino(
    samples: int, commands: int, seed: int, analog_seconds: float, baudrate: int | None = 115_200
) -> BoardRun:
    """protoduino at ``baudrate`` (pinned), or (None) at the rate its Board agrees on."""
    run = BoardRun(LABELS[0], baudrate or 0)
    rng = random.Random(seed)
    with TemporaryDirectory(prefix="bench-race-") as tmp:
        stats, trace_path = Path(tmp) / "stats.jsonl", Path(tmp) / "trace.jsonl"
        with (
            started("avr", stats=stats, trace=trace_path) as sim,
            Board.open(sim.port, window=WINDOW, baudrate=baudrate) as board,
        ):
            run.nominal_baud = board.baudrate  # the agreed rate (docs/protocol.md 5)
            clock = RunnerClock(sim, stats)
            trace = Trace(trace_path)
            led = board.digital_output(DIGITAL_PIN)
            servo = board.servo(SERVO_PIN)
            run.line = line = clock.line()
            sizes = WireSizes()
            board.add_frame_monitor(sizes)
            sizes.counting = True
            run.digital = _time_writes(
                run,
                clock,
                trace,
                kind="digital write",
                pin=DIGITAL_PIN,
                targets=_levels(samples),
                write=led.write,
                gap=DIGITAL_GAP,
                rng=rng,
            )
            sizes.counting = False
            run.command_bytes, run.answer_bytes = sizes.sizes()
            run.servo = _time_writes(
                run,
                clock,
                trace,
                kind="servo write",
                pin=SERVO_PIN,
                targets=_angles(_servo_samples(samples)),
                write=servo.write,
                gap=SERVO_GAP,
                rng=rng,
            )

            futures: list[Future[None]] = []
            led.write(False)
            run.flat = _flat_out(
                clock,
                trace,
                line,
                pins=(DIGITAL_PIN,),
                calls=commands // 2 * 2,
                issue=lambda i: futures.append(led.submit(i % 2 == 0)),
                finish=lambda: [f.result() for f in wait(futures).done],
                acked=True,
                last_write=lambda: sizes.last_command,
            )
            outs = [led, *(board.digital_output(p) for p in POSE_PINS if p != DIGITAL_PIN)]
            board.pose(dict.fromkeys(outs, False))
            pose_futures: list[Future[None]] = []
            poses = _poses(commands)
            run.poses = _flat_out(
                clock,
                trace,
                line,
                pins=POSE_PINS,
                calls=poses,
                issue=lambda i: pose_futures.append(
                    board.submit_pose(dict.fromkeys(outs, i % 2 == 0))
                ),
                finish=lambda: [f.result() for f in wait(pose_futures).done],
                acked=True,
                last_write=lambda: sizes.last_command,
            )
            run.cpu["pose (6 outputs)"] = [run.poses.cpu / run.poses.calls]
            rates, _gaps, _coalesced, _idle, _busy, _sizes = inputs.measure_streaming(
                board, analog_seconds, 5
            )
            run.analog = rates
            row = clock.snapshot()
            run.stack = int(row["ramend"]) - int(row["sp_min"])
            run.lag = clock.lag()
    size = firmware.footprint(programs.locate(programs.FIRMWARE_ELF))
    run.flash, run.static_ram = size.flash, size.ram
    return run


def run_firmata(samples: int, commands: int, seed: int, analog_seconds: float) -> BoardRun:
    run = BoardRun(LABELS[1], firmata_board.BAUD)
    rng = random.Random(seed)
    with TemporaryDirectory(prefix="bench-race-") as tmp:
        stats, trace_path = Path(tmp) / "stats.jsonl", Path(tmp) / "trace.jsonl"
        with (
            started_hex(FIRMATA_HEX, stats=stats, trace=trace_path) as sim,
            firmata_board.opened(sim.port) as firmata,
        ):
            clock = RunnerClock(sim, stats)
            trace = Trace(trace_path)
            led = firmata.digital_output(DIGITAL_PIN)
            servo = firmata.servo(SERVO_PIN, 0)
            # No Ack says the set-up arrived: the servo's first pulses at 0 degrees do, and
            # that its bytes are not counted as the digital writes' below.
            if wait_changes(trace, {SERVO_PIN: us(0)}, 0.0) is None:
                raise RuntimeError("StandardFirmata's servo never started")
            run.line = line = clock.line()
            rx0 = int(clock.snapshot()["uart_rx_bytes"])
            run.digital = _time_writes(
                run,
                clock,
                trace,
                kind="digital write",
                pin=DIGITAL_PIN,
                targets=_levels(samples),
                write=led.write,
                gap=DIGITAL_GAP,
                rng=rng,
            )
            rx = int(clock.snapshot()["uart_rx_bytes"]) - rx0
            # No answer to tell one command's bytes from another's: the mean, all alike here.
            run.command_bytes = [round(rx / samples)]
            run.servo = _time_writes(
                run,
                clock,
                trace,
                kind="servo write",
                pin=SERVO_PIN,
                targets=_angles(_servo_samples(samples)),
                write=servo.write,
                gap=SERVO_GAP,
                rng=rng,
            )

            led.write(False)
            run.flat = _flat_out(
                clock,
                trace,
                line,
                pins=(DIGITAL_PIN,),
                calls=commands // 2 * 2,
                issue=lambda i: led.write(i % 2 == 0),
                finish=list,  # nothing to wait for: Firmata answers nothing
                acked=False,
            )
            run.analog = firmata.stream_analog(
                6, analog_seconds, lambda: float(clock.snapshot()["t"])
            )
            row = clock.snapshot()
            run.stack = int(row["ramend"]) - int(row["sp_min"])
            run.lag = clock.lag()
    size = firmata_board.hex_footprint(FIRMATA_HEX)
    run.flash, run.static_ram = size.flash, size.static_ram
    return run


def collect(
    samples: int, commands: int, seed: int, analog_seconds: float = ANALOG_SECONDS
) -> list[BoardRun]:
    """protoduino at 115200, protoduino at the rate its Board agrees on (the fastest both
    ends offer: 1,000,000 on the Uno), then Firmata; one that cannot run carries its
    ``error``."""
    out: list[BoardRun] = []
    runs: tuple[tuple[str, Callable[[int, int, int, float], BoardRun], int], ...] = (
        (LABELS[0], run_protoduino, 115_200),
        (
            LABELS[0],
            lambda n, c, seed, secs: run_protoduino(n, c, seed, secs, baudrate=None),
            FAST_BAUD,
        ),
        (LABELS[1], run_firmata, firmata_board.BAUD),
    )
    for label, measure, nominal in runs:
        try:
            out.append(measure(samples, commands, seed, analog_seconds))
        except (ProtoduinoError, BoardUnavailableError, RuntimeError, OSError) as error:
            log.warning("race: %s not run: %s", label, error)
            out.append(BoardRun(label, nominal, error=str(error).splitlines()[0]))
    return out


# -- the report ------------------------------------------------------------------------------


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:.2f}"


def _pcts(values: list[float]) -> str:
    if not values:
        return "-"
    p = Percentiles.of(values)
    return f"{_ms(p.p50)} / {_ms(p.p99)} ms"


def _range(values: list[int]) -> str:
    if not values:
        return "-"
    lo, hi = min(values), max(values)
    return f"{lo} B" if lo == hi else f"{lo}-{hi} B"


def _behind(flat: Flat) -> str:
    text = f"the last change {_ms(flat.behind)} ms after the host's last write to the line"
    if flat.acked is not None:
        when = "before" if flat.acked < 0 else "after"
        text += (
            f" ({_ms(flat.returned)} ms after its last call returned, the rest queued in the "
            f"host; {_ms(abs(flat.acked))} ms {when} the last Ack)"
        )
    return text


def _command_line_time(run: BoardRun, line: Line) -> tuple[float, str]:
    """The digital write's own line time (s): its median frame into the board, and the
    words saying so."""
    cmd = statistics.median(run.command_bytes)
    own = cmd * line.host_byte_us / 1e6
    return own, (
        f"line time of the command: {own * 1e6:,.0f} us ({cmd:g} B x {line.host_byte_us:.1f} us)"
    )


def _done(runs: Sequence[RoundTripRun]) -> list[RoundTripRun]:
    return [r for r in runs if r.error is None and r.overheads and r.line is not None]


def _round_trip_table(trips: dict[int, list[RoundTripRun]]) -> str:
    """Per rate: the wire time subtracted, each run's p50 beyond it, their median and spread."""
    rows: list[list[str]] = []
    for nominal, runs in trips.items():
        done = _done(runs)
        if not done:
            why = next((r.error for r in runs if r.error), "no samples")
            rows.append([f"{nominal:,}", f"not run: {why}", "-", "-", "-"])
            continue
        line = done[0].line
        assert line is not None  # _done
        sizes = [pair for r in done for pair in r.sizes]
        cmd = statistics.median(c for c, _a in sizes)
        ack = statistics.median(a for _c, a in sizes)
        wire = line.wire_seconds(cmd, ack)
        p50s = [r.p50 for r in done]
        runs_text = ", ".join(_ms(p) for p in p50s)
        if len(done) < len(runs):
            runs_text += f" ({len(done)} of {len(runs)} runs)"
        rows.append(
            [
                f"{done[0].baud:,}",
                f"{wire * 1e6:,.0f} us: command {cmd:g} B x {line.host_byte_us:.1f} us + Ack "
                f"{ack:g} B x {line.board_byte_us:.1f} us",
                runs_text,
                f"**{_ms(statistics.median(p50s))}**",
                f"{_ms(min(p50s))}-{_ms(max(p50s))}",
            ]
        )
    return md_table(
        [
            "baud",
            "wire time subtracted (median call)",
            "p50 of each run, ms",
            "median, ms",
            "spread (min-max), ms",
        ],
        rows,
        "lllrr",
    )


def _round_trip_target(trips: dict[int, list[RoundTripRun]]) -> Target:
    """Issue 23's servo round trip goal, judged at every rate measured, over all its runs."""
    measured: list[str] = []
    met: bool | None = True
    for nominal, runs in trips.items():
        done = _done(runs)
        if len(done) < len(runs):
            met = None  # a rate with a run missing is not judged
            measured.append(f"{len(done)} of {len(runs)} runs at {nominal:,}")
            if not done:
                continue
        p50s = [r.p50 for r in done]
        median = statistics.median(p50s)
        if met is not None:
            met = met and median <= ROUND_TRIP_OVERHEAD
        measured.append(f"{_ms(median)} ms ({_ms(min(p50s))}-{_ms(max(p50s))}) at {done[0].baud:,}")
    return Target(
        "servo round trip p50 minus its wire time, emulated Uno",
        f"<= {ROUND_TRIP_OVERHEAD * 1e3:g} ms, median of {ROUND_TRIP_RUNS} runs, every rate",
        "; ".join(measured) or "not run",
        met if measured else None,
        "median (min-max) of the runs' p50s",
    )


def _cells(run: BoardRun) -> dict[str, str]:
    """Each row's cell for one board."""
    if run.error is not None or run.line is None:
        why = run.error or "no line"
        return dict.fromkeys(ROWS, f"not run: {why}")
    line = run.line
    answer = f"; its Ack {_range(run.answer_bytes)}" if run.answer_bytes else "; no answer (no ack)"
    less = "-"
    if run.digital and run.command_bytes:
        own, said = _command_line_time(run, line)
        less = f"{(statistics.median(run.digital) - own) * 1e6:,.0f} us ({said})"
    flat = run.flat
    flat_cell = f"{flat.rate:,.0f}/s; {_behind(flat)}" if flat else "-"
    poses = run.poses
    pose_cell = (
        f"{poses.rate:,.0f} changes/s, {(poses.line_share or 0) * 100:.0f} % of the line; "
        f"{_behind(poses)}"
        if poses
        else "- (no multi-output command)"
    )
    cpu = [f"{kind} {statistics.median(v) * 1e6:,.0f} us" for kind, v in run.cpu.items() if v]
    if flat is not None and flat.calls:
        cpu.append(f"digital flat out {flat.cpu / flat.calls * 1e6:,.0f} us")
    analog = (
        f"{statistics.median(run.analog.values()):,.1f} (min {min(run.analog.values()):,.1f}, "
        f"{len(run.analog)} channels)"
        if run.analog
        else "-"
    )
    return {
        "line": line.describe(run.nominal_baud),
        "digital write on the wire": f"{_range(run.command_bytes)}{answer}",
        "digital write -> pin p50 / p99": _pcts(run.digital),
        "the same minus the command's own line time, p50": less,
        "servo write -> new width at the pin p50 / p99": _pcts(run.servo),
        "output changes/s delivered, flat out (digital writes)": flat_cell,
        "six outputs per command (pose) at window 4": pose_cell,
        "host CPU per command (median)": "; ".join(cpu) or "-",
        "analog samples/s per channel (median)": analog,
        "flash / static RAM / deepest stack in this run": (
            f"{run.flash:,} / {run.static_ram:,} / {run.stack:,} B"
        ),
        "runner behind the wall clock at the end": f"{run.lag * 1e6:,.0f} us",
    }


ROWS: tuple[str, ...] = (
    "line",
    "digital write on the wire",
    "digital write -> pin p50 / p99",
    "the same minus the command's own line time, p50",
    "servo write -> new width at the pin p50 / p99",
    "output changes/s delivered, flat out (digital writes)",
    "six outputs per command (pose) at window 4",
    "host CPU per command (median)",
    "analog samples/s per channel (median)",
    "flash / static RAM / deepest stack in this run",
    "runner behind the wall clock at the end",
)


def _targets(ours: BoardRun, theirs: BoardRun, fast: BoardRun | None = None) -> list[Target]:
    """Issue 23's goals that this run can judge."""
    out: list[Target] = []
    if fast is not None and fast.digital and theirs.digital:
        p50, firmata = statistics.median(fast.digital), statistics.median(theirs.digital)
        out.append(
            Target(
                "digital write -> pin p50 at the agreed rate",
                "< Firmata's p50",
                f"{_ms(p50)} ms at {fast.nominal_baud:,} against {_ms(firmata)} ms",
                p50 < firmata,
            )
        )
    if ours.digital and ours.line is not None and ours.command_bytes:
        own, said = _command_line_time(ours, ours.line)
        p50 = statistics.median(ours.digital)
        out.append(
            Target(
                "digital write -> pin at 115200, p50",
                "<= its own line time + 0.15 ms",
                f"{_ms(p50)} ms ({said})",
                p50 <= own + 0.15e-3,
            )
        )
    if ours.poses is not None and theirs.flat is not None:
        met = ours.poses.rate > theirs.flat.rate and ours.poses.behind <= 0.010
        out.append(
            Target(
                "pose changes/s at window 4",
                "> Firmata's flat-out rate, last change <= 10 ms behind",
                f"{ours.poses.rate:,.0f}/s ({_ms(ours.poses.behind)} ms behind) against "
                f"{theirs.flat.rate:,.0f}/s",
                met,
                "Firmata's rate is at its own 57600 baud, not at the same baud",
            )
        )
    return out


def _quote(ours: BoardRun, theirs: BoardRun, fast: BoardRun | None = None) -> str:
    """The race in one sentence, as README.md quotes it (bench.report.quote)."""
    cpu_ours = statistics.median(ours.cpu["digital write"])
    cpu_theirs = statistics.median(theirs.cpu["digital write"])
    at_fast = (
        f" and {_ms(statistics.median(fast.digital))} ms at the agreed {fast.nominal_baud:,}"
        if fast is not None and fast.error is None and fast.digital
        else ""
    )
    text = (
        f"digital write -> pin p50 {_ms(statistics.median(ours.digital))} ms at 115200{at_fast} "
        f"({_range(ours.command_bytes)}: an acknowledged, CRC-checked frame) against "
        f"StandardFirmata's {_ms(statistics.median(theirs.digital))} ms at 57600 "
        f"({_range(theirs.command_bytes)}, no ack, no check); host CPU per digital write "
        f"{cpu_ours * 1e6:,.0f} us against {cpu_theirs * 1e6:,.0f} us"
    )
    if ours.flat is not None and theirs.flat is not None:
        text += (
            f"; flat out {ours.flat.rate:,.0f} acknowledged changes/s against "
            f"{theirs.flat.rate:,.0f}/s whose pins end {_ms(theirs.flat.behind)} ms behind the "
            "host (no flow control)"
        )
        if ours.poses is not None:
            text += (
                f", and {ours.poses.rate:,.0f} acknowledged changes/s with poses of six outputs "
                f"at 115200, the last {_ms(ours.poses.behind)} ms behind"
            )
    return text


def run(ctx: Context) -> SectionResult:
    if not FIRMATA_HEX.exists():
        return SectionResult(
            f"Not run: StandardFirmata's hex is missing ({FIRMATA_HEX.relative_to(ROOT)}); "
            f"{FETCH_STEP} fetches it.\n"
        )
    tool = missing_tool("avr")
    if tool is not None:
        return SectionResult(f"Not run: `{tool}` is not installed.\n")
    require("pyfirmata2.pyfirmata2", "pyFirmata2")  # MissingDependencyError: "not run"
    samples = max(10, ctx.samples)
    runs = collect(samples, ctx.commands, ctx.seed)
    ours, fast, theirs = runs
    trips = collect_round_trips(samples, ctx.seed)
    cpu = collect_host_cpu(samples, ctx.commands, ctx.seed)
    cells = [_cells(r) for r in runs]
    table = md_table(
        [
            "",
            f"{ours.label} (115200)",
            f"{fast.label} (agreed: {fast.nominal_baud or FAST_BAUD})",
            f"{theirs.label} 2.4 (57600)",
        ],
        [[row, cells[0][row], cells[1][row], cells[2][row]] for row in ROWS],
        "llll",
    )
    text = (
        "StandardFirmata 2.4 (the Uno hex of the npm package avrgirl-arduino 5.0.1, fetched "
        f"at setup by {FETCH_STEP}, pinned by sha256) and protoduino's firmware, one after the "
        "other on the same emulated Uno runner (tools/avrsim), each at its own baud "
        "(protoduino twice: pinned at its opening 115200, and at the rate its Board and the "
        "firmware agree on after the handshake); "
        "StandardFirmata through pyFirmata2, protoduino through its Board at window "
        f"{WINDOW}. {samples} digital writes (pin {DIGITAL_PIN} toggled) and "
        f"{_servo_samples(samples)} servo writes (pin {SERVO_PIN}) one at a time, each after a "
        "random pause; pin times from the emulated trace, mapped to host time through the "
        "runner's own time zero (within 50 us while the runner keeps up; its lag at the end is "
        "the last row). A servo shows a new width at its next 20 ms frame. Flat out: "
        f"{ctx.commands} digital writes as fast as the host issues them (protoduino: "
        f"`submit`, {WINDOW} in flight; Firmata has no acknowledgement and no flow control, so "
        f"the pty and the runner queue what the line cannot carry yet); poses: "
        f"{_poses(ctx.commands)} `submit_pose` of {len(POSE_PINS)} digital outputs, "
        "their share of the line counting the bytes that entered the board's UART. Host "
        "CPU: `time.process_time` around each call (all of the host library's threads). "
        f"Analog: every analog input streamed for {ANALOG_SECONDS:.0f} s (protoduino at "
        f"{ANALOG_HZ} Hz with a heartbeat of one period, Firmata at its 10 ms floor), counted "
        "per second of the board's own clock (protoduino's reports carry it; Firmata's "
        "between two readings of the runner's emulated time). "
        "Firmata's flash is the hex's bytes and its static RAM the end of .bss that its "
        "start-up code clears; the deepest stack is the runner's lowest stack pointer in this "
        "run for both.\n\n" + table
    )
    text += (
        "\nThe targets are issue 23's for protoduino; this part only measures. protoduino's "
        "frames are protocol version 6's (a one-byte message id per session, the short Ack; "
        "a pose's digital outputs in two bit masks, 14 to 17 B for the six, where six items "
        "took 47 to 59 B in version 5); a digital write's bytes on the wire count only its own "
        "frames and its Ack's (13 B at level 0, 15 B at level 1), not the automatic Ping's. "
        "The faster line agreed after the "
        "handshake is the third column. Firmata's figures are bought with no acknowledgement, "
        "no check and no flow control: flat out, its pins fall as far behind the host as the "
        "operating system will buffer.\n"
    )
    text += (
        "\n### Servo round trip beyond its wire time\n\n"
        f"{ROUND_TRIP_RUNS} runs at each rate, each on a fresh emulated Uno (protoduino's "
        f"firmware, its Board pinned at 115200 or at the rate it agrees on): {samples} "
        f"`Servo.write` calls after {roundtrip.WARMUP} untimed ones, one at a time, each "
        "awaiting its Ack after a random pause of up to "
        f"{roundtrip.MAX_GAP * 1e3:g} ms (part 2's timing, `time.perf_counter` from the call to "
        "its return; no automatic Ping). Each call's wire time is the size of its own command "
        "and Ack frames as the Board's frame monitor saw them, the command at the line's "
        "10 bits a byte into the board and the Ack at simavr's 11 bits a byte out of it; a "
        "run's figure is the p50 of (round trip - wire time), and the table gives the median "
        f"and the spread of the {ROUND_TRIP_RUNS} runs' p50s. An absolute overhead, not a "
        "ratio to the wire time (issue 23): shorter frames do not make it look worse.\n\n"
        + _round_trip_table(trips)
    )
    text += (
        "\n### Host CPU per acked command\n\n"
        f"protoduino alone, {HOST_CPU_RUNS} runs on each board, each on a fresh one (the "
        "simulated native board and the emulated Uno), its Board at the rate it agrees on, "
        f"window {WINDOW}, the automatic Ping on: {samples} `DigitalOutput.write` and "
        f"{_servo_samples(samples)} `Servo.write` calls one at a time after the race's random "
        f"pauses (up to {DIGITAL_GAP * 1e3:g} and {SERVO_GAP * 1e3:g} ms), a run's figure the "
        "median of `time.process_time` around each call, and the same servo writes again "
        "back to back (no pause: what a pause before a call adds to its CPU on this "
        "machine); then "
        f"{_poses(ctx.commands)} `submit_pose` of {len(POSE_PINS)} digital outputs and "
        f"{ctx.commands // 2 * 2} `DigitalOutput.submit` flat out, a run's figure the "
        "process CPU from the first call to the last Ack over the calls. Every thread of "
        "the process counts (the I/O thread's reading, Acks and writes). The table gives "
        "the median of the runs' figures in us and their spread (min-max).\n\n"
        + _host_cpu_table(cpu)
    )
    lost = [f"{r.label}: {r.lost}" for r in runs if r.lost]
    if lost:
        text += f"\nWrites whose change never showed at the pin: {', '.join(lost)}.\n"
    quotes: dict[str, str] = {}
    if ours.error is None and theirs.error is None and ours.digital and theirs.digital:
        quotes["race"] = _quote(ours, theirs, fast)
    targets = [*_targets(ours, theirs, fast), _round_trip_target(trips), _host_cpu_target(cpu)]
    return SectionResult(text, targets, packages=["pyFirmata2"], quotes=quotes)


SECTION = Section(9, "race", "The race against StandardFirmata", run)
