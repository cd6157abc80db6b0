"""Benchmark part 2 (docs/performance.md).

Command -> Ack round trip, next to the wire-time lower bound.

Wall-clock latency (``time.perf_counter``) of one call through the public API, from the call to
its return with the Ack: ``Servo.write`` (ServoControl) and ``Board.ping()`` (an empty Ping),
one at a time, against the simulated board (native, no baud rate) and the emulated Uno (avr:
the real firmware on simavr, its UART at 115200 baud, paced to real time).

The lower bound is the time the command's and the Ack's bytes take on a 115200-baud 8N1 line
(10 bits a byte), for the frames :mod:`bench.peers.protoduino` builds with the project's encoders
(a 1-byte message id and the short Ack, as protocol version 5's are).

To say where the time goes, the same board is also driven by :class:`bench.boards.RawClient`
(pyserial and the framing only, no I/O thread): the difference is the host library's share. On
the emulated Uno the runner's cycle counters give the firmware's awake time per command, and
the runner's own test program, which echoes each UART byte at once, gives what the emulator and
the pty add to a round trip with no protoduino code at all. The cases take turns in rounds
(library, then raw client) so that a slow spell of the shared machine lands on both.
"""

from __future__ import annotations

import logging
import os
import random
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory

from protoduino import Board
from protoduino._generated import protoduino_pb2 as pb
from protoduino.board import Servo
from protoduino.constants import PacketType
from protoduino.framing import frame_packet
from protoduino.simboard import SimBoard
from protoduino_dev import runnerstats

from . import charts
from .boards import (
    BACKENDS,
    LABELS,
    UNO_HZ,
    BoardUnavailableError,
    CycleCounter,
    CycleStats,
    Percentiles,
    RawClient,
    echo_round_trips,
    started,
    started_echo,
)
from .core import Chart, Context, Section, SectionResult, Target, md_table
from .peers import protoduino as protoduino_peer
from .wire import BAUD, EMULATED_BYTE_US, board_byte_us

log = logging.getLogger(__name__)

#: The goal: p50 on the emulated Uno at most this many times the wire time.
TARGET_RATIO = 1.3
#: Rounds the samples are split into (library, then raw client, each round).
ROUNDS = 3
#: Untimed calls at the start of every block.
WARMUP = 5
#: The emulated Uno's UART: U2X with UBRR 16 (firmware/avr/pd_avr_uart.c), so one 10-bit byte
#: is 10 * 8 * 17 cycles; polled transmit waits that long for each byte after the first.
UART_BYTE_CYCLES = 10 * 8 * 17
#: Each timed call starts after a random pause of up to this (seconds): back-to-back calls
#: would lock onto the emulated Uno's timers (1 ms clock tick, 20 ms servo frames) and the
#: emulator's loop at whatever phase they happen to start with, and
#: a run's median would depend on that luck; random starts sample every phase, as an
#: application's commands would.
MAX_GAP = 0.002
#: Idle time over which the Uno's background load (clock tick, servo interrupts) is measured.
IDLE_SECONDS = 0.3

KINDS: tuple[tuple[str, str], ...] = (
    ("servo", "servo write"),
    ("ping", "Ping, empty"),
)


def ping_frames(message_id: int = protoduino_peer.FIRST_MESSAGE_ID) -> tuple[bytes, bytes]:
    """An empty Ping and its Ack as frames (the Ack carries the empty echo, as the firmware's)."""
    msg = pb.ArduinoIn(message_id=message_id + 1)
    msg.ping.SetInParent()
    ack = pb.ArduinoOut()
    ack.ack.message_id = message_id + 1
    ack.ack.ping_echo = b""
    return (
        frame_packet(PacketType.COMMAND, 2, msg.SerializeToString()),
        frame_packet(PacketType.DATA, 1, ack.SerializeToString()),
    )


def wire_frames(kind: str) -> tuple[bytes, bytes]:
    """(command, Ack) frames of ``kind`` as they go on the wire."""
    if kind == "servo":
        sample = protoduino_peer.wire_sample()
        assert sample.ack is not None
        return sample.command, sample.ack
    return ping_frames()


def _servo_msg(i: int) -> pb.ArduinoIn:
    msg = pb.ArduinoIn()
    msg.servo_control.pin = 9
    msg.servo_control.degrees = 80 + 20 * (i & 1)
    return msg


