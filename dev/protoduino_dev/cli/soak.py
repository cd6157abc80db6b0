"""``protoduino soak``: long seeded fault scenarios on a simulated board, and their report.

By default: one long scenario (100,000 commands at a bit error rate of 1e-3
with error bursts, 20 device resets sprinkled in, then the failsafe check),
then one scenario per fault kind (bit errors, bursts, dropped bytes, garbage,
duplicated frames, latency, line cuts, device resets). Each prints its figures
as it ends; ``--report docs/reliability.md`` writes them all as Markdown, with
the command that reproduces each. The exit status is 1 if any invariant was
violated (see :mod:`protoduino_dev.soak`).
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from protoduino.cli import argtypes
from protoduino.cli.options import error
from protoduino.errors import ProtoduinoError
from protoduino.simboard import BACKENDS

from .. import soak as engine
from ..faults import parse_url
from ..soak import Scenario, fault_scenarios

HELP = "run seeded fault scenarios on the simulated board and report what happened"

DEFAULT_FAULTS = "ber=1e-3&burst=1e-4"
#: Everything from this line on in an existing report is kept as it is (the fuzzing record).
KEEP_MARKER = "<!-- written by hand below this line; protoduino soak keeps it -->"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--backend", choices=sorted(BACKENDS), default="native", help="native (default) or avr"
    )
    parser.add_argument(
        "--commands",
        type=argtypes.count,
        default=100_000,
        metavar="N",
        help="commands in the long scenario; 0 skips it (default: %(default)s)",
    )
    parser.add_argument(
        "--seed", type=argtypes.count, default=1, help="seed of every scenario (default: 1)"
    )
    parser.add_argument(
        "--faults",
        type=fault_query,
        default=DEFAULT_FAULTS,
        metavar="QUERY",
        help="faulty:// parameters of the long scenario (default: %(default)s)",
    )
    parser.add_argument(
        "--resets",
        type=argtypes.count,
        default=20,
        metavar="N",
        help="device resets in the long scenario (default: %(default)s)",
    )
    parser.add_argument(
        "--cuts", type=argtypes.count, default=0, metavar="N", help="line cuts in it"
    )
    parser.add_argument(
        "--cut-seconds",
        type=argtypes.positive_seconds,
        default=1.0,
        metavar="S",
        help="cut length (default: 1)",
    )
    parser.add_argument(
        "--failsafe",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="end the long scenario by stopping the pings and timing the failsafe",
    )
    parser.add_argument(
        "--kinds",
        type=fault_kinds,
        default="all",
        metavar="LIST",
        help="fault-kind scenarios to run after it: all, none, or a comma list of "
        f"{', '.join(fault_scenarios(1))}",
    )
    parser.add_argument(
        "--kind-commands",
        type=argtypes.positive_count,
        default=5000,
        metavar="N",
        help="commands in each fault-kind scenario (default: %(default)s)",
    )
    parser.add_argument("--report", type=Path, help="write the Markdown report here")
    parser.add_argument(
        "--json", type=Path, help="write every figure as JSON here (after each scenario)"
    )
    parser.add_argument(
        "--from-json",
        type=Path,
        metavar="FILE",
        help="run nothing: print and report the figures a --json run saved",
    )
    parser.add_argument(
        "--workdir", type=Path, help="keep the boards' traces here (default: a temporary folder)"
    )


def fault_query(text: str) -> str:
    """faulty:// parameters, checked as the line will read them."""
    try:
        parse_url(f"faulty://check?{text}" if text else "faulty://check")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def fault_kinds(text: str) -> str:
    """all, none, or a comma list of known fault kinds."""
    if text in ("all", "none"):
        return text
    known = fault_scenarios(1)
    wanted = [k.strip() for k in text.split(",") if k.strip()]
    unknown = [k for k in wanted if k not in known]
    if unknown or not wanted:
        raise argparse.ArgumentTypeError(
            f"unknown fault kind(s) {unknown or [text]}; known: all, none, {', '.join(known)}"
        )
    return text


def check(args: argparse.Namespace) -> str | None:
    if args.from_json is None and args.commands == 0 and args.kinds == "none":
        return "nothing to run (--commands 0 and --kinds none)"
    return None


