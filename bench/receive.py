"""Part 1 of issue 7: the host receive path, protoduino next to its peers, fed from memory.

Each library's stream is built with that library's own encoder, held in memory, cut into reads
of ``ctx.chunk`` bytes and consumed from a fresh parser state per repetition, up to the point
where a message reaches the application (a pending call resolved, a handler called). Rates are
frames and bytes per CPU second (see :mod:`bench.core`); the CPU share a line rate needs is that
rate divided by the measured bytes per second.

When a target is missed the section adds a profile of protoduino's path (cProfile) and measures
the proposals in :mod:`bench.proposal` step by step on the same stream.
"""

from __future__ import annotations

import cProfile
import io
import logging
import pstats
from collections.abc import Callable
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
    measure,
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


def run_case(case: RxCase, reps: int) -> RxResult:
    """Check that ``case`` dispatches every frame, then time it (the check is the warm-up)."""
    got = case.run()
    if got != case.frames:
        raise RuntimeError(f"{case.name}: dispatched {got} of {case.frames} frames")
    result = RxResult(case, measure(case.run, reps, warmup=0))
    log.info(
        "receive: %-40s %10s frames/s %8.2f MB/s",
        case.name,
        fmt_rate(result.frames_per_s),
        result.bytes_per_s / 1e6,
    )
    return result


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


