"""The line rate's CONTROL payloads (docs/protocol.md 5, *Line rate*): RESET_ACK's rate flags,
BAUD_SET and BAUD_ACK, as the host builds and parses them (the firmware's side: tests/c)."""

from __future__ import annotations

import pytest
from protoduino.constants import (
    FAST_BAUDRATES,
    RESET_ACK_BAUD_1M,
    RESET_ACK_BAUD_250K,
    RESET_ACK_BAUD_500K,
    ControlCode,
)
from protoduino.errors import ProtocolError
from protoduino.packets import baud_payload, parse_control, reset_ack_payload


def test_reset_ack_flags_offer_the_rates_fastest_first() -> None:
    payload = reset_ack_payload(4, 0x12345678, 7, resumed=True, baudrates=(250_000, 500_000))
    assert payload[-1] == 0x01 | RESET_ACK_BAUD_250K | RESET_ACK_BAUD_500K
    ctl = parse_control(payload)
    assert ctl.resumed is True and ctl.baudrates == (500_000, 250_000)
    assert parse_control(reset_ack_payload(4, 1, 7, baudrates=FAST_BAUDRATES)).baudrates == (
        1_000_000,
        500_000,
        250_000,
    )
    assert 1 << (FAST_BAUDRATES.index(1_000_000) + 1) == RESET_ACK_BAUD_1M


def test_a_reset_ack_without_rate_flags_offers_none() -> None:
    assert parse_control(reset_ack_payload(4, 1, 7)).baudrates == ()


@pytest.mark.parametrize("code", [ControlCode.BAUD_SET, ControlCode.BAUD_ACK])
@pytest.mark.parametrize("rate", [0, 250_000, 500_000, 1_000_000])
def test_baud_payloads_round_trip(code: ControlCode, rate: int) -> None:
    payload = baud_payload(code, rate)
    assert payload == bytes((code,)) + rate.to_bytes(4, "big")
    ctl = parse_control(payload)
    assert (ctl.code, ctl.baudrate) == (code, rate)
    assert ctl.to_json()["baudrate"] == rate


def test_a_baud_payload_of_another_length_is_refused() -> None:
    with pytest.raises(ProtocolError, match="4 argument bytes"):
        parse_control(bytes((ControlCode.BAUD_SET, 0, 1)))
