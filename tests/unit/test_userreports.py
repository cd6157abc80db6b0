"""The user reports' table (protoduino.userreports): newest wins for callbacks, every value
for sinks, the latest kept per report."""

from __future__ import annotations

from collections.abc import Callable

from protoduino.userreports import RawReport, UserReportTable


def test_a_slow_callback_sees_the_newest_value_once() -> None:
    jobs: list[Callable[[], None]] = []
    table = UserReportTable(jobs.append)
    seen: list[bytes] = []
    table.on_report(3, lambda raw: seen.append(raw.body))
    table.update(3, b"a", 0)
    table.update(3, b"b", 0)
    table.update(3, b"c", 2)
    assert len(jobs) == 1  # one job queued per report, whatever arrives meanwhile
    jobs.pop()()
    assert seen == [b"c"]
    assert (table.received, table.skipped) == (3, 2)
    latest = table.latest(3)
    assert latest is not None and latest.coalesced == 2 and latest.report == 3


def test_sinks_see_every_value_and_reports_are_apart() -> None:
    table = UserReportTable(lambda job: job())
    got: list[RawReport] = []
    current, remove = table.add_sink(4, got.append)
    assert current is None
    table.update(4, b"x", 0)
    table.update(5, b"other", 0)
    table.update(4, b"y", 1)
    remove()
    table.update(4, b"z", 0)
    assert [r.body for r in got] == [b"x", b"y"]
    assert table.latest(5) is not None and table.latest(6) is None


def test_a_removed_callback_is_not_called() -> None:
    table = UserReportTable(lambda job: job())
    seen: list[bytes] = []
    remove = table.on_report(1, lambda raw: seen.append(raw.body))
    table.update(1, b"1", 0)
    remove()
    table.update(1, b"2", 0)
    assert seen == [b"1"]