def _share_cells(result: RxResult) -> list[str]:
    return [fmt_percent(cpu_share(rate, result.bytes_per_s)) for _name, rate in LINE_RATES]


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
        rows.append(
            [
                r.case.name,
                f"{r.frame_size:.1f} B",
                fmt_rate(r.frames_per_s),
                f"{r.bytes_per_s / 1e6:.2f}",
                f"{base.frames_per_s / r.frames_per_s:.2f}x",
                f"{base.bytes_per_s / r.bytes_per_s:.2f}x",
                *_share_cells(r),
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


def _proposals(
    ctx: Context, baseline: RxResult, framing: RxResult, pymavlink: RxResult | None
) -> tuple[str, list[tuple[str, RxResult]]]:
    steps: list[tuple[str, RxResult]] = [("protoduino as committed", baseline)]
    variants: list[tuple[str, RxCase]] = [
        (
            "+ FastStreamDecoder",
            protoduino.rx_case(
                ctx.frames, ctx.chunk, ctx.seed, decoder=FastStreamDecoder, name="proposal 1"
            ),
        ),
        (
            "+ Packet built at slots-class cost",
            protoduino.rx_case(
                ctx.frames, ctx.chunk, ctx.seed, decoder=LightPacketDecoder, name="proposal 2"
            ),
        ),
        (
            "+ ArduinoOut.FromString in parse_out",
            protoduino.rx_case(
                ctx.frames,
                ctx.chunk,
                ctx.seed,
                decoder=LightPacketDecoder,
                parse=parse_out_from_string,
                name="proposal 3",
            ),
        ),
    ]
    steps += [(label, run_case(case, ctx.reps)) for label, case in variants]
    framing_labels = ["StreamDecoder (committed)", "FastStreamDecoder", "LightPacketDecoder"]
    framing_results = [
        framing,
        run_case(
            protoduino.framing_only_case(
                ctx.frames, ctx.chunk, ctx.seed, decoder=FastStreamDecoder, name="fast framing"
            ),
            ctx.reps,
        ),
        run_case(
            protoduino.framing_only_case(
                ctx.frames, ctx.chunk, ctx.seed, decoder=LightPacketDecoder, name="light framing"
            ),
            ctx.reps,
        ),
    ]
    rows = []
    for label, r in steps:
        rows.append(
            [
                label,
                fmt_rate(r.frames_per_s),
                f"{r.us_per_frame:.2f}",
                f"{r.frames_per_s / baseline.frames_per_s:.2f}x",
                fmt_percent(cpu_share(1_000_000, r.bytes_per_s)),
            ]
        )
    table = md_table(
        ["whole receive path", "frames/s", "us/frame", "vs committed", "CPU at 1 MB/s"], rows
    )
    frows = [
        [
            label,
            fmt_rate(r.frames_per_s),
            f"{r.us_per_frame:.2f}",
            f"{r.frames_per_s / framing_results[0].frames_per_s:.2f}x",
        ]
        for label, r in zip(framing_labels, framing_results, strict=True)
    ]
    ftable = md_table(["stream decoder alone", "frames/s", "us/frame", "vs committed"], frows)
    best = steps[-1][1]
    share = cpu_share(1_000_000, best.bytes_per_s)
    verdicts = [
        f"needs {fmt_percent(share)} of a core at 1 MB/s (goal < "
        f"{fmt_percent(GOAL_CPU_AT_1MBPS)}: {'met' if share < GOAL_CPU_AT_1MBPS else 'missed'})"
    ]
    if pymavlink is not None:
        ratio = best.frames_per_s / pymavlink.frames_per_s
        verdicts.insert(
            0,
            f"is {ratio:.2f}x pymavlink's frame rate (goal {GOAL_RATIO_TO_PYMAVLINK:.0f}x: "
            f"{'met' if ratio >= GOAL_RATIO_TO_PYMAVLINK else 'missed'})",
        )
    summary = (
        f"With all three, the receive path {' and '.join(verdicts)}. What is left per frame "
        "is the stream decoder's Python-level work (about "
        f"{framing_results[-1].us_per_frame:.2f} us above) plus one protobuf parse and the "
        "dispatch. Going further means splitting, COBS-decoding and CRC-checking a whole read "
        "in one C call; neither the `cobs` package (one frame per call) nor the standard "
        "library offers that, so it would be a small C extension of our own (not measured "
        "here).\n"
    )
    text = (
        "Each step keeps the previous ones and is measured on the same stream in the same run. "
        "`FastStreamDecoder` produces exactly what `StreamDecoder` does (items, reasons, raw "
        "bytes, counts; `tests/test_bench_smoke.py` compares them on damaged streams cut at "
        "random), so it can replace it in `framing.py` as is. The Packet step stands for making "
        "`packets.Packet` a plain `__slots__` class or a `NamedTuple` instead of a frozen "
        "dataclass; the last step is a one-line change in `messages.parse_out`. See "
        "`bench/proposal.py`.\n\n" + table + "\n" + ftable + "\n" + summary
    )
    return text, steps


def run(ctx: Context) -> SectionResult:
    results: list[RxResult] = []
    skipped: list[tuple[str, str]] = []
    packages = ["protoduino", "protobuf", "cobs"]
    for label, factory in PEERS:
        try:
            case = factory(ctx.frames, ctx.chunk, ctx.seed)
        except MissingDependencyError as missing:
            log.warning("receive: %s skipped: %s", label, missing)
            skipped.append((label, missing.package))
            continue
        results.append(run_case(case, ctx.reps))
        packages.append(case.package)
    base = results[0]
    by_package = {r.case.package: r for r in results}

    parts = [
        f"Fed from memory in reads of {ctx.chunk} B; {ctx.frames:,} frames per stream; rates "
        f"are per CPU second of this process, median of {ctx.reps} repetitions (spread = "
        "(max - min) / median). A CPU share above 100 % means one core cannot keep up.\n",
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
        ratio = base.frames_per_s / mav.frames_per_s
        targets.append(
            Target(
                "receive rate vs pymavlink",
                f">= {GOAL_RATIO_TO_PYMAVLINK:.0f}x pymavlink's frames/s",
                f"{ratio:.2f}x ({fmt_rate(base.frames_per_s)} vs "
                f"{fmt_rate(mav.frames_per_s)} frames/s; "
                f"{base.bytes_per_s / mav.bytes_per_s:.2f}x in bytes/s)",
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

    proposal_steps: list[tuple[str, RxResult]] = []
    if any(t.met is False for t in targets):
        parts.append("### Why the targets are missed\n")
        framing = run_case(protoduino.framing_only_case(ctx.frames, ctx.chunk, ctx.seed), ctx.reps)
        needed = 1_000_000 / base.frame_size
        parts.append(
            f"protoduino spends {base.us_per_frame:.2f} us of CPU per frame; "
            f"{framing.us_per_frame:.2f} us of that "
            f"({framing.timing.median / base.timing.median * 100:.0f} %) is `StreamDecoder` "
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
                "each Python call; own time first):\n\n```\n" + _profile(base.case) + "\n```\n"
            )
        parts.append("### Proposals, measured\n")
        text, proposal_steps = _proposals(ctx, base, framing, mav)
        parts.append(text)

    chart_list: list[Chart] = []
    if ctx.chart_dir is not None:
        rows = [(r.case.name, r) for r in results]
        rows += [(f"proposal {label}", r) for label, r in proposal_steps[1:]]
        path = charts.hbars(
            ctx.chart_dir / "receive.png",
            [label for label, _r in rows],
            [
                ("frames per CPU second", [r.frames_per_s for _label, r in rows]),
                (
                    "% of a core at 1 MB/s",
                    [cpu_share(1_000_000, r.bytes_per_s) * 100 for _label, r in rows],
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
