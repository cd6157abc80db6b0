"""The fake board for tests: one device written in Python, in-process or on a pty.

:class:`VirtualDevice` is a device that answers as the firmware does, as far as a host can
see: every pin mode with an Uno's pins and timers, digital and analog inputs and counters that
report as the firmware reports, interlocks, the failsafe, user services' calls and reports.
:meth:`VirtualDevice.open_board` gives a real :class:`protoduino.Board` on it, whose link,
requests and API are the ones a serial board runs; only the port, the clock and the threads
differ. Time is a :class:`ManualClock` that moves only when a call waits for an answer or the
test calls :meth:`VirtualDevice.run`, so every timer (Ack timeouts, retransmissions, the
automatic Ping, the device's failsafe) fires at an exact, repeatable time, and nothing waits on
the wall clock: a call returns as soon as its answer is in, an input's first value included::

    from protoduino.testing import VirtualDevice

    def test_a_pressed_button_stops_the_arm() -> None:
        device = VirtualDevice()
        with device.open_board(ping=False) as board:
            button = board.digital_input(7, pull_up=True)
            battery = board.analog_input(14)
            wheel = board.counter(2)
            device.set_level(7, 0)                   # reported at once
            device.set_analog(14, 700)
            device.pulses(2, 40)
            assert (button.read(), battery.read(), wheel.read()) == (False, 700, 40)

Blocking calls return as on a real board (the device answers while the call waits). A
``submit`` form's future, an ``on_change`` or ``on_event`` callback, runs when the test lets
time pass: :meth:`VirtualDevice.run` (``run(0)`` delivers what is due now). An input's
``wait_for`` waits as a call does: at once if its value holds, else on the device's clock
until one the device sends holds, or its timeout (exactly, on that clock).

:class:`PtyDevice` is the same device on a pseudo-terminal, answering from a thread of its
own on the wall clock: for tests that need the real transport (protoduino's own tests of the
serial transport, the CLI, reconnection). It adds what such tests script: ``unplug`` and
``replug``, raw and delayed bytes, SEQ jumps.

What the device does, per docs/protocol.md: the handshake (RESET -> RESET_ACK with version,
schema, boot id and whether the session resumed; NOT_ACTIVE before it; a new session releases
every pin), SEQ on every packet it sends, one Ack per COMMAND, the dedupe window and message
ids as the firmware keeps them (:class:`DedupeWindow`: a retransmitted id is acknowledged
again and not executed again), Ping echo, a DeviceInfo with an Uno's pins, EVENT BOOT on
:meth:`~VirtualDevice.reboot`, the pin table with the firmware's checks (a pin mode left
out of its ``features``, a pin it does not have, a reserved one, one another mode holds, a
mode the pin cannot do, the servos' Timer1 shared with PWM on pins 9 and 10, servo and counter
slots), an input's
value in an InputReport right after its Init's Ack and after each change the test makes
(:meth:`~VirtualDevice.set_level`, :meth:`~VirtualDevice.set_analog`,
:meth:`~VirtualDevice.pulses`), interlocks (an input at its trip level drives every output
safe, latches, and refuses values until it is back and cleared), and the failsafe with its
epochs (docs/protocol.md section 7): a timer restarted only by a liveness message that
carries the device's current epoch (a Heartbeat, or a Ping unless the session's liveness is
the Heartbeat), which fires after the session's ConfigureFailsafe timeout on the device's
clock: the outputs go safe, the epoch advances, a Failsafe event goes out, and Controls and
Poses are refused with STATUS_FAILSAFE_EXPIRED until the next such liveness message clears it
(a Stop advances the epoch and sends its event too, but refuses nothing: the timer still
runs); each liveness Ack carries the failsafe state once one was entered.

What it is not: it times no pin (no servo pulse or speed limit in motion, no PWM wave, no
debounce, no sample rate, threshold or heartbeat of an analog input: it reports every change
the test makes at once, and nothing else), keeps a commanded value per pin
(:attr:`~VirtualDevice.values`; absent: at its safe value; ReadOutputs answers with those, a
servo already where it goes), and runs no user handler (a UserCall is acknowledged; a test's
:attr:`~VirtualDevice.handler` answers it). For the
firmware itself, use :class:`protoduino.simboard.SimBoard` (the firmware compiled for this
machine, or the Uno's on an emulated ATmega328P).

Faults: ``lose`` drops the device's next packets on the way to the host, ``silent`` all of
them, and :attr:`~VirtualDevice.handler` answers each command (``default_reply`` unless a test
replaces it: to refuse, drop, repeat or delay an answer). protoduino's own tests drive the
link and request layers alone with it too (tests/unit/test_layers.py):
:meth:`VirtualDevice.start` as the port, :meth:`VirtualDevice.run` as the I/O thread.
"""

from __future__ import annotations

import collections
import contextlib
import os
import select
import struct
import threading
import time
import tty
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._generated import protoduino_pb2 as pb
from ._generated.schema_id import SCHEMA_ID
from .board import Board
from .boardoptions import BoardOptions
from .commands import PIN_MODES, Command, command
from .constants import (
    DEDUPE_WINDOW,
    FAILSAFE_TIMEOUT,
    ID_AHEAD_MAX,
    MAX_MESSAGE_ID,
    OPENING_BAUDRATE,
    PROTOCOL_VERSION,
    SERVO_DEFAULT_MAX_US,
    SERVO_DEFAULT_MIN_US,
    ControlCode,
    EventCode,
    PacketType,
)
from .errors import ArgumentError
from .events import EventDispatcher
from .framing import StreamDecoder, frame_packet
from .messages import ArduinoIn, ArduinoOut, Status, pin_mask, pin_set, pins_in, serialize_out
from .packets import Packet, event_payload, parse_control, reset_ack_payload
from .rpc import Done
from .transport import FrameMonitor, TransportListener
from .wiring import Wiring

if TYPE_CHECKING:
    from typing_extensions import Unpack

__all__ = [
    "DedupeWindow",
    "ManualClock",
    "PtyDevice",
    "Received",
    "VirtualDevice",
    "ack",
    "mask",
]

