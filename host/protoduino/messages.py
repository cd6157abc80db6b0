"""Application messages: protobuf ArduinoIn/ArduinoOut inside COMMAND/DATA packets.

Wraps protobuf's decode errors into :class:`ProtocolError` at this boundary,
and renders packets as JSON for ``decode`` and ``monitor``.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, Literal

from google.protobuf import json_format
from google.protobuf.message import DecodeError, Message

from ._generated import protoduino_pb2 as pb
from .constants import PacketType
from .errors import ProtocolError
from .packets import Packet, parse_control

ArduinoIn = pb.ArduinoIn
ArduinoOut = pb.ArduinoOut
Status = pb.Status


def parse_in(payload: bytes) -> pb.ArduinoIn:
    msg = pb.ArduinoIn()
    try:
        msg.ParseFromString(payload)
    except DecodeError as error:
        raise ProtocolError(f"ArduinoIn does not decode: {error}") from error
    return msg


#: The short Ack's tag byte (``ack_ok``, a varint field) and, per message id 1..127 (one
#: varint byte), the long Ack it stands for, serialised: parsing those bytes is one protobuf
#: call, where decoding the short form and building the long one took three times as long.
_ACK_OK_TAG = pb.ArduinoOut.DESCRIPTOR.fields_by_name["ack_ok"].number << 3
_LONG_ACKS = tuple(
    pb.ArduinoOut(ack=pb.Ack(message_id=mid)).SerializeToString() for mid in range(128)
)


def parse_out(payload: bytes) -> pb.ArduinoOut:
    """Decode an ArduinoOut; the short Ack (``ack_ok``, protocol version 5) comes back as
    the Ack it stands for, so every reader above sees one kind of Ack."""
    if len(payload) == 2 and payload[0] == _ACK_OK_TAG and payload[1] < 0x80:
        return pb.ArduinoOut.FromString(_LONG_ACKS[payload[1]])  # the receive hot path
    # FromString: one protobuf call instead of constructing then parsing (receive hot path).
    try:
        msg = pb.ArduinoOut.FromString(payload)
    except DecodeError as error:
        raise ProtocolError(f"ArduinoOut does not decode: {error}") from error
    if msg.WhichOneof("data") == "ack_ok":
        long = pb.ArduinoOut()
        long.ack.message_id = msg.ack_ok  # STATUS_OK and nothing else
        return long
    return msg


def is_plain_ack(msg: pb.ArduinoOut) -> bool:
    """Is ``msg`` an Ack of STATUS_OK that carries nothing but its id (the short form's)?"""
    if msg.WhichOneof("data") != "ack":
        return False
    ack = msg.ack
    return (
        ack.status == pb.STATUS_OK
        and ack.WhichOneof("result") is None
        and not ack.HasField("failsafe")
        and not ack.refused_item
        and not ack.user_code
    )


def serialize_out(msg: pb.ArduinoOut) -> bytes:
    """The bytes a device sends for ``msg``: the short Ack when it applies (protocol.md
    section 7), as the firmware's encoder does; the simulated devices use it."""
    if is_plain_ack(msg):
        short = pb.ArduinoOut()
        short.ack_ok = msg.ack.message_id
        return short.SerializeToString()
    return msg.SerializeToString()


#: Which value of a pin an InputReport carries: a digital level, analog counts, a count of edges.
InputKind = Literal["digital", "analog", "counter"]


#: The most pins a pin set of the schema holds (protoduino.options: 9 bytes, the Mega's 70 pins).
PIN_SET_PINS = 72


def pin_mask(pin_set: bytes) -> int:
    """A pin set from the wire as a mask, bit P for pin P.

    The wire's form (protocol version 8, docs/protocol.md section 7, *Pin sets*): pin P is
    bit P % 8 of byte P // 8, so the bytes are the mask's little-endian digits, and a byte
    left out is 0.
    """
    return int.from_bytes(pin_set, "little")


def pin_set(mask: int) -> bytes:
    """A mask of pins (bit P for pin P) as the wire's pin set: :func:`pin_mask`'s bytes,
    without trailing zero bytes (an empty set is no bytes: the field left out)."""
    return mask.to_bytes((mask.bit_length() + 7) // 8, "little")


def pins_in(pin_set: bytes) -> list[int]:
    """The pins of a pin set from the wire (:func:`pin_mask`), lowest first."""
    return list(_pins(pin_mask(pin_set)))


def _pins(mask: int) -> Iterator[int]:
    """The pins whose bits are set in a mask (:func:`pin_mask`), lowest first."""
    pin = 0
    while mask:
        if mask & 1:
            yield pin
        mask >>= 1
        pin += 1


def pose_refused(pose: pb.Pose, refused_item: int) -> Message | None:
    """The Control a Pose's ``Ack.refused_item`` names.

    The device's order (protocol.md section 7, rule 7): the items counted from 1, then the
    pins of ``digital_pins`` upwards, counted on, each a DigitalControl. None for 0 (no
    output named) or a position past them.
    """
    if refused_item < 1:
        return None
    if refused_item <= len(pose.items):
        item = pose.items[refused_item - 1]
        member = item.WhichOneof("output")
        if member is None:
            return None
        control: Message = getattr(item, member)
        return control
    levels = pin_mask(pose.digital_levels)
    for n, pin in enumerate(pins_in(pose.digital_pins), len(pose.items) + 1):
        if n == refused_item:
            level = bool(levels >> pin & 1)
            return pb.DigitalControl(pin=pin, level=level)
    return None


def input_values(report: pb.InputReport) -> list[tuple[InputKind, int, int]]:
    """Every value an InputReport carries: (kind, pin, value), a digital level as a bool.

    Every digital input's level is in every report; analog values and counts are packed
    in pin order, one per pin of their pin set. Raises :class:`ProtocolError` when a pin set
    and its values disagree.
    """
    levels = pin_mask(report.digital_levels)
    found: list[tuple[InputKind, int, int]] = [
        ("digital", pin, bool(levels >> pin & 1)) for pin in pins_in(report.digital_pins)
    ]
    packed: tuple[tuple[InputKind, bytes, Any], ...] = (
        ("analog", report.analog_pins, report.analog_values),
        ("counter", report.counter_pins, report.counter_counts),
    )
    for kind, pin_bytes, values in packed:
        pins = pins_in(pin_bytes)
        if len(pins) != len(values):
            raise ProtocolError(
                f"InputReport: {len(pins)} {kind} pins in the pin set but {len(values)} values"
            )
        found += [(kind, pin, int(v)) for pin, v in zip(pins, values, strict=True)]
    return found


def status_name(status: int) -> str:
    """``STATUS_OUT_OF_RANGE`` for 4; the number itself for an unknown value."""
    try:
        return pb.Status.Name(status)  # type: ignore[arg-type]
    except ValueError:
        return str(status)


def message_to_json(msg: Message) -> dict[str, Any]:
    return json_format.MessageToDict(msg, preserving_proto_field_name=True)


def packet_to_json(packet: Packet) -> dict[str, Any]:
    """One good packet as the JSON object ``protoduino decode`` prints."""
    obj: dict[str, Any] = {
        "ok": True,
        "type": packet.type.name,
        "seq": packet.seq,
        "payload": packet.payload.hex(),
    }
    try:
        if packet.type is PacketType.CONTROL:
            obj["message"] = parse_control(packet.payload).to_json()
        elif packet.type is PacketType.DATA:
            obj["message"] = message_to_json(parse_out(packet.payload))
        else:
            obj["message"] = message_to_json(parse_in(packet.payload))
    except ProtocolError as error:
        obj["message"] = None
        obj["message_error"] = str(error)
    return obj