def scenarios(args: argparse.Namespace) -> list[Scenario]:
    out: list[Scenario] = []
    if args.commands > 0:
        out.append(
            Scenario(
                "soak",
                commands=args.commands,
                seed=args.seed,
                faults=args.faults,
                resets=args.resets,
                cuts=args.cuts,
                cut_seconds=args.cut_seconds,
                failsafe=args.failsafe,
                backend=args.backend,
                description="the long run: " + describe(args.faults, args.resets, args.cuts),
            )
        )
    kinds = fault_scenarios(args.kind_commands, args.seed, args.backend)
    wanted = list(kinds) if args.kinds == "all" else []
    if args.kinds not in ("all", "none"):
        wanted = [k.strip() for k in args.kinds.split(",") if k.strip()]
        unknown = [k for k in wanted if k not in kinds]
        if unknown:
            raise ValueError(f"unknown fault kind(s) {unknown}; known: {', '.join(kinds)}")
    out.extend(kinds[k] for k in wanted)
    return out


def describe(faults: str, resets: int, cuts: int) -> str:
    parts = [faults or "a clean line"]
    if resets:
        parts.append(f"{resets} device resets")
    if cuts:
        parts.append(f"{cuts} line cuts")
    return ", ".join(parts)


def run(args: argparse.Namespace) -> int:
    if args.from_json is not None:
        try:
            results: list[dict[str, Any]] = json.loads(args.from_json.read_text())
        except (OSError, ValueError) as exc:
            return error("soak", f"cannot read {args.from_json}: {exc}")
        for r in results:
            print(f"== {r['scenario']}: {reproduce(r)}")
            print(figures(r))
        return finish(args, results, "soak")
    try:
        todo = scenarios(args)
    except ValueError as exc:
        return error("soak", exc)
    if not todo:
        return error("soak", "nothing to run (--commands 0 and --kinds none)")
    argv = " ".join(["soak", *sys.argv[2:]]) if sys.argv[1:2] == ["soak"] else "soak"
    results = []
    with tempfile.TemporaryDirectory(prefix="protoduino-soak-") as tmp:
        workdir = args.workdir or Path(tmp)
        for scenario in todo:
            print(f"== {scenario.name}: {scenario.commands} commands, {scenario.command_line()}")
            t0 = time.monotonic()

            def progress(n: int, t0: float = t0, total: int = scenario.commands) -> None:
                rate = n / max(1e-9, time.monotonic() - t0)
                print(f"   {n}/{total} commands, {rate:.0f}/s", file=sys.stderr, flush=True)

            try:
                result = engine.run(scenario, workdir, progress=progress).as_dict()
            except ProtoduinoError as exc:
                return error("soak", f"{scenario.name}: {exc}")
            result["argv"] = argv
            results.append(result)
            print(figures(result), flush=True)
            if args.json is not None:  # after each scenario: a long run is never lost
                args.json.write_text(json.dumps(results, indent=2) + "\n")
    return finish(args, results, argv)


def finish(args: argparse.Namespace, results: list[dict[str, Any]], argv: str) -> int:
    if args.report is not None:
        write_report(args.report, results, argv)
    failed = [r["scenario"] for r in results if not r["passed"]]
    if failed:
        print(f"INVARIANTS VIOLATED in: {', '.join(failed)}", file=sys.stderr)
        return 1
    print(f"all {len(results)} scenarios passed every invariant")
    return 0


def reproduce(r: dict[str, Any]) -> str:
    """The command that runs one saved scenario again, alone (older JSON lacks some fields)."""
    recovery = int(r.get("recovery_commands", 20))
    return engine.command_line(
        backend=str(r["backend"]),
        commands=int(r.get("commands", int(r["sent"]) - recovery)),
        seed=int(r["seed"]),
        faults=str(r["faults"]),
        resets=int(r["resets"]),
        cuts=int(r["cuts"]),
        cut_seconds=float(r.get("cut_seconds", 1.0)),
        failsafe=bool(r.get("failsafe", r["failsafe_checked"])),
    )


def _injected(r: dict[str, Any]) -> str:
    """The faulty:// parameters and what the line counted (resets and cuts included)."""
    counted = _dict(r["faults_injected"])
    if not r["faults"]:
        return counted
    return f"`{r['faults']}`" + ("" if counted == "none" else f": {counted}")


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x * 1000:.0f} ms"


def _dict(d: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(d.items()) if v) or "none"


