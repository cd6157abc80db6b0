"""Readback: every output object knows the value the device last acknowledged."""

from __future__ import annotations

import protoduino
import pytest
from protoduino import Board
from protoduino.messages import ArduinoOut, Status
from protoduino.testing import PtyDevice, ack

BOUND = 5.0


def test_last_acknowledged_values(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9, safe=90, min_us=1000, max_us=2000)
    assert servo.value == 1500  # the safe width, from the Init
    servo.write(45)
    assert servo.value == 1000 + 45 * 1000 // 180 == servo.to_us(45)
    servo.write_us(1234)
    assert servo.value == 1234
    narrow = board.servo(10, safe_us=1111)
    assert narrow.value == 1111
    led = board.digital_output(13, safe=True)
    assert led.value is True
    led.off()
    assert led.value is False
    # A future's value is recorded before the future resolves.
    future = servo.submit(180)
    future.result(BOUND)
    assert servo.value == 2000
    board.stop()
    assert (servo.value, narrow.value, led.value) == (1500, 1111, True)


def test_refused_value_is_not_recorded(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    servo.write(10)
    before = servo.value
    fake.handler = lambda msg: [ack(msg.message_id, Status.STATUS_OUT_OF_RANGE)]
    with pytest.raises(protoduino.CommandRejectedError):
        servo.write(20)
    with pytest.raises(protoduino.CommandRejectedError):
        servo.write(181)  # refused on the host
    assert servo.value == before


def test_failsafe_makes_values_safe(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9, safe=0)
    servo.write(90)
    led = board.digital_output(13)
    led.on()
    out = ArduinoOut()
    out.failsafe.active = True
    out.failsafe.cause = 1  # type: ignore[assignment]
    fake.send_data(out)
    assert fake.wait_for(lambda: servo.value == 544, BOUND)
    assert led.value is False


def test_value_of_a_replaced_configuration(board: Board) -> None:
    servo = board.servo(9)
    board.servo(9, safe=0)
    assert servo.value == 544  # the same pin, still a servo: the board's latest knowledge
    led = board.digital_output(13)
    assert led.value is False
    assert protoduino.Servo(board, 13, 544, 2400).value is None  # pin 13 is no servo