def _ping_msg(_i: int) -> pb.ArduinoIn:
    msg = pb.ArduinoIn()
    msg.ping.SetInParent()
    return msg


RAW_MESSAGES: dict[str, Callable[[int], pb.ArduinoIn]] = {"servo": _servo_msg, "ping": _ping_msg}


@dataclass(slots=True)
class BoardRun:
    """Everything measured on one board."""

    backend: str
    library: dict[str, list[float]] = field(default_factory=dict)  # kind -> seconds
    raw: dict[str, list[float]] = field(default_factory=dict)
    #: avr only: awake cycles per command (idle load removed) and the idle awake share.
    cycles: dict[str, float] = field(default_factory=dict)
    #: avr only: the firmware's answer time per command, in cycles: from the command's last
    #: byte ready in the UART to the Ack's first byte leaving (the runner's counters, a mean).
    answer: dict[str, float] = field(default_factory=dict)
    idle_share: float | None = None
    #: avr only: emulated time over wall time across the timed library blocks.
    pace: float | None = None
    #: kind -> (command bytes, Ack bytes) per call as the Board sent and received them (its
    #: message ids are one varint byte since protocol version 5).
    wire_bytes: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: avr only: 1-byte echo round trips through the runner's test program (no firmware).
    echo: list[float] = field(default_factory=list)
    error: str | None = None


def timed(op: Callable[[int], object], n: int, rng: random.Random) -> list[float]:
    """``n`` timed calls of ``op``, each after a random pause (see :data:`MAX_GAP`)."""
    for i in range(WARMUP):
        op(i)
    out: list[float] = []
    for i in range(n):
        time.sleep(rng.uniform(0.0, MAX_GAP))
        start = time.perf_counter()
        op(i)
        out.append(time.perf_counter() - start)
    return out


def busy_cycles(delta: CycleStats, idle_share: float) -> float:
    """Awake cycles over ``delta`` minus what the idle board spends in the same time (its
    clock tick and servo interrupts): the cycles the commands cost."""
    return delta.awake - idle_share * delta.cycles


def library_ops(board: Board, servo: Servo) -> dict[str, Callable[[int], object]]:
    """The public API's calls, by kind; servo writes alternate so every one moves it."""
    return {
        "servo": lambda i: servo.write(80 + 20 * (i & 1)),
        "ping": lambda _i: board.ping(),
    }


def _raw_op(raw: RawClient, make: Callable[[int], pb.ArduinoIn]) -> Callable[[int], float]:
    return lambda i: raw.call(make(i))


