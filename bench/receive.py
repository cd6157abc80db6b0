"""Part 1 of issue 7: the host receive path, protoduino next to its peers, fed from memory.

Each library's stream is built with that library's own encoder, held in memory, cut into reads
of ``ctx.chunk`` bytes and consumed from a fresh parser state per repetition, up to the point
where a message reaches the application (a pending call resolved, a handler called). Rates are
frames and bytes per CPU second (see :mod:`bench.core`); the CPU share a line rate needs is that
rate divided by the measured bytes per second.

The proposals in :mod:`bench.proposal` are measured step by step in the same run, on the same
stream; when a target is missed the section shows them with a profile of protoduino's path
(cProfile).
"""

from __future__ import annotations

import cProfile
import io
import logging
import pstats
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from . import charts
from .core import (
    LINE_RATES,
    Chart,
    Context,
    MissingDependencyError,
    Section,
    SectionResult,
    Target,
    Timing,
    cpu_share,
    fmt_percent,
    fmt_rate,
    md_table,
    measure_interleaved,
)
from .peers import RxCase, mavlink, pigweed, protoduino, serialtransfer
from .proposal import FastStreamDecoder, LightPacketDecoder, parse_out_from_string

log = logging.getLogger(__name__)

#: Goals from issue 7.
GOAL_RATIO_TO_PYMAVLINK = 5.0
GOAL_CPU_AT_1MBPS = 0.10

CaseFactory = Callable[[int, int, int], RxCase]

#: The libraries compared, protoduino first: (label, PyPI package, factory).
PEERS: tuple[tuple[str, CaseFactory], ...] = (
    ("protoduino", protoduino.rx_case),
    ("pymavlink", mavlink.rx_case),
    ("pigweed", pigweed.rx_case),
    ("pySerialTransfer", serialtransfer.rx_case),
)


@dataclass(frozen=True, slots=True)
class RxResult:
    case: RxCase
    timing: Timing

    @property
    def frames_per_s(self) -> float:
        return self.case.frames / self.timing.median

    @property
    def bytes_per_s(self) -> float:
        return len(self.case.stream) / self.timing.median

    @property
    def frame_size(self) -> float:
        return len(self.case.stream) / self.case.frames

    @property
    def us_per_frame(self) -> float:
        return self.timing.median / self.case.frames * 1e6

    def scaled_to(self, base: RxResult) -> tuple[float, float]:
        """This case's frames/s and bytes/s as ``base``'s medians times the paired ratios:
        the figures the report shows, so that rates, ratios and CPU shares agree."""
        return (
            base.frames_per_s * self.ratio(base),
            base.bytes_per_s * self.ratio(base, per_byte=True),
        )

    def ratio(self, other: RxResult, *, per_byte: bool = False) -> float:
        """How many times faster this case is than ``other``, in frames (or bytes) per second.

        The median of the ratios within each round of :func:`run_cases`, not the ratio of the
        medians: both cases of a round ran within a second of each other, so a slow spell of
        the machine cancels out of their ratio.
        """
        mine = len(self.case.stream) if per_byte else self.case.frames
        theirs = len(other.case.stream) if per_byte else other.case.frames
        return statistics.median(
            (mine / t_mine) / (theirs / t_theirs)
            for t_mine, t_theirs in zip(self.timing.samples, other.timing.samples, strict=True)
        )


def run_cases(cases: Sequence[RxCase], reps: int) -> list[RxResult]:
    """Check that every case dispatches all its frames (which also warms it up), then time
    them all, taking turns (:func:`bench.core.measure_interleaved`)."""
    for case in cases:
        got = case.run()
        if got != case.frames:
            raise RuntimeError(f"{case.name}: dispatched {got} of {case.frames} frames")
    timings = measure_interleaved([case.run for case in cases], reps, warmup=0)
    results = [RxResult(case, timing) for case, timing in zip(cases, timings, strict=True)]
    for r in results:
        log.info(
            "receive: %-40s %10s frames/s %8.2f MB/s (spread %s)",
            r.case.name,
            fmt_rate(r.frames_per_s),
            r.bytes_per_s / 1e6,
            fmt_percent(r.timing.spread),
        )
    return results


def run_case(case: RxCase, reps: int) -> RxResult:
    return run_cases([case], reps)[0]


