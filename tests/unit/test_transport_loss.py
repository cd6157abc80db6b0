"""How the I/O thread reports a lost port, that it never ends silently, and what it writes
before a RESET.

The order in which a lost port is reported (a pty whose other end closes):

A caller who reads ``connected`` False and then submits a command must find the
link down already: its call then waits for the next session. The transport tells
the link first and marks the port closed after; in the other order a command
submitted in between went to a dead port's queue, counted as sent, and failed as
"possibly run" when the next handshake found the outputs lost (a flaky e2e test,
tests/e2e/test_board_sim.py::test_call_waits_across_a_short_outage, found it).
"""

from __future__ import annotations

import os
import queue
import select
import threading
import time
from typing import Any

import pytest
import serial
from protoduino import Board, LinkError
from protoduino.constants import PacketType
from protoduino.events import Event, EventKind
from protoduino.framing import frame_packet
from protoduino.packets import BadFrame, Packet
from protoduino.testing import PtyDevice
from protoduino.transport import Transport


class _Listener:
    def __init__(self, transport: Transport) -> None:
        self.transport = transport
        self.connected_when_lost: bool | None = None
        self.lost = threading.Event()

    def transport_opened(self, reopened: bool) -> None:
        pass

    def transport_lost(self, error: Exception) -> None:
        if not self.lost.is_set():
            self.connected_when_lost = self.transport.connected
            self.lost.set()

    def transport_failed(self, error: Exception) -> None:
        pass

    def transport_received(self, items: list[Packet | BadFrame]) -> None:
        pass

    def transport_tick(self, now: float) -> float:
        return now + 0.05


def test_the_link_hears_of_a_lost_port_before_the_port_reads_closed() -> None:
    master, slave = os.openpty()
    path = os.ttyname(slave)
    transport = Transport(path)
    listener = _Listener(transport)
    try:
        transport.start(listener)
        os.close(slave)  # the transport holds its own descriptor
        os.close(master)  # the board's end: the port is gone
        assert listener.lost.wait(10), "the transport never reported the lost port"
        assert listener.connected_when_lost is True
    finally:
        transport.close()


#: How long a failing test waits for an event (the verdict is the event's).
BOUND = 10.0


def _wait_event(events: queue.Queue[Event], kind: EventKind) -> Event:
    while True:
        event = events.get(timeout=BOUND)  # queue.Empty: no such event
        if event.kind is kind:
            return event


class _RefusesRates(serial.Serial):
    """pyserial's port whose rate cannot be changed: a stalled rfc2217:// server."""

    @property
    def baudrate(self) -> int:
        return int(super().baudrate)

    @baudrate.setter
    def baudrate(self, rate: int) -> None:
        raise serial.SerialException("Remote does not accept parameter change (RFC2217)")


def test_a_rate_change_that_fails_is_a_lost_port_and_a_reconnect(fake: PtyDevice) -> None:
    """Issue 32: a re-handshake's rate cycling set the rate on a port that refused it;
    the exception ended the I/O thread and every later call timed out."""
    events: queue.Queue[Event] = queue.Queue()
    with Board.open(fake.port, watchdog_timeout=60.0) as board:
        board.on_event(events.put)
        transport: Any = board._link.transport
        port: Any = transport._port
        port.__class__ = _RefusesRates  # this port only: the reopened one is plain
        fake.answer_reset = False  # the handshake's RESETs go on to the other rates
        board._link.request_handshake()
        _wait_event(events, EventKind.DISCONNECTED)
        assert fake.wait_for(lambda: transport.opens >= 2, timeout=BOUND), transport.last_error
        assert "parameter change" in str(transport.last_error)
        fake.answer_reset = True
        _wait_event(events, EventKind.CONNECTED)
        assert board.ping() > 0
        assert board.stats.reconnects == 1


def test_a_bug_on_the_io_thread_is_a_reported_error(fake: PtyDevice) -> None:
    events: queue.Queue[Event] = queue.Queue()
    with Board.open(fake.port) as board:
        board.on_event(events.put)
        link: Any = board._link

        def broken(now: float) -> float:
            raise ZeroDivisionError("a bug")

        link._listener.link_tick = broken
        error = _wait_event(events, EventKind.ERROR)
        assert "I/O thread failed" in error.text and "a bug" in error.text
        with pytest.raises(LinkError, match="I/O thread failed"):
            board.ping()


#: stk500v2's "leave programming mode" message as docs/protocol.md 2 states it, byte for byte.
LEAVE = bytes.fromhex("1b 01 00 03 0e 11 01 01 06")


def _read(fd: int, count: int) -> bytes:
    got = b""
    deadline = time.monotonic() + BOUND
    while len(got) < count and time.monotonic() < deadline:
        if select.select([fd], [], [], 0.05)[0]:
            got += os.read(fd, count - len(got))
    return got


def test_a_reset_leaves_a_bootloader_only_while_the_device_has_said_nothing() -> None:
    master, slave = os.openpty()
    transport = Transport(os.ttyname(slave))
    payload = bytes([0x01, 8])
    frame = frame_packet(PacketType.CONTROL, 0, payload)
    try:
        transport.start(_Listener(transport))
        assert _read(master, 1) == b"\x00"  # the open's lone delimiter
        transport.send(PacketType.CONTROL, payload, reset_seq=True)
        first = LEAVE + b"\x00" + frame
        assert _read(master, len(first)) == first
        os.write(master, b"\x00")  # the device said something: no bootloader holds it
        deadline = time.monotonic() + BOUND
        while transport.rx_since_open == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        transport.send(PacketType.CONTROL, payload, reset_seq=True)
        second = b"\x00" + frame
        assert _read(master, len(second)) == second
    finally:
        transport.close()
        os.close(master)
        os.close(slave)
