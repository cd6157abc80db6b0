"""Link layer (docs/protocol.md sections 5 and 6): handshake, SEQ accounting, watchdog.

States: WAIT_ACK (handshaking, or waiting for the port) -> ACTIVE; FAILED when
the device speaks another protocol version or schema (nothing can fix that
but new firmware); CLOSED.

* Handshake: RESET(VERSION) with SEQ 0, resent with a doubling backoff (capped
  at 1 s) until a RESET_ACK arrives. The first handshake fails after
  ``handshake_timeout`` with :class:`HandshakeError`; a later one (after a
  reboot or a lost port) reports the failure as an event and keeps trying.
* Every RESET carries this host's session id and the message id the request
  layer transmits next (NEXT_ID, asked of the ``next_id`` hook the layer above
  hands in: the link imports nothing above it); the device's RESET_ACK carries
  its boot id (new at every power-up) and whether it resumed the session
  (kept its outputs). That answer alone says what happened while the link was
  down: the same boot id and "resumed" is a reconnect (nothing to redo); a new
  boot id is a reboot; the same boot id without "resumed" means another
  session took the device over. The last two lost the outputs: ``link_up``
  says ``lost=True`` so that the layer above re-initialises them.
* Any RESET_ACK, even while ACTIVE (the twin of a resent RESET), means the
  device just cleared its link state: the next expected SEQ is 1.
* EVENT BOOT or NOT_ACTIVE while ACTIVE, a reopened port, a SEQ jump of more
  than SEQ_DESYNC_THRESHOLD, or nothing valid received for WATCHDOG_TIMEOUT
  while traffic is expected, or, at an agreed rate (not the opening one),
  nothing valid received for ``silence_timeout`` (two Ack timeouts) after a
  COMMAND went out (a device that reset is back at the opening rate: its
  EVENT BOOT and everything after it are lost to this end's rate, so the
  watchdog alone found it only after 5 s, its calls failed with
  AckTimeoutError meanwhile), or the request layer asking for it
  (:meth:`request_handshake`: its ids would run 64 ahead of the device's newest):
  handshake again (the RESET_ACK then tells).
* The line rate (docs/protocol.md 5, *Line rate*), unless the board pinned one:
  after a RESET_ACK at the opening rate that offers faster rates, BAUD_SET of the
  fastest not yet failed, at the opening rate; on its BAUD_ACK the port switches
  and the same BAUD_SET probes the new rate; on that answer the handshake goes on
  with a RESET at the new rate, which confirms the switch to the device. A probe
  unanswered after BAUD_PROBE_TRIES x BAUD_PROBE_WAIT puts the port back at the
  opening rate, marks the rate failed (never sent at again) and handshakes there
  (the device, unconfirmed, is back within BAUD_CONFIRM: the next RESET goes then,
  the retries after it from the first retry delay again). An agreement starts
  only while the handshake's budget holds AGREEMENT_COST more (a bootloader may
  have used most of it); otherwise the link comes up at the opening rate and a
  later handshake tries the rates not yet failed. Every other RESET retry
  goes at the rate the link last ran at, the ones between cycle through the
  opening rate and the other rates not failed (after an agreed rate, two in
  three of those at the opening rate): a device that rebooted (at the opening
  rate) or that a previous host left at a fast one is found either way. The
  RESET that confirms an agreed rate starts its retries from the first delay.

Everything here runs on the transport's I/O thread, except :meth:`open` and
:meth:`close`. The state is a handful of fields written only by that thread,
so readers from other threads see a consistent-enough snapshot without locks.
"""

from __future__ import annotations

import dataclasses
import logging
import secrets
import threading
import time
from collections import Counter
from collections.abc import Callable
from enum import StrEnum
from typing import Protocol

from ._generated.schema_id import SCHEMA_ID
from .clock import Clock
from .constants import (
    ACK_TIMEOUT,
    BAUD_CONFIRM,
    BAUD_PROBE_TRIES,
    BAUD_PROBE_WAIT,
    FAST_BAUDRATES,
    OPENING_BAUDRATE,
    PROTOCOL_VERSION,
    SEQ_DESYNC_THRESHOLD,
    SEQ_TOLERANCE,
    WATCHDOG_TIMEOUT,
    ControlCode,
    EventCode,
    PacketType,
)
from .errors import (
    ArgumentError,
    ArgumentTypeError,
    BoardClosedError,
    HandshakeError,
    LinkError,
    ProtocolError,
    ProtoduinoError,
    SchemaMismatchError,
    TransportError,
    VersionMismatchError,
)
from .events import Event, EventKind
from .messages import ArduinoOut, parse_out
from .packets import BadFrame, Control, Packet, baud_payload, parse_control, reset_payload
from .transport import TransportListener

