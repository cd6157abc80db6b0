"""Requests (docs/protocol.md section 7): message ids, Acks, retransmission, window, ping.

One transaction table, one lock. A call is submitted from any thread and
waited on with a bound; everything timed (retransmission after ACK_TIMEOUT,
giving up after MAX_RETRIES, the 1 Hz Ping) runs in :meth:`link_tick` on the
I/O thread.

The session's rules (how the restore is sequenced and retried, what makes a
reboot loop, how an unseen reboot is inferred, what the failsafe epoch and
liveness tell) are the session layer's, :mod:`protoduino.session`: this
module holds them and applies them to its table, under its one lock. What
they decide is summed up below with the table's own rules.

* Message ids are per session and sequential, 1..127 (one varint byte on
  the wire), wrapping to 1 (protocol.md section 7, *Message ids*). A call
  gets its id at its first transmission, not when it is submitted, so ids go
  out in the order they were given; a retransmission reuses it (the device's
  dedupe window re-acks it without executing it twice). Every RESET tells
  the device the id that goes out next (the link asks :meth:`next_message_id`).
* Ids stay decidable: a new id never goes out 64 or more ahead of the oldest
  call still open (it waits for that call, whose retransmission would look
  newer than everything to the device), nor of the newest id the device
  acknowledged (or the one before the last handshake's NEXT_ID): then the
  device may have missed so many that newer and older can no longer be told
  apart, and the link handshakes again (a resumed session), which re-synchronises it.
* An Ack is matched by id only. An Ack for a call already finished (the twin
  of a retransmission, or after the call timed out) is counted as late; one
  for an id never sent is counted as unknown. Both are dropped: a stale reply
  never completes the wrong call.
* Up to ``window`` calls are in flight at once, so a burst is not paced by the
  round trip; the device answers them in order. Flow control by bytes: their
  frames together also stay within the receive buffer the device states
  (DeviceInfo.rx_buffer), so a burst never overflows it at any window.
* Dedupe guard: a retransmission is harmless only while its id is still in
  the device's window of the last DEDUPE_WINDOW (16) executed ids. So while a
  call X that changes outputs awaits its Ack, at most DEDUPE_WINDOW - 1
  distinct other ids may be transmitted after X's first transmission; a NEW
  id beyond that waits until X is acked or fails. Every id counts, Pings and
  GetInfo included (a device may store them; counting them costs nothing),
  and so does the retransmission of an older id (it may execute after X).
  Without this, a short round trip lets many newer calls complete while X's
  Ack is lost, and X's retransmission would run a second time. A reboot
  empties the device's window: the count starts again from there.
* Retries run on a fixed schedule from a call's first transmission: attempt
  k goes out at ``k * ack_timeout`` and, with no Ack, the call fails at
  ``(max_retries + 1) * ack_timeout``, exactly (the I/O thread sleeps until
  the next such time, and a late attempt does not delay the next one).
* While the link is down, nothing is sent: calls wait, bounded by their
  deadline (``call_timeout``), and fail with the link's own error (port lost,
  device silent) if it does not come back in time. When it comes back with
  the session resumed (a reconnect), calls that were in flight are sent again
  with their ids, with a fresh round of retries: the device's dedupe window
  still holds them. A link that failed for good (another protocol version or
  schema after a reboot) fails every outstanding and later call at once with
  its error: no deadline is waited out for a link that cannot come back.
* When it comes back with the outputs lost (a reboot, or another session took
  the device over), every call that had been sent and changes outputs fails
  with :class:`DeviceRebootedError`: it may or may not have run on the
  previous boot, and sending it again could repeat the very command that
  browned the board out. Calls not sent yet, and Pings, GetInfo and
  Heartbeats, go out after the restore. Then the messages from
  ``restore_provider`` are sent, one at a time and in order (an Init must
  land before its Control), and new calls are held until they are done. A
  restore message that times out is sent again (RESTORE_RETRIES times): a
  restore that skipped an Init would leave that output dead on the device.
* Reboot loop: the ``reboot_limit``-th loss of the outputs within
  ``reboot_window`` seconds stops restoring; every outstanding and later
  user call fails with :class:`RebootLoopError` and an ERROR event says why.
* A device that refuses a Control with STATUS_NOT_INITIALISED for an output
  the board configured has restarted unseen (its EVENT BOOT lost, then a
  re-handshake found it again): the restore runs, and that call is sent again
  after it, once, under a new id (the device keeps the refusal under the old
  one). It had not run, so this cannot run it twice. Any other call still
  open that was sent and changes outputs fails with DeviceRebootedError, as
  after a seen reboot: it may have run, and the restore's own ids would push
  it out of the device's dedupe window before it could be sent again.

Lock order: this layer's lock, then the board's. :meth:`Rpc` calls its hooks
(``restore_provider``, which takes the board's lock; ``on_done``) with its own
lock held, so the board never calls into this layer while it holds its own
lock: it takes what it needs under its lock, releases it, then submits.
tests/unit/test_lock_order.py checks that order on every path it drives.
"""

