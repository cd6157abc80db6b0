"""Benchmark part 6 (docs/performance.md): motion.

Two questions about motion (docs/api.md, Motion), on both boards:

* Poses: the time from the call until every joint of a 4- and a 6-servo pose shows its new
  width at the pins, and how far apart the joints start, for one ``Board.pose`` call, for
  separate ``Servo.write`` calls one after another, and for one thread per joint each calling
  ``Servo.write``.
* Commands per second from one thread with futures (``Servo.submit`` in a loop, then waiting
  for them all) against the blocking loop (``Servo.write`` one after another) and a loop in
  each of four threads.

The joints' change times are the boards' trace times (a servo's is the rising edge of its
first pulse with the new width on the emulated Uno, the moment of the write on the native
board), on the board's clock. Both boards keep that clock on CLOCK_MONOTONIC, the host's
``time.monotonic``, from an unknown start: the offset is bounded by digital toggles (each
change lies between its call and its Ack) and the midpoint of the tightest bound is used; its
half-width is reported as the uncertainty of every call-to-pin time.
"""

from __future__ import annotations

import logging
import random
import statistics
import threading
import time
from collections.abc import Sequence
from concurrent.futures import Future, wait
from dataclasses import dataclass, field

from protoduino import Board, DigitalOutput, Servo
from protoduino.simboard import SimBoard

from .boards import LABELS, Trace, on_each_board
from .core import Context, Section, SectionResult, fmt_rate, md_table

log = logging.getLogger(__name__)

#: Servo pins of the 4- and 6-joint arms, and the digital pin that calibrates the clock.
ARM_PINS: tuple[int, ...] = (3, 5, 6, 9, 10, 11)
CLOCK_PIN = 13
JOINTS: tuple[int, ...] = (4, 6)
METHODS: tuple[str, ...] = ("pose", "separate writes", "one thread per joint")
#: A pose's trials, and how long one may take to reach the pins before it counts as lost.
TRIALS = 15
SETTLE = 5.0
#: Trace times match a commanded width within this many us (the emulated Uno measures pulses).
TOLERANCE_US = 3
#: Threads of the multi-thread loop.
THREADS = 4


def us(degrees: int) -> int:
    return 544 + degrees * (2400 - 544) // 180


def wait_changes(
    trace: Trace,
    wants: dict[int, int],
    after: float,
    timeout: float = SETTLE,
    *,
    tolerance: int = TOLERANCE_US,
    mode: str | None = None,
) -> dict[int, float] | None:
    """Board-clock time at which each pin first showed its wanted value (within ``tolerance``,
    in a line of ``mode`` if one is named) after ``after``."""
    deadline = time.monotonic() + timeout
    while True:
        found: dict[int, float] = {}
        for e in trace.update():
            pin = int(e["pin"])
            want = wants.get(pin)
            if want is None or pin in found or e["t"] <= after:
                continue
            if mode is not None and e["mode"] != mode:
                continue
            if abs(int(e["value"]) - want) <= tolerance:
                found[pin] = float(e["t"])
        if len(found) == len(wants):
            return found
        if time.monotonic() > deadline:
            return None
        time.sleep(0.002)


@dataclass(slots=True)
class Clock:
    """host time = board time + offset, within +- ``half_width`` seconds."""

    offset: float
    half_width: float


