"""Packets: ``[TYPE][LEN][SEQ][PAYLOAD][CRC16 BE]`` (docs/protocol.md sections 3 to 5).

Pure functions, no I/O. Building a packet has no side effects, so a frame
that failed to write can be rebuilt and sent again with the same SEQ.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from typing import Literal, NamedTuple

from .constants import (
    BAUD_SIZE,
    CRC_SIZE,
    FAST_BAUDRATES,
    HEADER_SIZE,
    MAX_PAYLOAD,
    MIN_PACKET,
    RESET_ACK_RESUMED,
    RESET_ACK_SIZE,
    RESET_ACK_V1_SIZE,
    RESET_SIZE,
    ControlCode,
    EventCode,
    PacketType,
)
from .errors import ArgumentError, PayloadTooLargeError, ProtocolError

#: Why a frame was dropped. "cobs" and "overflow" come from the framing layer.
ErrorReason = Literal["cobs", "crc", "length", "type", "overflow"]


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0)."""
    return binascii.crc_hqx(data, 0xFFFF)


class Packet(NamedTuple):
    """A valid packet. A NamedTuple rather than a dataclass: the receive path
    builds one per frame, and a tuple costs a third of a frozen dataclass."""

    type: PacketType
    seq: int
    payload: bytes


class BadFrame(NamedTuple):
    """A frame that was dropped, with its bytes for diagnostics.

    ``raw`` is the COBS-encoded frame as received (without the delimiter);
    for "overflow" it is the first MAX_ENCODED_FRAME + 1 bytes.
    """

    reason: ErrorReason
    raw: bytes


def build_packet(ptype: PacketType, seq: int, payload: bytes = b"") -> bytes:
    """The raw packet (before COBS), CRC included."""
    if len(payload) > MAX_PAYLOAD:
        raise PayloadTooLargeError(
            f"payload of {len(payload)} bytes exceeds MAX_PAYLOAD ({MAX_PAYLOAD}); "
            "protocol version 1 has no fragmentation"
        )
    if not 0 <= seq <= 0xFF:
        raise ArgumentError(f"seq must be 0..255, not {seq}")
    body = bytes((ptype, len(payload), seq)) + payload
    return body + crc16(body).to_bytes(2, "big")


def parse_packet(raw: bytes) -> Packet | ErrorReason:
    """A valid packet, or why it is not one: "length", "crc" or "type".

    Checks run in that order: a packet whose LEN disagrees with its size is a
    length error whatever its CRC says.
    """
    if len(raw) < MIN_PACKET or len(raw) != MIN_PACKET + raw[1]:
        return "length"
    if crc16(raw) != 0:  # the CRC over data + big-endian CRC is zero
        return "crc"
    try:
        ptype = PacketType(raw[0])
    except ValueError:
        return "type"
    return Packet(ptype, raw[2], raw[HEADER_SIZE:-CRC_SIZE])


# --- CONTROL payloads (section 5) -------------------------------------------


@dataclass(frozen=True, slots=True)
class Control:
    """A decoded CONTROL payload; fields not used by ``code`` are None."""

    code: ControlCode
    version: int | None = None
    schema_id: int | None = None
    event: int | None = None  # an EventCode value, or an unknown code to log
    detail: bytes = b""
    #: RESET (version 2): the host session; None in version 1's shape.
    session: int | None = None
    #: RESET (version 5): the message id the host transmits next (section 7,
    #: *Message ids*); None in older shapes.
    next_id: int | None = None
    #: RESET_ACK (version 2): this power-up's id and whether the session was
    #: resumed; None in the short shape a device gives a RESET of another version.
    boot_id: int | None = None
    resumed: bool | None = None
    #: RESET_ACK (version 4): the line rates above the opening one the device can
    #: switch to (section 5, *Line rate*), fastest first; empty in older shapes.
    baudrates: tuple[int, ...] = ()
    #: BAUD_SET / BAUD_ACK (version 4): the rate (0 in a BAUD_ACK: refused).
    baudrate: int | None = None

    def to_json(self) -> dict[str, object]:
        out: dict[str, object] = {"code": self.code.name}
        if self.version is not None:
            out["version"] = self.version
        if self.session is not None:
            out["session"] = f"0x{self.session:08X}"
        if self.next_id is not None:
            out["next_id"] = self.next_id
        if self.schema_id is not None:
            out["schema_id"] = f"0x{self.schema_id:08X}"
        if self.boot_id is not None:
            out["boot_id"] = f"0x{self.boot_id:08X}"
            out["resumed"] = self.resumed
        if self.baudrates:
            out["baudrates"] = list(self.baudrates)
        if self.baudrate is not None:
            out["baudrate"] = self.baudrate
        if self.event is not None:
            try:
                out["event"] = EventCode(self.event).name
            except ValueError:
                out["event"] = self.event
            if self.detail:
                out["detail"] = self.detail.hex()
        return out