#: DeviceInfo.features with every pin mode built in.
ALL_FEATURES = sum(mode.feature_bit for mode in PIN_MODES)
#: The schema's FailsafeCause values.
PING_TIMEOUT = pb.FAILSAFE_CAUSE_PING_TIMEOUT
STOP = pb.FAILSAFE_CAUSE_STOP
INTERLOCK = pb.FAILSAFE_CAUSE_INTERLOCK
#: A Reply: the messages a device sends for one command, in order (the Ack first).
Reply = list[ArduinoOut]


@dataclass
class Received:
    """One COMMAND the device received (decoded), with its SEQ and its time on the device's
    clock; retransmissions are received again (:attr:`VirtualDevice.received`)."""

    seq: int
    msg: ArduinoIn
    t: float

    @property
    def kind(self) -> str:
        return str(self.msg.WhichOneof("data"))


def mask(pins: Iterable[int]) -> bytes:
    """A pin set as the wire has it (InputReport, OutputStates, Pose: protocol version 8)."""
    bits = 0
    for pin in pins:
        bits |= 1 << pin
    return pin_set(bits)


def ack(message_id: int, status: Status.ValueType = Status.STATUS_OK) -> ArduinoOut:
    """An Ack of ``message_id`` with ``status`` (a handler's building block)."""
    out = ArduinoOut()
    out.ack.message_id = message_id
    out.ack.status = status
    return out


class DedupeWindow:
    """The device's dedupe window and newest id N, as the firmware keeps them (pd_dedupe.c;
    docs/protocol.md section 7, *Message ids*): ids 1..127, Y newer than N when
    ``(Y - N) mod 127`` is 1..63, a repeat when in the window and ``(N - Y) mod 127`` is
    below DEDUPE_WINDOW; entries that fall that far behind N are dropped.

    Slot for slot: DEDUPE_WINDOW slots (0: free) and ``next``, the slot the next entry
    overwrites, so that a full window evicts the entry the firmware's would. As the firmware,
    :meth:`lookup` before a command runs, :meth:`done` once it is answered."""

    def __init__(self) -> None:
        self.ids = [0] * DEDUPE_WINDOW
        self.statuses: list[Status.ValueType] = [Status.STATUS_OK] * DEDUPE_WINDOW
        self.next = 0
        self.newest = MAX_MESSAGE_ID  # the id before 1

    @property
    def entries(self) -> dict[int, Status.ValueType]:
        """The recorded ids and their statuses (a copy)."""
        return {mid: self.statuses[i] for i, mid in enumerate(self.ids) if mid}

    def sync(self, next_id: int, clear: bool) -> None:
        """A RESET of version 5: N is the id before ``next_id``; a new session clears."""
        if clear:
            self.ids = [0] * DEDUPE_WINDOW
        self.newest = (next_id - 2) % MAX_MESSAGE_ID + 1
        self._forget_old()

    def lookup(self, mid: int) -> Status.ValueType | None:
        """The stored status if ``mid`` is a repeat now, else None; nothing changes."""
        if (self.newest - mid) % MAX_MESSAGE_ID < DEDUPE_WINDOW and mid in self.ids:
            return self.statuses[self.ids.index(mid)]
        return None

    def holds(self, mid: int) -> bool:
        """Would ``mid`` be answered as a repeat now (nothing changes)?"""
        return self.lookup(mid) is not None

    def done(self, mid: int, status: Status.ValueType | None) -> None:
        """``mid`` was answered: N moves to it if newer (every id), dropping the entries that
        fall behind; then it is recorded with ``status`` unless that is None (not executed:
        idempotent, or it did not decode)."""
        if 1 <= (mid - self.newest) % MAX_MESSAGE_ID <= ID_AHEAD_MAX:
            self.newest = mid
            self._forget_old()
        if status is not None:
            self.add(mid, status)

    def check(self, mid: int, lookup: bool) -> Status.ValueType | None:
        """:meth:`lookup` (if ``lookup``) and N's move of :meth:`done` at once, before the
        command runs: the same decisions, since nothing reads the window in between."""
        seen = self.lookup(mid) if lookup else None
        self.done(mid, None)
        return seen

    def add(self, mid: int, status: Status.ValueType) -> None:
        """Record an executed command as pd_dedupe.c's add(): in the slot of a stale entry of
        this id, else the first free slot from ``next`` on, else slot ``next``."""
        slot = self.next
        for k in range(DEDUPE_WINDOW):
            i = (self.next + k) % DEDUPE_WINDOW
            if self.ids[i] == mid:
                slot = i
                break
            if self.ids[i] == 0 and self.ids[slot] != 0:
                slot = i
        self.ids[slot] = mid
        self.statuses[slot] = status
        self.next = (slot + 1) % DEDUPE_WINDOW

    def _forget_old(self) -> None:
        for i, mid in enumerate(self.ids):
            if mid and (self.newest - mid) % MAX_MESSAGE_ID >= DEDUPE_WINDOW:
                self.ids[i] = 0


class ManualClock:
    """A clock that moves only when it is moved: ``clock()`` reads it, ``advance`` moves it."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


def _degrees_to_us(init: pb.ServoInit, degrees: int) -> int:
    """A servo's width for ``degrees`` (0..180), as the firmware's degrees_to_us rounds it."""
    lo = init.min_us or SERVO_DEFAULT_MIN_US
    hi = init.max_us or SERVO_DEFAULT_MAX_US
    return lo + degrees * (hi - lo) // 180


def _servo_safe_us(init_bytes: bytes) -> int:
    """A servo's safe width from its ServoInit (0: limp, no pulse)."""
    init = pb.ServoInit.FromString(init_bytes)
    which = init.WhichOneof("safe")
    if which == "safe_degrees":
        return _degrees_to_us(init, init.safe_degrees)
    return init.safe_us if which == "safe_us" else 0


#: Pins of one mode the firmware holds at once (pd_outputs.h, pd_inputs.h; servos: max_servos).
SLOTS = {"pwm": 4, "digital_input": 8, "analog_input": 6, "counter": 2}


