"""What the transport writes before a RESET (docs/protocol.md 2): a lone 0x00, and while the
device has said nothing at all since the open, stk500v2's "leave programming mode" message
before it (a Mega 2560's bootloader, run by the open's reset, stays while bytes arrive)."""

from __future__ import annotations

import os
import select
import time

from protoduino.constants import PacketType
from protoduino.framing import frame_packet
from protoduino.packets import BadFrame, Packet
from protoduino.transport import Transport

#: The message as docs/protocol.md 2 states it, byte for byte.
LEAVE = bytes.fromhex("1b 01 00 03 0e 11 01 01 06")
#: How long a failing test waits for bytes (the verdict is the bytes').
BOUND = 10.0


class _Quiet:
    def transport_opened(self, reopened: bool) -> None:
        pass

    def transport_lost(self, error: Exception) -> None:
        pass

    def transport_failed(self, error: Exception) -> None:
        pass

    def transport_received(self, items: list[Packet | BadFrame]) -> None:
        pass

    def transport_tick(self, now: float) -> float:
        return now + 0.05


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
        transport.start(_Quiet())
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
