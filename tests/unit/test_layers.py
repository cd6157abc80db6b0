"""The link and request layers on an in-process device: no port, no thread, no wall clock.

Each test builds the two layers exactly as ``Board`` does (``Rpc`` attached to a ``Link``),
hands the link a :class:`~protoduino.testing.VirtualDevice` as its port and the device's
:class:`~protoduino.testing.ManualClock` as its clock, and plays the I/O thread itself.
Every verdict is a count or an exact time on that clock.
"""

from __future__ import annotations

import pytest
from protoduino.constants import (
    ACK_TIMEOUT,
    FAILSAFE_TIMEOUT,
    MAX_RETRIES,
    PING_INTERVAL,
    PacketType,
)
from protoduino.errors import (
    AckTimeoutError,
    HandshakeError,
    TransportError,
    VersionMismatchError,
)
from protoduino.events import Event, EventKind
from protoduino.link import Link, LinkState
from protoduino.messages import ArduinoIn, ArduinoOut, parse_in, pin_set
from protoduino.packets import Control, parse_control
from protoduino.rpc import MessageHook, Rpc
from protoduino.testing import VirtualDevice

HANDSHAKE_TIMEOUT = 5.0
WATCHDOG_TIMEOUT = 2.0


class Stack:
    """A Link and its Rpc over a virtual device, as Board wires them."""

    def __init__(
        self,
        device: VirtualDevice,
        *,
        ping: bool = False,
        first_id: int = 1,
        message_hook: MessageHook | None = None,
    ) -> None:
        self.clock = device.clock
        self.device = device
        self.events: list[Event] = []
        self.restore: list[ArduinoIn] = []
        self.rpc = Rpc(
            notify=self.events.append,
            ack_timeout=ACK_TIMEOUT,
            max_retries=MAX_RETRIES,
            ping=ping,
            link_wait=HANDSHAKE_TIMEOUT,
            clock=self.clock,
            first_id=first_id,
            message_hook=message_hook,
            restore_provider=lambda: list(self.restore),
        )
        self.link = Link(
            device,
            self.rpc,
            handshake_timeout=HANDSHAKE_TIMEOUT,
            watchdog_timeout=WATCHDOG_TIMEOUT,
            notify=self.events.append,
            clock=self.clock,
            next_id=self.rpc.next_message_id,
        )
        self.rpc.attach(self.link)

    def run(self, seconds: float) -> None:
        self.device.run(seconds)

    def state(self) -> LinkState:
        # A call, not the attribute: each read is fresh to the type checker as well.
        return self.link.state

    def kinds(self) -> list[EventKind]:
        return [e.kind for e in self.events]


def digital_init(pin: int) -> ArduinoIn:
    msg = ArduinoIn()
    msg.digital_init.pin = pin
    return msg


def commands(device: VirtualDevice) -> int:
    return len(device.received)


def test_open_handshakes_with_one_reset() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    assert stack.link.state is LinkState.ACTIVE
    assert stack.device.resets == 1
    assert stack.link.expected_seq == 1  # RESET_ACK was SEQ 0


def test_a_command_is_acknowledged_and_executed_once() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    call = stack.rpc.submit(digital_init(13))
    assert stack.device.deliver() == 1
    assert call.done.is_set() and call.error is None
    assert [m.digital_init.pin for m in stack.device.executed] == [13]
    assert stack.rpc.acks == 1 and stack.rpc.retransmits == 0


def test_a_lost_ack_is_retransmitted_at_ack_timeout_and_not_executed_twice() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    stack.device.lose = 1  # the first Ack never arrives
    start = stack.clock()
    call = stack.rpc.submit(digital_init(7))
    stack.device.deliver()
    stack.run(ACK_TIMEOUT * 0.99)
    assert not call.done.is_set() and commands(stack.device) == 1
    stack.run(ACK_TIMEOUT * 0.02)  # the retransmission went out at start + ACK_TIMEOUT
    assert call.done.is_set() and call.error is None
    assert commands(stack.device) == 2
    assert len(stack.device.executed) == 1  # the dedupe window re-acknowledged it
    assert call.rtt is not None and call.rtt <= stack.clock() - start
    assert stack.rpc.retransmits == 1


def test_a_command_never_acknowledged_fails_at_the_call_bound() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    stack.device.silent = True
    call = stack.rpc.submit(digital_init(7))
    bound = ACK_TIMEOUT * (MAX_RETRIES + 1)
    stack.run(bound * 0.999)
    assert not call.done.is_set()
    assert commands(stack.device) == MAX_RETRIES + 1
    stack.run(bound * 0.002)
    assert isinstance(call.error, AckTimeoutError)
    assert stack.rpc.timeouts == 1