log = logging.getLogger(__name__)

#: First RESET retry delay and the largest one (seconds).
RESET_FIRST_RETRY = 0.1
RESET_MAX_RETRY = 1.0
#: How long a rate that fails costs the handshake at most: the probes, the device's return
#: to the opening rate and two RESETs there. An agreement starts only while the handshake's
#: budget holds this much more; otherwise the link comes up at the opening rate (a real
#: Uno's bootloader takes a second or two of the budget after the open's reset).
AGREEMENT_COST = BAUD_PROBE_TRIES * BAUD_PROBE_WAIT + BAUD_CONFIRM + 2 * RESET_FIRST_RETRY
#: After a failed switch, the first RESET at the opening rate waits for the device's own
#: return there (BAUD_CONFIRM after its switch, on its clock) plus this margin.
RETURN_MARGIN = 0.02


class PacketPort(Protocol):
    """What the link needs of the layer below it.

    :class:`~protoduino.transport.Transport` (a pyserial port and its I/O thread) in use; an
    in-process device in tests, which then drives the link without a thread or a port.
    """

    url: str
    name: str
    #: The rate the port runs at (set_baudrate changes it).
    baudrate: int
    #: True while the port is open.
    connected: bool
    #: Bytes received since the last open, and the first of them (to say what a wrong
    #: device sent).
    rx_since_open: int
    rx_head: bytes

    def start(self, listener: TransportListener) -> None: ...

    def close(self) -> None: ...

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None: ...

    def clear_queue(self) -> None: ...

    def set_baudrate(self, rate: int) -> None: ...

    def recent_frames(self) -> tuple[str, ...]: ...


class LinkState(StrEnum):
    WAIT_ACK = "handshaking"
    ACTIVE = "active"
    FAILED = "failed"
    CLOSED = "closed"


class LinkListener(Protocol):
    """What the request layer implements; called on the I/O thread."""

    def link_up(self, lost: bool, rebooted: bool) -> None:
        """The link is ACTIVE; ``lost``: the device no longer has this session's outputs."""

    def link_down(self, reason: str) -> None: ...

    def link_message(self, msg: ArduinoOut) -> None: ...

    def link_failed(self, error: ProtoduinoError) -> None: ...

    def link_tick(self, now: float) -> float:
        """Run the timers; return the time they next need to run."""
        ...

    def expect_traffic(self) -> bool:
        """Whether answers are due (pings on, or calls outstanding): the watchdog runs only
        then, since a device left alone is legitimately silent."""
        ...


Notify = Callable[[Event], None]


def describe_received(count: int, head: bytes, packets: int, reset_acks: int = 0) -> str:
    """What a device that did not answer RESET sent instead, for the error message.

    A port full of text is a sketch (or another firmware) printing; silence is
    no firmware, a wrong port or a wrong baud rate; frames without a RESET_ACK
    are a protoduino device stuck in some other state; RESET_ACKs are a device
    that answered, on a handshake that did not finish (the line rate's agreement).
    """
    if reset_acks:
        return f"received {packets} protoduino frames, {reset_acks} of them RESET_ACKs"
    if packets:
        return f"received {packets} protoduino frames but no RESET_ACK"
    if count == 0:
        return "received nothing"
    body = head.strip(b"\x00")  # a flush byte is no message
    text = body.decode("ascii", errors="replace")
    if body and all(c.isprintable() or c in "\r\n\t" for c in text):
        snippet = " ".join(text.split())
        more = "..." if count > len(head) or len(snippet) > 40 else ""
        return f"received {count} bytes of text, not protoduino frames: '{snippet[:40]}{more}'"
    more = " ..." if count > 16 else ""
    return f"received {count} bytes, not protoduino frames: {head[:16].hex(' ')}{more}"


