"""An in-process device for the link and request layers: no port, no thread, no wall clock.

:class:`VirtualDevice` is a :class:`~protoduino.link.PacketPort`: the link writes packets to
it as it would to the transport, and the test plays the transport's I/O thread, calling
``deliver()`` to hand the device's answers to the link and ``tick()`` to run the timers at
the time of a :class:`ManualClock` it moves itself. So a failing test points
at one layer (``protoduino.link`` or ``protoduino.rpc``), and every timer verdict is exact.

The device side follows docs/protocol.md as far as those layers can see: RESET -> RESET_ACK
(version, schema, boot id, the session resumed or not), NOT_ACTIVE before it, SEQ on every
packet it sends, one Ack per COMMAND,
the dedupe window (a retransmitted id is acknowledged again and not executed again), Ping
echo, DeviceInfo, EVENT BOOT on a reboot (which forgets the dedupe window), and an input's
value reported in an InputReport right after its Init's Ack (``levels`` holds the digital
levels). ``lose_next(n)`` loses the device's next ``n`` packets on the way to the host;
``silent`` loses all of them.
"""

from __future__ import annotations

import collections
from typing import Any

from protoduino._generated.schema_id import SCHEMA_ID
from protoduino.commands import DIGITAL_INPUT, PIN_MODES, command
from protoduino.constants import DEDUPE_WINDOW, PROTOCOL_VERSION, ControlCode, EventCode, PacketType
from protoduino.link import Link
from protoduino.messages import ArduinoIn, ArduinoOut, Status
from protoduino.packets import Packet, event_payload, parse_control, reset_ack_payload
from protoduino.transport import TransportListener