def _profile(case: RxCase, top: int = 14) -> str:
    """cProfile of one run of ``case``, the ``top`` functions by own time."""
    profiler = cProfile.Profile()
    profiler.enable()
    case.run()
    profiler.disable()
    out = io.StringIO()
    stats = pstats.Stats(profiler, stream=out)
    stats.strip_dirs().sort_stats("tottime").print_stats(top)
    lines = [line.rstrip() for line in out.getvalue().splitlines()]
    start = next((i for i, line in enumerate(lines) if line.lstrip().startswith("ncalls")), 0)
    return "\n".join(line for line in lines[start:] if line)


def _share_cells(bytes_per_s: float) -> list[str]:
    return [fmt_percent(cpu_share(rate, bytes_per_s)) for _name, rate in LINE_RATES]


def _results_table(results: list[RxResult]) -> str:
    base = results[0]
    header = [
        "library",
        "mean frame",
        "frames/s",
        "MB/s",
        "protoduino ÷ it, frames/s",
        "protoduino ÷ it, bytes/s",
        *[f"CPU at {name}" for name, _rate in LINE_RATES],
        "spread",
    ]
    rows = []
    for r in results:
        frames_per_s, bytes_per_s = r.scaled_to(base)
        rows.append(
            [
                r.case.name,
                f"{r.frame_size:.1f} B",
                fmt_rate(frames_per_s),
                f"{bytes_per_s / 1e6:.2f}",
                f"{base.ratio(r):.2f}x",
                f"{base.ratio(r, per_byte=True):.2f}x",
                *_share_cells(bytes_per_s),
                fmt_percent(r.timing.spread),
            ]
        )
    return md_table(header, rows)


def _mix_table(frames: int) -> str:
    total = sum(weight for _name, weight in protoduino.MIX)
    rows = [[name, f"{weight * 100 / total:.0f} %"] for name, weight in protoduino.MIX]
    return (
        f"protoduino's stream ({frames:,} frames, drawn at random with these weights, "
        "SEQ counting up as a device sends them):\n\n" + md_table(["frame", "share"], rows)
    )


#: The proposal steps, each keeping the previous ones.
STEP_LABELS = (
    "+ FastStreamDecoder",
    "+ Packet built at slots-class cost",
    "+ ArduinoOut.FromString in parse_out",
)
FRAMING_LABELS = ("StreamDecoder (committed)", "FastStreamDecoder", "LightPacketDecoder")


def _proposal_cases(ctx: Context) -> list[RxCase]:
    """The three proposal steps on the whole path, then the three decoders alone."""
    args = (ctx.frames, ctx.chunk, ctx.seed)
    return [
        protoduino.rx_case(*args, decoder=FastStreamDecoder, name=STEP_LABELS[0]),
        protoduino.rx_case(*args, decoder=LightPacketDecoder, name=STEP_LABELS[1]),
        protoduino.rx_case(
            *args, decoder=LightPacketDecoder, parse=parse_out_from_string, name=STEP_LABELS[2]
        ),
        protoduino.framing_only_case(*args, name=FRAMING_LABELS[0]),
        protoduino.framing_only_case(*args, decoder=FastStreamDecoder, name=FRAMING_LABELS[1]),
        protoduino.framing_only_case(*args, decoder=LightPacketDecoder, name=FRAMING_LABELS[2]),
    ]


