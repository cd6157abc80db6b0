"""Benchmark part 1 (docs/performance.md).

The host receive path, protoduino next to its peers, fed from memory.

Each library's stream is built with that library's own encoder, held in memory, cut into reads
of ``ctx.chunk`` bytes and consumed from a fresh parser state per repetition, up to the point
where a message reaches the application (a pending call resolved, a handler called). Rates are
frames and bytes per CPU second (see :mod:`bench.core`); the CPU share a line rate needs is that
rate divided by the measured bytes per second.

protoduino is measured twice, with each of its stream decoders: the C accelerator
(``protoduino._speedups``, what ``framing.StreamDecoder`` is when it was built) and the pure-Python
``PyStreamDecoder`` (the reference and fallback). The section then splits protoduino's time per
frame into its stages, measured in the same run on the same stream, and when a target is missed
adds a profile of the path (cProfile).
"""

from __future__ import annotations

import cProfile
import functools
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

log = logging.getLogger(__name__)

#: The targets this part is judged against (docs/performance.md shows them met or not).
GOAL_RATIO_TO_PYMAVLINK = 5.0
GOAL_CPU_AT_1MBPS = 0.10

CaseFactory = Callable[[int, int, int], RxCase]

#: The libraries compared, protoduino first (one row per stream decoder, the C accelerator first
#: when it was built): (label, factory).
PEERS: tuple[tuple[str, CaseFactory], ...] = (
    *(
        (label, functools.partial(protoduino.rx_case, decoder=decoder, name=label))
        for label, decoder in protoduino.DECODERS
    ),
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


def _results_table(results: list[RxResult], n_protoduino: int) -> str:
    base = results[0]
    header = [
        "library",
        "mean frame",
        "frames/s",
        "MB/s",
        f"{base.case.name} ÷ it, frames/s",
        *([f"{results[1].case.name} ÷ it, frames/s"] if n_protoduino > 1 else []),
        f"{base.case.name} ÷ it, bytes/s",
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
                *([f"{results[1].ratio(r):.2f}x"] if n_protoduino > 1 else []),
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


@dataclass(frozen=True, slots=True)
class Stages:
    """protoduino's CPU time per frame (us), split by stage, for one stream decoder.

    Each stage is measured on its own in the same interleaved run; ``rest`` is what the whole
    path costs beyond them: the request layer's loop over the items, SEQ check, reads of the
    Ack's fields, pending-call lookup and listener calls.
    """

    label: str
    decoder: float
    data: float
    control: float
    whole: float

    @property
    def rest(self) -> float:
        return self.whole - self.decoder - self.data - self.control


def _stage_cases(ctx: Context) -> list[RxCase]:
    """The stream decoders alone, then the DATA and CONTROL payload parsing alone."""
    args = (ctx.frames, ctx.chunk, ctx.seed)
    cases = [
        protoduino.framing_only_case(*args, decoder=decoder, name=f"{label}, decoder alone")
        for label, decoder in protoduino.DECODERS
    ]
    cases.append(protoduino.payload_case(*args, control=False))
    cases.append(protoduino.payload_case(*args, control=True))
    return cases


def _stages(base: RxResult, whole: Sequence[RxResult], parts: Sequence[RxResult]) -> list[Stages]:
    """Per-frame times as ``base``'s median scaled by the paired ratios (all these cases run
    over the same stream, so a frame-rate ratio is the inverse time ratio)."""

    def us(r: RxResult) -> float:
        return base.us_per_frame / r.ratio(base)

    decoders, data, control = parts[: len(whole)], parts[-2], parts[-1]
    return [
        Stages(w.case.name, us(d), us(data), us(control), us(w))
        for w, d in zip(whole, decoders, strict=True)
    ]


def _stages_table(stages: Sequence[Stages], budget_us: float) -> str:
    names = [
        ("stream decoder: bytes -> Packet", "decoder"),
        ("DATA payloads: messages.parse_out (protobuf upb)", "data"),
        ("CONTROL payloads: packets.parse_control", "control"),
        ("the rest: the request layer's per-packet Python (see below)", "rest"),
    ]
    header = ["stage, us of CPU per frame"]
    for s in stages:
        header += [s.label, "share"]
    rows = []
    for title, attr in names:
        row = [title]
        for s in stages:
            value = getattr(s, attr)
            row += [f"{value:.2f}", f"{value / s.whole * 100:.0f} %"]
        rows.append(row)
    total = ["**whole receive path**"]
    for s in stages:
        total += [f"**{s.whole:.2f}**", "100 %"]
    rows.append(total)
    budget = ["budget for 10 % of a core at 1 MB/s"]
    for _s in stages:
        budget += [f"{budget_us:.2f}", ""]
    rows.append(budget)
    return md_table(header, rows)


def _verdict(stages: Sequence[Stages], budget_us: float, ratio: float | None, cpu: float) -> str:
    """Why the targets are met or missed, from the measured stages."""
    fast = stages[0]
    above = fast.whole - fast.decoder
    lines = []
    if len(stages) > 1:
        slow = stages[-1]
        lines.append(
            f"The C decoder takes {fast.decoder:.2f} us per frame where the pure-Python one "
            f"takes {slow.decoder:.2f} us ({slow.decoder / fast.decoder:.1f}x); the whole path "
            f"goes from {slow.whole:.2f} to {fast.whole:.2f} us per frame "
            f"({slow.whole / fast.whole:.2f}x)."
        )
    lines.append(
        f"With {fast.label}, the decoder is {fast.decoder / fast.whole * 100:.0f} % of the "
        f"path; the other {above:.2f} us per frame are the layers above it, in Python: "
        f"protobuf parsing of DATA payloads ({fast.data:.2f} us per stream frame), CONTROL "
        f"parsing ({fast.control:.2f} us) and the rest of the request layer's per-packet "
        f"work ({max(fast.rest, 0):.2f} us: the loop over the items, the SEQ check, reading "
        "the Ack's fields from the upb message, the pending-call lookup, the listener calls)."
    )
    if cpu >= GOAL_CPU_AT_1MBPS:
        if above >= budget_us:
            lines.append(
                f"10 % of a core at 1 MB/s leaves {budget_us:.2f} us per frame for everything; "
                f"the layers above the decoder take {above:.2f} us on their own, so no stream "
                "decoder can meet that goal: it needs the per-packet dispatch (SEQ, Ack "
                "matching, CONTROL parsing) out of the interpreter as well, or fewer, larger "
                "frames (the cost is per frame, not per byte)."
            )
        else:
            lines.append(
                f"10 % of a core at 1 MB/s leaves {budget_us:.2f} us per frame; the path takes "
                f"{fast.whole:.2f} us."
            )
    if ratio is not None and ratio < GOAL_RATIO_TO_PYMAVLINK:
        bound = ratio * fast.whole / above if above > 0 else float("inf")
        lines.append(
            f"Against pymavlink the path is {ratio:.2f}x (goal "
            f"{GOAL_RATIO_TO_PYMAVLINK:.0f}x). A stream decoder costing nothing would make it "
            f"at most {bound:.2f}x: what is left is Python per packet above the decoder, the "
            "same kind of work pymavlink does per message."
        )
    return "\n\n".join(lines) + "\n"


def run(ctx: Context) -> SectionResult:
    peer_cases: list[RxCase] = []
    skipped: list[tuple[str, str]] = []
    packages = ["protoduino", "protobuf", "cobs"]
    for label, factory in PEERS:
        try:
            case = factory(ctx.frames, ctx.chunk, ctx.seed)
        except MissingDependencyError as missing:
            log.warning("receive: %s skipped: %s", label, missing)
            skipped.append((label, f"`{missing.package}` not installed"))
            continue
        peer_cases.append(case)
        packages.append(case.package)
    n_pd = len(protoduino.DECODERS)
    stage_cases = _stage_cases(ctx)
    measured = run_cases([*peer_cases, *stage_cases], ctx.reps)
    results = measured[: len(peer_cases)]
    base = results[0]
    stages = _stages(base, results[:n_pd], measured[len(peer_cases) :])
    by_package = {r.case.package: r for r in results[n_pd:]}
    budget_us = GOAL_CPU_AT_1MBPS / (1_000_000 / base.frame_size) * 1e6

    parts = [
        f"Fed from memory in reads of {ctx.chunk} B; {ctx.frames:,} frames per stream. "
        "protoduino runs twice, once with each stream decoder: the C accelerator "
        "(`protoduino._speedups`, which `framing.StreamDecoder` is wherever it was built) and "
        "the pure-Python `PyStreamDecoder` (the reference and fallback); everything above the "
        f"decoder is the same Python. Rates are per CPU second of this process, medians of "
        f"{ctx.reps} repetitions; the cases take turns, one repetition each per round, and a "
        "ratio is the median of the ratios within a round, which cancels most of the "
        "machine's drift. The first row's rate is its median; every other rate is that "
        "divided by the paired ratio, so that rates, ratios and CPU shares agree. Spread = "
        "(max - min) / median of a case's repetitions: a large one means the machine's speed "
        "changed during the run, and the absolute rates and CPU shares carry that "
        "uncertainty, the ratios much less. A CPU share above 100 % means one core cannot "
        "keep up.\n",
        _results_table(results, n_pd),
        "What each row does, from bytes to the application:\n",
    ]
    parts += [f"- **{r.case.name}**: {r.case.stages}. Parser: {r.case.parser}." for r in results]
    parts.append("")
    if n_pd == 1:
        skipped.insert(
            0,
            (
                "protoduino (C accelerator)",
                "`protoduino._speedups` not built: it needs a C compiler and the Python headers",
            ),
        )
    if skipped:
        parts.append(
            "Not run here: " + ", ".join(f"{label} ({why})" for label, why in skipped) + ".\n"
        )
    parts.append(_mix_table(ctx.frames))

    targets: list[Target] = []
    mav = by_package.get("pymavlink")
    ratio: float | None = None
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
        others = "".join(f"; {r.case.name} {r.ratio(mav):.2f}x" for r in results[1:n_pd])
        targets.append(
            Target(
                "receive rate vs pymavlink",
                f">= {GOAL_RATIO_TO_PYMAVLINK:.0f}x pymavlink's frames/s",
                f"{ratio:.2f}x with {base.case.name} ({fmt_rate(base.frames_per_s)} vs "
                f"{fmt_rate(mav.scaled_to(base)[0])} frames/s; "
                f"{base.ratio(mav, per_byte=True):.2f}x in bytes/s){others}",
                ratio >= GOAL_RATIO_TO_PYMAVLINK,
            )
        )
    share = cpu_share(1_000_000, base.bytes_per_s)
    others = "".join(
        f"; {r.case.name} {fmt_percent(cpu_share(1_000_000, r.scaled_to(base)[1]))}"
        for r in results[1:n_pd]
    )
    targets.append(
        Target(
            "receive CPU at 1 MB/s",
            f"< {fmt_percent(GOAL_CPU_AT_1MBPS)} of a core",
            f"{fmt_percent(share)} with {base.case.name}{others}",
            share < GOAL_CPU_AT_1MBPS,
        )
    )

    parts.append("### Where the time goes\n")
    parts.append(
        "Each stage measured on its own, in the same run and on the same stream: each stream "
        "decoder alone, then the stream's DATA and CONTROL payloads (already decoded) through "
        "the parsing the request layer does; the rest is the whole path minus those. Times are "
        "per frame of the stream (a stage that handles only DATA frames is spread over all of "
        f"them). At {base.frame_size:.1f} B per frame, 1 MB/s is "
        f"{fmt_rate(1_000_000 / base.frame_size)} frames/s, and 10 % of a core leaves "
        f"{budget_us:.2f} us per frame.\n"
    )
    parts.append(_stages_table(stages, budget_us))
    parts.append(_verdict(stages, budget_us, ratio, share))
    if any(t.met is False for t in targets) and ctx.profile:
        parts.append(
            f"Profile of one pass over the stream with {base.case.name} (cProfile, which "
            "inflates the cost of each Python call; own time first; the C decoder shows as one "
            "`feed` call per read):\n\n```\n" + _profile(base.case) + "\n```\n"
        )

    chart_list: list[Chart] = []
    if ctx.chart_dir is not None:
        # (label, frames/s, bytes/s) as the tables give them: the first row's medians scaled
        # by each row's paired ratio.
        rows = [(r.case.name, *r.scaled_to(base)) for r in results]
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
            secondary=range(1, n_pd),
            vline=("target 10 %", GOAL_CPU_AT_1MBPS * 100),
        )
        chart_list.append(
            Chart(path, "Receive path: frames per CPU second and the share of a core 1 MB/s needs")
        )
        path = charts.stacked_hbars(
            ctx.chart_dir / "receive_stages.png",
            [s.label for s in stages],
            [
                ("stream decoder", [s.decoder for s in stages]),
                ("DATA: protobuf parse", [s.data for s in stages]),
                ("CONTROL parse", [s.control for s in stages]),
                ("request layer (the rest)", [max(s.rest, 0.0) for s in stages]),
            ],
            title="protoduino's receive path: CPU time per frame, by stage",
            xlabel="us of CPU per frame",
            vline=(f"10 % of a core at 1 MB/s ({budget_us:.2f} us)", budget_us),
            legend_below=True,
        )
        chart_list.append(Chart(path, "protoduino's CPU time per frame, by stage"))
    return SectionResult("\n".join(parts), targets, chart_list, packages)


SECTION = Section(1, "receive", "Host receive path", run)
