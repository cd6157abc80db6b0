"""CONTROL payloads and packet-building errors."""

from __future__ import annotations

import pytest
from protoduino.constants import ControlCode, EventCode, PacketType
from protoduino.errors import PayloadTooLargeError, ProtocolError
from protoduino.packets import (
    Control,
    build_packet,
    event_payload,
    parse_control,
    reset_ack_payload,
    reset_payload,
)


def test_control_round_trips() -> None:
    assert parse_control(reset_payload(1)) == Control(ControlCode.RESET, version=1)
    assert parse_control(reset_ack_payload(1, 0xDEADBEEF)) == Control(
        ControlCode.RESET_ACK, version=1, schema_id=0xDEADBEEF
    )
    with pytest.raises(ProtocolError, match="unknown CONTROL code 0x02"):
        parse_control(b"\x02")  # HEARTBEAT until version 3: unassigned since
    assert parse_control(event_payload(EventCode.DESYNC, b"\x07")) == Control(
        ControlCode.EVENT, event=EventCode.DESYNC, detail=b"\x07"
    )


def test_unknown_event_code_is_kept_for_logging() -> None:
    c = parse_control(event_payload(0x42))
    assert c.event == 0x42
    assert c.to_json() == {"code": "EVENT", "event": 0x42}


@pytest.mark.parametrize(
    "payload",
    [b"", b"\x09", b"\x00", b"\x00\x01\x02", b"\x01\x01\x00\x00", b"\x02\x00", b"\x03"],
)
def test_malformed_control_raises_protocol_error(payload: bytes) -> None:
    with pytest.raises(ProtocolError):
        parse_control(payload)


def test_payload_over_max_is_refused_at_the_sender() -> None:
    build_packet(PacketType.COMMAND, 0, bytes(255))
    with pytest.raises(PayloadTooLargeError, match="MAX_PAYLOAD"):
        build_packet(PacketType.COMMAND, 0, bytes(256))
