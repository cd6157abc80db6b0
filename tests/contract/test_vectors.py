"""Every vector of the shared wire spec, through the host codec."""

from __future__ import annotations

from typing import Any

import crcmod.predefined
import pytest
from protoduino.constants import PROTOCOL_VERSION, ControlCode, PacketType
from protoduino.framing import StreamDecoder, cobs_decode, cobs_encode, frame_packet
from protoduino.messages import Status, parse_in, parse_out, pins_in, serialize_out
from protoduino.packets import BadFrame, Packet, build_packet, crc16, parse_control, parse_packet
from wirevectors import INVALID_FRAME_REASONS, load

V = load()


def _id(v: dict[str, Any]) -> str:
    return str(v.get("name") or v.get("decoded") or v.get("data") or "empty")[:40]


@pytest.mark.parametrize("v", V["cobs"], ids=_id)
def test_cobs_vectors(v: dict[str, str]) -> None:
    decoded, encoded = bytes.fromhex(v["decoded"]), bytes.fromhex(v["encoded"])
    assert cobs_encode(decoded) == encoded
    assert cobs_decode(encoded) == decoded


@pytest.mark.parametrize("v", V["crc16_ccitt_false"], ids=_id)
def test_crc_vectors(v: dict[str, Any]) -> None:
    assert crc16(bytes.fromhex(v["data"])) == v["crc"]


def test_crc_check_value_and_crcmod_cross_check() -> None:
    assert crc16(b"123456789") == 0x29B1
    reference = crcmod.predefined.mkCrcFun("crc-ccitt-false")
    samples = [bytes(i % 256 for i in range(n)) for n in range(0, 300, 7)] + [
        b"\xff" * 40,
        b"\x00" * 9,
    ]
    for data in samples:
        assert crc16(data) == reference(data)


@pytest.mark.parametrize("v", V["packets"], ids=_id)
def test_packet_vectors(v: dict[str, Any]) -> None:
    ptype, seq, payload = PacketType(v["type"]), v["seq"], bytes.fromhex(v["payload"])
    raw, wire = bytes.fromhex(v["raw"]), bytes.fromhex(v["wire"])
    assert build_packet(ptype, seq, payload) == raw
    assert frame_packet(ptype, seq, payload) == wire
    assert parse_packet(raw) == Packet(ptype, seq, payload)
    assert StreamDecoder().feed(wire) == [Packet(ptype, seq, payload)]


@pytest.mark.parametrize("v", V["invalid_frames"], ids=_id)
def test_invalid_frames(v: dict[str, str]) -> None:
    wire = bytes.fromhex(v["wire"])
    decoder = StreamDecoder()
    out = decoder.feed(wire)
    assert out == [BadFrame(INVALID_FRAME_REASONS[v["name"]], wire[:-1])]
    assert decoder.counts[INVALID_FRAME_REASONS[v["name"]]] == 1


def test_every_invalid_vector_has_an_expected_reason() -> None:
    assert {v["name"] for v in V["invalid_frames"]} == set(INVALID_FRAME_REASONS)


def test_whole_vector_stream_in_one_go() -> None:
    """All packets and invalid frames interleaved: every good packet survives."""
    stream = b""
    expected: list[Packet | BadFrame] = []
    for good, bad in zip(V["packets"], V["invalid_frames"], strict=False):
        stream += bytes.fromhex(bad["wire"]) + bytes.fromhex(good["wire"])
        expected.append(
            BadFrame(INVALID_FRAME_REASONS[bad["name"]], bytes.fromhex(bad["wire"])[:-1])
        )
        expected.append(
            Packet(PacketType(good["type"]), good["seq"], bytes.fromhex(good["payload"]))
        )
    assert StreamDecoder().feed(stream) == expected


def test_version_2_handshake_vectors_parse_field_by_field() -> None:
    by_name = {v["name"]: bytes.fromhex(v["payload"]) for v in V["packets"]}
    reset = parse_control(by_name["RESET from host, version 2, session 0x5E551011"])
    assert (reset.code, reset.version, reset.session) == (ControlCode.RESET, 2, 0x5E551011)
    ack = parse_control(
        by_name["RESET_ACK from device, version 2, schema id 0x1A2B3C00, boot id 7, resumed"]
    )
    assert (ack.version, ack.schema_id, ack.boot_id, ack.resumed) == (2, 0x1A2B3C00, 7, True)
    old = parse_control(by_name["RESET_ACK from device, version 1, schema id 0x1A2B3C00"])
    assert (old.version, old.schema_id, old.boot_id) == (1, 0x1A2B3C00, None)