def test_the_watchdog_handshakes_again_after_silence() -> None:
    stack = Stack(VirtualDevice(), ping=True)
    stack.link.open()
    stack.run(1.5)  # pings answered: nothing to say
    assert stack.link.watchdog_resets == 0 and stack.device.resets == 1
    stack.device.silent = True
    stack.run(WATCHDOG_TIMEOUT + 0.5)
    assert stack.link.watchdog_resets == 1
    assert stack.device.resets >= 2  # RESET again, until the device answers
    stack.device.silent = False
    stack.run(1.5)
    assert stack.link.state is LinkState.ACTIVE
    assert EventKind.CONNECTED in stack.kinds()


def test_a_device_reboot_restores_the_configuration_first() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    stack.restore = [digital_init(13)]
    stack.device.reboot()
    stack.run(0.5)  # BOOT seen -> RESET -> RESET_ACK -> restore
    assert stack.link.state is LinkState.ACTIVE and stack.link.reboots == 1
    assert [m.digital_init.pin for m in stack.device.executed] == [13]
    assert EventKind.REBOOTED in stack.kinds()


def test_message_ids_wrap_around_without_zero() -> None:
    stack = Stack(VirtualDevice(), first_id=126)
    stack.link.open()
    ids = []
    for pin in (2, 3, 4):
        call = stack.rpc.submit(digital_init(pin))
        stack.device.deliver()
        assert call.done.is_set() and call.error is None
        ids.append(call.message_id)
    assert ids == [126, 127, 1]
    assert stack.rpc.state().next_id == 2
    # The device ran all three: after the wrap, id 1 is newer than 127 (ahead by 1).
    assert [m.digital_init.pin for m in stack.device.executed] == [2, 3, 4]


def test_an_id_is_given_at_the_first_transmission_not_at_submit() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    stack.rpc.window = 1
    held = [stack.rpc.submit(digital_init(pin)) for pin in (2, 3, 4)]
    # Only the first went out: the others have no id yet, and a Ping submitted now, urgent,
    # overtakes them and takes the next id, so ids go on the wire in the order given.
    assert [c.message_id for c in held] == [stack.rpc.state().next_id - 1, 0, 0]
    ping = ArduinoIn()
    ping.ping.SetInParent()
    urgent = stack.rpc.submit(ping, urgent=True)
    stack.device.deliver()
    stack.run(0.1)
    assert all(c.done.is_set() and c.error is None for c in [*held, urgent])
    first = held[0].message_id
    assert urgent.message_id == first % 127 + 1
    assert [c.message_id for c in held[1:]] == [first % 127 + 2, first % 127 + 3]
    wire = [r.msg.message_id for r in stack.device.received]
    assert wire[-4:] == [first, first % 127 + 1, first % 127 + 2, first % 127 + 3]


class AckLosingDevice(VirtualDevice):
    """Runs every command; while ``lose_acks`` is set, its answers never reach the host."""

    lose_acks = False

    def __init__(self) -> None:
        super().__init__()
        self.handler = self.losing_reply

    def losing_reply(self, msg: ArduinoIn) -> list[ArduinoOut]:
        replies = self.default_reply(msg)
        return [] if self.lose_acks else replies


def test_ids_never_go_64_ahead_of_the_acked_one_a_resumed_handshake_resyncs() -> None:
    # Every Ack lost: the device runs each command, the host hears nothing. 63 ids past the
    # newest one the device acknowledged (none yet: the one before the first RESET's
    # NEXT_ID), the host handshakes again (the session resumed; the RESET's NEXT_ID
    # re-synchronises the device's newest id) before it sends a 64th.
    device = AckLosingDevice()
    stack = Stack(device)
    stack.link.open()
    stack.link.watchdog_timeout = 1000.0  # not the watchdog's re-handshake
    stack.rpc.window = 100
    device.lose_acks = True
    device.packets.clear()
    for _ in range(70):
        msg = ArduinoIn()
        msg.ping.SetInParent()
        stack.rpc.submit(msg)
    stack.run(0.1)
    wire = [
        (ptype, parse_control(p) if ptype is PacketType.CONTROL else parse_in(p).message_id)
        for ptype, p in device.packets
    ]
    reset = next(i for i, (ptype, _) in enumerate(wire) if ptype is PacketType.CONTROL)
    assert [mid for _, mid in wire[:reset]] == list(range(1, 64))
    ctl = wire[reset][1]
    assert isinstance(ctl, Control) and ctl.next_id == 64
    assert stack.rpc.id_resyncs == 1 and stack.link.state is LinkState.ACTIVE
    # After it, the 63 go again with their ids (the session resumed) and id 64 is new; 65
    # waits for id 1 to finish (it would be 64 ahead of an id still open).
    after = [mid for ptype, mid in wire[reset + 1 :] if isinstance(mid, int)]
    assert sorted(set(after)) == list(range(1, 65))
    assert stack.rpc.id_holds > 0