def measure_board(
    sim: SimBoard, backend: str, samples: int, counter: CycleCounter | None, seed: int
) -> BoardRun:
    run = BoardRun(backend)
    rng = random.Random(seed)
    per_round = max(1, samples // ROUNDS)
    for kind, _label in KINDS:
        run.library[kind] = []
        run.raw[kind] = []
    awake: dict[str, list[tuple[CycleStats, int]]] = {kind: [] for kind, _ in KINDS}
    io: dict[str, list[int]] = {kind: [0, 0, 0] for kind, _ in KINDS}  # tx, rx, calls
    for _round in range(ROUNDS):
        # Pinned: this part's figures are at 115200 (the agreed rate's: measure_agreed).
        with Board.open(sim.port, ping=False, baudrate=BAUD) as board:
            servo = board.servo(9)
            if counter is not None and run.idle_share is None:
                a = counter.snapshot()
                time.sleep(IDLE_SECONDS)
                run.idle_share = (counter.snapshot() - a).awake_share
            ops = library_ops(board, servo)
            for kind, _label in KINDS:
                before = counter.snapshot() if counter is not None else None
                link = board.stats
                run.library[kind] += timed(ops[kind], per_round, rng)
                after = board.stats
                io[kind][0] += after.tx_bytes - link.tx_bytes
                io[kind][1] += after.rx_bytes - link.rx_bytes
                io[kind][2] += per_round + WARMUP
                if counter is not None and before is not None:
                    awake[kind].append((counter.snapshot() - before, per_round + WARMUP))
        with RawClient(sim.port) as raw:
            init = pb.ArduinoIn()
            init.servo_init.pin = 9
            init.servo_init.safe_degrees = 90
            raw.call(init)
            for kind, _label in KINDS:
                run.raw[kind] += timed(_raw_op(raw, RAW_MESSAGES[kind]), per_round, rng)
    for kind, (tx, rx, calls) in io.items():
        run.wire_bytes[kind] = (tx / calls, rx / calls)
    if run.idle_share is not None:
        deltas = [d for blocks in awake.values() for d, _n in blocks]
        wall = sum(d.wall for d in deltas)
        run.pace = sum(d.t for d in deltas) / wall if wall > 0 else None
        for kind, blocks in awake.items():
            total = sum(n for _d, n in blocks)
            run.cycles[kind] = sum(busy_cycles(d, run.idle_share) for d, _n in blocks) / total
            answers = sum(d.answers for d, _n in blocks)
            if answers:
                run.answer[kind] = sum(d.answer_cycles for d, _n in blocks) / answers
    return run


@dataclass(slots=True)
class AgreedRun:
    """The emulated Uno at the rate its Board agrees on (docs/protocol.md 5, *Line rate*)."""

    baudrate: int = 0
    byte_us: float = 0.0  # the runner's byte time from the board at that rate (11 bits)
    library: dict[str, list[float]] = field(default_factory=dict)
    wire_bytes: dict[str, tuple[float, float]] = field(default_factory=dict)
    error: str | None = None


def measure_agreed(samples: int, seed: int) -> AgreedRun:
    """The library's round trips on the emulated Uno at the agreed rate (no raw client)."""
    run = AgreedRun()
    rng = random.Random(seed)
    try:
        with TemporaryDirectory(prefix="bench-rt-") as tmp:
            stats = Path(tmp) / "stats.jsonl"
            with started("avr", stats=stats) as sim, Board.open(sim.port, ping=False) as board:
                run.baudrate = board.baudrate
                servo = board.servo(9)
                for kind, op in library_ops(board, servo).items():
                    link = board.stats
                    run.library[kind] = timed(op, samples, rng)
                    after, calls = board.stats, samples + WARMUP
                    run.wire_bytes[kind] = (
                        (after.tx_bytes - link.tx_bytes) / calls,
                        (after.rx_bytes - link.rx_bytes) / calls,
                    )
                cycles = int(runnerstats.snapshot(sim.pid, stats)["uart_byte_cycles"])
                run.byte_us = cycles / UNO_HZ * 1e6
    except BoardUnavailableError as error:
        run.error = str(error)
    return run


def _agreed_table(agreed: AgreedRun, avr: BoardRun | None) -> str:
    """The agreed rate's round trips beside 115200's (the emulated Uno's)."""
    if agreed.error is not None or not agreed.library:
        return f"At the agreed rate: not run ({agreed.error or 'no samples'}).\n"
    rows = []
    for kind, kind_label in KINDS:
        command_b, ack_b = agreed.wire_bytes[kind]
        wire_s = agreed.byte_us * (command_b + ack_b) / 1e6
        lib = Percentiles.of(agreed.library[kind])
        base = (
            _us(Percentiles.of(avr.library[kind]).p50)
            if avr is not None and avr.library.get(kind)
            else "-"
        )
        rows.append(
            [
                kind_label,
                base,
                _us(lib.p50),
                _us(lib.p99),
                f"{_bytes(command_b)} + {_bytes(ack_b)}",
                _us(wire_s),
                _us(lib.p50 - wire_s),
                str(lib.n),
            ]
        )
    return (
        f"\n### At the agreed rate\n\nThe same calls on a fresh emulated Uno whose Board "
        f"agreed on {agreed.baudrate:,} baud after the handshake (docs/protocol.md 5, *Line "
        f"rate*; its runner times a byte at {agreed.byte_us:.1f} us), library only, beside "
        "the 115200 p50 of the table above.\n\n"
        + md_table(
            [
                "command",
                "p50 us at 115200",
                f"p50 us at {agreed.baudrate:,}",
                "p99 us",
                "bytes (cmd + Ack)",
                "wire time us",
                "p50 minus wire us",
                "samples",
            ],
            rows,
            "lrrrrrrr",
        )
    )


def collect(samples: int, seed: int = 7) -> list[BoardRun]:
    runs: list[BoardRun] = []
    for backend, _label in BACKENDS:
        log.info("round trip: %s board, %d samples per case", backend, samples)
        try:
            with TemporaryDirectory(prefix="bench-rt-") as tmp:
                stats = Path(tmp) / "stats.jsonl" if backend == "avr" else None
                with started(backend, stats=stats) as sim:
                    counter = CycleCounter(sim, stats) if stats is not None else None
                    board_run = measure_board(sim, backend, samples, counter, seed)
            if backend == "avr":
                with started_echo() as sim:
                    board_run.echo = echo_round_trips(
                        sim.port, samples, gap=MAX_GAP, rng=random.Random(seed)
                    )
            runs.append(board_run)
        except BoardUnavailableError as error:
            log.warning("round trip: %s board not run: %s", backend, error)
            runs.append(BoardRun(backend, error=str(error)))
    return runs


def _bytes(n: float) -> str:
    """A per-call byte count: whole when it is (``19``), else one decimal (``18.9``)."""
    return f"{round(n, 1):g}"


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:,.0f}"


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.2f}"


