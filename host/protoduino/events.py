"""What a board reports to its ``on_event`` callbacks, the thread that calls them, its counters.

Events are values, never exceptions: the callbacks run on the board's own
event thread (never the I/O thread), one at a time, in the order things
happened, so a slow callback delays other callbacks but never the link. The
queue in between is bounded (:class:`EventDispatcher`): a slow callback
behind a flood of Log lines costs dropped Log lines, counted, not memory.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, TypeVar

from .errors import ArgumentError

log = logging.getLogger(__name__)


class EventKind(StrEnum):
    """Every kind of event; ``details`` keys are listed with each."""

    #: The link is (again) up. details: rebooted (bool), lost (bool: the
    #: device no longer had our outputs), handshakes (int)
    CONNECTED = "connected"
    #: The link went down. details: reason ("port lost", "watchdog", "desync",
    #: "device rebooted", "handshake failed", ...)
    DISCONNECTED = "disconnected"
    #: The device restarted: its boot id changed. Its outputs were at their
    #: power-up state until the restore. details: boot_id (int)
    REBOOTED = "rebooted"
    #: Another host session took the device over (same boot id, our session not
    #: resumed): it released our outputs. details: boot_id (int)
    SESSION_LOST = "session_lost"
    #: Session restore finished: every output re-initialised (at its safe
    #: value), and with ``restore="last"`` its last acknowledged value sent again.
    #: details: replayed (int), failed (list of str), values (bool)
    RESTORED = "restored"
    #: The device entered or left its failsafe state. details: active (bool),
    #: cause ("ping_timeout", or "heartbeat_timeout" with liveness="heartbeat"; "stop",
    #: "interlock", "none"), epoch (int: the device's count of its safe states since
    #: power-up), and for an interlock pin (int: the input that tripped)
    FAILSAFE = "failsafe"
    #: The device could not decode a command. details: count (int, since boot)
    DECODE_ERROR = "decode_error"
    #: The device saw our SEQ jump (details: none) or dropped an over-long frame.
    DEVICE_DESYNC = "device_desync"
    RX_OVERFLOW = "rx_overflow"
    #: The capture file could not be written (a full disk): it stopped, the board
    #: goes on; once per board. details: path (str), error (str), errno (int)
    CAPTURE_LOST = "capture_lost"
    #: The link failed for good (version or schema mismatch), or the device
    #: rebooted too often to go on restoring. details: error (str)
    ERROR = "error"


@dataclass(frozen=True, slots=True)
class Event:
    kind: EventKind
    #: One readable sentence, for logs and the command line.
    text: str
    details: Mapping[str, Any] = field(default_factory=dict)
    #: time.monotonic() when it happened on the host.
    t: float = field(default_factory=time.monotonic)

    def __str__(self) -> str:
        return f"{self.kind.value}: {self.text}"


@dataclass(frozen=True, slots=True)
class Stats:
    """A snapshot of a board's link counters (``board.stats``)."""

    state: str  # "active", "handshaking", "disconnected", "failed", "closed"
    connected: bool  # the port is open
    rx_bytes: int
    tx_bytes: int
    rx_packets: int
    tx_packets: int
    #: Frames dropped on receipt, by reason: cobs, crc, length, type, overflow,
    #: and "direction" for a COMMAND packet reaching the host.
    dropped: Mapping[str, int]
    seq_lost: int  # packets the device sent that never arrived (SEQ gaps)
    seq_desyncs: int
    handshakes: int
    reconnects: int  # the port was lost and reopened
    reboots: int  # device restarts detected (a new boot id)
    sessions_lost: int  # another session took the device over
    watchdog_resets: int
    device_desyncs: int  # EVENT DESYNC from the device
    device_rx_overflows: int
    commands: int  # distinct commands sent (not counting retransmissions)
    acks: int
    retransmits: int
    timeouts: int
    rejected: int  # Acks with a status other than OK
    late_acks: int  # for a command already finished (e.g. a retransmission's twin)
    unknown_acks: int  # for an id this host never sent
    #: New commands held back so that a retransmission stays inside the device's dedupe window.
    guard_holds: int
    pings: int
    ping_failures: int
    #: Events the callbacks never saw because the event queue was full, by kind.
    events_dropped: Mapping[str, int]
    #: Capture records (lines) not written since a write failed, their bytes, and why
    #: (``capture_error``: None while the capture records, or without one).
    capture_lost: int
    capture_lost_bytes: int
    capture_error: str | None
    rtt: float | None  # last Ping round trip (seconds)
    last_ping: float | None  # time.monotonic() of the last acknowledged automatic Ping
    #: InputReports received; reports the device replaced by newer ones before it could
    #: send them (freshness over completeness); input changes an on_change callback never
    #: saw because a newer value came while it was busy.
    input_reports: int = 0
    inputs_coalesced: int = 0
    input_changes_skipped: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


