"""The sections of docs/performance.md, in order.

To add a part: write ``bench/<name>.py`` with a ``run(ctx: Context) -> SectionResult`` and
``SECTION = Section(number, key, title, run)`` (see ``bench/wire.py`` for a small one and
``bench/charts.py`` for the histogram and line charts issue 7 asks for), then replace its
``pending_section(...)`` line below with ``<name>.SECTION``. Return the issue's targets as
:class:`~bench.core.Target` so the summary at the top of the report lists them; raise
:class:`~bench.core.MissingDependencyError` for a missing optional package, and the runner reports
the section as not run instead of failing.

Useful pieces for the parts still to come: ``bench.peers.protoduino.wire_sample()`` gives the
exact command and Ack frames (part 2's wire-time lower bound is
``bench.wire.wire_time_us(len(command) + len(ack))``); ``bench.core.measure`` times a callable
in CPU time, but latency and throughput against a board are wall-clock quantities: use
``time.perf_counter`` there.
"""

from __future__ import annotations

from . import receive, wire
from .core import Section, pending_section

SECTIONS: tuple[Section, ...] = (
    receive.SECTION,
    pending_section(
        2,
        "roundtrip",
        "Round trip",
        "command -> Ack latency (p50, p99) against the simulated board and against the "
        "emulated Uno at 115200 baud, next to the wire-time lower bound for the same bytes; "
        "a latency histogram (bench.charts.histogram). Target: p50 on the emulated Uno at "
        "most 1.3x its wire time.",
        "the host Board API (host/protoduino/board.py) and the simulated/emulated boards "
        "(protoduino.simboard)",
        targets=(("round trip p50, emulated Uno", "<= 1.3x its wire time"),),
    ),
    pending_section(
        3,
        "throughput",
        "Throughput",
        "acknowledged commands per second with a window of outstanding commands, against "
        "the line rate, and Ping payload echo throughput; throughput vs window size chart "
        "(bench.charts.lines). Target: windowed throughput at least 90 % of the line rate.",
        "the request layer's window (host/protoduino/rpc.py) and the boards",
        targets=(("windowed throughput", ">= 90 % of the line rate"),),
    ),
    wire.SECTION,
    pending_section(
        5,
        "firmware",
        "Firmware",
        "flash and static RAM on the ATmega328P (avr-size of the Uno build), and cycles spent "
        "per received command on the emulated Uno. Target: within 12,000 B flash and 800 B "
        "static RAM.",
        "the firmware (firmware/avr, firmware/Makefile) and the simavr runner (tools/avrsim)",
        targets=(("firmware flash", "<= 12,000 B"), ("firmware static RAM", "<= 800 B")),
    ),
)
