"""The user service's reports as they arrive (docs/services.md): newest wins.

``ArduinoOut.user_report`` carries report method N's newest value as bytes of the
user's schema; this table keeps the latest body of each report with its arrival
time and the device's ``coalesced`` count, and hands it on:

* callbacks run on the board's event thread, in order with the events, at most one
  job queued per report: a job reads the newest body when it runs, so a slow
  callback skips values instead of queueing them (freshness over completeness, as
  the device does and as :class:`~protoduino.inputs.InputTable` does for inputs);
* sinks run on the I/O thread under the table's lock (the asyncio iterators hand
  them to their loop at once; they must not block).

Decoding into the user's message type is the generated client's job
(:mod:`protoduino.services`): this layer knows bytes only.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

Job = Callable[[], None]


@dataclass(frozen=True, slots=True)
class RawReport:
    """One report as received: its method number, body, arrival and coalesced count."""

    report: int
    body: bytes
    #: ``time.monotonic()`` when it arrived.
    received: float
    #: Values of this report the device replaced before sending (since the previous one).
    coalesced: int


RawSink = Callable[[RawReport], None]


class UserReportTable:
    """The newest body of each report method, and who wants it."""

    def __init__(self, put_job: Callable[[Job], None]) -> None:
        self._put_job = put_job
        self._lock = threading.Lock()
        self._latest: dict[int, RawReport] = {}
        self._callbacks: dict[int, list[RawSink]] = {}
        self._sinks: dict[int, list[RawSink]] = {}
        self._queued: set[int] = set()
        #: Reports received, and those a callback never saw (a newer one came first).
        self.received = 0
        self.skipped = 0

    def update(self, report: int, body: bytes, coalesced: int) -> None:
        """A UserReport arrived (I/O thread)."""
        raw = RawReport(report, body, time.monotonic(), coalesced)
        with self._lock:
            self.received += 1
            self._latest[report] = raw
            for sink in self._sinks.get(report, ()):
                sink(raw)
            if not self._callbacks.get(report):
                return
            if report in self._queued:
                self.skipped += 1
                return
            self._queued.add(report)
        self._put_job(lambda: self._deliver(report))

    def _deliver(self, report: int) -> None:  # the event thread
        with self._lock:
            self._queued.discard(report)
            raw = self._latest.get(report)
            callbacks = list(self._callbacks.get(report, ()))
        if raw is not None:
            for callback in callbacks:
                callback(raw)

    def latest(self, report: int) -> RawReport | None:
        """The newest value of ``report`` received, or None."""
        with self._lock:
            return self._latest.get(report)

    def on_report(self, report: int, callback: RawSink) -> Callable[[], None]:
        """Call ``callback`` (event thread) with each newest value; returns its remover."""
        with self._lock:
            self._callbacks.setdefault(report, []).append(callback)

        def remove() -> None:
            with self._lock:
                if callback in self._callbacks.get(report, []):
                    self._callbacks[report].remove(callback)

        return remove

    def add_sink(self, report: int, sink: RawSink) -> tuple[RawReport | None, Callable[[], None]]:
        """Call ``sink`` on the I/O thread with every value from now; returns the latest
        value known and the sink's remover."""
        with self._lock:
            self._sinks.setdefault(report, []).append(sink)
            current = self._latest.get(report)

        def remove() -> None:
            with self._lock:
                if sink in self._sinks.get(report, []):
                    self._sinks[report].remove(sink)

        return current, remove