def test_a_silent_device_fails_the_handshake_at_its_timeout() -> None:
    stack = Stack(VirtualDevice())
    stack.device.silent = True
    stack.device.start(stack.link)  # what Link.open does, without waiting for a thread
    stack.run(HANDSHAKE_TIMEOUT - 0.001)
    assert stack.state() is LinkState.WAIT_ACK
    assert stack.device.resets >= 5  # RESET resent with backoff: 0, 0.1, 0.3, 0.7, 1.5 ...
    stack.run(0.002)
    assert stack.state() is LinkState.FAILED
    assert isinstance(stack.link.down_error, HandshakeError)
    assert "did not answer RESET" in str(stack.link.down_error)


def test_a_device_on_another_protocol_version_is_refused() -> None:
    stack = Stack(VirtualDevice(version=99))
    with pytest.raises(VersionMismatchError):
        stack.link.open()
    assert stack.link.state is not LinkState.ACTIVE


def pings(device: VirtualDevice) -> int:
    return len(device.arrivals("ping"))


def test_pings_keep_their_interval_and_stop_while_paused() -> None:
    stack = Stack(VirtualDevice(), ping=True)
    stack.link.open()
    stack.run(PING_INTERVAL * 5 - 0.001)
    assert pings(stack.device) == 5  # one at once, then one per interval
    stack.rpc.pinging = False
    stack.run(FAILSAFE_TIMEOUT * 2)
    assert pings(stack.device) == 5
    assert stack.link.watchdog_resets == 0  # a device left alone may be silent
    stack.rpc.pinging = True
    stack.device.deliver()
    stack.run(0.001)
    assert pings(stack.device) == 6  # resumed at once


def test_a_call_fails_with_the_port_error_while_the_port_is_gone() -> None:
    stack = Stack(VirtualDevice())
    stack.link.open()
    stack.device.connected = False
    stack.link.transport_lost(TransportError("port vanished"))
    start = stack.clock()
    call = stack.rpc.submit(digital_init(7))
    # The bound of every call: its round of retries plus the link's handshake time.
    bound = stack.rpc.call_timeout
    assert bound == ACK_TIMEOUT * (MAX_RETRIES + 1) + HANDSHAKE_TIMEOUT
    stack.run(bound - 0.001)
    assert not call.done.is_set()  # waiting for the link to come back
    stack.run(0.002)
    assert isinstance(call.error, TransportError) and "vanished" in str(call.error)
    assert stack.clock() - start <= bound + 0.001
    assert commands(stack.device) == 0


def test_input_reports_reach_the_message_hook_and_are_no_acks() -> None:
    """An InputReport after an Init's Ack, and one between a command and its Ack, go to
    the board's hook; the request layer matches Acks as before and counts no stray one."""
    reports: list[ArduinoOut] = []
    stack = Stack(VirtualDevice(), message_hook=reports.append)
    stack.link.open()
    msg = ArduinoIn()
    msg.digital_input_init.pin = 2
    call = stack.rpc.submit(msg)
    assert stack.device.deliver() == 2  # the Ack, then the level
    assert call.done.is_set() and call.error is None
    assert [r.WhichOneof("data") for r in reports] == ["input_report"]
    assert reports[0].input_report.digital_pins == pin_set(1 << 2)
    assert reports[0].input_report.digital_levels == pin_set(1 << 2)
    stack.device.set_level(2, 0)  # a change, queued before the next command's Ack
    second = stack.rpc.submit(digital_init(13))
    assert stack.device.deliver() == 2
    assert second.done.is_set() and second.error is None
    assert reports[-1].input_report.digital_levels == b""
    assert stack.rpc.acks == 2 and stack.rpc.unknown_acks == 0 and stack.rpc.late_acks == 0