class Link:
    """The link state machine over one :class:`Transport`; see the module docstring."""

    def __init__(
        self,
        transport: PacketPort,
        listener: LinkListener,
        *,
        handshake_timeout: float,
        notify: Notify,
        watchdog_timeout: float = WATCHDOG_TIMEOUT,
        schema_id: int = SCHEMA_ID,
        version: int = PROTOCOL_VERSION,
        clock: Clock = time.monotonic,
        session: int | None = None,
        baudrate: int | None = None,
        next_id: Callable[[], int] | None = None,
        silence_timeout: float = 2 * ACK_TIMEOUT,
    ) -> None:
        self.transport = transport
        #: The message id the request layer transmits next, which every RESET carries
        #: (NEXT_ID, protocol.md section 5); a hook, so the link imports nothing above it.
        self._next_id: Callable[[], int] = next_id if next_id is not None else lambda: 1
        #: Set (from any thread) when the request layer asks for a re-handshake.
        self._handshake_wanted = False
        #: Every timestamp of the link's own comes from this clock (the I/O thread's ticks
        #: pass their ``now`` from the same one).
        self._clock = clock
        self._listener = listener
        self._notify = notify
        self.handshake_timeout = handshake_timeout
        self.watchdog_timeout = watchdog_timeout
        self.silence_timeout = silence_timeout
        #: When a COMMAND went out with nothing valid received since (None: answered);
        #: written by whichever thread sends, cleared by the I/O thread on any packet.
        self._unanswered_since: float | None = None
        self.schema_id = schema_id
        self.version = version
        #: This host's session id (never 0: the device's "no session").
        if session is not None and (isinstance(session, bool) or not isinstance(session, int)):
            # struct.pack in the I/O thread would fail on it, far from the caller.
            raise ArgumentTypeError(f"session must be an int, not {type(session).__name__}")
        self.session = session if session is not None else secrets.randbelow(0xFFFFFFFF) + 1
        if not 0 < self.session <= 0xFFFFFFFF:
            raise ArgumentError(f"session must be 1..2**32-1, not {self.session}")
        #: ``baudrate`` pins the line rate (no agreement); None: open at
        #: OPENING_BAUDRATE and agree on the fastest rate both sides offer.
        if baudrate is not None and (isinstance(baudrate, bool) or not isinstance(baudrate, int)):
            raise ArgumentTypeError(f"baudrate must be an int, not {type(baudrate).__name__}")
        if baudrate is not None and baudrate <= 0:
            raise ArgumentError(f"baudrate must be positive, not {baudrate}")
        self.pinned_baudrate = baudrate
        self.opening_baudrate = baudrate if baudrate is not None else OPENING_BAUDRATE
        #: The rate the link last ran at: where a re-handshake looks first.
        self.line_baudrate = self.opening_baudrate
        #: Rates whose switch failed: never proposed, nor sent at, again by this link.
        self.failed_baudrates: set[int] = set()
        #: The rates the device offered at the last handshake, fastest first.
        self.device_baudrates: tuple[int, ...] = ()
        self.baud_switches = 0
        self.baud_fallbacks = 0
        self._hs_attempt = 0  # RESETs sent in this handshake (which rate the next goes at)
        self._baud_phase: str | None = None  # "propose" (at the opening rate), "probe" (new)
        self._baud_rate = 0
        self._baud_tries = 0
        self._baud_due = 0.0
        self._baud_from: Control | None = None  # the RESET_ACK the agreement started from
        self._baud_switched = 0.0  # when the host followed the device to the new rate
        #: The device's boot id at the last handshake (None before the first).
        self.boot_id: int | None = None
        #: Whether the first handshake found the session still on the device.
        self.resumed_at_open = False
        self.state = LinkState.WAIT_ACK
        self._rx_expected = 0
        self._last_rx = 0.0
        self._hs_started = 0.0
        self._hs_next = 0.0
        self._hs_delay = RESET_FIRST_RETRY
        self._hs_reported = False
        self._hs_packets = 0  # good packets received while handshaking
        self._hs_reset_acks = 0  # RESET_ACKs among them
        self._was_active = False
        self._opened = threading.Event()
        #: Held while open() starts the transport and while close() marks the link closed,
        #: so a close from another thread never misses a transport that is starting.
        self._life = threading.Lock()
        self._hs_rx = 0  # transport.rx_since_open when this handshake started
        #: Why the link is not ACTIVE (what a waiting call should raise), or None.
        self.down_error: ProtoduinoError | None = None
        self.device_version: int | None = None
        self.device_schema_id: int | None = None
        # Counters
        self.rx_packets = 0
        self.direction_drops = 0
        self.seq_lost = 0
        self.seq_desyncs = 0
        self.handshakes = 0
        self.reconnects = 0
        self.reboots = 0
        self.sessions_lost = 0
        self.watchdog_resets = 0
        #: Re-handshakes because the device fell silent at an agreed rate (it reset?);
        #: counted in watchdog_resets too.
        self.silence_resets = 0
        self.device_events: Counter[str] = Counter()

    # --- called from user threads --------------------------------------------

    def open(self) -> None:
        """Open the port and handshake; raises if either fails within handshake_timeout.

        :meth:`close` from another thread abandons it: it raises
        :class:`BoardClosedError` at once, and the port and the I/O thread are released.
        """
        self.down_error = HandshakeError(self._no_answer_text())
        with self._life:  # a close() either comes first (nothing starts) or waits for start()
            if self.state is LinkState.CLOSED:
                raise BoardClosedError("the board was closed while it was opening")
            self.transport.start(self)  # raises TransportError for a port that cannot open
        # The I/O thread enforces the deadline; the margin covers scheduling only.
        if not self._opened.wait(self.handshake_timeout + 2.0):
            self.down_error = HandshakeError(self._no_answer_text())
        if self.closed:  # close() from another thread woke the wait
            raise BoardClosedError("the board was closed while it was opening")
        if self.state is not LinkState.ACTIVE:
            error = self.down_error or HandshakeError(self._no_answer_text())
            self.close()
            raise error

    def reboot_inferred(self) -> None:
        """The request layer found a reboot this link did not see (its EVENT BOOT was lost):
        counted here, with the ones it saw, since the link owns its counters."""
        self.reboots += 1

    def close(self) -> None:
        """Stop the I/O thread and close the port; an :meth:`open` in progress raises."""
        with self._life:
            self.state = LinkState.CLOSED
        self._opened.set()  # wakes an open() waiting for the handshake
        self.transport.close()

    @property
    def closed(self) -> bool:
        return self.state is LinkState.CLOSED

    @property
    def active(self) -> bool:
        return self.state is LinkState.ACTIVE

    def recent_frames(self) -> tuple[str, ...]:
        """The last frames on the line (the transport's record), to show in an error."""
        return self.transport.recent_frames()

    @property
    def expected_seq(self) -> int:
        """The SEQ the link expects on the device's next packet (docs/protocol.md 6)."""
        return self._rx_expected

    def request_handshake(self) -> None:
        """Handshake again, resuming the session, at the I/O thread's next tick (the
        request layer's ids: rpc.py's module docstring)."""
        self._handshake_wanted = True

    def send_command(self, payload: bytes) -> bool:
        """Queue one COMMAND; False (nothing queued) unless the link is ACTIVE."""
        if self.state is not LinkState.ACTIVE:
            return False
        if self._unanswered_since is None:
            self._unanswered_since = self._clock()
        self.transport.send(PacketType.COMMAND, payload)
        return True

    # --- TransportListener (I/O thread) ------------------------------------------

    def transport_opened(self, reopened: bool) -> None:
        if self.state in (LinkState.CLOSED, LinkState.FAILED):
            return
        if reopened:
            self.reconnects += 1  # a reboot or not: the RESET_ACK's boot id will say
        self._start_handshake(self._clock())

    def transport_lost(self, error: Exception) -> None:
        if self.state in (LinkState.CLOSED, LinkState.FAILED):
            return
        self.down_error = (
            error if isinstance(error, ProtoduinoError) else TransportError(str(error))
        )
        self._go_down("port lost")
        self.state = LinkState.WAIT_ACK
        self._hs_next = float("inf")  # no RESET until the port is back

    def transport_failed(self, error: Exception) -> None:
        """The I/O thread is ending on a bug: the board fails for good, reported (ERROR)."""
        if self.state in (LinkState.CLOSED, LinkState.FAILED):
            return
        self._fail(LinkError(f"{error}; close the board and open it again"))

    def transport_received(self, items: list[Packet | BadFrame]) -> None:
        for item in items:
            if self.state in (LinkState.CLOSED, LinkState.FAILED):
                return
            if isinstance(item, BadFrame):
                log.debug("%s: dropped frame (%s)", self.transport.name, item.reason)
                continue
            self._packet(item)

    def transport_tick(self, now: float) -> float:
        """Run the link's timers and the request layer's; return when they next need to run."""
        if self.state is LinkState.WAIT_ACK and self.transport.connected:
            # The timeout is a timer of its own: checked only at the next RESET retry, it
            # was reported up to a retry interval late (5.5 s for 5 s).
            if not self._hs_reported and now >= self._hs_started + self.handshake_timeout:
                self._handshake_failed()
            if self._baud_phase is not None:
                if self.state is LinkState.WAIT_ACK and now >= self._baud_due:
                    if self._baud_tries < BAUD_PROBE_TRIES:
                        self._send_baud(now)
                    else:
                        self._baud_failed(now, "no answer")
            elif self.state is LinkState.WAIT_ACK and now >= self._hs_next:
                self._send_reset(now)
        elif (
            self.state is LinkState.ACTIVE
            # >=: at the due time this returns below, not a hair later (an exact clock
            # would otherwise be asked to tick again at the same instant, forever).
            and now - self._last_rx >= self.watchdog_timeout
            and self._listener.expect_traffic()
        ):
            log.warning(
                "%s: nothing received for %.1f s; handshaking again",
                self.transport.name,
                self.watchdog_timeout,
            )
            self.watchdog_resets += 1
            self._restart("watchdog", now)
        elif self.state is LinkState.ACTIVE and self._silent_at_agreed_rate(now):
            log.warning(
                "%s: nothing received for %.2f s after a command at %d baud (a reset "
                "device is back at %d); handshaking again",
                self.transport.name,
                self.silence_timeout,
                self.line_baudrate,
                self.opening_baudrate,
            )
            self.watchdog_resets += 1  # the watchdog's shorter bound at an agreed rate
            self.silence_resets += 1
            self._restart("silent at the agreed rate", now)
        due = self._listener.link_tick(now)
        if self._handshake_wanted:
            self._handshake_wanted = False
            if self.state is LinkState.ACTIVE:
                self._restart("message ids", now)
        if self.state is LinkState.WAIT_ACK and self.transport.connected:
            due = min(due, self._baud_due if self._baud_phase is not None else self._hs_next)
            if not self._hs_reported:
                due = min(due, self._hs_started + self.handshake_timeout)
        elif self.state is LinkState.ACTIVE:
            if self._listener.expect_traffic():
                due = min(due, self._last_rx + self.watchdog_timeout)
            since = self._unanswered_since
            if since is not None and self.line_baudrate != self.opening_baudrate:
                due = min(due, since + self.silence_timeout)
        return due

    def _silent_at_agreed_rate(self, now: float) -> bool:
        """A COMMAND unanswered for silence_timeout at an agreed rate (module docstring)."""
        since = self._unanswered_since
        return (
            since is not None
            and self.line_baudrate != self.opening_baudrate
            and now - since >= self.silence_timeout
        )

    # --- internals (I/O thread) -----------------------------------------------

    def _no_answer_text(self) -> str:
        if self._was_active:
            # This device has answered this board before: it is protoduino firmware on the
            # right port at the right speed. Say what is known, not the first-open checklist.
            heard = max(0, self.transport.rx_since_open - self._hs_rx)
            acks = f"{self._hs_reset_acks} RESET_ACKs" if self._hs_reset_acks else "no RESET_ACK"
            return (
                f"the device on {self.transport.url} answered this board before, but not its "
                f"RESET for {self.handshake_timeout:g} s (meanwhile received {heard} bytes, "
                f"{self._hs_packets} frames, {acks}): the link stalled or the device "
                "stopped answering; still trying"
            )
        heard_text = describe_received(
            self.transport.rx_since_open,
            self.transport.rx_head,
            self._hs_packets,
            self._hs_reset_acks,
        )
        if self._hs_reset_acks:
            failed = ", ".join(f"{rate}" for rate in sorted(self.failed_baudrates, reverse=True))
            return (
                f"the device on {self.transport.url} answered RESET but the handshake did "
                f"not finish within {self.handshake_timeout:g} s ({heard_text}; line rates "
                f"that failed: {failed or 'none'}); if the line cannot carry the faster "
                f"rates, pin the opening rate (baudrate={self.opening_baudrate}, "
                f"--baud {self.opening_baudrate})"
            )
        # A bootloader that waits says nothing: the one silent cause the checklist cannot name
        # from what was heard (a Mega's stk500v2 one is told to leave: transport.py).
        bootloader = (
            "; a board just reset by the open may still be in a bootloader that does not let "
            "go (docs/api.md, When the device does not answer)"
            if self.transport.rx_since_open == 0
            else ""
        )
        return (
            f"the device on {self.transport.url} did not answer RESET within "
            f"{self.handshake_timeout:g} s ({heard_text}); check that the protoduino firmware is "
            "flashed, the port and baud rate are right, and nothing else holds the port"
            + bootloader
        )

    def _start_handshake(self, now: float) -> None:
        self.state = LinkState.WAIT_ACK
        self._unanswered_since = None
        self._hs_started = now
        self._hs_next = now
        self._hs_delay = RESET_FIRST_RETRY
        self._hs_reported = False
        self._hs_packets = 0
        self._hs_reset_acks = 0
        self._hs_attempt = 0
        self._baud_phase = None
        self._hs_rx = self.transport.rx_since_open
        if not self._opened.is_set():
            self.down_error = HandshakeError(self._no_answer_text())
        self._send_reset(now)

    def _attempt_rate(self) -> int:
        """The rate the next RESET goes at (module docstring: every other one at the last;
        after an agreed rate, two in three of those between at the opening rate)."""
        if self.pinned_baudrate is not None:
            return self.pinned_baudrate
        k = self._hs_attempt
        if k % 2 == 0:
            return self.line_baudrate
        j = k // 2
        fast = [
            rate
            for rate in reversed(FAST_BAUDRATES)
            if rate != self.line_baudrate and rate not in self.failed_baudrates
        ]
        if self.line_baudrate != self.opening_baudrate:
            # A device that reset, or that never heard the RESET confirming a switch, is at
            # the opening rate; another fast rate means another host's agreement, rare.
            # Two in three of these retries go to the opening rate: where one in three did,
            # a RESET lost there cost 4.4 s more (the soak's calls timed out at 6 s).
            if j % 3 != 2 or not fast:
                return self.opening_baudrate
            j //= 3
        return fast[j % len(fast)] if fast else self.line_baudrate

    def _send_reset(self, now: float) -> None:
        rate = self._attempt_rate()
        self._hs_attempt += 1
        self.transport.clear_queue()
        if self.transport.baudrate != rate:
            self.transport.set_baudrate(rate)
        self.transport.send(
            PacketType.CONTROL,
            reset_payload(self.version, self.session, self._next_id()),
            reset_seq=True,
        )
        self._hs_next = now + self._hs_delay
        self._hs_delay = min(self._hs_delay * 2, RESET_MAX_RETRY)

    def _handshake_failed(self) -> None:
        self._hs_reported = True
        self.down_error = HandshakeError(self._no_answer_text())
        if not self._opened.is_set():
            self.state = LinkState.FAILED
            self._opened.set()
            return
        log.warning("%s: %s (still trying)", self.transport.name, self.down_error)
        self._notify(
            Event(EventKind.DISCONNECTED, str(self.down_error), {"reason": "handshake failed"})
        )

    def _go_down(self, reason: str) -> None:
        if self.state is LinkState.ACTIVE:
            log.info("%s: link down (%s)", self.transport.name, reason)
            self.state = LinkState.WAIT_ACK
            self._notify(Event(EventKind.DISCONNECTED, f"link down: {reason}", {"reason": reason}))
            self._listener.link_down(reason)

    def _restart(self, reason: str, now: float) -> None:
        self.down_error = LinkError(
            f"the link to {self.transport.url} is re-handshaking ({reason})"
        )
        self._go_down(reason)
        self._start_handshake(now)

    def _fail(self, error: LinkError) -> None:
        self.down_error = error
        was_active = self.state is LinkState.ACTIVE
        self.state = LinkState.FAILED
        if self._opened.is_set():
            log.error("%s: %s", self.transport.name, error)
            self._notify(Event(EventKind.ERROR, str(error), {"error": str(error)}))
            if was_active:
                self._listener.link_down("failed")
        # For good: calls fail now rather than wait for a link that cannot come back.
        self._listener.link_failed(error)
        self._opened.set()

    def _packet(self, packet: Packet) -> None:
        now = self._clock()
        self._unanswered_since = None  # the device is heard at this end's rate
        if self.state is not LinkState.ACTIVE:
            self._hs_packets += 1  # what the handshake heard, for its error message
        if packet.type is PacketType.CONTROL:
            try:
                ctl = parse_control(packet.payload)
            except ProtocolError as error:
                log.warning("%s: bad CONTROL packet: %s", self.transport.name, error)
                return
            if ctl.code is ControlCode.RESET_ACK:
                self._reset_ack(ctl, now)
                return
            if ctl.code is ControlCode.BAUD_ACK:
                self._baud_ack(ctl, now)
                return
            if ctl.code is ControlCode.EVENT and ctl.event in (
                EventCode.BOOT,
                EventCode.NOT_ACTIVE,
            ):
                # Sent from a fresh device state: its SEQ says nothing about ours.
                self._last_rx = now
                self.device_events[EventCode(ctl.event).name.lower()] += 1
                if self.state is LinkState.ACTIVE:
                    # The device lost its link state (a reboot, most likely): the
                    # handshake's boot id says whether it lost its outputs too.
                    log.warning(
                        "%s: device says %s; handshaking again",
                        self.transport.name,
                        EventCode(ctl.event).name,
                    )
                    self._restart(f"device {EventCode(ctl.event).name}", now)
                return
        if self.state is not LinkState.ACTIVE:
            return  # stale traffic from before the handshake
        self.rx_packets += 1
        self._last_rx = now
        if not self._check_seq(packet.seq, now):
            return
        if packet.type is PacketType.DATA:
            try:
                msg = parse_out(packet.payload)
            except ProtocolError as error:
                log.warning("%s: %s", self.transport.name, error)
                return
            self._listener.link_message(msg)
        elif packet.type is PacketType.COMMAND:
            self.direction_drops += 1  # docs/protocol.md 4: a COMMAND reaching the host
        else:
            self._control(packet)

    def _check_seq(self, seq: int, now: float) -> bool:
        d = (seq - self._rx_expected) & 0xFF
        self._rx_expected = (seq + 1) & 0xFF
        if d == 0:
            return True
        if d <= SEQ_DESYNC_THRESHOLD:
            self.seq_lost += d
            if d > SEQ_TOLERANCE:
                log.warning("%s: %d packets from the device lost", self.transport.name, d)
            return True
        self.seq_desyncs += 1
        log.warning("%s: SEQ desync (got %d); handshaking again", self.transport.name, seq)
        self._restart("desync", now)
        return False

    def _control(self, packet: Packet) -> None:
        try:
            ctl = parse_control(packet.payload)
        except ProtocolError:  # pragma: no cover - parsed once already
            return
        if ctl.code is not ControlCode.EVENT:
            return  # HEARTBEAT: liveness only (already noted); RESET: not ours to answer
        if ctl.event == EventCode.DESYNC:
            self.device_events["desync"] += 1
            self._notify(Event(EventKind.DEVICE_DESYNC, "the device saw a SEQ desync"))
        elif ctl.event == EventCode.RX_OVERFLOW:
            self.device_events["rx_overflow"] += 1
            self._notify(Event(EventKind.RX_OVERFLOW, "the device dropped an over-long frame"))
        else:
            log.info("%s: unknown device event %s", self.transport.name, ctl.event)

    def _reset_ack(self, ctl: Control, now: float) -> None:
        version, schema_id = ctl.version or 0, ctl.schema_id or 0
        self.device_version, self.device_schema_id = version, schema_id
        self._rx_expected = 1
        self._last_rx = now
        if self.state is LinkState.WAIT_ACK:
            self._hs_reset_acks += 1
        if self.state is not LinkState.WAIT_ACK or self._baud_phase is not None:
            return  # the twin of a resent RESET: SEQ re-synchronised, nothing else
        if version != self.version:
            self._fail(VersionMismatchError(self.version, version))
            return
        if schema_id != self.schema_id:
            self._fail(SchemaMismatchError(self.schema_id, schema_id))
            return
        if ctl.boot_id is None:
            log.warning("%s: RESET_ACK without a boot id ignored", self.transport.name)
            return
        if self._baud_from is not None:
            # The RESET that confirmed a new rate: the session was opened or resumed by
            # the handshake before the switch, whose answer says which (unless the
            # device rebooted in between).
            if self._baud_from.boot_id == ctl.boot_id:
                ctl = dataclasses.replace(ctl, resumed=self._baud_from.resumed)
            self._baud_from = None
        self.line_baudrate = self.transport.baudrate
        if self._start_agreement(ctl, now):
            return
        self.handshakes += 1
        self.state = LinkState.ACTIVE
        self.down_error = None
        first = not self._was_active
        self._was_active = True
        rebooted = self.boot_id is not None and ctl.boot_id != self.boot_id
        lost = not first and not ctl.resumed
        self.boot_id = ctl.boot_id
        if first:
            self.resumed_at_open = bool(ctl.resumed)
        log.info(
            "%s: link active (boot 0x%08X, session %s)",
            self.transport.name,
            ctl.boot_id,
            "resumed" if ctl.resumed else "new",
        )
        if rebooted:
            self.reboots += 1
            log.warning(
                "%s: the device rebooted (boot id 0x%08X)", self.transport.name, ctl.boot_id
            )
            self._notify(
                Event(
                    EventKind.REBOOTED,
                    "the device rebooted: its outputs are back at power-up state",
                    {"boot_id": ctl.boot_id},
                )
            )
        elif lost:
            self.sessions_lost += 1
            log.warning("%s: another session took the device over", self.transport.name)
            self._notify(
                Event(
                    EventKind.SESSION_LOST,
                    "another host session took the device over: it released our outputs",
                    {"boot_id": ctl.boot_id},
                )
            )
        if not first:
            self._notify(
                Event(
                    EventKind.CONNECTED,
                    "link up again"
                    + (" (device rebooted)" if rebooted else " (outputs lost)" if lost else ""),
                    {"rebooted": rebooted, "lost": lost, "handshakes": self.handshakes},
                )
            )
        self._listener.link_up(lost, rebooted)
        self._opened.set()

    # --- the line rate (docs/protocol.md 5, *Line rate*) ------------------------

    def _start_agreement(self, ctl: Control, now: float) -> bool:
        """After a RESET_ACK at the opening rate: propose the fastest rate offered, if any,
        and if the handshake's budget still holds a failed switch (AGREEMENT_COST)."""
        if ctl.baudrates:
            self.device_baudrates = ctl.baudrates
        if self.pinned_baudrate is not None or self.transport.baudrate != self.opening_baudrate:
            return False
        offered = [rate for rate in ctl.baudrates if rate not in self.failed_baudrates]
        if not offered:
            return False
        if now + AGREEMENT_COST > self._hs_started + self.handshake_timeout:
            log.info(
                "%s: no time left in the handshake to try %d baud; staying at %d",
                self.transport.name,
                offered[0],
                self.opening_baudrate,
            )
            return False
        self._baud_from = ctl
        self._baud_rate = offered[0]  # fastest first
        self._baud_phase = "propose"
        self._baud_tries = 0
        self._send_baud(now)
        return True

    def _send_baud(self, now: float) -> None:
        self.transport.send(PacketType.CONTROL, baud_payload(ControlCode.BAUD_SET, self._baud_rate))
        self._baud_tries += 1
        self._baud_due = now + BAUD_PROBE_WAIT

    def _baud_ack(self, ctl: Control, now: float) -> None:
        self._last_rx = now
        if self.state is not LinkState.WAIT_ACK or self._baud_phase is None:
            return  # late: an answer to a BAUD_SET of an agreement that is over
        if ctl.baudrate == 0:
            self._baud_failed(now, "refused")
            return
        if ctl.baudrate != self._baud_rate:
            return
        if self._baud_phase == "propose":
            # Acked at the opening rate; the device switches once the ack is out.
            self._baud_switched = now
            self.transport.set_baudrate(self._baud_rate)
            self._baud_phase = "probe"
            self._baud_tries = 0
            self._send_baud(now)
            return
        # The probe was answered at the new rate: the RESET that goes on with the
        # handshake there confirms the switch to the device.
        log.info("%s: line rate %d baud agreed", self.transport.name, self._baud_rate)
        self._baud_phase = None
        self.baud_switches += 1
        self.line_baudrate = self._baud_rate
        self._hs_attempt = 0
        # The retries start over from the first delay, as after a failed rate: this RESET
        # confirms the switch, and one lost (or its answer) waited out the handshake's
        # grown backoff, then at every other retry only.
        self._hs_delay = RESET_FIRST_RETRY
        self._send_reset(now)

    def _baud_failed(self, now: float, why: str) -> None:
        log.warning(
            "%s: line rate %d baud failed (%s); back to %d baud",
            self.transport.name,
            self._baud_rate,
            why,
            self.opening_baudrate,
        )
        self.failed_baudrates.add(self._baud_rate)
        self.baud_fallbacks += 1
        switched = self._baud_phase == "probe"  # else the device never left the opening rate
        self._baud_phase = None
        self.line_baudrate = self.opening_baudrate
        self.transport.set_baudrate(self.opening_baudrate)
        self._hs_attempt = 0
        # The RESETs start over from the first retry delay (the handshake's own backoff
        # may have grown to its cap meanwhile, waiting out a bootloader: a RESET lost while
        # the device was still at the failed rate then cost a whole second), the first
        # one once the device is back at the opening rate too.
        self._hs_delay = RESET_FIRST_RETRY
        if switched:
            self._hs_next = max(now, self._baud_switched + BAUD_CONFIRM + RETURN_MARGIN)
        else:
            self._send_reset(now)
