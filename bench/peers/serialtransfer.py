"""pySerialTransfer (the host side of the SerialTransfer Arduino library).

Its parser pulls bytes from a pyserial port inside ``SerialTransfer.available()``, so the
benchmark swaps that port for :class:`MemoryPort`, which hands out bytes from memory. That is
kinder to it than a real port: its state machine reads one byte per ``read()`` call, which on a
real pyserial port costs a system call each (about 4.5 us, measured on the development machine),
and here costs a slice.

SerialTransfer moves application-defined structs; the layouts below (an Ack as message id
uint32 + status uint8, a servo command as pin + degrees, one packet id per command) are ours.
"""

from __future__ import annotations

import random
from typing import Any

from ..core import require
from . import RxCase, Slot, WireSample, chunked

#: Packet ids of our application layout.
PACKET_SERVO = 1
PACKET_ACK = 2


class MemoryPort:
    """Enough of ``serial.Serial`` for SerialTransfer: bytes in from memory, writes captured."""

    is_open = True

    def __init__(self) -> None:
        self._data = b""
        self._pos = 0
        self.written: list[bytes] = []

    def load(self, chunk: bytes) -> None:
        """Append a read's worth of bytes, as if the OS had just received them."""
        self._data = self._data[self._pos :] + chunk
        self._pos = 0

    @property
    def in_waiting(self) -> int:
        return len(self._data) - self._pos

    def read(self, size: int = 1) -> bytes:
        out = self._data[self._pos : self._pos + size]
        self._pos += len(out)
        return out

    def write(self, data: bytes | bytearray) -> int:
        self.written.append(bytes(data))
        return len(data)

    def open(self) -> None:
        """Already open."""


def _transfer(port: MemoryPort) -> Any:
    module = require("pySerialTransfer.pySerialTransfer", "pySerialTransfer")
    link = module.SerialTransfer("memory", restrict_ports=False, debug=False)
    link.connection = port
    return link


def _packet(link: Any, port: MemoryPort, packet_id: int, fields: list[tuple[int, str]]) -> bytes:
    pos = 0
    for value, fmt in fields:
        pos = link.tx_obj(value, pos, val_type_override=fmt)
    if not link.send(pos, packet_id=packet_id):
        raise RuntimeError("pySerialTransfer refused to send")
    return port.written.pop()


def ack_stream(frames: int, seed: int) -> tuple[bytes, list[int]]:
    port = MemoryPort()
    link = _transfer(port)
    rng = random.Random(seed)
    first = rng.randrange(1, 1 << 31)
    ids = [first + i for i in range(frames)]
    stream = b"".join(_packet(link, port, PACKET_ACK, [(i, "I"), (0, "B")]) for i in ids)
    return stream, ids


def rx_case(frames: int, chunk: int, seed: int) -> RxCase:
    stream, ids = ack_stream(frames, seed)
    chunks = chunked(stream, chunk)
    pending = {message_id: Slot() for message_id in ids}
    module = require("pySerialTransfer.pySerialTransfer", "pySerialTransfer")
    new_data = module.Status.NEW_DATA

    def run() -> int:
        port = MemoryPort()
        link = _transfer(port)
        handled = 0
        for data in chunks:
            port.load(data)
            while port.in_waiting:
                if not link.available():
                    continue
                if link.status is new_data and link.id_byte == PACKET_ACK:
                    waiter = pending.get(link.rx_obj("I", 0))
                    if waiter is not None:
                        waiter.value = link.rx_obj("B", 4)
                        handled += 1
        return handled

    return RxCase(
        name="pySerialTransfer",
        package="pySerialTransfer",
        parser="pure Python, one read() per byte (fed from memory here, not a port)",
        stages="SerialTransfer.available -> rx_obj(message id, status) -> pending call by id",
        stream=stream,
        frames=frames,
        run=run,
    )


def wire_sample() -> WireSample:
    port = MemoryPort()
    link = _transfer(port)
    return WireSample(
        library="pySerialTransfer",
        package="pySerialTransfer",
        encoder="SerialTransfer.tx_obj + send (our payload layout)",
        setup=None,
        setup_what="none: the sketch attaches its servo",
        command=_packet(link, port, PACKET_SERVO, [(9, "B"), (90, "B")]),
        command_what="packet id 1, payload {pin u8, degrees u8}",
        ack=_packet(link, port, PACKET_ACK, [(1, "I"), (0, "B")]),
        ack_what="packet id 2, payload {message id u32, status u8}",
        check="CRC-8 (poly 0x9B)",
        ack_by_protocol=False,
        notes="the library has no ack of its own; this one is an application-level reply, "
        "laid out by us; its CRC is 8 bits",
    )