#: Kinds that inform without changing what the host knows of the device: when the
#: queue is full the oldest of them is dropped first (a flood of Log lines must not
#: push out a failsafe or a reboot).
INFORMATIONAL = frozenset({EventKind.DECODE_ERROR, EventKind.DEVICE_DESYNC, EventKind.RX_OVERFLOW})

#: Events waiting for the callbacks, at most (a few hundred kilobytes).
EVENT_QUEUE_LIMIT = 1024

#: How long :meth:`EventDispatcher.close` waits for a callback that is running to return.
CLOSE_WAIT = 1.0

EventCallback = Callable[[Event], None]
#: Work for the event thread other than an event (a future's done-callback, an input's
#: callback), in order with them.
Job = Callable[[], None]

T = TypeVar("T")


def _call_back(fn: Callable[[Future[T]], object], future: Future[T]) -> None:
    try:
        fn(future)
    except Exception:  # logged as concurrent.futures logs a callback's failure
        logging.getLogger("concurrent.futures").exception(
            "exception calling callback for %r", future
        )


class EventThreadFuture(Future[T]):
    """A future resolved on the thread that learns its result unless it has
    done-callbacks, which then run on the event thread with its resolution.

    The board's submit forms settle theirs on the I/O thread as the Ack arrives. A
    future nobody added a done-callback to is resolved right there: a caller blocked
    in ``result()`` or ``concurrent.futures.wait`` wakes without a hop through the
    event thread (20-50 us of CPU per call on the emulated Uno, issue 23). One with a
    done-callback is resolved on the event thread (``post``:
    :meth:`EventDispatcher.put_job`), as every future was before: its callbacks run
    there as it resolves, in Ack order and in order with the events, may block or
    command the board, and have run once a waiter sees it done. User code never runs
    on the I/O thread: a callback added while the future is being resolved there is
    posted to the event thread too; one added once it is done is called at once by
    the thread that adds it, as :meth:`concurrent.futures.Future.add_done_callback`
    says.
    """

    def __init__(self, post: Callable[[Job], None]) -> None:
        super().__init__()
        self._post = post
        #: Guards the choice between resolving here and on the event thread.
        self._choice = threading.Lock()
        self._has_callbacks = False
        #: The thread resolving it where its result is known (None: not that way, or not yet).
        self._resolver: int | None = None

    def add_done_callback(self, fn: Callable[[Future[T]], object]) -> None:
        with self._choice:
            late = self._resolver is not None  # resolving (or resolved) on its own thread
            self._has_callbacks = True
        if not late:
            super().add_done_callback(fn)  # resolved on the event thread: called there
            return

        def deliver(future: Future[T]) -> None:
            if threading.get_ident() == self._resolver:
                self._post(lambda: _call_back(fn, future))
            else:
                fn(future)  # done already: the adding thread, as concurrent.futures does

        super().add_done_callback(deliver)

    def settle(self, result: Callable[[], T]) -> None:
        """Resolve with ``result()``, or with what it raises (the caller's exception):
        here, or on the event thread if a done-callback was added (class docstring)."""
        with self._choice:
            here = not self._has_callbacks
            if here:
                self._resolver = threading.get_ident()
        if here:
            self._resolve(result)
        else:
            self._post(lambda: self._resolve(result))

    def _resolve(self, result: Callable[[], T]) -> None:
        try:
            value = result()
        except BaseException as exc:  # the caller sees exactly what the blocking call raises
            self.set_exception(exc)
        else:
            self.set_result(value)


