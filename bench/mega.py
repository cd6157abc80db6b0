"""Benchmark part 11 (docs/performance.md): the Mega 2560's 24 servos.

A figure only the Mega has (issue 36): 24 servos, on both of its servo timers (Timer1's
channels 0..11, Timer5's 12..23: firmware/README.md, The Mega 2560), driven to new widths by
three poses of eight (a Pose carries at most 8 items: protoduino.options), on the emulated
Mega (``SimBoard("avr", board="mega")``: the firmware's ``make avr BOARD=mega`` build on
simavr's ATmega2560). Each trial measures

* the poses' round trips on the host's clock: each pose's call to its Ack, and the three
  one after another;
* at the pins, on the board's clock (its trace): from the first servo at its new width to the
  last, and how far each servo's later pulses stay from the width posed (every servo line of
  the trace until the next trial).

The link stays at 115200 baud (no switch to a faster rate: the figure's wire time is that
rate's), and simavr times a UART byte as 11 bits at the 117,647 baud the firmware's UBRR sets
(``bench.wire.EMULATED_BYTE_US``), not 10 at 115200: the round trips depend on it.
"""

from __future__ import annotations

import logging
import random
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

from protoduino import Board, Servo

from .boards import BoardUnavailableError, Percentiles, Trace, started
from .core import Context, Section, SectionResult, md_table
from .motion import wait_changes
from .wire import BAUD, EMULATED_BYTE_US

log = logging.getLogger(__name__)

#: The 24 servo pins: 4..15 and 20..31, as the run in docs/performance.md had them (16..19,
#: INT3 and INT2 among them, upset the emulated Mega's link until the runner stopped simavr
#: polling external interrupts' levels: tests/e2e/test_mega.py drives 4..27).
PINS: tuple[int, ...] = (*range(4, 16), *range(20, 32))
#: A Pose's most items (host board.MAX_POSE_ITEMS).
PER_POSE = 8
#: A servo's line matches a posed width within this many us (the new widths differ from the
#: old by more: :func:`targets`).
MATCH_US = 20
#: How long one trial's widths may take to reach the pins before it counts as lost (host).
SETTLE = 10.0


@dataclass(slots=True)
class MegaRun:
    """One run's measurements; ``error`` when the emulated Mega could not run."""

    trials: int = 0
    lost: int = 0
    pose_s: list[float] = field(default_factory=list)  # each pose's call -> Ack
    poses_s: list[float] = field(default_factory=list)  # the three poses, call -> last Ack
    spread_s: list[float] = field(default_factory=list)  # first servo -> last at the pins
    deviations: list[int] = field(default_factory=list)  # |line - posed| of every servo line
    bytes_out: float = 0.0  # per trial, host -> board
    bytes_in: float = 0.0  # per trial, board -> host
    error: str | None = None


def targets(rng: random.Random, servos: dict[int, Servo], now: dict[int, int]) -> dict[int, int]:
    """New degrees for every servo, each width more than MATCH_US from its current one."""
    out: dict[int, int] = {}
    for pin, servo in servos.items():
        degrees = rng.randrange(0, 181)
        while abs(servo.to_us(degrees) - now[pin]) <= MATCH_US:
            degrees = rng.randrange(0, 181)
        out[pin] = degrees
    return out


def deviations(
    events: list[dict[str, Any]], windows: list[tuple[dict[int, float], dict[int, int], float]]
) -> list[int]:
    """|line - posed| of every servo line from each pin's first new line to the window's end,
    both included: the end is the last line before the next trial's poses (its time, read
    from the trace), often the last pin's first new line itself (left out, a trial had 23 of
    24 pins whenever no latency outlier added a line)."""
    out: list[int] = []
    for starts, wants, end in windows:
        for e in events:
            pin = int(e["pin"])
            if e["mode"] == "servo" and pin in starts and starts[pin] <= e["t"] <= end:
                out.append(abs(int(e["value"]) - wants[pin]))
    return out


