"""Benchmark part 3 (docs/performance.md).

Acknowledged commands per second against the line rate, by window size.

The public API only: ``Board.open(port, window=W)`` and ``W`` threads each calling
``Servo.write`` in a loop (any number of threads may command one board; ``window`` is how many
commands may await their Ack at once), so at most ``W`` commands are outstanding. Rates are wall
clock (``time.perf_counter``) from the moment the threads start until the last Ack. The host also
keeps new message ids within the device's 16-id dedupe window (``protoduino.rpc``), so 16 is the
largest window worth trying.

The line rate at 115200 baud 8N1 is 11,520 bytes/s. A command and its Ack are bytes on the line:
counted together (the issue's reading: bytes per command + Ack) the line carries
11,520 / (command + Ack) commands/s; since the UART is full duplex, the physical ceiling is the
busier direction alone, 11,520 / max(command, Ack). Ping echo throughput is the same with 64-byte
Ping payloads, in payload bytes per second.

On the emulated Uno the runner's cycle counters give the MCU's awake share during each point, and
so the firmware's own ceiling: commands/s divided by the awake share is the rate at which the MCU
would never sleep.
"""

from __future__ import annotations

import logging
import os
import re
import statistics
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory

from protoduino import Board
from protoduino._generated import protoduino_pb2 as pb
from protoduino.constants import PacketType
from protoduino.errors import ProtoduinoError
from protoduino.framing import frame_packet
from protoduino.simboard import SimBoard

from . import charts
from .boards import (
    BACKENDS,
    LABELS,
    BoardUnavailableError,
    CycleCounter,
    CycleStats,
    started,
)
from .core import Chart, Context, Section, SectionResult, Target, fmt_rate, md_table
from .peers import protoduino as protoduino_peer
from .wire import EMULATED_BYTE_US

log = logging.getLogger(__name__)

WINDOWS: tuple[int, ...] = (1, 2, 4, 8, 16)
PING_WINDOWS: tuple[int, ...] = (1, 4, 16)
PING_PAYLOAD = 64
#: The goal: windowed throughput at least this share of the line rate.
TARGET_SHARE = 0.9
#: The windows at which the rate must reach the target and stay there without a retry.
HOLD_WINDOWS = (4, 8, 16)
#: The emulated Uno's line (bench.wire.EMULATED_BYTE_US: 11 bits a byte at 117,647 baud).
LINE_BYTES_PER_S = 1e6 / EMULATED_BYTE_US
#: Untimed calls per point before the clock starts.
WARMUP = 8
#: Longest one point may take before it is abandoned (every call is bounded by the Board).
POINT_TIMEOUT = 120.0


def _uno_rx_ring() -> int:
    """The Uno firmware's receive ring, PD_AVR_RX_SIZE, read from firmware/avr/pd_avr.h so
    that the report's text cannot go stale when the ring is resized (128 -> 64 -> 48 -> 96 B)."""
    header = Path(__file__).resolve().parents[1] / "firmware" / "avr" / "pd_avr.h"
    found = re.search(r"#define PD_AVR_RX_SIZE (\d+)", header.read_text())
    if found is None:
        raise RuntimeError(f"PD_AVR_RX_SIZE not found in {header}")
    return int(found.group(1))


#: The Uno firmware's receive ring (bytes).
UNO_RX_RING = _uno_rx_ring()
#: Each window is measured this many times, in turn with the others; the median round counts.
ROUNDS = 3


def ping_frames_64(message_id: int = protoduino_peer.FIRST_MESSAGE_ID) -> tuple[bytes, bytes]:
    """A Ping with a 64-byte payload and its Ack, as frames."""
    payload = bytes(range(PING_PAYLOAD))
    msg = pb.ArduinoIn(message_id=message_id + 1)
    msg.ping.payload = payload
    ack = pb.ArduinoOut()
    ack.ack.message_id = message_id + 1
    ack.ack.ping_echo = payload
    return (
        frame_packet(PacketType.COMMAND, 2, msg.SerializeToString()),
        frame_packet(PacketType.DATA, 1, ack.SerializeToString()),
    )