def test_version_5_vectors_parse_field_by_field() -> None:
    by_name = {v["name"]: bytes.fromhex(v["payload"]) for v in V["packets"]}
    reset = parse_control(by_name["RESET from host, version 5, session 0x5E551011, next id 1"])
    assert (reset.code, reset.version, reset.session, reset.next_id) == (
        ControlCode.RESET,
        5,
        0x5E551011,
        1,
    )
    on = parse_in(by_name["COMMAND version 5: digital write, message id 1, pin 13, level 1"])
    assert (on.message_id, on.digital_control.pin, on.digital_control.level) == (1, 13, True)
    off = parse_in(by_name["COMMAND version 5: digital write, message id 2, pin 13, level 0"])
    assert (off.message_id, off.digital_control.pin, off.digital_control.level) == (2, 13, False)
    # The short Ack reads as the long one: the Ack of id 1, STATUS_OK, nothing else.
    short = by_name["DATA version 5: short Ack (ack_ok) of message id 1"]
    assert short == bytes((0x38, 0x01))
    ack = parse_out(short)
    assert ack.WhichOneof("data") == "ack"
    assert (ack.ack.message_id, ack.ack.status) == (1, Status.STATUS_OK)
    assert serialize_out(ack) == short


def test_version_6_vectors_parse_field_by_field() -> None:
    by_name = {v["name"]: bytes.fromhex(v["payload"]) for v in V["packets"]}
    reset = parse_control(by_name["RESET from host, version 6, session 0x5E551011, next id 1"])
    assert (reset.code, reset.version, reset.session, reset.next_id) == (
        ControlCode.RESET,
        6,
        0x5E551011,
        1,
    )
    # Its Pose (uint32 masks, fields 2 and 3) is version 6's: version 8's pin sets are bytes,
    # so only its framing holds (the COBS, CRC and packet tests above); the bytes differ.
    name = "COMMAND version 6: Pose of six digital outputs (pins 2..7; 2, 4, 6 high), message id 3"
    wire = next(bytes.fromhex(v["wire"]) for v in V["packets"] if v["name"] == name)
    assert len(wire) == 16  # six DigitalControl items in version 5: 47 to 59 B
    assert bytes.fromhex("10fc01") in by_name[name]  # digital_pins: a varint


def test_version_8_vectors_parse_field_by_field() -> None:
    """Pin sets of any width (protocol version 8): pin P is bit P % 8 of byte P // 8."""
    by_name = {v["name"]: bytes.fromhex(v["payload"]) for v in V["packets"]}
    reset = parse_control(by_name["RESET from host, version 8, session 0x5E551011, next id 1"])
    assert (reset.code, reset.version, reset.session, reset.next_id) == (
        ControlCode.RESET,
        8,
        0x5E551011,
        1,
    )
    assert reset.version == PROTOCOL_VERSION
    name = "COMMAND version 8: Pose of six digital outputs (pins 2..7; 2, 4, 6 high), message id 3"
    pose = parse_in(by_name[name])
    assert (pose.message_id, len(pose.pose.items)) == (3, 0)
    assert (pose.pose.digital_pins, pose.pose.digital_levels) == (b"\xfc", b"\x54")
    assert (pins_in(pose.pose.digital_pins), pins_in(pose.pose.digital_levels)) == (
        [2, 3, 4, 5, 6, 7],
        [2, 4, 6],
    )
    wire = next(bytes.fromhex(v["wire"]) for v in V["packets"] if v["name"] == name)
    assert len(wire) == 17  # a byte more than version 6's uint32 masks for these pins
    mega = parse_in(
        by_name["COMMAND version 8: Pose of a Mega's pins 40 and 69 (69 high), message id 4"]
    )
    assert (pins_in(mega.pose.digital_pins), pins_in(mega.pose.digital_levels)) == ([40, 69], [69])
    assert len(mega.pose.digital_pins) == 9  # the schema's bound: the Mega's 70 pins
    assert (
        mega.SerializeToString()
        == by_name["COMMAND version 8: Pose of a Mega's pins 40 and 69 (69 high), message id 4"]
    )
