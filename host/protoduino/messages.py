"""Application messages: protobuf ArduinoIn/ArduinoOut inside COMMAND/DATA packets.

Wraps protobuf's decode errors into :class:`ProtocolError` at this boundary,
and renders packets as JSON for ``decode`` and ``monitor``.
"""

from __future__ import annotations

from typing import Any

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


def parse_out(payload: bytes) -> pb.ArduinoOut:
    # FromString: one protobuf call instead of constructing then parsing (receive hot path).
    try:
        return pb.ArduinoOut.FromString(payload)
    except DecodeError as error:
        raise ProtocolError(f"ArduinoOut does not decode: {error}") from error


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