class EventDispatcher:
    """The board's event thread: a bounded queue in, every callback called in order.

    :meth:`put` never blocks (the I/O thread calls it). When ``limit`` events
    already wait, one is dropped and counted in :attr:`dropped` by kind: the
    oldest informational one (:data:`INFORMATIONAL`); if none is waiting, the
    new event itself if it is informational; only when the queue holds
    nothing but state changes (failsafe, reboot, link up or down, restore,
    error) and another one comes, the oldest of them, logged as an error.
    That takes ``limit`` state changes piled up behind a callback stuck for
    minutes: memory stays bounded even then.

    Jobs (:meth:`put_job`: a future's done-callback, an input's callback) run
    in the same order but are never dropped nor counted: there is one per
    callback of an outstanding call, and a dropped one would never be called.

    :meth:`close` stops the thread: no callback starts after it was called,
    events still waiting are discarded, jobs still waiting run (each
    done-callback is called), and a callback that is running is
    waited for up to ``close_wait`` seconds. A callback still running after
    that is not interrupted (Python cannot stop a thread): it finishes on its
    own (daemon) thread, which then runs the jobs left and ends.
    """

    def __init__(
        self,
        name: str,
        *,
        limit: int = EVENT_QUEUE_LIMIT,
        close_wait: float = CLOSE_WAIT,
        threaded: bool = True,
    ) -> None:
        if limit < 1:
            raise ArgumentError("limit must be at least 1")
        self.name = name
        self.limit = limit
        self.close_wait = close_wait
        self._cond = threading.Condition()
        self._queue: collections.deque[Event | Job] = collections.deque()
        self._events = 0  # how many items of the queue are events
        self._callbacks: list[EventCallback] = []
        self._closed = False
        self._exited = False
        #: Events dropped because the queue was full, by kind.
        self.dropped: collections.Counter[str] = collections.Counter()
        #: None without a thread (``threaded=False``): whoever drives the board calls
        #: :meth:`run_pending` itself (:mod:`protoduino.testing`, where no thread may run).
        self._thread: threading.Thread | None = None
        if threaded:
            self._thread = threading.Thread(
                target=self._run, name=f"protoduino-events[{name}]", daemon=True
            )
            self._thread.start()

    @property
    def thread(self) -> threading.Thread:
        """The thread that runs the callbacks (to join after :meth:`close`, which does not)."""
        if self._thread is None:
            raise RuntimeError(f"{self.name}: this dispatcher has no thread (threaded=False)")
        return self._thread

    def subscribe(self, callback: EventCallback) -> Callable[[], None]:
        """Add ``callback``; returns the function that removes it."""
        with self._cond:
            self._callbacks.append(callback)

        def unsubscribe() -> None:
            with self._cond:
                if callback in self._callbacks:
                    self._callbacks.remove(callback)

        return unsubscribe

    def put(self, event: Event) -> None:
        """Queue ``event`` for the callbacks; never blocks, drops by the policy above."""
        with self._cond:
            if self._closed:
                return
            if self._events >= self.limit:
                victim = next(
                    (e for e in self._queue if isinstance(e, Event) and e.kind in INFORMATIONAL),
                    None,
                )
                if victim is None and event.kind in INFORMATIONAL:
                    self.dropped[event.kind.value] += 1
                    return
                if victim is None:
                    victim = next(e for e in self._queue if isinstance(e, Event))
                    log.error(
                        "%s: event queue full of state changes; dropped %s", self.name, victim
                    )
                self._queue.remove(victim)
                self._events -= 1
                self.dropped[victim.kind.value] += 1
            self._queue.append(event)
            self._events += 1
            self._cond.notify()

    def put_job(self, job: Job) -> None:
        """Run ``job`` on the event thread, in order with the events (see the class docstring)."""
        with self._cond:
            if not self._exited:
                self._queue.append(job)
                self._cond.notify()
                return
        job()  # the thread is gone (closed): run it here rather than never

    @property
    def waiting(self) -> int:
        """Events queued and not yet handed to the callbacks."""
        with self._cond:
            return self._events

    def close(self) -> None:
        """Stop the thread; see the class docstring. Idempotent; callable from a callback."""
        with self._cond:
            self._closed = True
            discarded = self._events
            self._queue = collections.deque(e for e in self._queue if not isinstance(e, Event))
            self._events = 0
            self._cond.notify_all()
        if discarded:
            log.debug("%s: %d undelivered events discarded at close", self.name, discarded)
        if self._thread is None:
            self.run_pending()  # the jobs left, here: each future gets its result
            return
        if self._thread is threading.current_thread():
            return  # a callback closing the board: the thread ends when it returns
        self._thread.join(self.close_wait)
        if self._thread.is_alive():
            log.warning(
                "%s: an on_event callback still runs %.1f s after close(); it is left to "
                "finish, and no other callback will be called",
                self.name,
                self.close_wait,
            )

    def run_pending(self) -> int:
        """Without a thread: run what is queued, in order, on this thread; how many items ran."""
        ran = 0
        while (taken := self._take(block=False)) is not None:
            self._deliver(*taken)
            ran += 1
        return ran

    def _run(self) -> None:
        while (taken := self._take(block=True)) is not None:
            self._deliver(*taken)

    def _take(self, *, block: bool) -> tuple[Event | Job, list[EventCallback]] | None:
        """The next item and the callbacks to call with it; None when there is none (and,
        once closed, never again: jobs put after that run where they are put)."""
        with self._cond:
            while block and not self._queue and not self._closed:
                self._cond.wait()
            if not self._queue:
                if self._closed:  # closed, and every job run
                    self._exited = True
                return None
            item = self._queue.popleft()
            if isinstance(item, Event):
                self._events -= 1
            return item, list(self._callbacks)

    def _deliver(self, item: Event | Job, callbacks: list[EventCallback]) -> None:
        if not isinstance(item, Event):
            try:
                item()
            except Exception:
                log.exception("%s: event-thread job failed", self.name)
            return
        for callback in callbacks:
            if self._closed:  # close() was called during an earlier callback
                break
            try:
                callback(item)
            except Exception:
                log.exception("%s: on_event callback failed", self.name)
