"""The order in which a lost port is reported (a pty whose other end closes).

A caller who reads ``connected`` False and then submits a command must find the
link down already: its call then waits for the next session. The transport tells
the link first and marks the port closed after; in the other order a command
submitted in between went to a dead port's queue, counted as sent, and failed as
"possibly run" when the next handshake found the outputs lost (a flaky e2e test,
tests/e2e/test_board_sim.py::test_call_waits_across_a_short_outage, found it).
"""

from __future__ import annotations

import os
import threading

from protoduino.packets import BadFrame, Packet
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
