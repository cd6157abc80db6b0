"""COBS framing (docs/protocol.md section 2) and the incremental stream decoder.

Recovery policy, the same on both ends of the link. The receiver collects
non-zero bytes and acts only at a 0x00 delimiter, so it needs no timer:

* Garbage before a frame (line noise, a bootloader's chatter, the tail of a
  frame whose start was lost) ends at the next 0x00 like any frame; it fails
  COBS decoding or the packet checks and is dropped and counted. The frame
  after it starts clean.
* A frame that decodes but whose CRC, LEN or TYPE is wrong is dropped and
  counted by reason; the next frame is unaffected.
* Garbage after a frame is the start of the next "frame" and meets the same
  fate at its delimiter; it never damages a good frame behind it, because
  that frame's first byte follows a 0x00.
* A run of more than MAX_ENCODED_FRAME bytes without a 0x00 is an overflow:
  the buffer is discarded at once (bounded memory), one overflow is counted,
  and everything up to the next 0x00 is skipped.

Lone 0x00 bytes (empty frames) are ignored: a sender emits one after opening
the port to flush the receiver's half-filled buffer.
"""

from __future__ import annotations

import binascii
import logging
from collections import Counter
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from cobs import cobs as _cobs

from .constants import CRC_SIZE, HEADER_SIZE, MAX_ENCODED_FRAME, MIN_PACKET, PacketType
from .packets import BadFrame, Packet, build_packet, parse_packet

log = logging.getLogger(__name__)


def _cobs_is_native() -> bool:
    try:
        from cobs.cobs import _cobs_ext  # noqa: F401
    except ImportError:
        return False
    return True


COBS_NATIVE = _cobs_is_native()
if not COBS_NATIVE:  # pragma: no cover - depends on the installed wheel
    log.warning("cobs C extension unavailable; using the pure-Python fallback (about 25x slower)")

DELIMITER = b"\x00"

_TYPES: dict[int, PacketType] = {int(t): t for t in PacketType}
_OVERFLOW_RAW = MAX_ENCODED_FRAME + 1
#: tuple.__new__ skips NamedTuple's Python-level __new__ (the per-frame cost).
_new_packet: Callable[[type[Packet], tuple[PacketType, int, bytes]], Packet] = tuple.__new__


def cobs_encode(data: bytes) -> bytes:
    """Standard COBS; the result holds no 0x00."""
    return bytes(_cobs.encode(data))


def cobs_decode(data: bytes) -> bytes | None:
    """COBS-decode one frame (without its delimiter); None if it is not valid COBS."""
    try:
        return bytes(_cobs.decode(data))
    except _cobs.DecodeError:
        return None


def encode_frame(raw_packet: bytes) -> bytes:
    """A raw packet as it goes on the wire: COBS plus the 0x00 delimiter."""
    return cobs_encode(raw_packet) + DELIMITER


def frame_size(payload_len: int) -> int:
    """The most bytes a packet with ``payload_len`` payload bytes takes on the wire.

    COBS adds one byte per 254 and one more; then the delimiter, and the lone
    0x00 a sender may put in front after a failed write. Flow control counts
    frames by this (docs/protocol.md section 7).
    """
    raw = MIN_PACKET + payload_len
    return raw + raw // 254 + 1 + 2


def frame_packet(ptype: PacketType, seq: int, payload: bytes = b"") -> bytes:
    """Build, CRC, COBS-encode and delimit one packet."""
    return encode_frame(build_packet(ptype, seq, payload))


def decode_frame(encoded: bytes) -> Packet | BadFrame:
    """One complete frame (no delimiter) to a packet or the reason it was dropped."""
    raw = cobs_decode(encoded)
    if raw is None:
        return BadFrame("cobs", bytes(encoded))
    result = parse_packet(raw)
    if isinstance(result, Packet):
        return result
    return BadFrame(result, bytes(encoded))


class PyStreamDecoder:
    """Incremental decoder: feed it chunks of bytes, get packets and bad frames.

    The output does not depend on how the stream was chunked. Memory is bounded
    by MAX_ENCODED_FRAME. ``counts`` tallies "packets" and each drop reason.

    The pure-Python reference: :data:`StreamDecoder` is the C accelerator
    (``protoduino._speedups``) when it was built, this class otherwise, and the
    tests hold both to the same results.

    This is the host's hot path (about one call per serial read), so the
    COBS, length, CRC and TYPE checks of :func:`decode_frame` are inlined here
    and each chunk is split once; ``tests/unit/test_framing_props.py`` holds the two
    to the same results.
    """

    __slots__ = ("_buf", "_skipping", "counts")

    def __init__(self) -> None:
        self._buf = b""
        self._skipping = False
        self.counts: Counter[str] = Counter()

    def reset(self) -> None:
        """Forget any partial frame (the link was reset)."""
        self._buf = b""
        self._skipping = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[Packet | BadFrame]:
        parts = bytes(data).split(b"\0")
        tail = parts.pop()  # after the last delimiter: the start of a frame, or b""
        out: list[Packet | BadFrame] = []
        counts = self.counts
        if parts:
            if self._skipping:  # this delimiter ends the frame that overflowed
                self._skipping = False
                parts[0] = b""
            elif self._buf:
                parts[0] = self._buf + parts[0]
            self._buf = b""
            good = 0
            decode = _cobs.decode
            decode_error = _cobs.DecodeError
            crc = binascii.crc_hqx
            types = _TYPES
            for enc in parts:
                if not enc:
                    continue
                if len(enc) > MAX_ENCODED_FRAME:
                    out.append(BadFrame("overflow", enc[:_OVERFLOW_RAW]))
                    counts["overflow"] += 1
                    continue
                try:
                    raw = decode(enc)
                except decode_error:
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
                    ptype = types.get(raw[0])
                    if ptype is None:
                        out.append(BadFrame("type", enc))
                        counts["type"] += 1
                    else:
                        out.append(_new_packet(Packet, (ptype, raw[2], raw[HEADER_SIZE:-CRC_SIZE])))
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

    def feed_all(self, chunks: Iterable[bytes]) -> list[Packet | BadFrame]:
        out: list[Packet | BadFrame] = []
        for chunk in chunks:
            out.extend(self.feed(chunk))
        return out


# The C accelerator (host/protoduino/_speedups.c, built by setup.py where a C
# compiler and the Python headers exist) does what PyStreamDecoder does, in
# one C call per read instead of interpreter work per frame.
if TYPE_CHECKING:
    StreamDecoder = PyStreamDecoder
else:
    try:
        from ._speedups import StreamDecoder
    except ImportError as error:  # pragma: no cover - depends on the build
        log.warning(
            "protoduino._speedups unavailable (%s); using the pure-Python stream decoder "
            "(several times slower)",
            error,
        )
        StreamDecoder = PyStreamDecoder

#: True when :data:`StreamDecoder` is the C accelerator.
ACCELERATED: bool = StreamDecoder is not PyStreamDecoder