def _proposals(
    baseline: RxResult,
    step_results: Sequence[RxResult],
    framing_results: Sequence[RxResult],
    pymavlink: RxResult | None,
) -> str:
    steps = [("protoduino as committed", baseline), *zip(STEP_LABELS, step_results, strict=True)]
    # Rates below are the committed path's median scaled by each step's paired ratio, so the
    # columns agree with each other even when the machine's speed drifted during the run.
    rows = []
    previous = baseline
    for label, r in steps:
        gain = r.ratio(baseline)
        rows.append(
            [
                label,
                fmt_rate(baseline.frames_per_s * gain),
                f"{baseline.us_per_frame / gain:.2f}",
                f"{gain:.2f}x",
                f"{r.ratio(previous):.2f}x",
                fmt_percent(cpu_share(1_000_000, baseline.bytes_per_s * gain)),
            ]
        )
        previous = r
    table = md_table(
        [
            "whole receive path",
            "frames/s",
            "us/frame",
            "vs committed",
            "vs previous step",
            "CPU at 1 MB/s",
        ],
        rows,
    )
    framing_base = framing_results[0]
    frows = []
    for label, r in zip(FRAMING_LABELS, framing_results, strict=True):
        gain = r.ratio(framing_base)
        frows.append(
            [
                label,
                fmt_rate(framing_base.frames_per_s * gain),
                f"{framing_base.us_per_frame / gain:.2f}",
                f"{gain:.2f}x",
            ]
        )
    ftable = md_table(["stream decoder alone", "frames/s", "us/frame", "vs committed"], frows)
    best = steps[-1][1]
    share = cpu_share(1_000_000, baseline.bytes_per_s * best.ratio(baseline))
    verdicts = [
        f"needs {fmt_percent(share)} of a core at 1 MB/s (goal < "
        f"{fmt_percent(GOAL_CPU_AT_1MBPS)}: {'met' if share < GOAL_CPU_AT_1MBPS else 'missed'})"
    ]
    if pymavlink is not None:
        ratio = best.ratio(pymavlink)
        verdicts.insert(
            0,
            f"is {ratio:.2f}x pymavlink's frame rate (goal {GOAL_RATIO_TO_PYMAVLINK:.0f}x: "
            f"{'met' if ratio >= GOAL_RATIO_TO_PYMAVLINK else 'missed'})",
        )
    framing_us = framing_base.us_per_frame / framing_results[-1].ratio(framing_base)
    budget_us = GOAL_CPU_AT_1MBPS / (1_000_000 / baseline.frame_size) * 1e6
    over_budget = (
        f" Framing alone then takes {framing_us:.2f} us per frame, more than the "
        f"{budget_us:.2f} us that 10 % of a core allows at 1 MB/s: with frames this short, "
        "that goal stays out of reach of these decoders in pure Python."
        if framing_us > budget_us
        else ""
    )
    summary = (
        f"With all three, the receive path {' and '.join(verdicts)}.{over_budget} What is "
        "left per frame is the stream decoder's Python-level work (about "
        f"{framing_us:.2f} us above) plus one protobuf parse and the "
        "dispatch. Going further means splitting, COBS-decoding and CRC-checking a whole read "
        "in one C call; neither the `cobs` package (one frame per call) nor the standard "
        "library offers that, so it would be a small C extension of our own (not measured "
        "here).\n"
    )
    return (
        "Each step keeps the previous ones and is measured on the same stream in the same run. "
        "`FastStreamDecoder` produces exactly what `StreamDecoder` does (items, reasons, raw "
        "bytes, counts; `tests/test_bench_smoke.py` compares them on damaged streams cut at "
        "random), so it can replace it in `framing.py` as is. The Packet step stands for making "
        "`packets.Packet` a plain `__slots__` class or a `NamedTuple` instead of a frozen "
        "dataclass; the last step tries `ArduinoOut.FromString` in `messages.parse_out` (one "
        "line). See "
        "`bench/proposal.py`. Rates and times in these two tables are the committed "
        "version's median scaled by each row's paired ratio.\n\n"
        + table
        + "\n"
        + ftable
        + "\n"
        + summary
    )