@dataclass(frozen=True, slots=True)
class Budget:
    """Where a median round trip on the emulated Uno goes, in microseconds.

    The host library's share is measured on the simulated board (library minus raw client
    there), where nothing else moves: on the emulated Uno the difference of two medians drowns
    in the spread the emulator's pacing and the Uno's timers give.
    """

    command_bytes: float
    ack_bytes: float
    wire: float
    awake: float  # the firmware's awake time per command
    awake_cycles: float
    answer: float  # the firmware's answer time: command's last byte in to the Ack's first out
    answer_cycles: float
    host: float  # the host library's own time (simulated board: library p50 - raw p50)
    library: float  # Board p50 on the emulated Uno

    @property
    def beyond(self) -> float:
        """The round trip beyond the wire, the firmware's answer time and the host library:
        the emulator's pacing, the pty, the raw I/O, scheduling."""
        return self.library - self.wire - self.answer - self.host

    def rows(self) -> list[list[str]]:
        return [
            [
                f"command + Ack on the wire ({_bytes(self.command_bytes)} + "
                f"{_bytes(self.ack_bytes)} B)",
                f"{self.wire:,.0f}",
            ],
            [
                "the firmware's answer time: from the command's last byte ready in the UART to "
                f"the Ack's first byte leaving ({self.answer_cycles:,.0f} cycles at 16 MHz, "
                "the emulator's count, mean over the calls)",
                f"{self.answer:,.0f}",
            ],
            [
                "host library (on the simulated board: Board p50 minus raw client p50)",
                f"{self.host:,.0f}",
            ],
            [
                "the rest: the emulator's pacing (a host byte enters the UART at most 50 us "
                "after it was read; answers handed over no earlier than the line delivers "
                "them), the pty both ways, the raw I/O, scheduling",
                f"{self.beyond:,.0f}",
            ],
            ["= Board p50 on the emulated Uno", f"{self.library:,.0f}"],
            [
                "for scale, not in the sum: the firmware awake per command "
                f"({self.awake_cycles:,.0f} cycles), most of it while the bytes are on the wire",
                f"{self.awake:,.0f}",
            ],
        ]


def host_overhead(run: BoardRun, kind: str) -> float:
    """The host library's share of a round trip on ``run``'s board, in us."""
    lib = Percentiles.of(run.library[kind]).p50
    raw = Percentiles.of(run.raw[kind]).p50
    return (lib - raw) * 1e6


def budget(run: BoardRun, kind: str, host: float) -> Budget | None:
    """The median round trip of ``kind`` on the emulated Uno, split (None without cycles);
    ``host`` is the host library's share in us."""
    if kind not in run.cycles or kind not in run.answer:
        return None
    command, ack = run.wire_bytes[kind]
    cycles = run.cycles[kind]
    answer = run.answer[kind]
    return Budget(
        command_bytes=command,
        ack_bytes=ack,
        wire=EMULATED_BYTE_US * (command + ack),
        awake=cycles / UNO_HZ * 1e6,
        awake_cycles=cycles,
        answer=answer / UNO_HZ * 1e6,
        answer_cycles=answer,
        host=host,
        library=Percentiles.of(run.library[kind]).p50 * 1e6,
    )