class VirtualDevice:
    """An in-process device; see the module docstring."""

    def __init__(
        self,
        clock: ManualClock | None = None,
        *,
        version: int = PROTOCOL_VERSION,
        schema_id: int = SCHEMA_ID,
    ) -> None:
        #: The time of everything on this device and of the boards opened on it.
        self.clock = clock if clock is not None else ManualClock()
        self.url = self.name = "virtual://device"
        self.connected = False
        self.rx_since_open = 0
        self.rx_head = b""
        self.rx_bytes = 0
        self.tx_bytes = 0
        self.tx_packets = 0
        self.version = version
        self.schema_id = schema_id
        #: Answer a RESET at all (False: a device that never completes a handshake).
        self.answer_reset = True
        #: What DeviceInfo states (the Uno's pins and timers; a test may change them before a
        #: board opens): its pin table (DeviceInfo.pins, timers) is written from these, as
        #: the firmware's from its board's table, and the host knows no other.
        self.board_name = "virtual"
        self.firmware_version = "virtual"
        self.num_pins = 20
        self.max_servos = 8
        self.reserved_pins = [0, 1]
        self.features = ALL_FEATURES
        self.pwm_pins = [3, 5, 6, 9, 10, 11]
        self.analog_pins = list(range(14, 20))
        self.counter_pins = list(range(2, 14))
        #: Counter pins on a pin-change interrupt (the Uno's 4..13), not an external one.
        self.pin_change_pins = list(range(4, 14))
        #: Analog inputs and nothing else (a Nano's A6 and A7: 20, 21): no digital I/O.
        self.analog_only_pins: list[int] = []
        self.servo_timer_pins = [9, 10]
        #: Pins whose timer runs the clock in a mode without PWM (none on the Uno: its
        #: Timer0 keeps the clock in fast PWM, so 5 and 6 are PWM pins).
        self.clock_timer_pins: list[int] = []
        #: The numbers of those pins' timers (the Uno's Timer1; its clock's Timer0).
        self.servo_timer = 1
        self.clock_timer = 0
        #: DeviceInfo.rx_buffer (0: not stated) and user_fingerprint (0: no user service).
        self.rx_buffer = 0
        self.user_fingerprint = 0
        #: Every COMMAND the host sent, decoded, retransmissions included.
        self.received: list[Received] = []
        #: Every packet the host sent, in order: (type, payload).
        self.packets: list[tuple[PacketType, bytes]] = []
        #: The commands the device executed, each once (retransmissions are not executed;
        #: Pings and Heartbeats, answered each time, are only in ``received``).
        self.executed: list[ArduinoIn] = []
        self.resets = 0
        #: Device packets still to be lost on the way to the host; ``silent`` loses them all.
        self.lose = 0
        self.silent = False
        #: Answers each decoded COMMAND of an active session; replace it to script faults.
        self.handler: Callable[[ArduinoIn], Reply] = self.default_reply
        #: The inputs as the device sees them: levels (1 until set: a pulled-up open switch),
        #: analog counts, edges counted since each counter's Init.
        self.levels: dict[int, int] = {}
        self.analog: dict[int, int] = {}
        self.counts: dict[int, int] = {}
        #: InputReport.time_ms: None, the device's clock in ms since power-up; or fixed.
        self.time_ms: int | None = None
        #: InputReport.coalesced of the next report.
        self.coalesced = 0
        self._listener: TransportListener | None = None
        self._events: EventDispatcher | None = None
        self._outbox: collections.deque[Packet] = collections.deque()
        self._power_up_state()
        self.boot_id = 1

    def _power_up_state(self) -> None:
        self._active = False
        self._tx_seq = 0
        #: The dedupe window and newest id, with the firmware's rules.
        self.dedupe = DedupeWindow()
        #: The session that owns the device (0: none since power-up).
        self.session = 0
        self._booted = self.clock()
        #: The pin table: mode by pin (forgotten at power-up and by a new session), each
        #: pin's Init (a repeated Init keeps the value), the commanded values (absent: safe).
        self.pins: dict[int, str] = {}
        self.values: dict[int, int] = {}
        self._inits: dict[int, bytes] = {}
        self._counter_edge: dict[int, int] = {}
        self._servo_us: dict[int, int] = {}
        #: Interlock inputs: pin -> trip level; the pin whose interlock latched (None: none).
        self.trips: dict[int, int] = {}
        self.latched: int | None = None
        #: The failsafe: its epoch (0 at power-up), whether a safe state holds and why
        #: (FailsafeCause, the interlock's pin), whether any was entered since power-up.
        self.failsafe_epoch = 0
        self.failsafe_active = False
        self.failsafe_cause = 0
        self.failsafe_pin = 0
        self._failsafe_entered = False
        self._failsafe_timeout = FAILSAFE_TIMEOUT
        self._heartbeat_only = False
        #: When the timer runs out (device clock; None before a session), and whether it ran
        #: out since the last liveness message (then, and only then, Controls are refused).
        self._failsafe_due: float | None = None
        self._fired = False

    # --- a board on it ----------------------------------------------------------------------

    def open_board(self, **options: Unpack[BoardOptions]) -> Board:
        """A :class:`~protoduino.Board` on this device (the options of ``Board.open``; no
        ``monitor`` or ``capture``: there are no frames)."""
        wiring = Wiring(
            port=self, clock=self.clock, wait=self.wait, events=self._dispatcher, inline=True
        )
        return Board(self.url, wiring=wiring, **options)

    def _dispatcher(self) -> EventDispatcher:
        self._events = EventDispatcher(self.url, threaded=False)
        return self._events

    # --- what a test asserts on ---------------------------------------------------------------

    def last(self, kind: str) -> ArduinoIn:
        """The last executed command of ``kind`` (``"servo_control"``, ``"pose"``, ...)."""
        for msg in reversed(self.executed):
            if msg.WhichOneof("data") == kind:
                return msg
        raise LookupError(f"the device executed no {kind}")

    def commands(self, kind: str) -> list[ArduinoIn]:
        """Every executed command of ``kind``, in order, each once."""
        return [msg for msg in self.executed if msg.WhichOneof("data") == kind]

    def arrivals(self, kind: str | None = None) -> list[Received]:
        """Every COMMAND received (of ``kind``), retransmissions included."""
        with self._lock():
            return [r for r in self.received if kind is None or r.kind == kind]

    # --- what a test drives -------------------------------------------------------------------

    def set_level(self, pin: int, level: bool | int) -> float:
        """A digital input's level changes (after its debounce): reported at once, an
        interlock at its trip level trips; the board has it on return (in-process). Returns
        the device's time, as SimBoard's ``set_level`` returns the board's."""
        with self._lock():
            self.levels[pin] = 1 if level else 0
            if self.pins.get(pin) == "digital_input":
                self._send_all([self.report()])
                if self.trips.get(pin) == self.levels[pin] and self.latched is None:
                    self._send_all(self._trip(pin))
        self._flush()
        return self.clock()

    def set_analog(self, pin: int, counts: int) -> float:
        """An analog input's counts (0..1023) change: reported at once (no threshold, no
        sample rate). Returns the device's time."""
        with self._lock():
            self.analog[pin] = counts
            if self.pins.get(pin) == "analog_input":
                self._send_all([self.report(analog=[pin])])
        self._flush()
        return self.clock()

    def pulses(self, pin: int, count: int, hz: float | None = None) -> float:
        """``count`` pulses on ``pin``, each away from its level and back (as SimBoard's): a
        counter there counts their edges of its kind (both: two a pulse), and the new count is
        reported at once. The fake times no pin: ``hz`` is taken for SimBoard's signature and
        not used. Returns the device's time."""
        del hz
        with self._lock():
            if self.pins.get(pin) == "counter":
                edges = count * (2 if self._counter_edge.get(pin) == pb.EDGE_BOTH else 1)
                self.counts[pin] = (self.counts.get(pin, 0) + edges) % 2**32
                self._send_all([self.report(counters=[pin])])
        self._flush()
        return self.clock()

    def user_report(self, report: int, body: bytes, *, coalesced: int = 0) -> None:
        """A user service's report ``report`` (1..) with its encoded message ``body``."""
        out = ArduinoOut()
        out.user_report.report = report
        out.user_report.body = body
        out.user_report.coalesced = coalesced
        self.send_data(out)

    def send_data(self, msg: ArduinoOut, *, seq: int | None = None) -> None:
        """Send any message as the device would (the next SEQ unless ``seq`` is given)."""
        with self._lock():
            self._emit(PacketType.DATA, serialize_out(msg), seq)
        self._flush()

    def reboot(self) -> None:
        """A power cycle: state, pins, dedupe window and failsafe epoch forgotten, EVENT BOOT."""
        with self._lock():
            self._power_up_state()
            self.boot_id += 1
            self._emit(PacketType.CONTROL, event_payload(EventCode.BOOT))

    def forget(self) -> None:
        """Lose every pin, value and remembered id without a BOOT (a reset the host missed)."""
        with self._lock():
            self.pins.clear()
            self.values.clear()
            self._inits.clear()
            self.dedupe = DedupeWindow()

    def next_seq(self, seq: int | None = None) -> int:
        """The SEQ for the next packet the device sends (``seq``, if given, instead)."""
        with self._lock():
            if seq is not None:
                return seq
            seq, self._tx_seq = self._tx_seq, (self._tx_seq + 1) & 0xFF
            return seq

    def skip_seq(self, count: int) -> None:
        """Use up ``count`` SEQ numbers: to the host, that many packets lost on the way."""
        for _ in range(count):
            self.next_seq()

    @property
    def tx_seq(self) -> int:
        """The SEQ the device's next packet will carry."""
        return self._tx_seq

    # --- the board's port (BoardPort) --------------------------------------------------------

    def start(self, listener: TransportListener) -> None:
        """The port opens: the link sends RESET, and has its answer before start returns."""
        self._listener = listener
        self.connected = True
        listener.transport_opened(False)
        self.deliver()

    def close(self) -> None:
        self.connected = False

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None:
        # Only queues the answer: the link may hold the request layer's lock while it sends.
        self.tx_packets += 1
        self.tx_bytes += len(payload)
        self.packet(Packet(ptype, 0, payload))

    def clear_queue(self) -> None:
        pass  # nothing waits: every send reached the device at once

    #: The line rate the link set: a virtual device has no line, offers no faster rate
    #: (its RESET_ACK says none), and answers at any rate a RESET retry goes at.
    baudrate = OPENING_BAUDRATE

    def set_baudrate(self, rate: int) -> None:
        self.baudrate = rate

    def recent_frames(self) -> tuple[str, ...]:
        return ()

    @property
    def decoder_counts(self) -> dict[str, int]:
        return {}  # no bytes, so nothing to drop

    def add_monitor(self, monitor: FrameMonitor) -> None:
        raise ArgumentError("a virtual device has no frames to monitor or capture")

    def on_io_thread(self) -> bool:
        return False  # the caller plays the I/O thread only while it waits

    # --- time: the test (or a waiting call) as the I/O thread ---------------------------------

    def deliver(self) -> int:
        """Hand every queued device packet to the link (or lose it); how many arrived."""
        arrived = 0
        while self._outbox and self._listener is not None:
            packet = self._outbox.popleft()
            arrived += 1
            self.rx_bytes += len(packet.payload)
            self._listener.transport_received([packet])
        return arrived

    def tick(self) -> float:
        """Deliver, run the link's timers at the clock's time, run the board's callbacks;
        when the timers next need to run."""
        if self._listener is None:
            return float("inf")
        self.check_failsafe()
        self.deliver()
        due = self._listener.transport_tick(self.clock())
        self.deliver()
        if self._events is not None:
            self._events.run_pending()
        if self._failsafe_due is not None and not self._fired:
            due = min(due, self._failsafe_due)
        return due

    def run(self, seconds: float) -> None:
        """Let ``seconds`` pass on the clock, running every timer at the time it is due."""
        self._advance(self.clock() + seconds, None)

    def wait(self, event: Done, timeout: float) -> bool:
        """The board's way of waiting for a call: time passes until it is done or ``timeout``."""
        return self._advance(self.clock() + timeout, event)

    def _advance(self, end: float, until: Done | None) -> bool:
        while True:
            due = self.tick()
            if until is not None and until.is_set():
                return True
            if due > end:
                break
            if due <= self.clock():
                # A timer due again at the instant it ran would spin a real I/O thread too.
                raise RuntimeError(f"the link's timers asked to run again at once (due {due})")
            self.clock.now = due
        self.clock.now = max(self.clock.now, end)
        self.tick()
        return until is not None and until.is_set()

    def _flush(self) -> None:
        """What the device sent reaches a board opened on it now (a pty's is on its way; the
        link alone, without a board, has it when the test delivers)."""
        if self._events is not None:
            self.run(0)

    def _lock(self) -> contextlib.AbstractContextManager[object]:
        """In-process, one thread does everything; a pty's device thread shares the state."""
        return contextlib.nullcontext()

    def _emit(self, ptype: PacketType, payload: bytes, seq: int | None = None) -> None:
        """The device sends a packet (lost if ``lose`` or ``silent`` says so)."""
        packet = Packet(ptype, self.next_seq(seq), payload)
        if self.silent or self.lose > 0:
            self.lose = max(0, self.lose - 1)
            return
        self._outbox.append(packet)

    def _send_all(self, msgs: Iterable[ArduinoOut]) -> None:
        for out in msgs:
            self._emit(PacketType.DATA, serialize_out(out))

    # --- the device ----------------------------------------------------------------------------

    def packet(self, packet: Packet) -> None:
        """A packet from the host reaches the device."""
        with self._lock():
            self.packets.append((packet.type, packet.payload))
            if packet.type is PacketType.CONTROL:
                self._control(packet.payload)
                return
            if packet.type is not PacketType.COMMAND:
                return
            if not self._active:
                self._emit(PacketType.CONTROL, event_payload(EventCode.NOT_ACTIVE))
                return
            msg = ArduinoIn()
            msg.ParseFromString(packet.payload)
            self.received.append(Received(packet.seq, msg, self.clock()))
            self._received()
        # Outside the lock: a test's handler may hold its answer back (a pty's thread waits).
        replies = self.handler(msg)
        with self._lock():
            self._send_all(replies)

    def _received(self) -> None:
        """A COMMAND was recorded (a pty wakes the threads in ``wait_for``)."""

    def _control(self, payload: bytes) -> None:
        ctl = parse_control(payload)
        if ctl.code is not ControlCode.RESET:
            return
        self.resets += 1
        self._received()
        if not self.answer_reset:
            return
        self._tx_seq = 0
        if (
            ctl.version != self.version
            or ctl.session is None
            or self.version < 2
            or (self.version >= 5 and not 1 <= (ctl.next_id or 0) <= MAX_MESSAGE_ID)
        ):
            # Another version (or version 1 itself): the short answer every host reads.
            self._active = self.version < 2 and ctl.version == self.version
            self._emit(PacketType.CONTROL, reset_ack_payload(self.version, self.schema_id))
            return
        self._active = True
        resumed = ctl.session != 0 and ctl.session == self.session
        if not resumed:
            # Another owner: every pin released, the interlocks with their inputs; the
            # failsafe's timer runs from the handshake.
            self._release_all()
            self._failsafe_due, self._fired = self.clock() + self._failsafe_timeout, False
        if ctl.next_id is not None:
            self.dedupe.sync(ctl.next_id, clear=not resumed)
        self.session = ctl.session
        self._emit(
            PacketType.CONTROL,
            reset_ack_payload(self.version, self.schema_id, self.boot_id, resumed),
        )

    def default_reply(self, msg: ArduinoIn) -> Reply:
        """The firmware's answer: the Ack, then what follows it (an input's first value, a
        Failsafe message)."""
        with self._lock():
            return self._firmware_reply(msg)

    def _firmware_reply(self, msg: ArduinoIn) -> Reply:
        mid = msg.message_id
        kind = msg.WhichOneof("data")
        if not 1 <= mid <= MAX_MESSAGE_ID:
            return [ack(mid, Status.STATUS_INVALID_ARGUMENT)]
        if kind is None:
            return [ack(mid, Status.STATUS_UNKNOWN_COMMAND)]
        declared = command(kind)
        seen = self.dedupe.check(mid, lookup=not declared.idempotent)
        if seen is not None:  # a retransmission: acknowledged again, not executed again
            return [ack(mid, seen)]
        out = ack(mid)
        after: Reply = []
        if kind in ("ping", "heartbeat"):
            epoch = msg.ping.failsafe_epoch if kind == "ping" else msg.heartbeat.failsafe_epoch
            cleared = self._liveness(kind, epoch)
            if kind == "ping":
                out.ack.ping_echo = msg.ping.payload
            if self._failsafe_entered:
                self._failsafe_state(out.ack.failsafe)
            # Answered in full each time, never in the dedupe window nor in `executed` (a
            # repeat counts as the original would): `received` has every one.
            return [out, self._failsafe_message()] if cleared else [out]
        if kind == "get_info":
            self._info(out.ack.info)
            return [out]
        if declared.sets_output and self._fired:
            status: Status.ValueType = Status.STATUS_FAILSAFE_EXPIRED  # no timer behind a value
        elif declared.sets_output and self.latched is not None:
            status = Status.STATUS_INTERLOCK_ACTIVE  # outputs stay safe until ClearInterlock
        elif not self._built_in(declared):
            status = Status.STATUS_NOT_SUPPORTED  # the table's answer for a feature left out
        else:
            status, after = self._execute(declared, msg, out)
        out.ack.status = status
        if status == Status.STATUS_OK:
            self.executed.append(msg)
        else:
            after = []
        if not declared.idempotent:
            self.dedupe.add(mid, status)
        return [out, *after]

    def _built_in(self, declared: Command) -> bool:
        """Whether ``features`` has the pin-mode feature the command needs (a user service's
        calls are the test's to answer: see ``handler``)."""
        if declared.feature is None or declared.feature == "user":
            return True
        return bool(self.features >> pb.Feature.Value(f"FEATURE_{declared.feature.upper()}") & 1)

    def _info(self, info: Any) -> None:
        info.firmware_version = self.firmware_version
        info.protocol_version = self.version
        info.schema_id = self.schema_id
        info.board = self.board_name
        info.num_pins = self.num_pins
        info.max_servos = self.max_servos
        info.reserved_pins.extend(self.reserved_pins)
        info.rx_buffer = self.rx_buffer
        info.features = self.features
        info.user_fingerprint = self.user_fingerprint
        info.pins = bytes(self._pin_byte(pin) for pin in range(self.num_pins))
        held = {self.servo_timer: pb.TIMER_SERVOS} if self.servo_timer_pins else {}
        if self.clock_timer_pins:
            held[self.clock_timer] = pb.TIMER_CLOCK
        info.timers = bytes(held.get(t, pb.TIMER_FREE) for t in range(max(held, default=-1) + 1))

    def _pin_byte(self, pin: int) -> int:
        """Pin ``pin``'s byte of DeviceInfo.pins (docs/protocol.md section 7)."""
        if pin in self.reserved_pins:
            return 0
        flags = {
            pb.PIN_DIGITAL: pin not in self.analog_only_pins,
            pb.PIN_PWM: pin in self.pwm_pins,
            pb.PIN_ANALOG: pin in self.analog_pins,
            pb.PIN_COUNTER: pin in self.counter_pins,
            pb.PIN_PIN_CHANGE: pin in self.pin_change_pins,
        }
        byte: int = sum(flag for flag, has in flags.items() if has)
        if pin in self.servo_timer_pins:
            byte |= (self.servo_timer + 1) << 5
        elif pin in self.clock_timer_pins:
            byte |= (self.clock_timer + 1) << 5
        return byte

    def _execute(
        self, declared: Command, msg: ArduinoIn, out: ArduinoOut
    ) -> tuple[Status.ValueType, Reply]:
        """Run one command (not a retransmission); its status and what follows its Ack."""
        kind = declared.kind
        if declared.is_init:
            return self._init(declared, msg)
        if declared.is_control:
            assert declared.pin_mode is not None
            ctl = getattr(msg, kind)
            status = self._owned(ctl.pin, declared.pin_mode.name)
            if status == Status.STATUS_OK:
                self._apply(kind, ctl)
            return status, []
        if kind == "pose":
            return self._pose(msg.pose, out), []
        if kind == "release":
            pin = msg.release.pin
            status = self._check_pin(pin)
            if status == Status.STATUS_OK and pin not in self.pins:
                status = Status.STATUS_NOT_INITIALISED
            if status == Status.STATUS_OK:
                self._release(pin)
            return status, []
        if kind == "release_all":
            self._release_all()
            return Status.STATUS_OK, []
        if kind == "configure_failsafe":
            cfg = msg.configure_failsafe
            self._failsafe_timeout = cfg.timeout_ms / 1000 or FAILSAFE_TIMEOUT
            self._heartbeat_only = cfg.liveness == pb.LIVENESS_HEARTBEAT
            if not self._fired:  # restarts a timer that has not run out
                self._failsafe_due = self.clock() + self._failsafe_timeout
            return Status.STATUS_OK, []
        if kind == "stop":
            self._enter_failsafe(STOP)
            return Status.STATUS_OK, [self._failsafe_message()]
        if kind == "clear_interlock":
            return self._clear_interlock(msg.clear_interlock.failsafe_epoch)
        if kind == "read_outputs":
            self._read_outputs(out.ack.outputs)
        return Status.STATUS_OK, []  # a user_call: acknowledged (a test's handler answers it)

    # --- pins ---------------------------------------------------------------------------------

    def _check_pin(self, pin: int) -> Status.ValueType:
        if pin >= self.num_pins:
            return Status.STATUS_INVALID_PIN
        if pin in self.reserved_pins:
            return Status.STATUS_RESERVED_PIN
        return Status.STATUS_OK

    def _owned(self, pin: int, mode: str) -> Status.ValueType:
        status = self._check_pin(pin)
        if status == Status.STATUS_OK and self.pins.get(pin) != mode:
            status = Status.STATUS_NOT_INITIALISED
        return status

    def _init(self, declared: Command, msg: ArduinoIn) -> tuple[Status.ValueType, Reply]:
        """A pin mode's Init, with the firmware's checks in the firmware's order."""
        mode = declared.pin_mode
        assert mode is not None
        init = getattr(msg, declared.kind)
        pin: int = init.pin
        status = self._check_pin(pin)
        flag = pb.PinBit.Value(mode.pins or "PIN_DIGITAL")
        capable = [p for p in range(self.num_pins) if self._pin_byte(p) & flag]
        if status == Status.STATUS_OK and mode.name == "pwm":
            if pin not in self.pwm_pins:
                status = Status.STATUS_NOT_SUPPORTED  # no timer output there
            elif self.pins.get(pin, "pwm") != "pwm":
                status = Status.STATUS_PIN_IN_USE
            elif pin in self.servo_timer_pins and "servo" in self.pins.values():
                status = Status.STATUS_TIMER_IN_USE  # its timer makes the servo pulses
        elif status == Status.STATUS_OK and pin not in capable:
            status = Status.STATUS_NOT_SUPPORTED
        elif (
            status == Status.STATUS_OK
            and mode.name == "servo"
            and any(self.pins.get(p) == "pwm" for p in self.servo_timer_pins)
        ):
            status = Status.STATUS_TIMER_IN_USE  # the servos' timer makes PWM
        if status == Status.STATUS_OK and self.pins.get(pin, mode.name) != mode.name:
            status = Status.STATUS_PIN_IN_USE
        slots = self.max_servos if mode.name == "servo" else SLOTS.get(mode.name)
        if (
            status == Status.STATUS_OK
            and pin not in self.pins
            and slots is not None
            and list(self.pins.values()).count(mode.name) >= slots
        ):
            status = Status.STATUS_NO_FREE_RESOURCE
        if status != Status.STATUS_OK:
            return status, []
        config = init.SerializeToString()
        if self._inits.get(pin) != config:  # a new configuration starts at its safe value
            self.values.pop(pin, None)
        self.pins[pin], self._inits[pin] = mode.name, config
        if not mode.is_input:
            return status, []
        # An input's value follows its Ack (docs/protocol.md, Reports).
        if mode.name == "digital_input":
            self.trips.pop(pin, None)
            if init.interlock != pb.TRIP_NONE:
                self.trips[pin] = 1 if init.interlock == pb.TRIP_HIGH else 0
            after = [self.report()]
            if self.trips.get(pin) == self.levels.get(pin, 1) and self.latched is None:
                after += self._trip(pin)  # already at its trip level: it trips at once
            return status, after
        if mode.name == "counter":
            self.counts[pin] = 0  # counted since this Init
            self._counter_edge[pin] = init.edge
            return status, [self.report(counters=[pin])]
        return status, [self.report(analog=[pin])]

    def _apply(self, kind: str, ctl: Any) -> None:
        if kind == "digital_control":
            self.values[ctl.pin] = int(ctl.level)
        elif kind == "pwm_control":
            self.values[ctl.pin] = ctl.duty
        else:
            self.values[ctl.pin] = getattr(ctl, str(ctl.WhichOneof("value")))
            init = pb.ServoInit.FromString(self._inits[ctl.pin])
            us = ctl.us if ctl.WhichOneof("value") == "us" else _degrees_to_us(init, ctl.degrees)
            self._servo_us[ctl.pin] = us

    def _read_outputs(self, states: Any) -> None:
        """ReadOutputs as pd_outputs_read answers it: each output's value now (its commanded
        one, else its safe one), in pin order; a servo is where it goes (the fake times no
        pin: no speed limit in motion)."""
        states.SetInParent()
        servos = bytearray()
        digital, levels, pwm = [], [], []
        for pin in sorted(self.pins):
            mode, init = self.pins[pin], self._inits[pin]
            if mode == "servo":
                us = self._servo_us[pin] if pin in self.values else _servo_safe_us(init)
                servos += struct.pack("<BHH", pin, us, us)
            elif mode == "digital":
                digital.append(pin)
                safe = int(pb.DigitalInit.FromString(init).safe_level)
                if self.values.get(pin, safe):
                    levels.append(pin)
            elif mode == "pwm":
                pwm.append(pin)
                safe = pb.PwmInit.FromString(init).safe_duty
                states.pwm_duties.append(self.values.get(pin, safe))
        states.servos = bytes(servos)
        states.digital_pins, states.digital_levels = mask(digital), mask(levels)
        states.pwm_pins = mask(pwm)

    def _pose(self, pose: Any, out: ArduinoOut) -> Status.ValueType:
        """All or nothing: every item's pin in its mode, or none is set (refused_item: which)."""
        # A PoseItem's oneof member is named after its pin mode ("servo", "digital"); the
        # pin sets' pins follow the items, upwards (protocol version 6), as on the device.
        items = [(i.WhichOneof("output"), getattr(i, i.WhichOneof("output"))) for i in pose.items]
        levels = pin_mask(pose.digital_levels)
        items += [
            ("digital", pb.DigitalControl(pin=pin, level=bool(levels >> pin & 1)))
            for pin in pins_in(pose.digital_pins)
        ]
        if not items:
            return Status.STATUS_INVALID_ARGUMENT  # sets nothing
        for n, (mode, ctl) in enumerate(items, 1):
            status = self._owned(ctl.pin, mode)
            if status != Status.STATUS_OK:
                out.ack.refused_item = n
                return status
        for mode, ctl in items:
            self._apply(f"{mode}_control", ctl)
        return Status.STATUS_OK

    def _release(self, pin: int) -> None:
        self.pins.pop(pin, None)
        self.values.pop(pin, None)
        self._inits.pop(pin, None)
        self.trips.pop(pin, None)

    def _release_all(self) -> None:
        for pin in list(self.pins):
            self._release(pin)
        self.latched = None  # the interlocks it latched were released with their inputs

    # --- inputs ---------------------------------------------------------------------------------

    def report(self, *, analog: Iterable[int] = (), counters: Iterable[int] = ()) -> ArduinoOut:
        """An InputReport as the firmware builds it: every digital input's level, and the
        analog inputs and counters named."""
        out = ArduinoOut()
        rep = out.input_report
        now_ms = round((self.clock() - self._booted) * 1000)
        rep.time_ms = (now_ms if self.time_ms is None else self.time_ms) % 2**32
        rep.coalesced, self.coalesced = self.coalesced, 0
        inputs = sorted(p for p, m in self.pins.items() if m == "digital_input")
        rep.digital_pins = mask(inputs)
        rep.digital_levels = mask(p for p in inputs if self.levels.get(p, 1))
        analog = sorted(set(analog))
        counters = sorted(set(counters))
        rep.analog_pins = mask(analog)
        rep.analog_values.extend(self.analog.get(p, 0) for p in analog)
        rep.counter_pins = mask(counters)
        rep.counter_counts.extend(self.counts.get(p, 0) for p in counters)
        return out

    def _trip(self, pin: int) -> Reply:
        """An interlock reached its trip level: every output safe, latched, told."""
        self.values.clear()
        self.failsafe_epoch = (self.failsafe_epoch + 1) % 256
        self.failsafe_active, self.failsafe_cause, self.failsafe_pin = True, INTERLOCK, pin
        self._failsafe_entered = True
        self.latched = pin
        return [self._failsafe_message()] if self._active else []

    def _clear_interlock(self, epoch: int) -> tuple[Status.ValueType, Reply]:
        tripped = any(self.levels.get(p, 1) == level for p, level in self.trips.items())
        if tripped or (self.latched is not None and epoch != self.failsafe_epoch):
            return Status.STATUS_INTERLOCK_ACTIVE, []
        cleared, self.latched = self.latched is not None, None
        if not cleared:
            return Status.STATUS_OK, []
        if not self._fired:
            self.failsafe_active = False  # the host saw it and cleared it: the flag too
        return Status.STATUS_OK, [self._failsafe_message()]

    # --- the failsafe (docs/protocol.md section 7) ---------------------------------------------

    def _liveness(self, kind: str, epoch: int) -> bool:
        """A Ping or Heartbeat: it counts only from the session's source, with the epoch.
        Whether it cleared a safe state (said after its Ack)."""
        if kind == "ping" and self._heartbeat_only:
            return False
        if epoch != self.failsafe_epoch:
            return False  # written before a failsafe this host had not heard of: re-arms nothing
        self._failsafe_due = self.clock() + self._failsafe_timeout
        self._fired = False
        if self.failsafe_active and self.latched is None:
            self.failsafe_active = False
            return True
        return False

    def check_failsafe(self) -> None:
        """Fire the failsafe if its timer ran out on the device's clock."""
        with self._lock():
            due = self._failsafe_due
            if due is not None and not self._fired and self.clock() >= due:
                self._expire()

    def expire_failsafe(self) -> None:
        """The failsafe's timer runs out now (on a pty, without waiting its timeout): every
        output safe, a new epoch, the Failsafe event; values refused until a liveness message."""
        with self._lock():
            self._expire()
        self._flush()

    def _expire(self) -> None:
        self._fired = True  # once per silence
        self._enter_failsafe(PING_TIMEOUT)
        if self._active:
            self._send_all([self._failsafe_message()])

    def _enter_failsafe(self, cause: int) -> None:
        self.values.clear()  # every output at its safe value
        self.failsafe_epoch = (self.failsafe_epoch + 1) % 256
        self.failsafe_active, self.failsafe_cause = True, cause
        self._failsafe_entered = True

    def _failsafe_state(self, fs: Any) -> None:
        fs.active, fs.cause, fs.epoch = (
            self.failsafe_active,
            self.failsafe_cause,
            self.failsafe_epoch,
        )
        if self.failsafe_cause == INTERLOCK:
            fs.pin = self.failsafe_pin

    def _failsafe_message(self) -> ArduinoOut:
        out = ArduinoOut()
        self._failsafe_state(out.failsafe)
        return out


