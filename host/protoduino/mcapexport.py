"""A capture as MCAP, the log format Foxglove (and the ROS 2 tools) open directly.

The protobuf messages keep their own encoding, with the schema embedded as a
FileDescriptorSet (what ``mcap-protobuf-support`` builds from the generated
classes), so the viewer decodes every field and plots any number in them
(servo degrees, digital levels, input values) against time without knowing
protoduino. What is not protobuf goes on JSON channels:

=====================  ============  =============================================
topic                  encoding      what
=====================  ============  =============================================
/protoduino/commands   protobuf      ``ArduinoIn`` sent by the host (COMMAND)
/protoduino/device     protobuf      ``ArduinoOut`` from the device (DATA: acks,
                                     failsafe, logs, ...)
/protoduino/frames     json          every frame: direction, type, SEQ, control
                                     message or why it was dropped
/protoduino/stats      json          the link counters (plot retransmits, rtt...)
/protoduino/events     json          the board's events (reboot, failsafe, ...)
/protoduino/outputs    json          each readback (``read_outputs``) decoded:
                                     ``servos``: pin, ``us`` (width now),
                                     ``target_us``; ``digital``: pin, ``level``
=====================  ============  =============================================

The readback's servo widths travel packed in a ``bytes`` field (5 bytes per servo,
to keep the Uno's encoder small), which no viewer can plot; ``/protoduino/outputs``
carries them decoded as numbers. In Foxglove a servo's width is the message path
``/protoduino/outputs.servos[:]{pin==9}.us`` (and ``.target_us``), a digital level
``/protoduino/outputs.digital[:]{pin==13}.level``.

Log times are the capture's UNIX times in nanoseconds.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from typing import Any

from .capture import CapturedEvent, CapturedFrame, CapturedStats, CaptureHeader, Record
from .constants import PacketType
from .errors import CaptureError, ProtocolError
from .messages import ArduinoIn, ArduinoOut, parse_in, parse_out
from .packets import BadFrame, parse_control
from .readback import decode_output_states

COMMANDS = "/protoduino/commands"
DEVICE = "/protoduino/device"
FRAMES = "/protoduino/frames"
STATS = "/protoduino/stats"
EVENTS = "/protoduino/events"
OUTPUTS = "/protoduino/outputs"

_JSON_SCHEMAS: dict[str, dict[str, Any]] = {
    FRAMES: {
        "type": "object",
        "properties": {
            "dir": {"type": "string"},
            "ok": {"type": "boolean"},
            "type": {"type": "string"},
            "seq": {"type": "integer"},
            "error": {"type": "string"},
            "control": {"type": "object"},
        },
    },
    STATS: {"type": "object", "additionalProperties": True},
    EVENTS: {
        "type": "object",
        "properties": {"event": {"type": "string"}, "text": {"type": "string"}},
    },
    OUTPUTS: {
        "type": "object",
        "properties": {
            "message_id": {"type": "integer"},
            "servos": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "pin": {"type": "integer"},
                        "us": {"type": "integer"},
                        "target_us": {"type": "integer"},
                    },
                },
            },
            "digital": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {"pin": {"type": "integer"}, "level": {"type": "integer"}},
                },
            },
        },
    },
}


def _ns(t: float) -> int:
    return round(t * 1e9)


def write_mcap(records: Iterable[Record], path: str | os.PathLike[str]) -> dict[str, int]:
    """Write ``records`` (a capture) to ``path``; returns the message count per topic."""
    try:
        from mcap.writer import Writer
        from mcap_protobuf.schema import build_file_descriptor_set
    except ImportError as error:
        raise CaptureError(
            "MCAP export needs the mcap and mcap-protobuf-support packages "
            "(pip install 'protoduino[mcap]')"
        ) from error

    counts: dict[str, int] = {}
    try:
        out = open(path, "wb")  # noqa: SIM115 - closed below
    except OSError as error:
        raise CaptureError(f"cannot write {os.fspath(path)}: {error.strerror}") from error
    with out:
        writer = Writer(out)
        writer.start(profile="", library="protoduino")
        channels: dict[str, int] = {}
        for topic, cls in ((COMMANDS, ArduinoIn), (DEVICE, ArduinoOut)):
            schema = writer.register_schema(
                name=cls.DESCRIPTOR.full_name,
                encoding="protobuf",
                data=build_file_descriptor_set(cls).SerializeToString(),
            )
            channels[topic] = writer.register_channel(topic, "protobuf", schema)
        for topic, jschema in _JSON_SCHEMAS.items():
            schema = writer.register_schema(
                name=topic.rsplit("/", 1)[-1], encoding="jsonschema", data=_json(jschema)
            )
            channels[topic] = writer.register_channel(topic, "json", schema)

        def add(topic: str, t: float, data: bytes) -> None:
            counts[topic] = counts.get(topic, 0) + 1
            writer.add_message(
                channel_id=channels[topic],
                log_time=_ns(t),
                publish_time=_ns(t),
                data=data,
                sequence=counts[topic],
            )

        for record in records:
            if isinstance(record, CaptureHeader):
                writer.add_metadata(
                    "protoduino",
                    {"url": record.url, "schema_id": f"0x{record.schema_id:08X}"},
                )
            elif isinstance(record, CapturedFrame):
                add(FRAMES, record.t, _json(_frame(record)))
                item = record.item
                if isinstance(item, BadFrame):
                    continue
                try:
                    if item.type is PacketType.COMMAND:
                        add(COMMANDS, record.t, parse_in(item.payload).SerializeToString())
                    elif item.type is PacketType.DATA:
                        data = parse_out(item.payload)
                        add(DEVICE, record.t, data.SerializeToString())
                        if _is_readback(data):
                            add(OUTPUTS, record.t, _json(_readback(data)))
                except ProtocolError:
                    pass  # already on /protoduino/frames with its error
            elif isinstance(record, CapturedStats):
                add(STATS, record.t, _json(record.stats))
            elif isinstance(record, CapturedEvent):
                add(
                    EVENTS,
                    record.t,
                    _json({"event": record.kind, "text": record.text, **record.details}),
                )
        writer.finish()  # type: ignore[no-untyped-call]
    return counts


def _is_readback(out: ArduinoOut) -> bool:
    return out.WhichOneof("data") == "ack" and out.ack.WhichOneof("result") == "outputs"


def _readback(out: ArduinoOut) -> dict[str, Any]:
    """A readback's OutputStates as plain numbers, decoded as the board decodes it."""
    states = decode_output_states(out.ack.outputs)
    return {
        "message_id": out.ack.message_id,
        "servos": [
            {"pin": s.pin, "us": s.value, "target_us": s.target}
            for s in states.values()
            if s.mode == "servo"
        ],
        "digital": [
            {"pin": s.pin, "level": s.value} for s in states.values() if s.mode == "digital"
        ],
    }


def _frame(record: CapturedFrame) -> dict[str, Any]:
    item = record.item
    if isinstance(item, BadFrame):
        return {"dir": record.direction, "ok": False, "error": item.reason}
    obj: dict[str, Any] = {
        "dir": record.direction,
        "ok": True,
        "type": item.type.name,
        "seq": item.seq,
    }
    if item.type is PacketType.CONTROL:
        try:
            obj["control"] = parse_control(item.payload).to_json()
        except ProtocolError as error:
            obj["error"] = str(error)
    return obj


def _json(obj: object) -> bytes:
    return json.dumps(obj, separators=(",", ":"), default=str).encode()