from __future__ import annotations

import collections
import itertools
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from .clock import Clock
from .commands import command
from .constants import (
    ACK_TIMEOUT,
    DEDUPE_WINDOW,
    FAILSAFE_TIMEOUT,
    ID_AHEAD_MAX,
    MAX_MESSAGE_ID,
    MAX_PAYLOAD,
    MAX_RETRIES,
    PING_INTERVAL,
)
from .errors import (
    AckTimeoutError,
    ArgumentError,
    BoardClosedError,
    DeviceRebootedError,
    PayloadTooLargeError,
    ProtoduinoError,
    RebootLoopError,
    rejection,
)
from .events import Event, EventKind
from .framing import frame_size
from .messages import ArduinoIn, ArduinoOut, Status, status_name
from .session import (
    REBOOT_LIMIT,
    REBOOT_WINDOW,
    Failsafe,
    FailsafeLiveness,
    RebootLoop,
    RestorePlan,
    refused_configured_output,
)

log = logging.getLogger(__name__)

Ack = Any  # protoduino_pb2.Ack (protobuf message classes are dynamic)
#: Commands that carry the latest failsafe epoch the host saw (protocol.md section 7,
#: failsafe epochs): the liveness messages, and ClearInterlock, which also re-arms.
EPOCH_KINDS = ("ping", "heartbeat", "clear_interlock")


class Done:
    """Set once, when a call completes: what its caller waits on.

    ``threading.Event``'s ``is_set``, ``set`` and ``wait``, on one lock held until
    it is set: a call makes one per command, and an Event (a Condition, its
    lock, a waiter lock per wait) cost more to build, wait on and set than
    everything else its caller does. ``set`` is called once, under the
    transaction table's lock (:meth:`Rpc._finish`); any number may wait.
    """

    __slots__ = ("_flag", "_lock")

    def __init__(self) -> None:
        self._flag = False
        self._lock = threading.Lock()
        self._lock.acquire()

    def is_set(self) -> bool:
        return self._flag

    def set(self) -> None:
        if not self._flag:
            self._flag = True
            self._lock.release()

    def wait(self, timeout: float | None = None) -> bool:
        """True once set; False if ``timeout`` seconds passed first (None: no bound)."""
        if self._flag:
            return True
        if self._lock.acquire(timeout=-1 if timeout is None else max(0.0, timeout)):
            self._lock.release()  # the next waiter passes too
        return self._flag


class Call:
    """One command on its way; :meth:`wait` for its Ack."""

    __slots__ = (
        "ack",
        "attempts",
        "deadline",
        "done",
        "epoch",
        "error",
        "first_tx",
        "frame",
        "key",
        "kind",
        "message_id",
        "on_done",
        "payload",
        "protected",
        "refusal",
        "restored",
        "round_start",
        "rtt",
        "sent_at",
        "serial",
        "submitted",
    )

    def __init__(
        self,
        key: int,
        kind: str,
        payload: bytes,
        *,
        submitted: float,
        deadline: float,
        on_done: Callable[[Call], None] | None,
    ) -> None:
        #: The call's own number in the table, from submit to the end.
        self.key = key
        #: Its message id, given at its first transmission (0: not sent yet).
        self.message_id = 0
        #: How many ids the session gave before this one, plus one: ids wrap, this does not.
        self.serial = 0
        self.kind = kind
        self.payload = payload
        #: Whether running it twice could matter (not idempotent): the dedupe guard's.
        self.protected = not command(kind).idempotent
        #: The most bytes its frame takes on the wire (the payload's length never changes).
        self.frame = frame_size(len(payload))
        self.submitted = submitted
        self.deadline = deadline
        self.on_done = on_done
        #: Transmissions in the current round of retries (a new round after a link outage).
        self.attempts = 0
        #: When the current round's first transmission went out: attempt k is due at
        #: round_start + k * ack_timeout, and the round ends at (max_retries + 1) of them.
        self.round_start = 0.0
        self.sent_at = 0.0
        #: Serial number of the first transmission to the current device boot (None: not yet).
        self.first_tx: int | None = None
        #: Sent again after a restore the device's refusal started (at most once).
        self.restored = False
        self.rtt: float | None = None
        #: A liveness message's failsafe epoch (Ping, Heartbeat), None for other kinds.
        self.epoch: int | None = None
        self.ack: Ack | None = None
        #: The device's refusing Ack, if it refused the call (``error`` is then set).
        self.refusal: Ack | None = None
        self.error: ProtoduinoError | None = None
        self.done = Done()

    def result(self) -> Ack:
        """The Ack (status OK), or raise the call's error. Call after ``done``."""
        if self.error is not None:
            raise self.error
        assert self.ack is not None
        return self.ack


MessageHook = Callable[[ArduinoOut], None]
RestoreProvider = Callable[[], list[ArduinoIn]]
#: How a caller waits for a call: (its done event, the bound in seconds) -> whether it was set.
#: :meth:`Done.wait` while an I/O thread runs the link; an in-process device runs the
#: link itself on its own clock instead (:mod:`protoduino.testing`).
Waiter = Callable[[Done, float], bool]