def run(ctx: Context) -> SectionResult:
    load = os.getloadavg()[0]
    runs = collect(ctx.samples, ctx.seed)
    rows: list[list[str]] = []
    targets: list[Target] = []
    hist_series: dict[str, dict[str, list[float]]] = {}
    notes: list[str] = []
    for board_run in runs:
        label = LABELS[board_run.backend]
        if board_run.error is not None:
            notes.append(f"The {label} was not run: {board_run.error}.")
            continue
        for kind, kind_label in KINDS:
            command_b, ack_b = board_run.wire_bytes[kind]
            wire_s = board_byte_us(board_run.backend) * (command_b + ack_b) / 1e6
            lib = Percentiles.of(board_run.library[kind])
            raw = Percentiles.of(board_run.raw[kind])
            rows.append(
                [
                    label,
                    kind_label,
                    f"{_bytes(command_b)} + {_bytes(ack_b)}",
                    _us(wire_s),
                    _us(lib.p50),
                    _us(lib.p90),
                    _us(lib.p99),
                    f"{lib.p50 / wire_s:.2f}x",
                    _us(raw.p50),
                    _us(lib.p50 - raw.p50),
                    str(lib.n),
                ]
            )
            scale = 1e3 if board_run.backend == "avr" else 1e6
            hist_series.setdefault(board_run.backend, {})[kind_label] = [
                x * scale for x in board_run.library[kind]
            ]
            if board_run.backend == "avr" and kind == "servo":
                ratio = lib.p50 / wire_s
                targets.append(
                    Target(
                        "round trip p50, emulated Uno",
                        f"<= {TARGET_RATIO}x its wire time",
                        f"{ratio:.2f}x (servo write: p50 {_ms(lib.p50)} ms, wire {_ms(wire_s)} ms)",
                        ratio <= TARGET_RATIO,
                    )
                )
    if not targets:
        targets.append(
            Target(
                "round trip p50, emulated Uno", f"<= {TARGET_RATIO}x its wire time", "not run", None
            )
        )

    parts = [
        f"Wall-clock time of one call through the public API (`Servo.write`, `Board.ping()`), "
        f"one at a time, {ctx.samples} samples per case after {WARMUP} untimed ones, each "
        f"after a random pause of 0 to {MAX_GAP * 1e3:g} ms so that the calls do not lock onto "
        "the emulated Uno's timers and the emulator's loop (a core that idled that long also "
        "takes its time to wake, as an application's would); "
        f"percentiles by nearest rank. The wire time is the lower bound: the command's and the "
        "Ack's bytes counted as the Board sent and received them (message ids 1..127, one "
        "varint byte, and the short Ack, protocol version 5), on the emulated Uno at its "
        "own line's byte time: simavr 1.6 times every "
        f"byte as 11 bits at the 117,647 baud the firmware's UBRR sets, {EMULATED_BYTE_US:.1f} "
        f"us a byte (a real line at {BAUD} baud, 8N1, takes 86.8 us). The simulated board has "
        "no baud rate (a pty at memory speed), so its wire time, at 8N1, is only for scale. "
        "*Raw client*: the same command "
        "from pyserial and the framing alone, no I/O thread (bench/boards.py), in turns with "
        f"the library ({ROUNDS} rounds); the difference is the host library's own cost, "
        "clear on the simulated board and lost in the emulated Uno's spread (there it can "
        "even come out negative). "
        f"Load average at the start of this section: {load:.2f} (2 cores, shared).\n",
        md_table(
            [
                "board",
                "command",
                "bytes (cmd + Ack)",
                "wire time us",
                "p50 us",
                "p90 us",
                "p99 us",
                "p50 / wire",
                "raw client p50 us",
                "host library us",
                "samples",
            ],
            rows,
            "llrrrrrrrrr",
        ),
    ]
    parts += [note + "\n" for note in notes]
    avr = next((r for r in runs if r.backend == "avr" and r.error is None), None)
    native = next((r for r in runs if r.backend == "native" and r.error is None), None)
    if avr is not None:
        parts.append(_explain(avr, native or avr, targets[0]))
    if any(r.backend == "avr" for r in runs):
        parts.append(_agreed_table(measure_agreed(ctx.samples, ctx.seed), avr))

    chart_list: list[Chart] = []
    if ctx.chart_dir is not None:
        for backend, series in hist_series.items():
            avr_board = backend == "avr" and avr is not None
            unit = "ms" if avr_board else "us"
            vlines: dict[str, float] = {}
            if avr is not None and avr_board:
                wire = EMULATED_BYTE_US * sum(avr.wire_bytes["servo"]) / 1e3
                vlines[f"servo wire time {wire:.2f} ms"] = wire
                vlines[f"target {TARGET_RATIO}x wire"] = wire * TARGET_RATIO
            path = charts.histogram(
                ctx.chart_dir / f"roundtrip_{backend}.png",
                series,
                title=f"Round trip, {LABELS[backend]}",
                xlabel=f"command -> Ack, {unit}",
                bins=60,
                vlines=vlines,
            )
            chart_list.append(Chart(path, f"Round-trip latency histogram, {LABELS[backend]}"))
    return SectionResult("\n".join(parts), targets, chart_list, ["pyserial"])


