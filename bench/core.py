"""Shared types of the benchmark sections and the one way they measure time.

Time is CPU time of this process (``time.process_time_ns``), not wall time: the report's
question is "what share of a core does this cost", and CPU time does not count the moments the
scheduler gives the core to someone else (the machine may be shared while the benchmark runs).
Every measurement is repeated and the median is reported; the garbage collector is paused
during a repetition, as :mod:`timeit` does, so that a collection triggered by an earlier case
does not land in a later one.
"""

from __future__ import annotations

import gc
import importlib
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

#: The line rates the report prices the receive path at, in bytes per second of payload-bearing
#: serial traffic: 115200 baud and 1 Mbaud with 10 bits per byte (8N1), and a full-speed USB CDC
#: link moving about 1 MB/s.
LINE_RATES: tuple[tuple[str, float], ...] = (
    ("115200 baud", 11_520.0),
    ("1 Mbaud", 100_000.0),
    ("1 MB/s USB", 1_000_000.0),
)

#: How to get every optional library the benchmarks compare against.
INSTALL_HINT = "tools/bench_setup.sh (pip install -e '.[bench]' plus pigweed --no-deps)"


class MissingDependencyError(Exception):
    """An optional library a benchmark needs is not installed; ``package`` names it on PyPI."""

    def __init__(self, package: str) -> None:
        super().__init__(f"{package} is not installed; install the bench extras: {INSTALL_HINT}")
        self.package = package


def require(module: str, package: str) -> ModuleType:
    """Import ``module`` or raise :class:`MissingDependencyError` naming the PyPI ``package``."""
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise MissingDependencyError(package) from error


@dataclass(frozen=True, slots=True)
class Timing:
    """CPU seconds of each repetition of one measured callable."""

    samples: tuple[float, ...]

    @property
    def median(self) -> float:
        return statistics.median(self.samples)

    @property
    def spread(self) -> float:
        """(max - min) / median: how much the repetitions disagreed."""
        med = self.median
        return (max(self.samples) - min(self.samples)) / med if med > 0 else 0.0


def measure(run: Callable[[], object], reps: int, *, warmup: int = 1) -> Timing:
    """Run ``run`` ``warmup`` times untimed, then ``reps`` times timed (CPU time, GC paused)."""
    if reps < 1:
        raise ValueError("reps must be at least 1")
    for _ in range(warmup):
        run()
    samples: list[float] = []
    gc_was_enabled = gc.isenabled()
    for _ in range(reps):
        gc.collect()
        gc.disable()
        try:
            start = time.process_time_ns()
            run()
            elapsed = time.process_time_ns() - start
        finally:
            if gc_was_enabled:
                gc.enable()
        # A run faster than the clock's resolution still counts as one nanosecond.
        samples.append(max(elapsed, 1) / 1e9)
    return Timing(tuple(samples))


def measure_interleaved(
    runs: Sequence[Callable[[], object]], reps: int, *, warmup: int = 1
) -> list[Timing]:
    """Like :func:`measure` for several callables, taking turns: repetition 1 of each, then
    repetition 2 of each, and so on. On a machine whose speed drifts (a shared virtual
    machine), a slow spell then lands on every case instead of on one, so the ratios between
    cases hold better than their absolute rates."""
    if reps < 1:
        raise ValueError("reps must be at least 1")
    for run in runs:
        for _ in range(warmup):
            run()
    samples: list[list[float]] = [[] for _ in runs]
    for _ in range(reps):
        for i, run in enumerate(runs):
            samples[i].append(measure(run, 1, warmup=0).samples[0])
    return [Timing(tuple(s)) for s in samples]


def cpu_share(rate_bytes_per_s: float, throughput_bytes_per_s: float) -> float:
    """Fraction of one core needed to keep up with ``rate`` given a measured throughput."""
    return rate_bytes_per_s / throughput_bytes_per_s


@dataclass(frozen=True, slots=True)
class Target:
    """One of the benchmarks' targets as the report shows it; ``met`` is None when not measured."""

    name: str
    goal: str
    measured: str
    met: bool | None
    why: str = ""


@dataclass(frozen=True, slots=True)
class Chart:
    """A PNG the section wrote, with the caption the report puts under it."""

    path: Path
    caption: str


@dataclass(slots=True)
class SectionResult:
    """What a section contributes to the report.

    ``markdown`` is the section body (the runner writes the heading). ``packages`` lists the
    distributions whose versions matter for this section; the machine table shows them.
    """

    markdown: str
    targets: list[Target] = field(default_factory=list)
    charts: list[Chart] = field(default_factory=list)
    packages: list[str] = field(default_factory=list)
    #: Figures other documents quote from this run: name -> text (bench.report.quote).
    quotes: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Context:
    """Run-wide settings every section receives.

    ``frames`` is the number of frames each receive-path stream holds, ``chunk`` the size of the
    reads it is fed in, ``reps`` the timed repetitions per measurement. ``samples`` and
    ``commands`` size the measurements against boards (parts 2, 3 and 5). ``chart_dir`` is where
    PNGs go, or None to make no charts (the smoke test); ``docs_dir`` is where the report goes,
    so that chart links can be made relative to it.
    """

    reps: int = 21
    frames: int = 5_000
    chunk: int = 1024
    seed: int = 7
    docs_dir: Path = Path("docs")
    chart_dir: Path | None = Path("docs/perf")
    profile: bool = True
    #: Parts 2 and 5: timed calls per case against a board.
    samples: int = 300
    #: Part 3: acknowledged commands per throughput point.
    commands: int = 600

    def link(self, path: Path) -> str:
        """``path`` as a link target relative to the report."""
        try:
            return path.resolve().relative_to(self.docs_dir.resolve()).as_posix()
        except ValueError:
            return path.resolve().as_posix()


@dataclass(frozen=True, slots=True)
class Section:
    """One part of the report: ``run`` measures and returns the section's body.

    ``number`` is the part of the report it answers, used for ordering and the heading.
    """

    number: int
    key: str
    title: str
    run: Callable[[Context], SectionResult]


def pending_section(
    number: int,
    key: str,
    title: str,
    what: str,
    needs: str,
    *,
    targets: tuple[tuple[str, str], ...] = (),
) -> Section:
    """A placeholder for a part that cannot be measured yet; the report says what it waits for
    and lists its ``targets`` (name, goal) as not measured.

    Replace it in ``bench.registry`` with the real section once ``needs`` exists.
    """

    def run(_ctx: Context) -> SectionResult:
        return SectionResult(
            markdown=f"Not measured yet: {what}\n\nWaiting for: {needs}.\n",
            targets=[Target(name, goal, "not measured yet", None) for name, goal in targets],
        )

    return Section(number, key, title, run)


def fmt_rate(value: float) -> str:
    """A rate with a thousands separator and no false precision."""
    if value >= 100:
        return f"{value:,.0f}"
    return f"{value:,.1f}"


def fmt_percent(fraction: float) -> str:
    pct = fraction * 100
    if pct >= 100:
        return f"{pct:,.0f} %"
    if pct >= 10:
        return f"{pct:.0f} %"
    if pct >= 1:
        return f"{pct:.1f} %"
    return f"{pct:.2f} %"


def md_table(header: list[str], rows: list[list[str]], align: str = "") -> str:
    """A GitHub markdown table; ``align`` has one of l/r per column (default: first l, rest r)."""
    if not align:
        align = "l" + "r" * (len(header) - 1)
    marks = ["---:" if a == "r" else "---" for a in align]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(marks) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"
