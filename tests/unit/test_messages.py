"""messages.parse_out and serialize_out: the short Ack (protocol version 5) both ways."""

from __future__ import annotations

from protoduino._generated import protoduino_pb2 as pb
from protoduino.messages import parse_in, parse_out, pin_set, pose_refused, serialize_out


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


def test_pose_refused_counts_the_items_then_the_mask_pins_upwards() -> None:
    pose = pb.Pose(
        digital_pins=pin_set((1 << 13) | (1 << 4) | (1 << 19)), digital_levels=pin_set(1 << 13)
    )
    pose.items.add().servo.pin = 9
    pose.items.add().pwm.pin = 11
    named = [pose_refused(pose, n) for n in range(6)]
    assert named[0] is None  # no output named (failsafe, interlock, a stray level bit)
    assert named[1] == pb.ServoControl(pin=9)
    assert named[2] == pb.PwmControl(pin=11)
    assert named[3] == pb.DigitalControl(pin=4, level=False)
    assert named[4] == pb.DigitalControl(pin=13, level=True)
    assert named[5] == pb.DigitalControl(pin=19, level=False)
    assert pose_refused(pose, 6) is None


def test_compact_pose_on_the_wire() -> None:
    """Six digital outputs in the pin sets: 10 bytes of payload (17 on the wire), where six
    DigitalControl items took 40 to 52 (47 to 59)."""
    msg = pb.ArduinoIn(message_id=3)
    msg.pose.digital_pins = pin_set(0xFC)
    msg.pose.digital_levels = pin_set(0x54)
    payload = msg.SerializeToString()
    assert payload == bytes.fromhex("080332061201fc1a0154")
    assert parse_in(payload) == msg
    items = pb.ArduinoIn(message_id=3)
    for pin in range(2, 8):
        items.pose.items.add().digital.pin = pin  # all low: the shortest form
    assert len(items.SerializeToString()) == 40