def run(ctx: Context) -> SectionResult:
    peer_cases: list[RxCase] = []
    skipped: list[tuple[str, str]] = []
    packages = ["protoduino", "protobuf", "cobs"]
    for label, factory in PEERS:
        try:
            case = factory(ctx.frames, ctx.chunk, ctx.seed)
        except MissingDependencyError as missing:
            log.warning("receive: %s skipped: %s", label, missing)
            skipped.append((label, missing.package))
            continue
        peer_cases.append(case)
        packages.append(case.package)
    extra_cases = _proposal_cases(ctx)
    measured = run_cases([*peer_cases, *extra_cases], ctx.reps)
    results = measured[: len(peer_cases)]
    step_results = measured[len(peer_cases) : len(peer_cases) + len(STEP_LABELS)]
    framing_results = measured[len(peer_cases) + len(STEP_LABELS) :]
    base = results[0]
    by_package = {r.case.package: r for r in results}

    parts = [
        f"Fed from memory in reads of {ctx.chunk} B; {ctx.frames:,} frames per stream. Rates "
        f"are per CPU second of this process, medians of {ctx.reps} repetitions; the cases "
        "take turns, one repetition each per round, and a ratio is the median of the ratios "
        "within a round, which cancels most of the machine's drift. protoduino's rate is its "
        "median; every other rate is that divided by the paired ratio, so that rates, ratios "
        "and CPU shares agree. Spread = (max - min) / median of a case's repetitions: a large "
        "one means the machine's speed changed during the run, and the absolute rates and "
        "CPU shares carry that uncertainty, the ratios much less. A CPU share above 100 % "
        "means one core cannot keep up.\n",
        _results_table(results),
        "What each row does, from bytes to the application:\n",
    ]
    parts += [f"- **{r.case.name}**: {r.case.stages}. Parser: {r.case.parser}." for r in results]
    parts.append("")
    if skipped:
        parts.append(
            "Not run here: "
            + ", ".join(f"{label} (`{package}` not installed)" for label, package in skipped)
            + ".\n"
        )
    parts.append(_mix_table(ctx.frames))

    targets: list[Target] = []
    mav = by_package.get("pymavlink")
    if mav is None:
        targets.append(
            Target(
                "receive rate vs pymavlink",
                f">= {GOAL_RATIO_TO_PYMAVLINK:.0f}x pymavlink's frames/s",
                "pymavlink not installed",
                None,
            )
        )
    else:
        ratio = base.ratio(mav)
        targets.append(
            Target(
                "receive rate vs pymavlink",
                f">= {GOAL_RATIO_TO_PYMAVLINK:.0f}x pymavlink's frames/s",
                f"{ratio:.2f}x ({fmt_rate(base.frames_per_s)} vs "
                f"{fmt_rate(mav.scaled_to(base)[0])} frames/s; "
                f"{base.ratio(mav, per_byte=True):.2f}x in bytes/s)",
                ratio >= GOAL_RATIO_TO_PYMAVLINK,
            )
        )
    share = cpu_share(1_000_000, base.bytes_per_s)
    targets.append(
        Target(
            "receive CPU at 1 MB/s",
            f"< {fmt_percent(GOAL_CPU_AT_1MBPS)} of a core",
            fmt_percent(share),
            share < GOAL_CPU_AT_1MBPS,
        )
    )

    proposal_rows: list[tuple[str, RxResult]] = []
    if any(t.met is False for t in targets):
        parts.append("### Why the targets are missed\n")
        framing_share = 1 / framing_results[0].ratio(base)
        needed = 1_000_000 / base.frame_size
        parts.append(
            f"protoduino spends {base.us_per_frame:.2f} us of CPU per frame; "
            f"{base.us_per_frame * framing_share:.2f} us of that "
            f"({framing_share * 100:.0f} %) is `StreamDecoder` "
            "alone, the rest is protobuf parsing and the per-packet work of the layers above "
            f"(SEQ, dispatch). Its frames are short ({base.frame_size:.1f} B on average"
            + (
                f", against {mav.frame_size:.1f} B for MAVLink's COMMAND_LONG"
                if mav is not None
                else ""
            )
            + f"), so 1 MB/s means {fmt_rate(needed)} frames/s, and 10 % of a core leaves "
            f"{0.1 / needed * 1e6:.2f} us per frame: the cost is per frame (interpreter "
            "calls and objects), not per byte, so a short-frame protocol pays more per byte "
            "than MAVLink does.\n"
        )
        if ctx.profile:
            parts.append(
                "Profile of one pass over the stream (cProfile, which inflates the cost of "
                "each Python call; own time first; `<string>:2(__init__)` is the generated "
                "`__init__` of the frozen dataclasses `Packet` and `Control`):\n\n```\n"
                + _profile(base.case)
                + "\n```\n"
            )
        parts.append("### Proposals, measured\n")
        parts.append(_proposals(base, step_results, framing_results, mav))
        proposal_rows = list(zip(STEP_LABELS, step_results, strict=True))

    chart_list: list[Chart] = []
    if ctx.chart_dir is not None:
        # (label, frames/s, bytes/s) as the tables give them: protoduino's medians scaled by
        # each row's paired ratio.
        rows = [(r.case.name, *r.scaled_to(base)) for r in results]
        rows += [
            (
                f"proposal {label}",
                base.frames_per_s * r.ratio(base),
                base.bytes_per_s * r.ratio(base),
            )
            for label, r in proposal_rows
        ]
        path = charts.hbars(
            ctx.chart_dir / "receive.png",
            [label for label, _f, _b in rows],
            [
                ("frames per CPU second", [fps for _label, fps, _b in rows]),
                (
                    "% of a core at 1 MB/s",
                    [cpu_share(1_000_000, bps) * 100 for _label, _f, bps in rows],
                ),
            ],
            title="Host receive path, fed from memory",
            highlight=0,
            secondary=range(len(results), len(rows)),
            vline=("target 10 %", GOAL_CPU_AT_1MBPS * 100),
        )
        chart_list.append(
            Chart(path, "Receive path: frames per CPU second and the share of a core 1 MB/s needs")
        )
    return SectionResult("\n".join(parts), targets, chart_list, packages)


SECTION = Section(1, "receive", "Host receive path", run)
