"""A fake board to unit-test robot code with: no compiler, no pseudo-terminal, no thread.

:class:`VirtualDevice` is an in-process device. :meth:`VirtualDevice.open_board` gives a real
:class:`protoduino.Board` on it, whose link, requests and API are the ones a serial board
runs; only the port, the clock and the threads differ. The device answers in Python, and time
is a :class:`ManualClock` that moves only when a call waits for an answer or the test calls
:meth:`VirtualDevice.run`, so every timer (Ack timeouts, retransmissions, the automatic Ping)
fires at an exact, repeatable time::

    from protoduino.testing import VirtualDevice

    def test_the_gripper_opens() -> None:
        device = VirtualDevice()
        with device.open_board() as board:
            grip = board.servo(9, safe=90)
            my_robot.open_gripper(board, grip)       # your code, unchanged
        assert device.last("servo_control").servo_control.degrees == 10

    def test_a_pressed_button_stops_the_arm() -> None:
        device = VirtualDevice()
        with device.open_board() as board:
            button = board.digital_input(7, pull_up=True)
            device.set_level(7, 0)                   # reported at once
            assert button.read() is False

Blocking calls return as on a real board (the device answers while the call waits). A
``submit`` form's future, an ``on_change`` or ``on_event`` callback, runs when the test lets
time pass: :meth:`VirtualDevice.run` (``run(0)`` delivers what is due now). An input's
``wait_for`` would block (nothing runs while it waits): read the input instead.

What the device does, per docs/protocol.md as far as the host can see: the handshake
(RESET -> RESET_ACK with version, schema, boot id and whether the session resumed;
NOT_ACTIVE before it), SEQ on every packet it sends, one Ack per COMMAND (STATUS_OK for every
command; it checks no pin), the dedupe window and message ids as the firmware keeps them
(:class:`DedupeWindow`: a retransmitted id is acknowledged again and
not executed again), Ping echo, a DeviceInfo with an Uno's pins, EVENT BOOT on
:meth:`~VirtualDevice.reboot` (which forgets the dedupe window and the session), and a digital
input's level in an InputReport right after its Init's Ack and after each
:meth:`~VirtualDevice.set_level`, and the failsafe with its epochs (docs/protocol.md section
7): a timer restarted only by a liveness message that carries the device's current epoch
(a Heartbeat, or a Ping unless the session's liveness is the Heartbeat), which fires after
the session's ConfigureFailsafe timeout on the device's clock: the epoch advances, a
Failsafe event goes out, and Controls and Poses are refused with STATUS_FAILSAFE_EXPIRED
until the next such liveness message clears it (a Stop advances the epoch and sends its
event too, but refuses nothing: the timer still runs); each liveness Ack carries the
failsafe state once one was entered. It models no output values and no
readback: what it executed is in :attr:`~VirtualDevice.executed`. For the firmware itself,
use :class:`protoduino.simboard.SimBoard` (the firmware compiled for this machine, on a pty).

Faults: ``lose`` drops the device's next packets on the way to the host, ``silent`` all of
them. protoduino's own tests drive the link and request layers alone with it too
(tests/unit/test_layers.py): :meth:`VirtualDevice.start` as the port, :meth:`VirtualDevice.run`
as the I/O thread.
"""

from __future__ import annotations

import collections
from typing import TYPE_CHECKING, Any

from ._generated import protoduino_pb2 as pb
from ._generated.schema_id import SCHEMA_ID
from .board import Board
from .boardoptions import BoardOptions
from .commands import DIGITAL_INPUT, PIN_MODES, command
from .constants import (
    DEDUPE_WINDOW,
    FAILSAFE_TIMEOUT,
    ID_AHEAD_MAX,
    MAX_MESSAGE_ID,
    OPENING_BAUDRATE,
    PROTOCOL_VERSION,
    ControlCode,
    EventCode,
    PacketType,
)
from .errors import ArgumentError
from .events import EventDispatcher
from .messages import ArduinoIn, ArduinoOut, Status, serialize_out
from .packets import Packet, event_payload, parse_control, reset_ack_payload
from .rpc import Done
from .transport import FrameMonitor, TransportListener
from .wiring import Wiring

