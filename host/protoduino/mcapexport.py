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
/protoduino/inputs     json          each InputReport decoded: ``time_ms`` (the
                                     device's clock), ``values``: pin, ``kind``
                                     (digital, analog, counter), ``value``
=====================  ============  =============================================

The readback's servo widths travel packed in a ``bytes`` field (5 bytes per servo,
to keep the Uno's encoder small), which no viewer can plot; ``/protoduino/outputs``
carries them decoded as numbers. In Foxglove a servo's width is the message path
``/protoduino/outputs.servos[:]{pin==9}.us`` (and ``.target_us``), a digital level
``/protoduino/outputs.digital[:]{pin==13}.level``, an input's value
``/protoduino/inputs.values[:]{pin==14}.value``.

Log times are the capture's UNIX times in nanoseconds. The channels and the messages each
record makes are declared once (:func:`channel_specs`, :func:`record_messages`): the live
console's Foxglove server (:mod:`protoduino.console.foxglive`) sends the same, so one Foxglove
layout (``docs/foxglove-layout.json``) serves a recording and a live robot.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from .capture import CapturedEvent, CapturedFrame, CapturedStats, CaptureHeader, Record
from .constants import PacketType
from .errors import CaptureError, ProtocolError
from .messages import ArduinoIn, ArduinoOut, input_values, parse_in, parse_out
from .packets import BadFrame, parse_control
from .readback import decode_output_states

COMMANDS = "/protoduino/commands"
DEVICE = "/protoduino/device"
FRAMES = "/protoduino/frames"
STATS = "/protoduino/stats"
EVENTS = "/protoduino/events"
OUTPUTS = "/protoduino/outputs"
INPUTS = "/protoduino/inputs"

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
    INPUTS: {
        "type": "object",
        "properties": {
            "time_ms": {"type": "integer"},
            "values": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "pin": {"type": "integer"},
                        "kind": {"type": "string"},
                        "value": {"type": "integer"},
                    },
                },
            },
        },
    },
}


def _ns(t: float) -> int:
    return round(t * 1e9)


@dataclass(frozen=True)
class ChannelSpec:
    """One channel: its topic, its messages' encoding and its schema."""

    topic: str
    message_encoding: str  # "protobuf" or "json"
    schema_name: str
    schema_encoding: str  # "protobuf" (a FileDescriptorSet) or "jsonschema"
    schema_data: bytes


def channel_specs() -> list[ChannelSpec]:
    """Every channel of the export (and of the live Foxglove server), in order."""
    try:
        from mcap_protobuf.schema import build_file_descriptor_set
    except ImportError as error:
        raise CaptureError(
            "MCAP export needs the mcap and mcap-protobuf-support packages "
            "(pip install 'protoduino[mcap]')"
        ) from error
    specs = [
        ChannelSpec(
            topic,
            "protobuf",
            cls.DESCRIPTOR.full_name,
            "protobuf",
            build_file_descriptor_set(cls).SerializeToString(),
        )
        for topic, cls in ((COMMANDS, ArduinoIn), (DEVICE, ArduinoOut))
    ]
    specs += [
        ChannelSpec(topic, "json", topic.rsplit("/", 1)[-1], "jsonschema", _json(jschema))
        for topic, jschema in _JSON_SCHEMAS.items()
    ]
    return specs


def record_messages(record: Record) -> list[tuple[str, float, bytes]]:
    """The messages one capture record makes: (topic, UNIX time, encoded message)."""
    found: list[tuple[str, float, bytes]] = []
    if isinstance(record, CapturedFrame):
        found.append((FRAMES, record.t, _json(_frame(record))))
        item = record.item
        if isinstance(item, BadFrame):
            return found
        try:
            if item.type is PacketType.COMMAND:
                found.append((COMMANDS, record.t, parse_in(item.payload).SerializeToString()))
            elif item.type is PacketType.DATA:
                data = parse_out(item.payload)
                found.append((DEVICE, record.t, data.SerializeToString()))
                if _is_readback(data):
                    found.append((OUTPUTS, record.t, _json(_readback(data))))
                elif data.WhichOneof("data") == "input_report":
                    found.append((INPUTS, record.t, _json(_inputs(data))))
        except ProtocolError:
            pass  # already on /protoduino/frames with its error
    elif isinstance(record, CapturedStats):
        found.append((STATS, record.t, _json(record.stats)))
    elif isinstance(record, CapturedEvent):
        event = {"event": record.kind, "text": record.text, **record.details}
        found.append((EVENTS, record.t, _json(event)))
    return found


def write_mcap(records: Iterable[Record], path: str | os.PathLike[str]) -> dict[str, int]:
    """Write ``records`` (a capture) to ``path``; returns the message count per topic."""
    try:
        from mcap.writer import Writer
    except ImportError as error:
        raise CaptureError(
            "MCAP export needs the mcap and mcap-protobuf-support packages "
            "(pip install 'protoduino[mcap]')"
        ) from error
    specs = channel_specs()

    counts: dict[str, int] = {}
    try:
        out = open(path, "wb")  # noqa: SIM115 - closed below
    except OSError as error:
        raise CaptureError(f"cannot write {os.fspath(path)}: {error.strerror}") from error
    with out:
        writer = Writer(out)
        writer.start(profile="", library="protoduino")
        channels: dict[str, int] = {}
        for spec in specs:
            schema = writer.register_schema(
                name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data
            )
            channels[spec.topic] = writer.register_channel(
                spec.topic, spec.message_encoding, schema
            )

        for record in records:
            if isinstance(record, CaptureHeader):
                writer.add_metadata(
                    "protoduino",
                    {"url": record.url, "schema_id": f"0x{record.schema_id:08X}"},
                )
            for topic, t, data in record_messages(record):
                counts[topic] = counts.get(topic, 0) + 1
                writer.add_message(
                    channel_id=channels[topic],
                    log_time=_ns(t),
                    publish_time=_ns(t),
                    data=data,
                    sequence=counts[topic],
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


def _inputs(out: ArduinoOut) -> dict[str, Any]:
    """An InputReport's values as plain numbers, decoded as the board decodes them."""
    report = out.input_report
    return {
        "time_ms": report.time_ms,
        "values": [
            {"pin": pin, "kind": kind, "value": int(value)}
            for kind, pin, value in input_values(report)
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