class ManualClock:
    """A clock that moves only when the test moves it."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


class VirtualDevice:
    """See the module docstring."""

    def __init__(self, *, version: int = PROTOCOL_VERSION, schema_id: int = SCHEMA_ID) -> None:
        self.url = self.name = "virtual://device"
        self.connected = False
        self.rx_since_open = 0
        self.rx_head = b""
        self.version = version
        self.schema_id = schema_id
        #: Every packet the host sent, in order: (type, payload).
        self.received: list[tuple[PacketType, bytes]] = []
        #: The commands the device executed, each once (retransmissions are not executed).
        self.executed: list[Any] = []  # ArduinoIn
        self.resets = 0
        #: Device packets still to be lost on the way to the host; ``silent`` loses them all.
        self.lose = 0
        self.silent = False
        self._listener: TransportListener | None = None
        self._outbox: collections.deque[Packet] = collections.deque()
        self._active = False
        self._tx_seq = 0
        self._dedupe: collections.OrderedDict[int, Status.ValueType] = collections.OrderedDict()
        #: Version 2's handshake: the session that owns the device (0: none) and this boot.
        self.session = 0
        self.boot_id = 1
        #: Digital inputs configured, and their levels (1 until a test sets one).
        self.inputs: set[int] = set()
        self.levels: dict[int, int] = {}

    # --- PacketPort: what the link calls ---------------------------------------------------

    def start(self, listener: TransportListener) -> None:
        """The port opens: the link sends RESET, and gets the answer before start returns."""
        self._listener = listener
        self.connected = True
        listener.transport_opened(False)
        self.deliver()

    def close(self) -> None:
        self.connected = False

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None:
        # Only queues the answer: the link may hold the request layer's lock while it sends.
        self.received.append((ptype, payload))
        if ptype is PacketType.CONTROL:
            ctl = parse_control(payload)
            if ctl.code is ControlCode.RESET:
                self.resets += 1
                self._tx_seq = 0
                if ctl.version != self.version or ctl.session is None or self.version < 2:
                    # Another version (or version 1 itself): the short answer every host reads.
                    self._active = self.version < 2 and ctl.version == self.version
                    self._reply(PacketType.CONTROL, reset_ack_payload(self.version, self.schema_id))
                    return
                self._active = True
                resumed = ctl.session != 0 and ctl.session == self.session
                self.session = ctl.session
                self._reply(
                    PacketType.CONTROL,
                    reset_ack_payload(self.version, self.schema_id, self.boot_id, resumed),
                )
        elif ptype is PacketType.COMMAND:
            if not self._active:
                self._reply(PacketType.CONTROL, event_payload(EventCode.NOT_ACTIVE))
                return
            msg = ArduinoIn()
            msg.ParseFromString(payload)
            executed = len(self.executed)
            self._reply(PacketType.DATA, self._answer(msg).SerializeToString())
            if len(self.executed) > executed and command(str(msg.WhichOneof("data"))).is_init:
                self._after_init(msg)

    def clear_queue(self) -> None:
        pass  # nothing waits: every send reached the device at once

    #: The line rate the link set (Link's RESET retries may change it; no rate is emulated).
    baudrate = 115200

    def set_baudrate(self, rate: int) -> None:
        self.baudrate = rate

    def recent_frames(self) -> tuple[str, ...]:
        return ()

    # --- the test, as the transport's I/O thread -------------------------------------------

    def deliver(self) -> int:
        """Hand every queued device packet to the link (or lose it); how many arrived."""
        arrived = 0
        while self._outbox and self._listener is not None:
            packet = self._outbox.popleft()
            if self.silent or self.lose > 0:
                self.lose = max(0, self.lose - 1)
                continue
            arrived += 1
            self._listener.transport_received([packet])
        return arrived

    def tick(self, link: Link, clock: ManualClock) -> float:
        """Deliver, then run the timers at the clock's time; when they next need to run."""
        self.deliver()
        due = link.transport_tick(clock())
        self.deliver()
        return due

    def run_until(self, link: Link, clock: ManualClock, seconds: float) -> None:
        """Advance the clock by ``seconds``, running every timer at the time it is due."""
        end = clock() + seconds
        while True:
            due = self.tick(link, clock)
            if due > end:
                break
            # A timer that asks to run again at the instant it ran would spin the I/O thread.
            assert due > clock(), f"the timers asked to run again at once (due {due})"
            clock.now = due
        clock.now = end
        self.tick(link, clock)

    def reboot(self) -> None:
        """A power cycle: state and dedupe window forgotten, EVENT BOOT sent."""
        self._active = False
        self._tx_seq = 0
        self._dedupe.clear()
        self.session = 0
        self.boot_id += 1
        self._reply(PacketType.CONTROL, event_payload(EventCode.BOOT))

    # --- the device ----------------------------------------------------------------------------

    def _after_init(self, msg: Any) -> None:
        """A digital input's Init: its level follows the Ack (protocol.md, Reports)."""
        declared = command(str(msg.WhichOneof("data")))
        if declared.pin_mode is not DIGITAL_INPUT:
            return
        self.inputs.add(msg.digital_input_init.pin)
        self.report()

    def report(self) -> None:
        """Send an InputReport with every digital input's level."""
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

    def _answer(self, msg: Any) -> Any:
        out = ArduinoOut()
        mid = msg.message_id
        out.ack.message_id = mid
        kind = msg.WhichOneof("data")
        if kind == "ping":
            out.ack.ping_echo = msg.ping.payload
            return out
        if kind == "get_info":
            info = out.ack.info
            info.firmware_version = "virtual"
            info.protocol_version = self.version
            info.schema_id = self.schema_id
            info.board = "virtual"
            info.num_pins = 20
            info.max_servos = 8
            info.features = sum(mode.feature_bit for mode in PIN_MODES)
            return out
        if mid in self._dedupe:  # a retransmission: acknowledged again, not executed again
            out.ack.status = self._dedupe[mid]
            return out
        self.executed.append(msg)
        out.ack.status = Status.STATUS_OK
        self._dedupe[mid] = out.ack.status
        while len(self._dedupe) > DEDUPE_WINDOW:
            self._dedupe.popitem(last=False)
        return out
