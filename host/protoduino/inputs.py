"""Inputs: what digital inputs, analog inputs and pulse counters share, fed by the device's
InputReports (each mode's own class, with its Init, is in :mod:`protoduino.modes`:
``digital_input``, ``analog_input``, ``counter``).

The device reports "freshness over completeness" (docs/protocol.md section 7): when an
input changed it sends one InputReport with the current values, and a report it could
not send yet is replaced by a newer one (``coalesced`` counts the replaced ones). The
host keeps to the same rule. :class:`InputTable` holds the latest :class:`Reading` of
every input and nothing older:

* the I/O thread (:meth:`InputTable.update`) only stores the values, wakes the threads
  in :meth:`InputTable.wait_for` and hands each new value to the sinks (a ``wait_for``
  or an asyncio ``changes()`` iterator, each with its own bounded buffer);
* ``on_change`` callbacks run on the board's event thread, in order with the events,
  newest-wins: at most one callback job per input waits in the event queue, and it
  reads the latest value when it runs. A callback slower than its input skips values
  (counted in ``board.stats.input_changes_skipped``) rather than being fed stale ones.

Ages are host times: a :class:`Reading`'s ``received`` is the board's clock when its report
arrived (``time.monotonic()``; a :mod:`protoduino.testing` device's manual clock for a board
on one), and an input's ``age`` the seconds since on that clock. It leaves out the report's time on
the wire (at 115200 baud about 2 ms for the largest report) and in the device's
transmit queue behind Acks; ``time_ms`` is the device's own clock when the values were
taken (milliseconds since its boot, wrapping at 2**32), for ordering and intervals on
the device's time scale.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ._generated import protoduino_pb2 as pb
from .clock import Clock
from .errors import (
    ArgumentError,
    ArgumentTypeError,
    BoardClosedError,
    InputTimeoutError,
    ProtocolError,
)
from .messages import InputKind, input_values
from .rpc import Done, Waiter

#: Values one waiter (``wait_for``, an asyncio iterator) keeps before the oldest is dropped.
SINK_BUFFER = 64


@dataclass(frozen=True, slots=True)
class Reading:
    """One value of one input, as a report carried it."""

    pin: int
    #: A digital level (a bool), analog counts (0..1023) or edges counted (wraps at 2**32).
    value: int
    #: The device's clock (ms since its boot, wrapping) when the value was taken.
    time_ms: int
    #: The board's clock when the report arrived: time.monotonic() on the host (a
    #: protoduino.testing device's manual clock for a board on it).
    received: float

    @property
    def age(self) -> float:
        """Seconds since the report that carried this value arrived, by time.monotonic()
        (an input's ``age`` reads the board's own clock)."""
        return time.monotonic() - self.received


def decode_report(report: pb.InputReport, received: float) -> list[tuple[InputKind, Reading]]:
    """Every value an InputReport carries (:func:`protoduino.messages.input_values`) as a
    :class:`Reading` received at host time ``received``; raises :class:`ProtocolError` for a
    report whose pin sets and values disagree."""
    t = report.time_ms
    return [(kind, Reading(pin, value, t, received)) for kind, pin, value in input_values(report)]


Sink = Callable[[Reading], None]
Callback = Callable[[Reading], None]
Job = Callable[[], None]


@dataclass(slots=True)
class _Slot:
    """One input's latest value and who wants to hear of the next."""

    reading: Reading | None = None
    callbacks: list[Callback] = field(default_factory=list)
    sinks: list[Sink] = field(default_factory=list)
    #: A callback job for this input waits in the event queue (it reads the latest value).
    job_queued: bool = False