@dataclass(frozen=True, slots=True)
class LineRate:
    """What the line allows for one kind of call, in calls per second."""

    command_bytes: int
    ack_bytes: int

    @property
    def both(self) -> float:
        """Command and Ack counted together on the line (the issue's line rate)."""
        return LINE_BYTES_PER_S / (self.command_bytes + self.ack_bytes)

    @property
    def duplex(self) -> float:
        """The busier direction alone: the full-duplex ceiling."""
        return LINE_BYTES_PER_S / max(self.command_bytes, self.ack_bytes)


def servo_line() -> LineRate:
    sample = protoduino_peer.wire_sample()
    assert sample.ack is not None
    return LineRate(len(sample.command), len(sample.ack))


def ping_line() -> LineRate:
    command, ack = ping_frames_64()
    return LineRate(len(command), len(ack))


@dataclass(frozen=True, slots=True)
class Round:
    """One timed run of one window size."""

    seconds: float
    ok: int
    failed: int
    retransmits: int
    timeouts: int
    cycles: CycleStats | None  # emulated Uno only: its counters over the run

    @property
    def rate(self) -> float:
        return self.ok / self.seconds if self.seconds > 0 else 0.0


@dataclass(frozen=True, slots=True)
class Point:
    """One window size over every round: the median round's rate, the sums of the rest."""

    window: int
    rounds: tuple[Round, ...]

    @property
    def rate(self) -> float:
        return statistics.median(r.rate for r in self.rounds)

    @property
    def spread(self) -> float:
        """(max - min) / median of the rounds' rates: how much the machine moved."""
        rates = [r.rate for r in self.rounds]
        return (max(rates) - min(rates)) / self.rate if self.rate > 0 else 0.0

    @property
    def failed(self) -> int:
        return sum(r.failed for r in self.rounds)

    @property
    def retransmits(self) -> int:
        return sum(r.retransmits for r in self.rounds)

    @property
    def timeouts(self) -> int:
        return sum(r.timeouts for r in self.rounds)

    @property
    def awake_share(self) -> float | None:
        """The emulated Uno's awake share over every round."""
        counted = [r.cycles for r in self.rounds if r.cycles is not None]
        cycles = sum(c.cycles for c in counted)
        return sum(c.awake for c in counted) / cycles if counted and cycles else None

    @property
    def firmware_ceiling(self) -> float | None:
        """Calls/s at which the MCU would be awake all the time (rate / awake share)."""
        share = self.awake_share
        return self.rate / share if share else None


