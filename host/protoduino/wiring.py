"""What a board runs on: its port, its clock, how a caller waits, where events are delivered.

A board on a device (:meth:`protoduino.Board.open`) runs on a serial port with its I/O thread
(:class:`~protoduino.transport.Transport`), the monotonic clock, callers waiting on their
call's event while that thread runs the link, and an event thread. :mod:`protoduino.testing`
wires a board to an in-process device instead: no port, no thread, a clock the test moves.
One :class:`Wiring`, passed to the board's constructor, says which; nothing is set afterwards.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from .clock import Clock
from .constants import OPENING_BAUDRATE
from .events import EventDispatcher
from .link import PacketPort
from .rpc import Waiter, event_wait
from .transport import FrameMonitor, Transport


class BoardPort(PacketPort, Protocol):
    """What a board needs of its port beyond the link's needs: counters, frame monitors."""

    rx_bytes: int
    tx_bytes: int
    tx_packets: int

    @property
    def decoder_counts(self) -> dict[str, int]: ...

    def add_monitor(self, monitor: FrameMonitor) -> None: ...

    def on_io_thread(self) -> bool:
        """Whether the caller is the thread that runs the link (a blocking call would hang)."""
        ...


@dataclass(frozen=True)
class Wiring:
    """A board's port, clock, way of waiting and event delivery (see the module docstring)."""

    port: BoardPort
    clock: Clock
    wait: Waiter
    #: Called once the options were all accepted: an event thread starts only then.
    events: Callable[[], EventDispatcher]
    #: No I/O thread: a waiting caller runs the link itself (``wait``), so an input's
    #: ``wait_for`` waits through ``wait`` too (protoduino.testing).
    inline: bool = False


def serial_wiring(url: str, baudrate: int | None) -> Wiring:
    """A board on the pyserial port ``url``, with its I/O and event threads.

    ``baudrate`` None: the port opens at the firmware's default opening rate, and the link
    agrees on a faster one (docs/protocol.md 5, *Line rate*)."""
    return Wiring(
        port=Transport(url, baudrate=baudrate or OPENING_BAUDRATE),
        clock=time.monotonic,
        wait=event_wait,
        events=lambda: EventDispatcher(url),
    )