class PtyDevice(VirtualDevice):
    """The same device on a pseudo-terminal, for tests that need the real transport.

    The host opens :attr:`port`, a symlink to the pty's slave, exactly as it would open a
    real board (``Board.open(device.port)``, or :meth:`open_board`); the device answers on the
    master side from its own thread, on the wall clock (its :attr:`clock` follows
    ``time.monotonic()``, so the failsafe fires in real seconds). Use it as a context manager.
    Besides the device's own faults (``handler``, ``lose``, ``silent``): :meth:`unplug` and
    :meth:`replug` make the pty disappear and come back under the same path, as a USB cable
    or a killed simulator would; :meth:`send_raw` writes any bytes, now or later;
    :meth:`send_burst` writes messages back to back.
    """

    def __init__(
        self,
        directory: Path,
        *,
        version: int = PROTOCOL_VERSION,
        schema_id: int = SCHEMA_ID,
        answer_reset: bool = True,
    ) -> None:
        self._cond = threading.Condition(threading.RLock())
        super().__init__(ManualClock(time.monotonic()), version=version, schema_id=schema_id)
        self.port = str(directory / "fake-tty")
        self.url = self.name = self.port
        self.answer_reset = answer_reset
        #: Every byte the host wrote.
        self.raw_rx = bytearray()
        self._decoder = StreamDecoder()
        self._later: list[tuple[float, bytes]] = []
        self._master = -1
        self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._wlock = threading.Lock()

    def open_board(self, **options: Unpack[BoardOptions]) -> Board:
        """A :class:`~protoduino.Board` on :attr:`port` (``Board.open``'s options)."""
        return Board.open(self.port, **options)

    # --- life cycle -------------------------------------------------------------

    def __enter__(self) -> PtyDevice:
        self.begin()
        return self

    def __exit__(self, *exc: object) -> None:
        self.end()

    def begin(self) -> None:
        """Create the pty and start answering on it."""
        self.replug()
        self._thread = threading.Thread(target=self._serve, name="fake-device", daemon=True)
        self._thread.start()

    def end(self) -> None:
        """Stop answering; the pty is gone."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.unplug()

    def unplug(self) -> None:
        """The pty disappears: the host's reads fail, the path is gone."""
        with self._wlock:
            for fd in (self._master, self._slave):
                if fd >= 0:
                    os.close(fd)
            self._master = self._slave = -1
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)

    def replug(self) -> None:
        """A new pty under the same path; the device boots (configuration forgotten)."""
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        os.set_blocking(master, False)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)
        os.symlink(os.ttyname(slave), self.port)
        with self._wlock:
            self._master, self._slave = master, slave
        self.reboot()

    def reboot(self) -> None:
        with self._cond:
            self._decoder.reset()
            super().reboot()

    # --- sending ------------------------------------------------------------------

    def send_raw(self, data: bytes, delay: float = 0.0) -> None:
        """Write ``data`` to the host now, or ``delay`` s later (dropped if the pty is full)."""
        if delay > 0:
            with self._cond:
                self._later.append((time.monotonic() + delay, data))
            return
        with self._wlock:
            if self._master >= 0:
                with contextlib.suppress(OSError):
                    os.write(self._master, data)

    def send_data(self, msg: ArduinoOut, *, seq: int | None = None, delay: float = 0.0) -> None:
        """Send any message as the device would, now or ``delay`` seconds later."""
        payload = serialize_out(msg)  # a plain Ack in its short form, as the device sends it
        self.send_raw(frame_packet(PacketType.DATA, self.next_seq(seq), payload), delay)

    def send_control(self, payload: bytes, *, seq: int | None = None) -> None:
        """Send a CONTROL packet (an event) with the next SEQ, or ``seq``."""
        self.send_raw(frame_packet(PacketType.CONTROL, self.next_seq(seq), payload))

    def send_burst(self, msgs: list[ArduinoOut], timeout: float = 10.0) -> None:
        """Send DATA messages back to back, every byte (send_raw drops what a full pty refuses)."""
        data = b"".join(
            frame_packet(PacketType.DATA, self.next_seq(), serialize_out(m)) for m in msgs
        )
        view = memoryview(data)
        deadline = time.monotonic() + timeout
        with self._wlock:
            while view:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"the host read nothing for {timeout} s")
                select.select([], [self._master], [], 0.1)
                try:
                    view = view[os.write(self._master, view) :]
                except BlockingIOError:
                    continue

    def _emit(self, ptype: PacketType, payload: bytes, seq: int | None = None) -> None:
        seq = self.next_seq(seq)
        if self.silent or self.lose > 0:
            self.lose = max(0, self.lose - 1)
            return
        self.send_raw(frame_packet(ptype, seq, payload))

    def _flush(self) -> None:
        pass  # written to the pty already: the host's I/O thread reads it

    def _lock(self) -> contextlib.AbstractContextManager[object]:
        return self._locked()

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        with self._cond:
            self.clock.now = max(self.clock.now, time.monotonic())
            yield

    def _received(self) -> None:
        self._cond.notify_all()

    # --- observing ------------------------------------------------------------------

    def wait_for(self, predicate: Callable[[], bool], timeout: float = 30.0) -> bool:
        """Whether ``predicate`` held within ``timeout`` s (checked as each command arrives)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
            return True

    # --- the device thread ------------------------------------------------------------

    def _serve(self) -> None:
        while not self._stop.is_set():
            with self._wlock:
                master = self._master
            now = time.monotonic()
            with self._cond:
                due = [d for t, d in self._later if t <= now]
                self._later = [(t, d) for t, d in self._later if t > now]
            for data in due:
                self.send_raw(data)
            self.check_failsafe()
            if master < 0:
                time.sleep(0.01)
                continue
            try:
                ready, _, _ = select.select([master], [], [], 0.01)
                data = os.read(master, 4096) if ready else b""
            except (OSError, ValueError):
                time.sleep(0.01)  # unplugged under us
                continue
            if data:
                with self._cond:
                    self.raw_rx += data
                    items = self._decoder.feed(data)
                for item in items:
                    if isinstance(item, Packet):
                        self.packet(item)