def measure(trials: int, seed: int) -> MegaRun:
    run = MegaRun()
    rng = random.Random(seed)
    try:
        with (
            TemporaryDirectory(prefix="bench-mega-") as tmp,
            started("avr", board="mega", trace=Path(tmp) / "trace.jsonl") as sim,
            Board.open(sim.port, baudrate=BAUD) as board,
        ):
            if board.info.max_servos < len(PINS):
                run.error = f"the Mega build has {board.info.max_servos} servos, not {len(PINS)}"
                return run
            assert sim.trace_path is not None
            trace = Trace(sim.trace_path)
            servos = {pin: board.servo(pin) for pin in PINS}
            now = {pin: servo.to_us(90) for pin, servo in servos.items()}  # their safe 90
            windows: list[tuple[dict[int, float], dict[int, int], float]] = []
            stats0 = board.stats
            for _ in range(trials):
                degrees = targets(rng, servos, now)
                wants = {pin: servos[pin].to_us(d) for pin, d in degrees.items()}
                time.sleep(rng.uniform(0.0, 0.020))  # any phase of the servo frames
                after = trace.update()[-1]["t"] if trace.events else 0.0
                if windows:
                    windows[-1] = (*windows[-1][:2], after)
                t0 = time.perf_counter()
                for first in range(0, len(PINS), PER_POSE):
                    pins = PINS[first : first + PER_POSE]
                    t = time.perf_counter()
                    board.pose({servos[pin]: degrees[pin] for pin in pins})
                    run.pose_s.append(time.perf_counter() - t)
                run.poses_s.append(time.perf_counter() - t0)
                changed = wait_changes(trace, wants, after, tolerance=MATCH_US, mode="servo")
                run.trials += 1
                if changed is None:
                    run.lost += 1
                    continue
                run.spread_s.append(max(changed.values()) - min(changed.values()))
                windows.append((changed, wants, float("inf")))
                now = wants
            stats1 = board.stats
            run.bytes_out = (stats1.tx_bytes - stats0.tx_bytes) / max(trials, 1)
            run.bytes_in = (stats1.rx_bytes - stats0.rx_bytes) / max(trials, 1)
            time.sleep(0.1)  # a few more frames of the last widths into the trace
            run.deviations = deviations(trace.update(), windows)
    except BoardUnavailableError as error:
        run.error = str(error)
    return run


def _row(what: str, values: list[float]) -> list[str]:
    if not values:
        return [what, "-", "-", "-"]
    p = Percentiles.of(values)
    return [what, *(f"{v * 1e3:.1f}" for v in (p.p50, p.p90, p.high))]


def report(run: MegaRun) -> str:
    if run.error is not None:
        return f"Not run: the emulated Mega ({run.error}).\n"
    rows = [
        _row("each pose, call to Ack (host clock)", run.pose_s),
        _row("the three poses, first call to last Ack (host clock)", run.poses_s),
        _row("first servo to last at its new width (board clock)", run.spread_s),
    ]
    worst = max(run.deviations) if run.deviations else 0
    within = sum(1 for d in run.deviations if d <= 3)
    parts = [
        f"24 servos on the emulated Mega 2560 (pins {PINS[0]}..{PINS[11]} on Timer1, "
        f"{PINS[12]}..{PINS[-1]} on Timer5), moved to new widths by three poses of "
        f"{PER_POSE} (a Pose's most items), {run.trials} trials"
        + (f", {run.lost} of them lost (not at the pins within {SETTLE:.0f} s)" if run.lost else "")
        + f". The link at {BAUD:,} baud: simavr times a byte as 11 bits at the firmware's "
        f"117,647 baud, {EMULATED_BYTE_US:.1f} us a byte, and the round trips count that; "
        f"{run.bytes_out:.0f} B to the board and {run.bytes_in:.0f} B back a trial (three "
        "poses, their Acks and the automatic Pings).\n",
        md_table(["ms", "p50", "p90", "max"], rows),
        f"Every width at the pins: {len(run.deviations):,} servo lines of the trace (each a "
        "change of a pulse's measured width, from the servo's first pulse at its new width to "
        f"the next trial), all within {worst} us of the width posed, {within:,} of them within "
        "3 us. An edge of one timer's interrupt that falls on the other's waits for it, a few "
        "microseconds (firmware/README.md, The Mega 2560).\n",
    ]
    return "\n".join(parts)


def run(ctx: Context) -> SectionResult:
    trials = max(3, ctx.samples // 10)
    result = measure(trials, ctx.seed)
    if result.spread_s:
        log.info(
            "mega: %d trials, spread p50 %.1f ms",
            result.trials,
            1e3 * statistics.median(result.spread_s),
        )
    return SectionResult(report(result))


SECTION = Section(11, "mega", "The Mega 2560: 24 servos from three poses", run)