def drive(op: Callable[[int], object], window: int, total: int) -> tuple[float, int, int]:
    """``total`` calls of ``op`` spread over ``window`` threads started together.

    Returns (wall seconds from the start to the last return, calls that returned, calls that
    raised a protoduino error).
    """
    counts = [total // window + (1 if k < total % window else 0) for k in range(window)]
    ok = [0] * window
    failed = [0] * window
    barrier = threading.Barrier(window + 1)

    def worker(k: int) -> None:
        try:
            barrier.wait(timeout=POINT_TIMEOUT)
        except threading.BrokenBarrierError:
            return
        for i in range(counts[k]):
            try:
                op(i)
            except ProtoduinoError as error:
                failed[k] += 1
                log.debug("throughput: call failed: %s", error)
            else:
                ok[k] += 1

    threads = [
        threading.Thread(target=worker, args=(k,), name=f"bench-load-{k}", daemon=True)
        for k in range(window)
    ]
    for thread in threads:
        thread.start()
    barrier.wait(timeout=POINT_TIMEOUT)
    start = time.perf_counter()
    deadline = time.monotonic() + POINT_TIMEOUT
    for thread in threads:
        thread.join(max(0.0, deadline - time.monotonic()))
    elapsed = time.perf_counter() - start
    if any(thread.is_alive() for thread in threads):
        raise RuntimeError(f"a throughput point did not finish in {POINT_TIMEOUT:.0f} s")
    return elapsed, sum(ok), sum(failed)


def measure_round(
    sim: SimBoard,
    window: int,
    total: int,
    make_op: Callable[[Board], Callable[[int], object]],
    counter: CycleCounter | None,
) -> Round:
    """A fresh Board with ``window``, warmed up, then ``total`` calls."""
    with Board.open(sim.port, window=window, ping=False, baudrate=115_200) as board:
        op = make_op(board)
        for i in range(WARMUP):
            op(i)
        before = board.stats
        cycles = counter.snapshot() if counter is not None else None
        seconds, ok, failed = drive(op, window, total)
        delta = counter.snapshot() - cycles if counter is not None and cycles else None
        after = board.stats
    return Round(
        seconds,
        ok,
        failed,
        after.retransmits - before.retransmits,
        after.timeouts - before.timeouts,
        delta,
    )


def measure_points(
    sim: SimBoard,
    windows: Sequence[int],
    total: int,
    make_op: Callable[[Board], Callable[[int], object]],
    counter: CycleCounter | None,
) -> list[Point]:
    """Every window, ROUNDS times in turn (1, 2, 4, ..., then again), ``total`` calls each
    time: a slow spell of the shared machine then lands on every window, not on one."""
    rounds: dict[int, list[Round]] = {w: [] for w in windows}
    for _ in range(ROUNDS):
        for window in windows:
            rounds[window].append(measure_round(sim, window, total, make_op, counter))
    return [Point(w, tuple(rounds[w])) for w in windows]


def servo_op(board: Board) -> Callable[[int], object]:
    servo = board.servo(9)
    return lambda i: servo.write(80 + 20 * (i & 1))


def ping_op(board: Board) -> Callable[[int], object]:
    payload = bytes(range(PING_PAYLOAD))
    return lambda _i: board.ping(payload)


@dataclass(slots=True)
class BoardPoints:
    backend: str
    servo: list[Point] = field(default_factory=list)
    ping: list[Point] = field(default_factory=list)
    error: str | None = None


def collect(commands: int, windows: Sequence[int] = WINDOWS) -> list[BoardPoints]:
    out: list[BoardPoints] = []
    ping_total = max(4, commands // 4)
    for backend, _label in BACKENDS:
        log.info("throughput: %s board, %d commands per point", backend, commands)
        points = BoardPoints(backend)
        try:
            with TemporaryDirectory(prefix="bench-tp-") as tmp:
                stats = Path(tmp) / "stats.jsonl" if backend == "avr" else None
                with started(backend, stats=stats) as sim:
                    counter = CycleCounter(sim, stats) if stats is not None else None
                    per_round = max(1, commands // ROUNDS)
                    points.servo = measure_points(sim, windows, per_round, servo_op, counter)
                    ping_windows = [w for w in PING_WINDOWS if w in windows]
                    points.ping = measure_points(
                        sim, ping_windows, max(1, ping_total // ROUNDS), ping_op, counter
                    )
        except BoardUnavailableError as error:
            log.warning("throughput: %s board not run: %s", backend, error)
            points.error = str(error)
        out.append(points)
    return out


def _share(x: float | None) -> str:
    return "-" if x is None else f"{x * 100:.0f} %"


def _ceiling(x: float | None) -> str:
    return "-" if x is None else fmt_rate(x)


def run(ctx: Context) -> SectionResult:
    load = os.getloadavg()[0]
    boards = collect(ctx.commands)
    servo, ping = servo_line(), ping_line()
    parts = [
        f"`W` threads each call `Servo.write` in a loop on one `Board.open(port, window=W)`, "
        f"{ctx.commands} acknowledged commands per point after {WARMUP} untimed ones; Ping "
        f"echo: `Board.ping(payload)` with {PING_PAYLOAD}-byte payloads, "
        f"{max(4, ctx.commands // 4)} per point. Each point is {ROUNDS} rounds, the windows "
        "taking turns; a rate is the median round's wall-clock rate, and the spread "
        "((max - min) / median of the rounds) shows how much the shared machine moved. "
        "Failures, retransmissions and timeouts are summed over the rounds. The emulated Uno's "
        "line (simavr times every byte as 11 bits, at the 117,647 baud the firmware's UBRR "
        f"sets) carries {LINE_BYTES_PER_S:,.0f} B/s: a servo command is "
        f"{servo.command_bytes} B and "
        f"its Ack {servo.ack_bytes} B (a 1-byte message id, the short Ack: protocol version "
        "5), so the line rate is "
        f"{servo.both:,.0f} commands/s with "
        f"command and Ack counted together, and {servo.duplex:,.0f} commands/s if only the "
        "busier direction counts (the UART is full duplex). The awake share and the firmware's "
        "ceiling (rate / awake share: the rate at which the MCU would never sleep) come from "
        "the emulator's cycle counters. Load average at the start of this section: "
        f"{load:.2f} (2 cores, shared).\n"
    ]
    targets: list[Target] = []
    chart_list: list[Chart] = []
    for points in boards:
        label = LABELS[points.backend]
        if points.error is not None:
            parts.append(f"The {label} was not run: {points.error}.\n")
            continue
        avr = points.backend == "avr"
        parts.append(f"### {label[0].upper()}{label[1:]}\n")
        rows = []
        for p in points.servo:
            row = [str(p.window), fmt_rate(p.rate)]
            if avr:
                row += [_share(p.rate / servo.both), _share(p.rate / servo.duplex)]
            row += [str(p.failed), str(p.retransmits), str(p.timeouts)]
            if avr:
                row += [_share(p.awake_share), _ceiling(p.firmware_ceiling)]
            rows.append([*row, _share(p.spread)])
        header = ["window", "acked commands/s"]
        if avr:
            header += ["of line rate (cmd + Ack)", "of full duplex"]
        header += ["failed", "retransmits", "timeouts"]
        if avr:
            header += ["Uno awake", "firmware ceiling cmd/s"]
        header.append("spread")
        parts.append("Servo writes:\n")
        parts.append(md_table(header, rows))
        prow = []
        for p in points.ping:
            payload_rate = p.rate * PING_PAYLOAD
            row = [str(p.window), fmt_rate(p.rate), fmt_rate(payload_rate)]
            if avr:
                row += [
                    _share(p.rate / ping.both),
                    _share(p.rate / ping.duplex),
                    _share(p.awake_share),
                ]
            row += [str(p.failed), str(p.retransmits), _share(p.spread)]
            prow.append(row)
        pheader = ["window", "Pings/s", "payload B/s echoed"]
        if avr:
            pheader += ["of line rate (cmd + Ack)", "of full duplex", "Uno awake"]
        pheader += ["failed", "retransmits", "spread"]
        parts.append(
            f"Ping echo, {PING_PAYLOAD}-byte payloads (command {ping.command_bytes} B, Ack "
            f"{ping.ack_bytes} B; line rate {ping.both * PING_PAYLOAD:,.0f} payload B/s with "
            f"both counted, {ping.duplex * PING_PAYLOAD:,.0f} full duplex):\n"
        )
        parts.append(md_table(pheader, prow))
        if avr and points.servo:
            best = max(points.servo, key=lambda p: p.rate)
            targets += _targets(points, servo)
            parts.append(_explain(points, servo, best))
        if ctx.chart_dir is not None and points.servo:
            xs = [float(p.window) for p in points.servo]
            series = {"acked servo commands/s": [p.rate for p in points.servo]}
            hlines: dict[str, float] = {}
            if avr:
                ceilings = [p.firmware_ceiling for p in points.servo]
                if all(c is not None for c in ceilings):
                    series["firmware ceiling (rate / awake share)"] = [
                        c for c in ceilings if c is not None
                    ]
                hlines = {
                    f"line rate, cmd + Ack ({servo.both:,.0f}/s)": servo.both,
                    f"target {TARGET_SHARE * 100:.0f} %": servo.both * TARGET_SHARE,
                    f"full duplex ({servo.duplex:,.0f}/s)": servo.duplex,
                }
            path = charts.lines(
                ctx.chart_dir / f"throughput_{points.backend}.png",
                xs,
                series,
                title=f"Throughput vs window, {label}",
                xlabel="window (commands awaiting their Ack)",
                ylabel="commands/s",
                hlines=hlines,
            )
            chart_list.append(Chart(path, f"Acknowledged servo commands/s by window, {label}"))
    if not targets:
        targets.append(
            Target(
                "windowed throughput",
                f">= {TARGET_SHARE * 100:.0f} % of the line rate",
                "not run",
                None,
            )
        )
    return SectionResult("\n".join(parts), targets, chart_list, [])


def _targets(points: BoardPoints, servo: LineRate) -> list[Target]:
    """Issue 11's: >= 90 % of the full-duplex line at window 4, held at 8 and 16, no retries."""
    by_window = {p.window: p for p in points.servo}
    goal = servo.duplex * TARGET_SHARE
    out = []
    four = by_window.get(HOLD_WINDOWS[0])
    if four is not None:
        out.append(
            Target(
                f"acked servo commands/s, window {four.window}",
                f">= {TARGET_SHARE * 100:.0f} % of full duplex ({goal:,.0f}/s)",
                f"{four.rate / servo.duplex * 100:.0f} % ({fmt_rate(four.rate)} of "
                f"{servo.duplex:,.0f} commands/s; {four.rate / servo.both * 100:.0f} % of "
                "command + Ack)",
                four.rate >= goal,
            )
        )
    held = [by_window[w] for w in HOLD_WINDOWS if w in by_window]
    if held:
        retries = sum(p.retransmits + p.failed + p.timeouts for p in held)
        out.append(
            Target(
                "held at windows " + ", ".join(str(p.window) for p in held),
                f">= {goal:,.0f}/s and 0 retransmissions at each",
                ", ".join(f"{fmt_rate(p.rate)}/s" for p in held)
                + f"; {sum(p.retransmits for p in held)} retransmissions, "
                f"{sum(p.failed + p.timeouts for p in held)} failed or timed out",
                all(p.rate >= goal for p in held) and retries == 0,
            )
        )
    return out


def _explain(points: BoardPoints, servo: LineRate, best: Point) -> str:
    one = points.servo[0]
    ceiling = best.firmware_ceiling
    lines = [
        f"With one command at a time the Uno does {fmt_rate(one.rate)} commands/s (one round "
        f"trip each); from window 2 on, the next command is already arriving while the "
        f"previous one is handled. The best point, window {best.window}, reaches "
        f"{fmt_rate(best.rate)} commands/s with the Uno awake {_share(best.awake_share)} of "
        "the time."
    ]
    if ceiling is not None:
        lines.append(
            f" The firmware's ceiling is {fmt_rate(ceiling)} commands/s: each command keeps "
            f"the MCU busy {16e6 / ceiling:,.0f} cycles ({1e3 / ceiling:.2f} ms at 16 MHz), "
            f"against {1e3 / servo.both:.2f} ms of line time for command and Ack together and "
            f"{1e3 / servo.duplex:.2f} ms for the busier direction"
            + (
                ": the line, not the Uno, sets the limit now (part 5 splits the cycles)."
                if ceiling > servo.duplex
                else ". So the Uno, not the host and not the line, sets the limit; part 5 "
                "splits those cycles."
            )
        )
    trouble = [p for p in points.servo if p.retransmits or p.failed or p.timeouts]
    if not trouble:
        lines.append(
            " No window retransmitted a command: the host keeps the command frames in flight "
            "within the receive buffer the device states (DeviceInfo.rx_buffer, "
            f"{UNO_RX_RING - 1} B on the Uno), so a larger window adds no overflow, and the "
            "firmware acts on a frame only when its transmit ring has room for every reply."
            + _ping_trouble(points)
        )
    if trouble:
        first = trouble[0]
        calm = [p.window for p in points.servo if p.window < first.window]
        lines.append(
            f" From window {first.window} on, commands were retransmitted: the host puts "
            f"{first.window} x {servo.command_bytes} = {first.window * servo.command_bytes} B "
            f"of commands on the line at once against the Uno's {UNO_RX_RING}-byte receive "
            "ring, although the host keeps the frames in flight within the buffer the device "
            "states (DeviceInfo.rx_buffer). "
            + (f"Windows up to {max(calm)} have none. " if calm else "")
            + _ping_trouble(points)
        )
    return "".join(lines) + "\n"


def _ping_trouble(points: BoardPoints) -> str:
    retried = [p.window for p in points.ping if p.retransmits or p.failed]
    if not retried:
        return ""
    size = ping_line().command_bytes
    return (
        f"The {PING_PAYLOAD}-byte Pings ({size} B each, {retried[0] * size} B at window "
        f"{retried[0]}) are retransmitted from window {retried[0]} on for the same reason. "
    )


SECTION = Section(3, "throughput", "Throughput", run)