def figures(r: dict[str, Any]) -> str:
    """The figures of one run (``SoakResult.as_dict()``) as a few readable lines."""
    link = r["link"]
    lines = [
        f"   {r['sent']} sent, {r['ok']} ok, {r['executed']} executed (seen in the trace; "
        f"{r['executed_after_timeout']} of them had timed out), rejected "
        f"{_dict(r['rejected'])}, {r['timed_out']} timed out, other errors {_dict(r['errors'])}",
        f"   duplicates {r['duplicates']}, corrupted executions {r['corrupted']}, hung calls "
        f"{r['hung']} (longest {r['max_call_s']:.3f} s, bound {r['call_bound_s']:g} s), "
        f"run again after a reboot {r['reexecuted_after_reboot']}",
        f"   recovery: {len(r['recovery_s'])} disruptions, median {_ms(r['recovery_median_s'])}, "
        f"max {_ms(r['recovery_max_s'])}; healed line: "
        + ("all commands ok" if r["recovered"] else f"{r['recovery_failures']} failed"),
        f"   injected: {_dict(r['faults_injected'])}",
        f"   link: {link.get('retransmits', 0)} retransmits, {link.get('late_acks', 0)} late "
        f"acks, bad frames {_dict(link.get('bad_frames', {}))}, "
        f"{link.get('rehandshakes', 0)} re-handshakes, {link.get('reboots_seen', 0)} reboots "
        f"seen, {link.get('restores', 0)} restores, {link.get('seq_desyncs', 0)} SEQ desyncs, "
        f"{link.get('watchdog_resets', 0)} watchdog resets, {link.get('guard_holds', 0)} "
        "dedupe-guard holds",
    ]
    if r["failsafe_checked"]:
        low, high = r["failsafe_delay_s"] or (None, None)
        lines.append(
            f"   failsafe: outputs safe {low}..{high} s after the device's last Ping: "
            + ("on time" if r["failsafe_ok"] else "NOT on time")
        )
    lines.append(f"   {r['duration_s']:.1f} s, " + ("PASSED" if r["passed"] else "FAILED"))
    lines.extend(f"   ! {v}" for v in r["violations"])
    return "\n".join(lines)


def write_report(path: Path, results: list[dict[str, Any]], argv: str) -> None:
    kept = ""
    if path.exists():
        old = path.read_text()
        if KEEP_MARKER in old:
            kept = old[old.index(KEEP_MARKER) :]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_report(results, argv) + ("\n" + kept if kept else ""))


def render_report(results: list[dict[str, Any]], argv: str) -> str:
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d")
    # The command lines of the runs the figures come from (a JSON file may merge several).
    runs = list(dict.fromkeys(str(r.get("argv", argv)) for r in results)) or [argv]
    out = [
        "# Reliability under faults",
        "",
        "Generated by " + " and ".join(f"`protoduino {a}`" for a in runs) + f" on {when} "
        f"({platform.machine()}, "
        f"Python {platform.python_version()}); `protoduino soak --from-json` re-renders it. "
        "Each scenario opens a simulated board with a trace, talks to it through the seeded "
        "`faulty://` line (`protoduino_dev.faults`) and checks the board's own record of its "
        "outputs against what the host sent (`protoduino_dev.soak`): no corrupted command "
        "executed, no message id executed twice within one boot, every call returned or "
        "raised within `ACK_TIMEOUT x (MAX_RETRIES + 1) + HANDSHAKE_TIMEOUT`, the link "
        "recovered by itself once the faults stopped, and (long run) the failsafe fired "
        "10 s after the last Ping.",
        "",
        "| scenario | injected | sent | ok | executed | rejected | timed out | duplicates "
        "| corrupted | hung | recovery median / max | result |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        out.append(
            f"| {r['scenario']} ({r['backend']}) | {_injected(r)} | {r['sent']} | "
            f"{r['ok']} | "
            f"{r['executed']} | {sum(r['rejected'].values())} | {r['timed_out']} | "
            f"{r['duplicates']} | {r['corrupted']} | {r['hung']} | "
            f"{_ms(r['recovery_median_s'])} / {_ms(r['recovery_max_s'])} | "
            + ("passed" if r["passed"] else "**FAILED**")
            + " |"
        )
    out += [
        "",
        "*sent*: calls made through the API (the stream, then the recovery commands on the "
        "healed line). *executed*: seen in the board's trace; a call that timed out may still "
        "have run (its Acks were lost), and a digital write that found its pin at that level "
        "leaves no trace line. *recovery*: from the end of each disruption (a reset, a cut, "
        "the faults stopping) to the next successful call.",
        "",
    ]
    for r in results:
        out += [
            f"## {r['scenario']} ({r['backend']})",
            "",
            r["description"] or describe(r["faults"], r["resets"], r["cuts"]),
            "",
            f"Reproduce: `{reproduce(r)}` (seed {r['seed']}, {r['backend']} board, "
            f"{r['servos']} servos and {r['digitals']} digital outputs, {r['workers']} calling "
            f"threads, window {r['window']}, ack timeout {r['ack_timeout']:g} s, "
            f"{r['max_retries']} retries).",
            "",
            "```",
            figures(r),
            "```",
            "",
        ]
    return "\n".join(out)