def event_wait(event: Done, timeout: float) -> bool:
    return event.wait(timeout)


class LinkPort(Protocol):
    """What the request layer needs of the link below it (:class:`~protoduino.link.Link`)."""

    down_error: ProtoduinoError | None

    @property
    def active(self) -> bool: ...

    def send_command(self, payload: bytes) -> bool: ...

    def request_handshake(self) -> None:
        """Handshake again (the session resumed) as soon as the link's thread can:
        the device's newest message id may lag too far behind (module docstring)."""

    def reboot_inferred(self) -> None:
        """Count a reboot only the request layer could see (the link owns the counter)."""

    def recent_frames(self) -> tuple[str, ...]:
        """The last frames on the line, to show in an error."""
        ...


@dataclass(frozen=True)
class RpcState:
    """A consistent snapshot of the transaction table (:meth:`Rpc.state`), for diagnosis."""

    #: The calls sent and awaiting their Ack, oldest first.
    inflight: tuple[Call, ...]
    #: Message ids of every call not finished yet (in flight or queued; 0: not sent yet).
    open_calls: tuple[int, ...]
    #: Calls queued behind the window: automatic Pings first, then the user's.
    urgent: int
    pending: int
    #: The id the next call transmitted will get.
    next_id: int


class Rpc:
    """The transaction table over one :class:`Link`; see the module docstring."""

    def __init__(
        self,
        *,
        notify: Callable[[Event], None],
        ack_timeout: float = ACK_TIMEOUT,
        max_retries: int = MAX_RETRIES,
        window: int = 4,
        ping: bool = True,
        ping_interval: float = PING_INTERVAL,
        link_wait: float = 5.0,
        clock: Clock = time.monotonic,
        first_id: int | None = None,
        reboot_limit: int = REBOOT_LIMIT,
        reboot_window: float = REBOOT_WINDOW,
        failsafe_timeout: float = FAILSAFE_TIMEOUT,
        heartbeat_liveness: bool = False,
        waiter: Waiter = event_wait,
        message_hook: MessageHook | None = None,
        restore_provider: RestoreProvider | None = None,
        restore_values: bool = False,
    ) -> None:
        if ack_timeout <= 0 or max_retries < 0 or window < 1 or reboot_limit < 1:
            raise ArgumentError(
                "ack_timeout > 0, max_retries >= 0, window >= 1 and reboot_limit >= 1 are required"
            )
        self.link: LinkPort | None = None
        self._notify = notify
        #: time.monotonic() unless a test injects its own; the I/O thread passes its
        #: ``now`` to link_tick, every other timestamp here comes from this clock.
        self._clock = clock
        self._waiter = waiter
        #: Set once the link failed for good: every call fails at once with it.
        self._failed: ProtoduinoError | None = None
        self.ack_timeout = ack_timeout
        self.max_retries = max_retries
        self.window = window
        #: Bytes of received frames the device can hold (DeviceInfo.rx_buffer): the command
        #: frames in flight are kept within it, so they never overflow its receive buffer
        #: whatever the window. None: not known yet, the window alone limits.
        self.rx_budget: int | None = None
        self.ping_interval = ping_interval
        #: Longest a call waits for the link to come back before it fails.
        self.link_wait = link_wait
        #: Where every message that is no Ack goes (the board's events and inputs).
        self.message_hook = message_hook
        #: The messages that rebuild the board's outputs after the device lost them; called
        #: with this layer's lock held (see "Lock order" in the module docstring).
        self.restore_provider = restore_provider
        #: Whether the restore sends last values too (for the RESTORED event only).
        self.restore_values = restore_values
        self._lock = threading.Lock()
        # A session's ids start at 1 (every RESET tells the device the next one);
        # ``first_id`` starts elsewhere (tests of the wrap).
        if first_id is not None and not 1 <= first_id <= MAX_MESSAGE_ID:
            raise ArgumentError(f"first_id must be 1 .. {MAX_MESSAGE_ID} (0 is never a message id)")
        self._next_id = first_id or 1
        #: Serial of the next id given (Call.serial), and of the newest id the device
        #: acknowledged or the one before the last handshake's NEXT_ID.
        self._next_serial = 1
        self._acked_serial = 0
        self._resync_asked = False
        #: Every call not finished, by Call.key; those with an id also by id.
        self._calls: dict[int, Call] = {}
        self._by_id: dict[int, Call] = {}
        self._keys = itertools.count(1)
        self._inflight: dict[int, Call] = {}
        self._urgent: collections.deque[Call] = collections.deque()  # pings
        self._pending: collections.deque[Call] = collections.deque()  # user calls
        #: No queued call's deadline is earlier than this (inf: none queued). Lowered as a
        #: call joins a queue, made exact again only when it is reached: a tick then looks
        #: at the queues, where looking at every queued call on every tick cost O(n) per
        #: pass and O(n^2) for a burst of n submits (issue 23).
        self._queued_due = float("inf")
        #: The session layer's rules (session.py), kept under this layer's lock.
        self._plan = RestorePlan()
        self._loop = RebootLoop(reboot_limit, reboot_window)
        self._failsafe = FailsafeLiveness(failsafe_timeout, heartbeat_liveness)
        self._restore_call: Call | None = None
        self._holding = False
        # Finished ids not given out again, to tell a late Ack from an unknown one (ids are
        # 1..127, so this holds at most 127).
        self._finished_set: set[int] = set()
        # Dedupe guard: id -> serial number of its last transmission, in that order.
        self._tx_log: collections.OrderedDict[int, int] = collections.OrderedDict()
        self._tx_serial = 0
        #: Transmissions of new ids held back by the dedupe guard (a counter, for tests).
        self.guard_holds = 0
        #: New ids held back by an old call still open, and re-handshakes asked for
        #: because the device's newest id lagged 64 behind (module docstring).
        self.id_holds = 0
        self.id_resyncs = 0
        self._closed = False
        self._pinging = ping
        self._next_ping = 0.0
        self._ping_call: Call | None = None
        # Counters
        self.commands = 0
        self.acks = 0
        self.retransmits = 0
        self.timeouts = 0
        self.rejected = 0
        self.late_acks = 0
        self.unknown_acks = 0
        self.pings = 0
        self.ping_failures = 0
        self.rtt: float | None = None
        #: time.monotonic() of the last acknowledged automatic Ping.
        self.last_ping: float | None = None

    def state(self) -> RpcState:
        """The transaction table as it is now (taken under the table's lock)."""
        with self._lock:
            return RpcState(
                inflight=tuple(self._inflight.values()),
                open_calls=tuple(c.message_id for c in self._calls.values()),
                urgent=len(self._urgent),
                pending=len(self._pending),
                next_id=self._next_id,
            )

    @property
    def loop_error(self) -> RebootLoopError | None:
        """Set once a reboot loop was detected: every user call fails with it."""
        return self._loop.error

    @property
    def failsafe_epoch(self) -> int:
        """The latest failsafe epoch the device reported: every Ping, Heartbeat and
        ClearInterlock carries it back (protocol.md section 7, failsafe epochs)."""
        return self._failsafe.epoch

    def attach(self, link: LinkPort) -> None:
        """The link below, which is built on this layer as its listener: the one step that
        ties the two together, once, before the link opens."""
        self.link = link

    @property
    def round_time(self) -> float:
        """How long a call may await its Ack from its first transmission, every retry included."""
        return self.ack_timeout * (self.max_retries + 1)

    @property
    def call_timeout(self) -> float:
        """The longest any call may take: every retry plus waiting for the link."""
        return self.ack_timeout * (self.max_retries + 1) + self.link_wait

    # --- pinging ------------------------------------------------------------------

    @property
    def pinging(self) -> bool:
        return self._pinging

    @pinging.setter
    def pinging(self, on: bool) -> None:
        with self._lock:
            self._pinging = bool(on)
            self._next_ping = 0.0  # resuming: ping at once, the failsafe may be close

    def expect_traffic(self) -> bool:
        return self._pinging or bool(self._calls)

    # --- submitting (any thread) ------------------------------------------------------

    def submit(
        self,
        msg: ArduinoIn,
        *,
        urgent: bool = False,
        on_done: Callable[[Call], None] | None = None,
    ) -> Call:
        """Queue one command (its message_id is assigned here) and return its Call."""
        with self._lock:
            if self._closed:
                raise BoardClosedError("the board is closed")
            if self._failed is not None:
                raise self._failed.with_traceback(None)
            if self.loop_error is not None:
                raise self.loop_error.with_traceback(None)
            call = self._new_call(msg, on_done)
            (self._urgent if urgent else self._pending).append(call)
            self._queued(call)
            self._pump(self._clock())
        return call

    def call(self, msg: ArduinoIn) -> Ack:
        """Send ``msg`` and wait for its Ack; raises on rejection, timeout or close."""
        call = self.submit(msg)
        return self.wait(call)

    def wait(self, call: Call) -> Ack:
        # The I/O thread fails every call by its deadline; the margin only
        # guards against that thread having died.
        bound = call.deadline - self._clock() + self.ack_timeout * (self.max_retries + 2) + 1.0
        if not self._waiter(call.done, max(0.0, bound)):
            with self._lock:
                self._finish(
                    call, error=AckTimeoutError(f"{call.kind} never completed (I/O thread stuck?)")
                )
        return call.result()

    def next_message_id(self) -> int:
        """The id the next new transmission gets: every RESET carries it (NEXT_ID)."""
        return self._next_id

    def _queued(self, call: Call) -> None:
        """``call`` joined a queue (lock held): its deadline is a timer (``_queued_due``)."""
        self._queued_due = min(self._queued_due, call.deadline)

    def _allocate_id(self, call: Call) -> None:
        """Give ``call`` the next id, at its first transmission (lock held)."""
        mid = self._next_id
        self._next_id = mid % MAX_MESSAGE_ID + 1  # 1 .. 127, never 0
        call.message_id = mid
        call.serial = self._next_serial
        self._next_serial += 1
        self._by_id[mid] = call
        self._finished_set.discard(mid)  # an Ack for it is this call's now
        # message_id is field 1, serialised first: one tag byte and one value byte.
        call.payload = bytes((0x08, mid)) + call.payload[2:]

    def _release_id(self, call: Call) -> None:
        """Take back the id just given to ``call``: it never left (lock held)."""
        self._by_id.pop(call.message_id, None)
        self._next_id = call.message_id
        self._next_serial = call.serial
        call.message_id = call.serial = 0

    def _ids_allow_new(self) -> bool:
        """May a new id go out and stay decidable on the device (module docstring)?"""
        serial = self._next_serial
        oldest = min((c.serial for c in self._by_id.values()), default=serial)
        if serial - oldest > ID_AHEAD_MAX:
            self.id_holds += 1  # it finishes (acked, or failed by its deadline)
            return False
        if serial - self._acked_serial > ID_AHEAD_MAX:
            if not self._resync_asked and self.link is not None:
                self._resync_asked = True
                self.id_resyncs += 1
                log.info("no Ack for the last %d ids: handshaking again", ID_AHEAD_MAX)
                self.link.request_handshake()
            return False
        return True

    def _new_call(self, msg: ArduinoIn, on_done: Callable[[Call], None] | None) -> Call:
        msg.message_id = 1  # a stand-in of the same size: the id is given at transmission
        kind = msg.WhichOneof("data") or "empty"
        epoch: int | None = None
        if kind in EPOCH_KINDS:
            # The latest failsafe this host saw: only then may it re-arm the device.
            epoch = self.failsafe_epoch
            getattr(msg, kind).failsafe_epoch = epoch
        payload = msg.SerializeToString()
        assert payload[:2] == b"\x08\x01"  # field 1 first: _allocate_id writes the id there
        if len(payload) > MAX_PAYLOAD:
            raise PayloadTooLargeError(
                f"command of {len(payload)} bytes exceeds MAX_PAYLOAD ({MAX_PAYLOAD})"
            )
        now = self._clock()
        call = Call(
            next(self._keys),
            kind,
            payload,
            submitted=now,
            deadline=now + self.call_timeout,
            on_done=on_done,
        )
        call.epoch = epoch
        self._calls[call.key] = call
        self.commands += 1
        return call

    # --- the I/O thread ---------------------------------------------------------------

    def _transmit(self, call: Call, now: float) -> None:
        assert self.link is not None
        fresh = not call.message_id
        if fresh:
            self._allocate_id(call)
        if not self.link.send_command(call.payload):
            if fresh:
                self._release_id(call)
            return
        if call.attempts:
            self.retransmits += 1
            log.debug("retransmitting %s id=%d", call.kind, call.message_id)
        else:
            call.round_start = now
        call.attempts += 1
        call.sent_at = now
        self._inflight[call.message_id] = call
        self._tx_serial += 1
        if call.first_tx is None:
            call.first_tx = self._tx_serial
        self._tx_log[call.message_id] = self._tx_serial
        self._tx_log.move_to_end(call.message_id)

    def _guard_allows_new(self) -> bool:
        """May a NEW id go out without pushing a protected call out of the device's window?

        The protected call X is the one, among calls awaiting their Ack that
        change outputs, transmitted first; any later one has seen a subset of
        what X has seen since (plus X itself), so guarding X guards them all.
        Ids transmitted after X's first transmission may each have been
        executed after X; with the new one they must stay under DEDUPE_WINDOW.
        """
        # A call transmitted to this boot holds its id until it finishes or is renumbered
        # (which clears first_tx): the calls with ids are the few in flight or requeued,
        # not every call queued behind the window.
        oldest = min(
            (c.first_tx for c in self._by_id.values() if c.first_tx is not None and c.protected),
            default=None,
        )
        if oldest is None:
            self._tx_log.clear()
            return True
        while self._tx_log:  # forget what went out before every protected call
            mid, serial = next(iter(self._tx_log.items()))
            if serial >= oldest:
                break
            del self._tx_log[mid]
        # The protected call itself is in the log with a serial >= oldest.
        return len(self._tx_log) - 1 < DEDUPE_WINDOW - 1

    def _fits(self, call: Call) -> bool:
        """Does ``call``'s frame fit the device's receive buffer beside those in flight?

        Every byte sent and not yet answered may still sit in that buffer (the
        device takes a frame out before it answers it), so keeping their sum
        within it means no frame is ever dropped for want of room. One call is
        always allowed, whatever its size, or nothing could ever go.
        """
        if self.rx_budget is None or not self._inflight:
            return True
        used = sum(c.frame for c in self._inflight.values())
        return used + call.frame <= self.rx_budget

    def _pump(self, now: float) -> None:
        """Send what may be sent now (lock held)."""
        link = self.link
        if link is None or not link.active or self._closed:
            return
        if self._holding:
            if (
                self._restore_call is None
                and self._plan.pending
                and self._guard_allows_new()
                and self._ids_allow_new()
            ):
                msg = self._plan.next()
                self._restore_call = self._new_call(msg, self._restore_step)
                self._transmit(self._restore_call, now)
            queues: tuple[collections.deque[Call], ...] = (self._urgent,)
        else:
            queues = (self._urgent, self._pending)
        for queue in queues:
            while queue and len(self._inflight) < self.window and self._fits(queue[0]):
                if queue[0].first_tx is None and not self._guard_allows_new():
                    # Held: a new id. The next queue may still hold a retransmission
                    # (a call requeued when the link went down), which the guard waits for.
                    self.guard_holds += 1
                    break
                if not queue[0].message_id and not self._ids_allow_new():
                    break
                self._transmit(queue.popleft(), now)

    def _finish(
        self, call: Call, *, ack: Ack | None = None, error: ProtoduinoError | None = None
    ) -> None:
        """Complete a call (lock held); its on_done runs now, on this thread."""
        if call.done.is_set():
            return
        self._calls.pop(call.key, None)
        in_flight = False
        if call.message_id:
            in_flight = self._inflight.pop(call.message_id, None) is not None
            if self._by_id.get(call.message_id) is call:
                del self._by_id[call.message_id]
        if not in_flight:  # a call in flight is in no queue
            for queue in (self._urgent, self._pending):
                if call in queue:
                    queue.remove(call)
        if call.message_id:  # an id given out again leaves the set (_allocate_id)
            self._finished_set.add(call.message_id)
        call.ack, call.error = ack, error
        call.done.set()
        if call.on_done is not None:
            try:
                call.on_done(call)
            except Exception:
                log.exception("completion callback failed")

    def _timeout_error(self, call: Call) -> ProtoduinoError:
        link = self.link
        if link is not None and not link.active and link.down_error is not None:
            return link.down_error
        frames = link.recent_frames() if link is not None else ()
        return AckTimeoutError(
            f"no Ack for {call.kind} (message_id {call.message_id}) after {call.attempts} "
            f"transmissions, {self.ack_timeout:g} s each",
            recent_frames=frames,
        )

    def _attempt_due(self, call: Call) -> float:
        """When an in-flight call's next transmission, or its failure, is due.

        Counted from the round's first transmission, not from the previous
        one: a retransmission that went out late (the I/O thread was busy)
        does not push the others back, so a round ends exactly
        ack_timeout x (max_retries + 1) after it began. Never after the deadline.
        """
        return min(call.round_start + call.attempts * self.ack_timeout, call.deadline)

    def link_tick(self, now: float) -> float:
        """Run the timers; return when they next need to run (the I/O thread sleeps until then)."""
        with self._lock:
            if self._closed:
                return now + PING_INTERVAL
            # Most ticks find nothing due: the calls are walked without copies until one is.
            if any(now >= self._attempt_due(c) for c in self._inflight.values()):
                for call in list(self._inflight.values()):
                    if now < self._attempt_due(call):
                        continue
                    # The round is over even if this thread woke too late to send every attempt.
                    over = min(call.deadline, call.round_start + self.round_time)
                    if call.attempts > self.max_retries or now >= over:
                        self.timeouts += 1
                        self._finish(call, error=self._timeout_error(call))
                    else:
                        del self._inflight[call.message_id]
                        self._transmit(call, now)
            if now >= self._queued_due:
                for queue in (self._urgent, self._pending):
                    for call in [c for c in queue if now >= c.deadline]:
                        self.timeouts += 1
                        self._finish(call, error=self._timeout_error(call))
                self._queued_due = min(
                    (c.deadline for q in (self._urgent, self._pending) for c in q),
                    default=float("inf"),
                )
            self._maybe_ping(now)
            self._pump(now)
            return self._next_due(now)

    def _next_due(self, now: float) -> float:
        """The earliest timer still pending after a tick at ``now`` (lock held)."""
        due = min(map(self._attempt_due, self._inflight.values()), default=None)
        if self._queued_due != float("inf"):  # a lower bound: at worst a tick comes early
            due = self._queued_due if due is None else min(due, self._queued_due)
        link = self.link
        if self._pinging and self._ping_call is None and link is not None and link.active:
            due = self._next_ping if due is None else min(due, self._next_ping)
        return max(now, now + PING_INTERVAL if due is None else due)

    def _maybe_ping(self, now: float) -> None:
        link = self.link
        if not self._pinging or link is None or not link.active or self._ping_call is not None:
            return
        if now < self._next_ping:
            return
        self._next_ping = now + self.ping_interval
        msg = ArduinoIn()
        msg.ping.SetInParent()
        self._ping_call = self._new_call(msg, self._ping_done)
        self._urgent.append(self._ping_call)
        self._queued(self._ping_call)
        self.pings += 1

    def _ping_done(self, call: Call) -> None:
        self._ping_call = None
        if call.error is not None:
            self.ping_failures += 1
            log.debug("automatic ping failed: %s", call.error)
        else:
            self.last_ping = self._clock()

    def link_message(self, msg: ArduinoOut) -> None:
        if msg.WhichOneof("data") != "ack":
            if msg.WhichOneof("data") == "failsafe":
                with self._lock:
                    self._failsafe_seen(msg.failsafe)
            if self.message_hook is not None:
                self.message_hook(msg)
            return
        ack = msg.ack
        with self._lock:
            call = self._by_id.get(ack.message_id)
            if call is None or call.done.is_set():
                if ack.message_id in self._finished_set:
                    self.late_acks += 1
                else:
                    self.unknown_acks += 1
                    log.debug("Ack for unknown message_id %d dropped", ack.message_id)
                return
            self.acks += 1
            self._acked_serial = max(self._acked_serial, call.serial)  # the device has it
            now = self._clock()
            if call.sent_at:
                call.rtt = now - call.sent_at
            if ack.status == 0:
                if call.kind == "ping":
                    self.rtt = call.rtt
                self._liveness_acked(call, ack)
                self._finish(call, ack=ack)
            elif self._lost_session(call, ack):
                if not self._holding:  # the first such answer: restore, then send again
                    self._session_lost(call)
                else:  # another call sent before the restore began: it goes again after it
                    self._renumber(call)
                    if call not in self._pending:
                        self._pending.appendleft(call)
                        self._queued(call)
            else:
                self.rejected += 1
                call.refusal = ack  # it may say more (a Pose's refused_item)
                self._finish(
                    call,
                    error=rejection(
                        ack.status,
                        f"{call.kind} rejected by the device: {status_name(ack.status)}",
                    ),
                )
            self._pump(now)

    def _failsafe_seen(self, fs: Failsafe) -> None:
        """The device's failsafe state, from its event or a liveness Ack (lock held)."""
        if self._failsafe.seen(fs):
            self._next_ping = 0.0  # send the epoch back at once: the device re-arms

    def _liveness_acked(self, call: Call, ack: Ack) -> None:
        """Note what an acknowledged call tells of the failsafe (lock held).

        A Ping's or Heartbeat's Ack carries the device's failsafe state once one
        was entered since power-up: a failsafe whose event was lost (a host
        stalled past its re-handshake, a device-to-host cut) is learned here and
        reported like the event (the Board sees it through ``message_hook``).
        Whether it fed the device's timer is the session's rule (session.py).
        """
        if call.kind in ("ping", "heartbeat") and ack.HasField("failsafe"):
            self._failsafe_seen(ack.failsafe)
            if self.message_hook is not None:
                out = ArduinoOut()
                out.failsafe.CopyFrom(ack.failsafe)
                self.message_hook(out)
        self._failsafe.acked(call.kind, call.epoch, call.round_start, ack)

    def liveness_lapsed(self) -> bool:
        """May the device's failsafe have fired without this host hearing of it?
        (:meth:`protoduino.session.FailsafeLiveness.lapsed`, now)."""
        return self._failsafe.lapsed(self._clock())

    def _lost_session(self, call: Call, ack: Ack) -> bool:
        """Did the device refuse ``call`` because it restarted unseen (session.py,
        :func:`~protoduino.session.refused_configured_output`)? Once per call, and never
        for the restore's own messages."""
        if (
            ack.status != Status.STATUS_NOT_INITIALISED
            or call.restored
            or call is self._restore_call
            or self.restore_provider is None
        ):
            return False
        try:
            msgs = self.restore_provider()
        except Exception:
            log.exception("restore provider failed")
            return False
        return refused_configured_output(call.payload, ack, msgs)

    def _session_lost(self, call: Call) -> None:
        log.warning(
            "the device answered %s for a configured output: it restarted unseen; restoring",
            status_name(Status.STATUS_NOT_INITIALISED),
        )
        if self.link is not None:
            self.link.reboot_inferred()
        self._notify(
            Event(
                EventKind.REBOOTED,
                "device rebooted (it lost its configuration unseen)",
                {"how": "NOT_INITIALISED"},
            )
        )
        self._requeue_inflight()  # this call and every other one in flight, oldest first
        self._renumber(call)
        self._begin_restore()

    def _renumber(self, call: Call) -> None:
        """Give a refused call a new id, to be sent again after the restore (lock held).

        The device stored the refusal under the old id in its dedupe window and
        would only repeat it; the call did not run, so a new id runs it once.
        """
        self._inflight.pop(call.message_id, None)
        self._by_id.pop(call.message_id, None)
        self._finished_set.add(call.message_id)  # a late answer to it is late, not unknown
        call.message_id = call.serial = 0  # a new one at its next transmission
        call.first_tx = None
        call.attempts = 0
        call.restored = True

    def link_up(self, lost: bool, rebooted: bool) -> None:
        with self._lock:
            # The RESET told the device our next id: its newest is the one before.
            self._acked_serial = self._next_serial - 1
            self._resync_asked = False
            if rebooted:
                self._failsafe.rebooted()
            if lost:
                self._outputs_lost(rebooted, self._clock())
            else:
                self._requeue_inflight()  # a reconnect: the dedupe window still has them
            self._next_ping = 0.0
            self._pump(self._clock())

    def _outputs_lost(self, rebooted: bool, now: float) -> None:
        """The device no longer has our outputs (lock held): fail what was outstanding, restore."""
        what = "rebooted" if rebooted else "was taken over by another session"
        error: DeviceRebootedError
        loop = self._loop.lost(now)
        if loop is not None:
            error = loop
            log.error("%s", error)
            self._notify(Event(EventKind.ERROR, str(error), {"error": str(error)}))
        else:
            error = DeviceRebootedError(
                f"the device {what} while the call was outstanding; its outputs are being "
                "re-initialised at their safe values and the call is not sent again"
            )
        self._requeue_inflight()
        self._tx_log.clear()  # the device's dedupe window is void
        for call in list(self._calls.values()):
            call.first_tx = None
            # Sent to the lost device: it may have run there (and be what reset it).
            # Never sent, or harmless to repeat: it goes out after the restore.
            stale = call.sent_at and not command(call.kind).idempotent
            if (self.loop_error is not None or stale) and call is not self._ping_call:
                self._finish(call, error=error)
        self._plan.clear()
        self._holding = False
        if self.loop_error is None and self.restore_provider is not None:
            self._begin_restore()

    def _begin_restore(self) -> None:
        """Replay the board's session (lock held); user calls wait until it is done."""
        assert self.restore_provider is not None
        # The device lost the outputs. A call sent to it that changes outputs and is still
        # open (from _session_lost: the device restarted unseen) may have run there, and
        # its id may be in the window; but the restore's own ids go out first, and past
        # DEDUPE_WINDOW - 1 of them its retransmission would run again. So it is not sent
        # again, as after a reboot (_outputs_lost). What is left is idempotent or unsent:
        # what went out before guards nothing.
        self._tx_log.clear()
        for call in list(self._calls.values()):
            if call.first_tx is not None and not command(call.kind).idempotent:
                self._finish(
                    call,
                    error=DeviceRebootedError(
                        "the device restarted unseen while the call was outstanding; its "
                        "outputs are being re-initialised at their safe values and the call "
                        "is not sent again"
                    ),
                )
            call.first_tx = None
        try:
            msgs = self.restore_provider()
        except Exception:
            log.exception("restore provider failed")
            msgs = []
        self._plan.start(msgs)
        if self._restore_call is not None:  # an interrupted restore: start over
            self._finish(self._restore_call, error=BoardClosedError("restore restarted"))
            self._restore_call = None
        self._holding = bool(msgs)
        if not msgs:
            self._restored()

    def link_down(self, reason: str) -> None:
        with self._lock:
            self._requeue_inflight()

    def link_failed(self, error: ProtoduinoError) -> None:
        """The link failed for good (e.g. another protocol version after a reboot).

        Nothing can bring it back but other firmware, so waiting is pointless:
        every outstanding call fails now with ``error``, and so does every
        later one, at once, instead of each waiting out its deadline.
        """
        with self._lock:
            self._failed = error
            self._plan.clear()
            self._holding = False
            self._restore_call = None
            for call in list(self._calls.values()):
                self._finish(call, error=error)

    def _requeue_inflight(self) -> None:
        """Calls in flight go back to the front of their queues, oldest first, to be resent."""
        calls = sorted(self._inflight.values(), key=lambda c: c.submitted, reverse=True)
        self._inflight.clear()
        for call in calls:
            call.attempts = 0  # a fresh set of retries once the link is back
            if call is self._restore_call:
                self._restore_call = None
                self._plan.put_back(call.payload)
                self._calls.pop(call.key, None)
                self._by_id.pop(call.message_id, None)
            elif call.kind == "ping" and call is self._ping_call:
                self._urgent.appendleft(call)
                self._queued(call)
            else:
                self._pending.appendleft(call)
                self._queued(call)

    def _restore_step(self, call: Call) -> None:
        if call is not self._restore_call:
            return
        self._restore_call = None
        self._plan.finished(call.kind, call.payload, call.error)
        if not self._plan.pending:
            self._holding = False
            self._restored()

    def _restored(self) -> None:
        self._notify(self._plan.event(self.restore_values))

    # --- closing ------------------------------------------------------------------

    def close(self) -> None:
        """Fail every outstanding call with BoardClosedError; idempotent."""
        with self._lock:
            self._closed = True
            for call in list(self._calls.values()):
                self._finish(call, error=BoardClosedError(f"the board was closed ({call.kind})"))
            self._plan.clear()

    def outstanding(self) -> int:
        with self._lock:
            return len(self._calls)
