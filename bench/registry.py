"""The sections of docs/performance.md, in order.

To add a part: write ``bench/<name>.py`` with a ``run(ctx: Context) -> SectionResult`` and
``SECTION = Section(number, key, title, run)`` (see ``bench/wire.py`` for a small one), then list
it below; a part that cannot be measured yet can stand in as ``core.pending_section(...)``.
Return the issue's targets as :class:`~bench.core.Target` so the summary at the top of the report
lists them; raise :class:`~bench.core.MissingDependencyError` for a missing optional package, and
the runner reports the section as not run instead of failing.

Parts 2, 3, 5 and 6 measure boards (``bench.boards``: the simulated board, the emulated Uno and its
cycle counters); latency and throughput there are wall-clock quantities (``time.perf_counter``),
while part 1 measures CPU time (``bench.core.measure``).
"""

from __future__ import annotations

from . import (
    firmware,
    inputs,
    loop,
    mega,
    motion,
    race,
    receive,
    ros2,
    roundtrip,
    services,
    throughput,
    wire,
)
from .core import Section

SECTIONS: tuple[Section, ...] = (
    receive.SECTION,
    roundtrip.SECTION,
    throughput.SECTION,
    wire.SECTION,
    firmware.SECTION,
    motion.SECTION,
    inputs.SECTION,
    ros2.SECTION,
    race.SECTION,
    services.SECTION,
    mega.SECTION,
    loop.SECTION,
)