def reset_payload(version: int, session: int = 1, next_id: int = 1) -> bytes:
    """RESET for host ``session`` whose next message id is ``next_id``; version 1's
    shape (CODE VERSION) for version 1, versions 2 to 4's (no NEXT_ID) for them."""
    head = bytes((ControlCode.RESET, version))
    if version < 2:
        return head
    if version < 5:
        return head + struct.pack(">I", session)
    return head + struct.pack(">IB", session, next_id)


def reset_ack_payload(
    version: int,
    schema_id: int,
    boot_id: int | None = None,
    resumed: bool = False,
    baudrates: tuple[int, ...] = (),
) -> bytes:
    """RESET_ACK; without ``boot_id``, the short shape every version parses.

    ``baudrates``: the rates of FAST_BAUDRATES the device offers (FLAGS bits 1..3).
    """
    head = bytes((ControlCode.RESET_ACK, version)) + struct.pack(">I", schema_id)
    if boot_id is None:
        return head
    flags = RESET_ACK_RESUMED if resumed else 0
    for bit, rate in enumerate(FAST_BAUDRATES, start=1):
        if rate in baudrates:
            flags |= 1 << bit
    return head + struct.pack(">IB", boot_id, flags)


def baud_payload(code: ControlCode, rate: int) -> bytes:
    """BAUD_SET or BAUD_ACK of ``rate`` (section 5, *Line rate*)."""
    return bytes((code,)) + struct.pack(">I", rate)


def event_payload(event: int, detail: bytes = b"") -> bytes:
    return bytes((ControlCode.EVENT, event)) + detail


_CONTROL_CODES: dict[int, ControlCode] = {int(c): c for c in ControlCode}


def parse_control(payload: bytes) -> Control:
    """Decode a CONTROL payload; raises :class:`ProtocolError` if malformed."""
    if not payload:
        raise ProtocolError("empty CONTROL payload")
    code = _CONTROL_CODES.get(payload[0])
    if code is None:
        raise ProtocolError(f"unknown CONTROL code 0x{payload[0]:02X}")
    args = payload[1:]
    if code is ControlCode.RESET:
        # Version 1's shape (1 byte) is still parsed: the monitor shows it, and
        # a device answers it with the short RESET_ACK so the host names the mismatch.
        if len(args) == 1:
            return Control(code, version=args[0])
        if len(args) not in (RESET_SIZE - 2, RESET_SIZE - 1):
            raise ProtocolError(f"RESET takes 1, 5 or 6 argument bytes, got {len(args)}")
        # Versions 2 to 4: CODE VERSION SESSION; version 5 adds NEXT_ID.
        return Control(
            code,
            version=args[0],
            session=int.from_bytes(args[1:5], "big"),
            next_id=args[5] if len(args) == RESET_SIZE - 1 else None,
        )
    if code is ControlCode.RESET_ACK:
        version, n = (args[0] if args else None), len(args)
        if n >= RESET_ACK_V1_SIZE - 1 and n != RESET_ACK_SIZE - 1:
            # The short shape; and a later version may add bytes: its VERSION and
            # SCHEMA_ID still sit here, enough to name the mismatch (versions 2
            # and 3 share the long shape: the host compares VERSION after this).
            return Control(code, version=version, schema_id=int.from_bytes(args[1:5], "big"))
        if n != RESET_ACK_SIZE - 1:
            raise ProtocolError(f"RESET_ACK takes 5 or 10 argument bytes, got {n}")
        return Control(
            code,
            version=version,
            schema_id=int.from_bytes(args[1:5], "big"),
            boot_id=int.from_bytes(args[5:9], "big"),
            resumed=bool(args[9] & RESET_ACK_RESUMED),
            baudrates=tuple(
                rate
                for bit, rate in reversed(list(enumerate(FAST_BAUDRATES, start=1)))
                if args[9] & (1 << bit)
            ),
        )
    if code in (ControlCode.BAUD_SET, ControlCode.BAUD_ACK):
        if len(args) != BAUD_SIZE - 1:
            raise ProtocolError(f"{code.name} takes 4 argument bytes, got {len(args)}")
        return Control(code, baudrate=int.from_bytes(args, "big"))
    if not args:
        raise ProtocolError("EVENT without an event code")
    return Control(code, event=args[0], detail=bytes(args[1:]))
