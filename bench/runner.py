"""``python -m bench``: run the benchmarks and write docs/performance.md with its charts.

A full run writes the report into docs/; ``--only`` runs some sections and, unless ``--out``
says otherwise, writes into build/bench/ so that a partial report never replaces the real one.
"""

from __future__ import annotations

import argparse
import logging
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from . import charts, machine, registry, report
from .core import Context, MissingDependencyError, Section, SectionResult

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PARTIAL = ROOT / "build" / "bench"


def build_parser() -> argparse.ArgumentParser:
    keys = [s.key for s in registry.SECTIONS]
    parser = argparse.ArgumentParser(
        prog="python -m bench", description="Benchmark protoduino against its peers."
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="1,000 frames, 5 repetitions, 60 samples and 200 commands per board case",
    )
    parser.add_argument("--frames", type=int, help="frames per receive stream (default 5,000)")
    parser.add_argument("--reps", type=int, help="timed repetitions (default 21)")
    parser.add_argument("--chunk", type=int, default=1024, help="bytes per read (default 1024)")
    parser.add_argument(
        "--samples", type=int, help="round trips and cycle counts per board case (default 300)"
    )
    parser.add_argument(
        "--commands", type=int, help="acknowledged commands per throughput point (default 600)"
    )
    parser.add_argument("--seed", type=int, default=7, help="seed of the generated streams")
    parser.add_argument(
        "--only", action="append", choices=keys, metavar="SECTION", help=f"one of {keys}"
    )
    parser.add_argument("--out", type=Path, help="report path (default docs/performance.md)")
    parser.add_argument(
        "--merge",
        action="store_true",
        help="with --only: put those parts into the existing report (docs/performance.md "
        "unless --out), keeping the other parts of its earlier run, and say so in its header",
    )
    parser.add_argument("--no-charts", action="store_true", help="skip the PNG charts")
    parser.add_argument("--no-profile", action="store_true", help="skip the cProfile dumps")
    return parser


def make_context(args: argparse.Namespace, out: Path) -> Context:
    # Many short repetitions rather than a few long ones: the cases take turns, and a round
    # short enough to fall inside one of the machine's speed phases keeps their ratios honest.
    frames = args.frames or (1_000 if args.quick else 5_000)
    reps = args.reps or (5 if args.quick else 21)
    chart_dir: Path | None = out.parent / "perf"
    if args.no_charts:
        chart_dir = None
    samples = args.samples or (60 if args.quick else 300)
    commands = args.commands or (200 if args.quick else 600)
    return Context(
        samples=samples,
        commands=commands,
        reps=reps,
        frames=frames,
        chunk=args.chunk,
        seed=args.seed,
        docs_dir=out.parent,
        chart_dir=chart_dir,
        profile=not args.no_profile,
    )


def run_sections(sections: Sequence[Section], ctx: Context) -> list[tuple[Section, SectionResult]]:
    """Run each section; one whose optional package is missing is reported, not fatal."""
    results: list[tuple[Section, SectionResult]] = []
    for section in sections:
        log.info("section %d: %s", section.number, section.title)
        try:
            result = section.run(ctx)
        except MissingDependencyError as missing:
            log.warning("section %s not run: %s", section.key, missing)
            result = SectionResult(f"Not run: `{missing.package}` is not installed.\n")
        results.append((section, result))
    return results


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    args = build_parser().parse_args(argv)
    sections = [s for s in registry.SECTIONS if not args.only or s.key in args.only]
    if args.merge and not args.only:
        build_parser().error("--merge needs --only")
    out: Path = args.out or (PARTIAL if args.only and not args.merge else DOCS) / "performance.md"
    ctx = make_context(args, out)
    notes: list[str] = []
    if ctx.chart_dir is not None:
        try:
            charts.pyplot()
        except MissingDependencyError as missing:
            log.warning("no charts: %s", missing)
            notes.append(f"Charts not drawn: `{missing.package}` is not installed.")
            ctx = make_context(argparse.Namespace(**{**vars(args), "no_charts": True}), out)
    results = run_sections(sections, ctx)
    packages: list[str] = []
    for _section, result in results:
        packages += result.packages
    packages += ["matplotlib"] if ctx.chart_dir is not None else []
    argv_text = " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
    command = f"python -m bench {argv_text}".strip()
    described = machine.describe(ROOT, packages)
    text = report.render(results, described, ctx, command, notes)
    if args.merge and out.exists():
        facts = dict(described)
        parts = report.parts_come([section.number for section, _result in results])
        note = (
            f"{parts} from a later run, `{command}` "
            f"({facts.get('date (UTC)', '?')}, commit {facts.get('commit', '?')}, load average "
            f"{facts.get('load average at start', '?')}); the machine table is the earlier run's."
        )
        text = report.merge(out.read_text(encoding="utf-8"), text, note)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    log.info("wrote %s", out)
    if out == DOCS / "performance.md":  # the real report: the READMEs quote its figures
        quotes: dict[str, str] = {}
        for _section, result in results:
            quotes.update(result.quotes)
        for path in report.quote(report.QUOTING, quotes):
            log.info("quoted this run's figures in %s", path)
    return 0
