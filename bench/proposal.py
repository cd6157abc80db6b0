"""A faster drop-in for ``framing.StreamDecoder``, measured as a proposal (issue 7, part 1).

``framing.py`` belongs to the foundation, so the receive benchmark measures this next to it
instead of changing it. It keeps the public behaviour exactly (same items in the same order,
same ``BadFrame`` reasons and raw bytes, same ``counts``, chunking-independent, memory bounded by
MAX_ENCODED_FRAME); ``tests/test_bench_smoke.py`` checks that on streams with every kind of
damage. What it changes:

* one ``bytes.split(b"\\0")`` per chunk instead of a ``find`` loop with an append and a method
  call per frame, and the partial frame kept as ``bytes`` instead of a ``bytearray`` that is
  copied again before decoding;
* the COBS decode, length, CRC and TYPE checks inlined (no ``decode_frame`` / ``parse_packet``
  / ``cobs_decode`` calls and their extra ``bytes()`` copies);
* TYPE looked up in a dict instead of calling the ``PacketType`` enum (an enum call costs
  about as much as the CRC);
* the ``packets`` counter bumped once per chunk instead of once per frame.

Two further proposals are measured with it, each as its own step:

* :class:`LightPacketDecoder` builds each ``Packet`` without the frozen dataclass's
  ``__init__`` (which sets every field through ``object.__setattr__``). It writes the slots
  directly, which costs what a plain ``__slots__`` class or a ``NamedTuple`` would: the
  proposal for ``packets.py`` is to make ``Packet`` one of those; the object built here is a
  real, equal ``Packet`` so the rest of the path is unchanged.
* :func:`parse_out_from_string` is ``messages.parse_out`` with ``ArduinoOut.FromString``
  instead of constructing an empty message and calling ``ParseFromString`` on it.
"""

from __future__ import annotations

import binascii
from collections import Counter
from collections.abc import Callable

from cobs import cobs as _cobs
from google.protobuf.message import DecodeError
from protoduino._generated import protoduino_pb2 as pb
from protoduino.constants import CRC_SIZE, HEADER_SIZE, MAX_ENCODED_FRAME, MIN_PACKET, PacketType
from protoduino.errors import ProtocolError
from protoduino.packets import BadFrame, Packet

_TYPES: dict[int, PacketType] = {int(t): t for t in PacketType}
_OVERFLOW_RAW = MAX_ENCODED_FRAME + 1


def _packet_via_slots() -> Callable[[PacketType, int, bytes], Packet]:
    # Packet is now a NamedTuple (the proposal was adopted in framing.py);
    # tuple.__new__ is how the committed decoder builds one.
    new = tuple.__new__

    def make(ptype: PacketType, seq: int, payload: bytes) -> Packet:
        return new(Packet, (ptype, seq, payload))

    return make


class FastStreamDecoder:
    """Same contract as ``framing.StreamDecoder``; see the module docstring for what differs."""

    __slots__ = ("_buf", "_skipping", "counts")

    #: How a good packet is built; :class:`LightPacketDecoder` swaps it.
    make_packet: Callable[[PacketType, int, bytes], Packet] = Packet

    def __init__(self) -> None:
        self._buf = b""
        self._skipping = False
        self.counts: Counter[str] = Counter()

    def reset(self) -> None:
        self._buf = b""
        self._skipping = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[Packet | BadFrame]:
        parts = bytes(data).split(b"\0")
        tail = parts.pop()  # what follows the last delimiter: the start of a frame, or b""
        out: list[Packet | BadFrame] = []
        counts = self.counts
        if parts:
            if self._skipping:  # the first delimiter ends the frame that overflowed
                self._skipping = False
                parts[0] = b""
            elif self._buf:
                parts[0] = self._buf + parts[0]
            self._buf = b""
            good = 0
            decode = _cobs.decode
            crc = binascii.crc_hqx
            make_packet = self.make_packet
            for enc in parts:
                if not enc:
                    continue
                if len(enc) > MAX_ENCODED_FRAME:
                    out.append(BadFrame("overflow", enc[:_OVERFLOW_RAW]))
                    counts["overflow"] += 1
                    continue
                try:
                    raw = decode(enc)
                except _cobs.DecodeError:
                    out.append(BadFrame("cobs", enc))
                    counts["cobs"] += 1
                    continue
                size = len(raw)
                if size < MIN_PACKET or size != MIN_PACKET + raw[1]:
                    out.append(BadFrame("length", enc))
                    counts["length"] += 1
                elif crc(raw, 0xFFFF):
                    out.append(BadFrame("crc", enc))
                    counts["crc"] += 1
                else:
                    ptype = _TYPES.get(raw[0])
                    if ptype is None:
                        out.append(BadFrame("type", enc))
                        counts["type"] += 1
                    else:
                        out.append(make_packet(ptype, raw[2], raw[HEADER_SIZE:-CRC_SIZE]))
                        good += 1
            if good:
                counts["packets"] += good
        if tail and not self._skipping:
            buf = self._buf + tail
            if len(buf) > MAX_ENCODED_FRAME:
                out.append(BadFrame("overflow", buf[:_OVERFLOW_RAW]))
                counts["overflow"] += 1
                self._buf = b""
                self._skipping = True
            else:
                self._buf = buf
        return out


class LightPacketDecoder(FastStreamDecoder):
    """:class:`FastStreamDecoder` building packets at the cost of a plain slots class."""

    __slots__ = ()

    make_packet = staticmethod(_packet_via_slots())


def parse_out_from_string(payload: bytes) -> pb.ArduinoOut:
    """``messages.parse_out`` with one protobuf call instead of two."""
    try:
        return pb.ArduinoOut.FromString(payload)
    except DecodeError as error:
        raise ProtocolError(f"ArduinoOut does not decode: {error}") from error