def _explain(avr: BoardRun, host_board: BoardRun, target: Target) -> str:
    out = ["### Where the emulated Uno's round trip goes\n"]
    for kind, kind_label in KINDS:
        split = budget(avr, kind, host_overhead(host_board, kind))
        if split is not None:
            out += [f"Median {kind_label}:\n", md_table(["", "us"], split.rows())]
    servo = budget(avr, "servo", host_overhead(host_board, "servo"))
    if servo is None:
        return "\n".join(out)
    echo_text = ""
    if avr.echo:
        echo = Percentiles.of(avr.echo)
        echo_wire = EMULATED_BYTE_US * 2
        echo_text = (
            "The runner alone, with its own test program answering each byte at once, "
            f"echoes one byte in {echo.p50 * 1e6:,.0f} us at the median (p99 "
            f"{echo.p99 * 1e6:,.0f} us) against {echo_wire:,.0f} us on the wire: the emulator "
            f"and the pty alone add {echo.p50 * 1e6 - echo_wire:,.0f} us at the median to a "
            "one-byte round trip with no protoduino code involved. "
        )
    allowed = servo.wire * (TARGET_RATIO - 1)
    verdict = "met" if target.met else "missed"
    out.append(
        f"The target is {verdict}: {TARGET_RATIO}x the servo write's wire time leaves "
        f"{allowed:,.0f} us above the wire for everything else; the firmware's answer time "
        f"takes {servo.answer:,.0f} us of it, the host library {servo.host:,.0f} us and the "
        f"rest of the round trip {servo.beyond:,.0f} us. The firmware COBS-decodes each byte "
        "and folds it into the CRC as it arrives, hands a command's payload to nanopb as soon "
        "as its last byte is in (the CRC and the delimiter, 3 byte times, are still on the "
        "wire), and sends its Ack through a ring an interrupt drains; its answer time is "
        "what remains after the command's last byte: the end of nanopb's decode, the checks, "
        "the command, and the Ack's encoding, CRC and COBS (part 5 profiles the cycles), so "
        f"most of its {servo.awake:,.0f} us awake per command overlaps the wire. The rest is "
        "the emulated Uno's own: its runner keeps emulated time at most 50 us ahead of the "
        "wall clock (a sleeping MCU included), and a host byte enters the emulated UART at "
        "most that much after the runner read it (its wake-up on the pty comes first); what "
        "the UART sends reaches the host no earlier than a line would deliver it (a burst in "
        "one write once its last byte is due), so the emulator can only lengthen a round "
        "trip, never shorten it; on a loaded machine the runner also waits for a core. "
        f"{echo_text}{_pace_text(avr.pace)}The host library adds {servo.host:,.0f} us (its I/O "
        "thread wakes up at the Ack and resolves the call, and the caller wakes up from its "
        "wait; the caller writes its own command when nothing is queued), "
        f"{servo.host / servo.library * 100:.0f} % of the round trip. The emulator's share would "
        "be a real Uno's USB-serial bridge latency instead, which this bench cannot measure.\n"
    )
    return "\n".join(out)


def _pace_text(pace: float | None) -> str:
    if pace is None:
        return ""
    return (
        f"Over the timed calls, emulated time ran at {pace * 100:.1f} % of the wall clock's pace. "
    )


SECTION = Section(2, "roundtrip", "Round trip", run)