def calibrate(led: DigitalOutput, trace: Trace, samples: int = 20) -> Clock:
    """The offset from board time to host time, from ``samples`` edges on the clock pin.

    Each edge lies between its call and its Ack, so each sample bounds the offset; their
    intersection is the estimate. On a loaded host the simulated board's clock can fall
    behind the wall clock (firmware/posix caps each step it takes), so the bounds need
    not intersect: then the median of the samples' midpoints is the offset, and the
    uncertainty reported is how far the midpoints spread around it, plus a half window.
    """
    lower, upper = -1e9, 1e9
    windows: list[tuple[float, float]] = []
    level = bool(led.value)
    for _ in range(samples):
        level = not level
        before = trace.update()[-1]["t"] if trace.update() else -1.0
        t_call = time.monotonic()
        led.write(level)
        t_ack = time.monotonic()
        changed = wait_changes(trace, {CLOCK_PIN: int(level)}, before)
        if changed is None:
            continue
        # The trace time of a digital change is its edge: between the call and the Ack.
        windows.append((t_call - changed[CLOCK_PIN], t_ack - changed[CLOCK_PIN]))
        lower = max(lower, windows[-1][0])
        upper = min(upper, windows[-1][1])
    if not windows:
        raise RuntimeError("no edge of the clock pin reached the trace")
    if lower <= upper:
        return Clock((lower + upper) / 2, (upper - lower) / 2)
    mids = sorted((lo + hi) / 2 for lo, hi in windows)
    offset = mids[len(mids) // 2]
    half = max((hi - lo) / 2 for lo, hi in windows)
    return Clock(offset, max(abs(m - offset) for m in mids) + half)


@dataclass(slots=True)
class PoseStats:
    joints: int
    method: str
    to_pins: list[float] = field(default_factory=list)  # call -> last joint at the pins (s)
    spread: list[float] = field(default_factory=list)  # first joint -> last joint (s)
    returned: list[float] = field(default_factory=list)  # call -> call returned (s)
    lost: int = 0


def _move(method: str, board: Board, servos: Sequence[Servo], targets: Sequence[int]) -> None:
    if method == "pose":
        board.pose(dict(zip(servos, targets, strict=True)))
    elif method == "separate writes":
        for servo, degrees in zip(servos, targets, strict=True):
            servo.write(degrees)
    else:
        threads = [
            threading.Thread(target=s.write, args=(d,))
            for s, d in zip(servos, targets, strict=True)
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join()


def measure_poses(
    board: Board, trace: Trace, clock: Clock, trials: int, seed: int
) -> list[PoseStats]:
    # Each trial waits until the trace shows the last one, and the emulated Uno writes a
    # servo's line a frame after the change: without a random pause the trials would all
    # start at the same phase of the servo frame, and the wait for the next frame would be
    # the same, unrepresentative, share of every call-to-pin time.
    rng = random.Random(seed)
    out: list[PoseStats] = []
    for joints in JOINTS:
        servos = [board.servo(pin) for pin in ARM_PINS[:joints]]
        stats = {m: PoseStats(joints, m) for m in METHODS}
        for trial in range(trials):
            for method in METHODS:  # the methods take turns
                targets = [
                    (37 * trial + 53 * i + 11 * METHODS.index(method)) % 170 + 5
                    for i in range(joints)
                ]
                wants = {s.pin: us(d) for s, d in zip(servos, targets, strict=True)}
                if any(s.value == w for s, w in zip(servos, wants.values(), strict=True)):
                    targets = [t + 3 for t in targets]
                    wants = {s.pin: us(d) for s, d in zip(servos, targets, strict=True)}
                time.sleep(rng.uniform(0.0, 0.020))
                after = trace.update()[-1]["t"] if trace.events else 0.0
                t0 = time.monotonic()
                _move(method, board, servos, targets)
                t1 = time.monotonic()
                changed = wait_changes(trace, wants, after)
                s = stats[method]
                if changed is None:
                    s.lost += 1
                    continue
                s.returned.append(t1 - t0)
                s.to_pins.append(max(changed.values()) + clock.offset - t0)
                s.spread.append(max(changed.values()) - min(changed.values()))
        out += [stats[m] for m in METHODS]
    return out


@dataclass(slots=True)
class RateStats:
    method: str
    rates: list[float] = field(default_factory=list)


def _rate_once(method: str, servos: Sequence[Servo], total: int) -> float:
    t0 = time.perf_counter()
    if method == "futures, one thread":
        futures: list[Future[None]] = [
            servos[i % len(servos)].submit(i % 180) for i in range(total)
        ]
        wait(futures)
        for f in futures:
            f.result()
    elif method == "blocking loop, one thread":
        for i in range(total):
            servos[i % len(servos)].write(i % 180)
    else:
        per = total // THREADS

        def loop(servo: Servo) -> None:
            for i in range(per):
                servo.write(i % 180)

        threads = [threading.Thread(target=loop, args=(servos[k],)) for k in range(THREADS)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        total = per * THREADS
    return total / (time.perf_counter() - t0)


RATE_METHODS: tuple[str, ...] = (
    "futures, one thread",
    "blocking loop, one thread",
    f"blocking loop, {THREADS} threads",
)


def measure_rates(board: Board, total: int, rounds: int = 3) -> list[RateStats]:
    servos = [board.servo(pin) for pin in ARM_PINS[:THREADS]]
    out = {m: RateStats(m) for m in RATE_METHODS}
    for _ in range(rounds):
        for method in RATE_METHODS:
            out[method].rates.append(_rate_once(method, servos, total))
    return list(out.values())


@dataclass(slots=True)
class BoardResult:
    backend: str
    clock: Clock | None = None
    poses: list[PoseStats] = field(default_factory=list)
    rates: list[RateStats] = field(default_factory=list)
    error: str | None = None


def collect(trials: int, commands: int, seed: int = 7) -> list[BoardResult]:
    def measure(result: BoardResult, sim: SimBoard, trace: Trace, board: Board) -> None:
        led = board.digital_output(CLOCK_PIN)
        result.clock = calibrate(led, trace)
        result.poses = measure_poses(board, trace, result.clock, trials, seed)
        result.rates = measure_rates(board, commands)

    return on_each_board("motion", BoardResult, measure)


def _ms(values: list[float], q: float = 0.5) -> str:
    if not values:
        return "-"
    ordered = sorted(values)
    return f"{ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000:.1f}"


def run(ctx: Context) -> SectionResult:
    trials = max(3, min(TRIALS, ctx.samples // 20))
    commands = max(40, ctx.commands // 3)
    results = collect(trials, commands, ctx.seed)
    parts = [
        f"**Poses.** {trials} trials per case, the methods taking turns, each moving every "
        "joint to a new angle: `Board.pose({servo: degrees, ...})` (one command), `Servo.write` "
        "for each joint one after another, and one thread per joint each calling "
        "`Servo.write`. *To the pins*: from the call until the last joint shows its new width "
        "in the board's trace; *spread*: from the first joint's change to the last one's; "
        "*returned*: until the call (or the last thread) returned. Median and 90th percentile, "
        "in ms. A servo shows a new width at its next 20 ms frame, so up to a frame of every "
        "to-the-pins time is the frame's phase (each trial starts after a random pause of "
        "0-20 ms, so that the phases vary). The call-to-pin times compare host and board "
        "clocks (both CLOCK_MONOTONIC) through an offset measured with digital toggles; its "
        "uncertainty is given per board.\n",
        f"**Commands per second.** {commands} acknowledged servo commands per round, 3 rounds, "
        "the methods taking turns, the median round: `Servo.submit` in a loop from one thread "
        "then waiting for every future, `Servo.write` in a loop from one thread, and "
        f"`Servo.write` loops in {THREADS} threads. The board keeps its default window "
        "(4 commands awaiting their Ack).\n",
    ]
    for result in results:
        label = LABELS[result.backend]
        if result.error is not None:
            parts.append(f"The {label} was not run: {result.error}.\n")
            continue
        assert result.clock is not None
        parts.append(f"### {label[0].upper()}{label[1:]}\n")
        parts.append(
            f"Host/board clock offset known within +-{result.clock.half_width * 1000:.2f} ms.\n"
        )
        rows = [
            [
                str(p.joints),
                p.method,
                _ms(p.to_pins),
                _ms(p.to_pins, 0.9),
                _ms(p.spread),
                _ms(p.spread, 0.9),
                _ms(p.returned),
                str(p.lost),
            ]
            for p in result.poses
        ]
        parts.append(
            md_table(
                [
                    "joints",
                    "method",
                    "to the pins, median",
                    "p90",
                    "spread, median",
                    "p90",
                    "returned, median",
                    "lost",
                ],
                rows,
                "rlrrrrrr",
            )
        )
        rate_rows = [
            [
                r.method,
                fmt_rate(statistics.median(r.rates)),
                fmt_rate(min(r.rates)),
                fmt_rate(max(r.rates)),
            ]
            for r in result.rates
        ]
        parts.append(md_table(["method", "commands/s, median", "min", "max"], rate_rows))
    return SectionResult("\n".join(parts))


SECTION = Section(6, "motion", "Motion: poses, futures, threads", run)
