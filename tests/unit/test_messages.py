"""messages.parse_out and serialize_out: the short Ack (protocol version 5) both ways."""

from __future__ import annotations

from protoduino._generated import protoduino_pb2 as pb
from protoduino.messages import parse_out, serialize_out


def _long_ack(mid: int) -> pb.ArduinoOut:
    out = pb.ArduinoOut()
    out.ack.message_id = mid
    return out


def test_every_short_ack_reads_as_the_long_ack_it_stands_for() -> None:
    for mid in range(128):
        short = pb.ArduinoOut()
        short.ack_ok = mid
        payload = short.SerializeToString()
        assert len(payload) == 2 and payload[0] == 0x38  # field 7, varint; one byte of id
        assert parse_out(payload) == _long_ack(mid)
        if mid:
            assert serialize_out(_long_ack(mid)) == payload


def test_a_short_ack_of_a_wider_id_still_reads_as_its_long_ack() -> None:
    """Not what a device sends (ids are 1..127), but the schema allows it: the general path."""
    short = pb.ArduinoOut()
    short.ack_ok = 300
    assert parse_out(short.SerializeToString()) == _long_ack(300)


def test_an_ack_with_more_than_its_id_keeps_the_long_form() -> None:
    out = _long_ack(9)
    out.ack.status = pb.STATUS_INVALID_PIN
    assert serialize_out(out) == out.SerializeToString()
    assert parse_out(out.SerializeToString()) == out