class InputTable:
    """The latest value of every input; see the module docstring for the threads.

    ``post`` hands a job to the board's event thread (``EventDispatcher.put_job``).
    """

    def __init__(
        self,
        post: Callable[[Job], None],
        clock: Clock = time.monotonic,
        *,
        wait: Waiter | None = None,
    ) -> None:
        self._post = post
        self._clock = clock
        #: A board without an I/O thread (protoduino.testing): how a caller waits while it
        #: runs the link itself; None: the I/O thread feeds the waits below.
        self._wait = wait
        self._cond = threading.Condition()
        self._slots: dict[tuple[InputKind, int], _Slot] = {}
        self._closed = False
        #: InputReports received, and reports the device replaced before sending them.
        self.reports = 0
        self.coalesced = 0
        #: Changes an on_change callback never saw because a newer value came first.
        self.skipped = 0
        #: Reports whose pin sets and values disagreed (dropped whole).
        self.malformed = 0

    # --- the I/O thread -------------------------------------------------------------

    def update(self, report: pb.InputReport) -> None:
        """Take in one InputReport (I/O thread): store, wake the waiters, queue callbacks."""
        try:
            readings = decode_report(report, self._clock())
        except ProtocolError:
            with self._cond:
                self.malformed += 1
            raise
        jobs: list[Job] = []
        with self._cond:
            self.reports += 1
            self.coalesced += report.coalesced
            for kind, reading in readings:
                slot = self._slots.setdefault((kind, reading.pin), _Slot())
                before = slot.reading
                slot.reading = reading  # fresher even when unchanged: its age restarts
                if before is not None and before.value == reading.value:
                    continue
                for sink in slot.sinks:
                    sink(reading)
                if slot.callbacks:
                    if slot.job_queued:
                        self.skipped += 1
                    else:
                        slot.job_queued = True
                        jobs.append(self._callback_job(kind, reading.pin))
            self._cond.notify_all()
        for job in jobs:
            self._post(job)

    def _callback_job(self, kind: InputKind, pin: int) -> Job:
        def run() -> None:
            with self._cond:
                slot = self._slots.get((kind, pin))
                if slot is None:
                    return
                slot.job_queued = False
                reading, callbacks = slot.reading, list(slot.callbacks)
            if reading is None:
                return
            for callback in callbacks:
                callback(reading)  # the dispatcher logs an exception and goes on

        return run

    def configure(self, kind: InputKind, pin: int) -> None:
        """An Init for this input was acknowledged: what was known of it is void.

        The device reports the input's value right after the Init's Ack, so the
        next reading is the new configuration's.
        """
        with self._cond:
            slot = self._slots.setdefault((kind, pin), _Slot())
            slot.reading = None

    def forget(self, pin: int) -> None:
        """The pin was released: its values go (``read()`` says None). Its listeners stay:
        a wait or an iterator on it hears the pin again if it is configured anew."""
        with self._cond:
            for (_kind, slot_pin), slot in self._slots.items():
                if slot_pin == pin:
                    slot.reading = None

    def clear(self) -> None:
        """Every pin was released (ReleaseAll): every value goes, the listeners stay."""
        with self._cond:
            for slot in self._slots.values():
                slot.reading = None

    def close(self) -> None:
        """The board closed: every wait ends with BoardClosedError."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    # --- readers ----------------------------------------------------------------------

    def latest(self, kind: InputKind, pin: int) -> Reading | None:
        with self._cond:
            slot = self._slots.get((kind, pin))
            return None if slot is None else slot.reading

    def subscribe(self, kind: InputKind, pin: int, callback: Callback) -> Callable[[], None]:
        """``callback(reading)`` on the event thread for each change (newest-wins)."""
        with self._cond:
            self._slots.setdefault((kind, pin), _Slot()).callbacks.append(callback)

        def unsubscribe() -> None:
            with self._cond:
                slot = self._slots.get((kind, pin))
                if slot is not None and callback in slot.callbacks:
                    slot.callbacks.remove(callback)

        return unsubscribe

    def add_sink(self, kind: InputKind, pin: int, sink: Sink) -> tuple[Reading | None, Job]:
        """Call ``sink(reading)`` on the I/O thread for every change from now on.

        ``sink`` must be quick and must not block (it runs under the table's
        lock). Returns the value known now (so nothing falls between it and the
        first change) and the function that removes the sink.
        """
        with self._cond:
            slot = self._slots.setdefault((kind, pin), _Slot())
            slot.sinks.append(sink)
            current = slot.reading

        def remove() -> None:
            with self._cond:
                found = self._slots.get((kind, pin))
                if found is not None and sink in found.sinks:
                    found.sinks.remove(sink)

        return current, remove

    def listeners(self, kind: InputKind, pin: int) -> int:
        """How many waits and iterators listen to this input now (for tests and diagnostics)."""
        with self._cond:
            slot = self._slots.get((kind, pin))
            return 0 if slot is None else len(slot.sinks)

    def wait_for(
        self,
        kind: InputKind,
        pin: int,
        predicate: Callable[[Reading], bool],
        timeout: float,
    ) -> Reading:
        """The first value (the current one included) for which ``predicate`` holds.

        Every change is looked at, even one a newer value replaced while the
        predicate ran (up to :data:`SINK_BUFFER` of them), so a short pulse
        the device reported is not missed. Raises :class:`InputTimeoutError`
        after ``timeout`` seconds, :class:`BoardClosedError` if the board closes.
        """
        if not timeout >= 0 or math.isinf(timeout):  # NaN, negative, infinite
            raise ArgumentError(f"timeout must be a finite number of seconds >= 0, not {timeout!r}")
        if self._wait is not None:
            return self._wait_inline(self._wait, kind, pin, predicate, timeout)
        seen: collections.deque[Reading] = collections.deque(maxlen=SINK_BUFFER)
        current, remove = self.add_sink(kind, pin, seen.append)
        try:
            if current is not None and predicate(current):
                return current
            deadline = time.monotonic() + timeout
            while True:
                with self._cond:
                    while not seen and not self._closed:
                        left = deadline - time.monotonic()
                        if left <= 0:
                            raise InputTimeoutError(
                                f"{kind} input {pin}: no matching value within {timeout:g} s "
                                f"(latest: {self._describe(kind, pin)})"
                            )
                        self._cond.wait(left)
                    if self._closed:
                        raise BoardClosedError("the board was closed while waiting for an input")
                    batch = list(seen)
                    seen.clear()
                for reading in batch:
                    if predicate(reading):
                        return reading
        finally:
            remove()

    def _wait_inline(
        self,
        wait: Waiter,
        kind: InputKind,
        pin: int,
        predicate: Callable[[Reading], bool],
        timeout: float,
    ) -> Reading:
        """:meth:`wait_for` without an I/O thread: ``wait`` runs the link (and its clock) on
        this thread until a value holds or ``timeout`` passed, so the sink, on this thread
        too, tests each value as it arrives."""
        found: list[Reading] = []
        done = Done()

        def sink(reading: Reading) -> None:
            if not found and predicate(reading):
                found.append(reading)
                done.set()

        current, remove = self.add_sink(kind, pin, sink)
        try:
            if current is not None and predicate(current):
                return current
            wait(done, timeout)
        finally:
            remove()
        if found:
            return found[0]
        if self._closed:
            raise BoardClosedError("the board was closed while waiting for an input")
        raise InputTimeoutError(
            f"{kind} input {pin}: no matching value within {timeout:g} s "
            f"(latest: {self._describe(kind, pin)})"
        )

    def age(self, reading: Reading) -> float:
        """Seconds since ``reading`` arrived, on the board's clock (the table's)."""
        return self._clock() - reading.received

    def _describe(self, kind: InputKind, pin: int) -> str:
        slot = self._slots.get((kind, pin))
        if slot is None or slot.reading is None:
            return "none yet"
        return f"{slot.reading.value}, {self.age(slot.reading):.3f} s old"


#: What a DigitalInput's wait_for takes: a level, or a test of the level.
LevelCondition = bool | Callable[[bool], bool]
#: What an AnalogInput's or a Counter's wait_for takes: a test of the value.
ValueCondition = Callable[[int], bool]


class Input:
    """What every input object has; get one from ``board.digital_input`` and its siblings.

    ``read()`` (in each subclass) returns the latest value at once, without a
    round trip, or None before the first report; ``reading()`` the whole
    :class:`Reading` (value, device time, host receive time, age).
    """

    kind: InputKind = "digital"

    def __init__(
        self, table: InputTable, pin: int, release: Callable[[int], None], timeout: float
    ) -> None:
        self._table = table
        self.pin = pin
        self._release = release
        #: The default timeout of wait_for (the board's call timeout).
        self.timeout = timeout

    def reading(self) -> Reading | None:
        """The latest reading, or None before the first report (or after a release)."""
        return self._table.latest(self.kind, self.pin)

    @property
    def age(self) -> float | None:
        """Seconds since the latest report of this input arrived, on the board's clock
        (None: none yet)."""
        reading = self.reading()
        return None if reading is None else self._table.age(reading)

    def on_change(self, callback: Callable[[Reading], None]) -> Callable[[], None]:
        """Call ``callback(reading)`` on the board's event thread when the value changes.

        Newest-wins: a callback slower than the input sees the latest value, not
        every one in between. Returns the function that removes the callback.
        """
        return self._table.subscribe(self.kind, self.pin, callback)

    def _wait(self, predicate: Callable[[Reading], bool], timeout: float | None) -> Reading:
        return self._table.wait_for(
            self.kind, self.pin, predicate, self.timeout if timeout is None else timeout
        )

    def release(self) -> None:
        """Release the pin: it is free for any mode (an input without pull-up)."""
        self._release(self.pin)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(pin={self.pin})"


def _level_test(level: LevelCondition) -> Callable[[bool], bool]:
    if callable(level):
        return level
    if isinstance(level, bool) or level in (0, 1):
        wanted = bool(level)
        return lambda value: value == wanted
    raise ArgumentTypeError(
        f"wait for a level (True/False, 1/0) or a function of it, not {level!r}"
    )