if TYPE_CHECKING:
    from typing_extensions import Unpack

__all__ = ["DedupeWindow", "ManualClock", "VirtualDevice"]

#: What the device's DeviceInfo states: an Uno's pins (serial pins 0 and 1 reserved).
NUM_PINS = 20
RESERVED_PINS = (0, 1)
PWM_PINS = (3, 5, 6, 9, 10, 11)
ANALOG_PINS = tuple(range(14, 20))
COUNTER_PINS = (2, 3)
#: What a failsafe refuses: every command that sets a commanded value.
CONTROLS = frozenset({mode.control for mode in PIN_MODES if mode.control} | {"pose"})
#: The schema's FailsafeCause values (pb: protoduino_pb2).
PING_TIMEOUT, STOP = pb.FAILSAFE_CAUSE_PING_TIMEOUT, pb.FAILSAFE_CAUSE_STOP


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


def _mask(pins: tuple[int, ...]) -> int:
    return sum(1 << pin for pin in pins)


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
        #: Every packet the host sent, in order: (type, payload).
        self.received: list[tuple[PacketType, bytes]] = []
        #: The commands the device executed, each once (retransmissions are not executed;
        #: Pings and Heartbeats, answered each time, are only in ``received``).
        self.executed: list[ArduinoIn] = []
        self.resets = 0
        #: Device packets still to be lost on the way to the host; ``silent`` loses them all.
        self.lose = 0
        self.silent = False
        self._listener: TransportListener | None = None
        self._events: EventDispatcher | None = None
        self._outbox: collections.deque[Packet] = collections.deque()
        self._active = False
        self._tx_seq = 0
        self._dedupe = DedupeWindow()
        #: The session that owns the device (0: none) and this boot's id.
        self.session = 0
        self.boot_id = 1
        #: Digital inputs configured, and their levels (1 until set).
        self.inputs: set[int] = set()
        self.levels: dict[int, int] = {}
        #: The failsafe: its epoch (kept across sessions, 0 at power-up), whether a safe state
        #: holds and why (FailsafeCause), whether any was entered since power-up.
        self.failsafe_epoch = 0
        self.failsafe_active = False
        self.failsafe_cause = 0
        self._failsafe_entered = False
        self._failsafe_timeout = FAILSAFE_TIMEOUT
        self._heartbeat_only = False
        #: When the timer runs out (device clock; None before a session), and whether it ran
        #: out since the last liveness message (then, and only then, Controls are refused).
        self._failsafe_due: float | None = None
        self._fired = False
        self._pending_clear = False

    # --- a board on it ----------------------------------------------------------------------

    def open_board(self, **options: Unpack[BoardOptions]) -> Board:
        """A :class:`~protoduino.Board` on this device (the options of ``Board.open``; no
        ``monitor`` or ``capture``: there are no frames)."""
        wiring = Wiring(port=self, clock=self.clock, wait=self.wait, events=self._dispatcher)
        return Board(self.url, wiring=wiring, **options)

    def _dispatcher(self) -> EventDispatcher:
        self._events = EventDispatcher(self.url, threaded=False)
        return self._events

    def last(self, kind: str) -> ArduinoIn:
        """The last executed command of ``kind`` (``"servo_control"``, ``"pose"``, ...)."""
        for msg in reversed(self.executed):
            if msg.WhichOneof("data") == kind:
                return msg
        raise LookupError(f"the device executed no {kind}")

    def commands(self, kind: str) -> list[ArduinoIn]:
        """Every executed command of ``kind``, in order."""
        return [msg for msg in self.executed if msg.WhichOneof("data") == kind]

    def set_level(self, pin: int, level: int) -> None:
        """Drive a digital input: the device reports it, and the board has it on return."""
        self.levels[pin] = 1 if level else 0
        if pin in self.inputs:
            self.report()
        self.run(0)

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
        self.received.append((ptype, payload))
        self.tx_packets += 1
        self.tx_bytes += len(payload)
        if ptype is PacketType.CONTROL:
            self._control(payload)
        elif ptype is PacketType.COMMAND:
            if not self._active:
                self._reply(PacketType.CONTROL, event_payload(EventCode.NOT_ACTIVE))
                return
            msg = ArduinoIn()
            msg.ParseFromString(payload)
            executed = len(self.executed)
            self._reply(PacketType.DATA, serialize_out(self._answer(msg)))
            if self._pending_clear:  # a liveness message cleared the flag: said after its Ack
                self._pending_clear = False
                self._send_failsafe()
            if len(self.executed) > executed and command(str(msg.WhichOneof("data"))).is_init:
                self._after_init(msg)

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
            if self.silent or self.lose > 0:
                self.lose = max(0, self.lose - 1)
                continue
            arrived += 1
            self.rx_bytes += len(packet.payload)
            self._listener.transport_received([packet])
        return arrived

    def tick(self) -> float:
        """Deliver, run the link's timers at the clock's time, run the board's callbacks;
        when the timers next need to run."""
        if self._listener is None:
            return float("inf")
        self._check_failsafe()
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

    def reboot(self) -> None:
        """A power cycle: state, dedupe window and failsafe epoch forgotten, EVENT BOOT sent."""
        self._active = False
        self._tx_seq = 0
        self._dedupe = DedupeWindow()
        self.session = 0
        self.boot_id += 1
        self.failsafe_epoch, self.failsafe_active, self.failsafe_cause = 0, False, 0
        self._failsafe_entered = False
        self._failsafe_timeout, self._heartbeat_only = FAILSAFE_TIMEOUT, False
        self._failsafe_due, self._fired = None, False
        self._reply(PacketType.CONTROL, event_payload(EventCode.BOOT))

    # --- the device ----------------------------------------------------------------------------

    def _control(self, payload: bytes) -> None:
        ctl = parse_control(payload)
        if ctl.code is not ControlCode.RESET:
            return
        self.resets += 1
        self._tx_seq = 0
        if (
            ctl.version != self.version
            or ctl.session is None
            or self.version < 2
            or (self.version >= 5 and not 1 <= (ctl.next_id or 0) <= MAX_MESSAGE_ID)
        ):
            # Another version (or version 1 itself): the short answer every host reads.
            self._active = self.version < 2 and ctl.version == self.version
            self._reply(PacketType.CONTROL, reset_ack_payload(self.version, self.schema_id))
            return
        self._active = True
        resumed = ctl.session != 0 and ctl.session == self.session
        if not resumed:  # a session opens: its timer runs from the handshake
            self._failsafe_due = self.clock() + self._failsafe_timeout
        if ctl.next_id is not None:
            self._dedupe.sync(ctl.next_id, clear=not resumed)
        self.session = ctl.session
        self._reply(
            PacketType.CONTROL,
            reset_ack_payload(self.version, self.schema_id, self.boot_id, resumed),
        )

    def _after_init(self, msg: ArduinoIn) -> None:
        """A digital input's Init: its level follows the Ack (protocol.md, Reports)."""
        declared = command(str(msg.WhichOneof("data")))
        if declared.pin_mode is not DIGITAL_INPUT:
            return
        self.inputs.add(msg.digital_input_init.pin)
        self.report()

    def report(self) -> None:
        """Queue an InputReport with every digital input's level."""
        out = ArduinoOut()
        rep = out.input_report
        for pin in self.inputs:
            rep.digital_pins |= 1 << pin
            if self.levels.get(pin, 1):
                rep.digital_levels |= 1 << pin
        self._reply(PacketType.DATA, out.SerializeToString())

    def _reply(self, ptype: PacketType, payload: bytes) -> None:
        self._outbox.append(Packet(ptype, self._tx_seq, payload))
        self._tx_seq = (self._tx_seq + 1) & 0xFF

    def _answer(self, msg: ArduinoIn) -> Any:
        out = ArduinoOut()
        mid = msg.message_id
        out.ack.message_id = mid
        kind = msg.WhichOneof("data")
        if not 1 <= mid <= MAX_MESSAGE_ID:
            out.ack.status = Status.STATUS_INVALID_ARGUMENT
            return out
        idempotent = kind is not None and command(kind).idempotent  # as the firmware's table
        seen = self._dedupe.check(mid, lookup=not idempotent)
        if kind in ("ping", "heartbeat"):
            self._liveness(kind, getattr(msg, kind).failsafe_epoch)
            if kind == "ping":
                out.ack.ping_echo = msg.ping.payload
            if self._failsafe_entered:
                self._failsafe_state(out.ack.failsafe)
            # Answered in full each time, never in the dedupe window nor in `executed` (a
            # repeat counts as the original would): `received` has every one.
            return out
        if kind == "get_info":
            info = out.ack.info
            info.firmware_version = "virtual"
            info.protocol_version = self.version
            info.schema_id = self.schema_id
            info.board = "virtual"
            info.num_pins = NUM_PINS
            info.max_servos = 8
            info.reserved_pins.extend(RESERVED_PINS)
            info.features = sum(mode.feature_bit for mode in PIN_MODES)
            info.pwm_pins = _mask(PWM_PINS)
            info.analog_pins = _mask(ANALOG_PINS)
            info.counter_pins = _mask(COUNTER_PINS)
            return out
        if seen is not None:  # a retransmission: acknowledged again, not executed again
            out.ack.status = seen
            return out
        if kind in CONTROLS and self._fired:
            out.ack.status = Status.STATUS_FAILSAFE_EXPIRED  # no timer behind a value now
            self._remember(mid, out.ack.status, None)
            return out
        out.ack.status = Status.STATUS_OK
        self._remember(mid, out.ack.status, msg)
        if kind == "configure_failsafe":
            cfg = msg.configure_failsafe
            self._failsafe_timeout = cfg.timeout_ms / 1000 or FAILSAFE_TIMEOUT
            self._heartbeat_only = cfg.liveness == pb.LIVENESS_HEARTBEAT
            if not self._fired:  # restarts a timer that has not run out
                self._failsafe_due = self.clock() + self._failsafe_timeout
        elif kind == "stop":
            self._enter_failsafe(STOP)
        return out

    def _remember(self, mid: int, status: Status.ValueType, executed: ArduinoIn | None) -> None:
        if executed is not None:
            self.executed.append(executed)
        self._dedupe.add(mid, status)

    # --- the failsafe (docs/protocol.md section 7) ---------------------------------------------

    def _liveness(self, kind: str, epoch: int) -> None:
        """A Ping or Heartbeat: it counts only from the session's source, with the epoch."""
        if kind == "ping" and self._heartbeat_only:
            return
        if epoch != self.failsafe_epoch:
            return  # written before a failsafe this host had not heard of: re-arms nothing
        self._failsafe_due = self.clock() + self._failsafe_timeout
        self._fired = False
        if self.failsafe_active:
            self.failsafe_active = False
            self._pending_clear = True

    def _check_failsafe(self) -> None:
        due = self._failsafe_due
        if due is not None and not self._fired and self.clock() >= due:
            self._fired = True  # once per silence
            self._enter_failsafe(PING_TIMEOUT)

    def _enter_failsafe(self, cause: int) -> None:
        self.failsafe_epoch = (self.failsafe_epoch + 1) % 256
        self.failsafe_active, self.failsafe_cause = True, cause
        self._failsafe_entered = True
        if self._active:
            self._send_failsafe()

    def _failsafe_state(self, fs: Any) -> None:
        fs.active, fs.cause, fs.epoch = (
            self.failsafe_active,
            self.failsafe_cause,
            self.failsafe_epoch,
        )

    def _send_failsafe(self) -> None:
        out = ArduinoOut()
        self._failsafe_state(out.failsafe)
        self._reply(PacketType.DATA, out.SerializeToString())
