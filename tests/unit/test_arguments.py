"""Board.open's options and the servo's values (issue 20, items 7 and 14), on the fake device.

A wrong option is refused with an error of protoduino's tree before any thread starts
(``session=1.5`` once crashed the I/O thread with ``struct.error`` and surfaced as a
HandshakeError blaming the firmware); a number of seconds or degrees may be any real number.
"""

from __future__ import annotations

import math
import threading
from decimal import Decimal
from fractions import Fraction
from typing import Any

import numpy as np
import protoduino
import pytest
from protoduino import Board, Event, EventKind
from protoduino.messages import ArduinoOut, Status
from protoduino.testing import PtyDevice


@pytest.mark.parametrize(
    ("options", "error"),
    [
        ({"session": 1.5}, protoduino.ArgumentTypeError),
        ({"session": True}, protoduino.ArgumentTypeError),
        ({"session": "7"}, protoduino.ArgumentTypeError),
        ({"session": 0}, protoduino.ArgumentError),
        ({"session": 2**32}, protoduino.ArgumentError),
        ({"failsafe_timeout": True}, protoduino.ArgumentTypeError),
        ({"failsafe_timeout": "1"}, protoduino.ArgumentTypeError),
        ({"failsafe_timeout": math.nan}, protoduino.ArgumentError),
        ({"failsafe_timeout": math.inf}, protoduino.ArgumentError),
        ({"failsafe_timeout": Decimal("0.0994")}, protoduino.ArgumentError),
        ({"failsafe_timeout": 61}, protoduino.ArgumentError),
        ({"liveness": "pong"}, protoduino.ArgumentError),
        ({"restore": "first"}, protoduino.ArgumentError),
    ],
)
def test_wrong_options_are_refused_before_any_thread(
    fake: PtyDevice, options: dict[str, Any], error: type[Exception]
) -> None:
    before = set(threading.enumerate())
    with pytest.raises(error) as info:
        Board.open(fake.port, ping=False, **options)
    assert isinstance(info.value, protoduino.ProtoduinoError)
    assert not isinstance(info.value, protoduino.LinkError)  # nothing blames the firmware
    assert set(threading.enumerate()) <= before
    assert fake.arrivals() == []  # nothing was sent
    with Board.open(fake.port, ping=False) as board:  # the port was not even held
        assert board.stats.state == "active"


@pytest.mark.parametrize(
    ("timeout", "ms"),
    [(Decimal("0.1"), 100), (Fraction(1, 2), 500), (np.float32(0.25), 250), (60, 60000)],
)
def test_failsafe_timeout_is_any_real_number(fake: PtyDevice, timeout: object, ms: int) -> None:
    with Board.open(fake.port, ping=False, failsafe_timeout=timeout) as board:  # type: ignore[arg-type]
        assert board.failsafe_timeout == ms / 1000
    sent = fake.arrivals("configure_failsafe")
    assert [r.msg.configure_failsafe.timeout_ms for r in sent] == [ms]


def _failsafe_event(fake: PtyDevice, board: Board) -> Event:
    seen: list[Event] = []
    done = threading.Event()

    def record(event: Event) -> None:
        if event.kind is EventKind.FAILSAFE:
            seen.append(event)
            done.set()

    board.on_event(record)
    msg = ArduinoOut()
    msg.failsafe.active = True
    msg.failsafe.cause = 1  # type: ignore[assignment]  # FAILSAFE_CAUSE_PING_TIMEOUT on the wire
    fake.send_data(msg)
    assert done.wait(30.0), "no FAILSAFE event"
    return seen[0]


def test_a_heartbeat_failsafe_is_named_for_the_heartbeat(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False, liveness="heartbeat") as board:
        event = _failsafe_event(fake, board)
    assert event.details == {"active": True, "cause": "heartbeat_timeout", "epoch": 0}
    assert "ping" not in event.text


def test_a_ping_failsafe_keeps_its_name(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False) as board:
        event = _failsafe_event(fake, board)
    assert event.details == {"active": True, "cause": "ping_timeout", "epoch": 0}


@pytest.mark.parametrize(
    ("degrees", "sent"),
    [
        (45.0, 45),
        (45.4, 45),
        (45.6, 46),
        (44.5, 44),  # a half goes to the even degree
        (45.5, 46),
        (Fraction(91, 2), 46),
        (Decimal("44.5"), 44),
        (Decimal("149.9"), 150),
        (np.float64(12.3), 12),
        (np.float32(12.7), 13),
        (np.int16(30), 30),
    ],
)
def test_servo_write_takes_real_numbers(
    board: Board, fake: PtyDevice, degrees: Any, sent: int
) -> None:
    servo = board.servo(9)
    servo.write(degrees)
    assert fake.values[9] == sent
    assert servo.value == servo.to_us(sent)
    board.pose({servo: degrees + 1})
    assert fake.values[9] == round(degrees + 1)
    servo.submit(degrees).result(timeout=30)
    assert fake.values[9] == sent


def test_servo_write_us_rounds_to_the_microsecond(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    servo.write_us(1500.5)  # half to even
    assert fake.values[9] == 1500
    servo.submit_us(Decimal("1501.5")).result(timeout=30)
    assert fake.values[9] == 1502


def test_servo_refuses_what_has_no_nearest_degree(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    before = len(fake.arrivals())
    for value in (math.nan, math.inf, -math.inf, Decimal("NaN"), 180.6, -0.6):
        with pytest.raises(protoduino.CommandRejectedError) as info:
            servo.write(value)
        assert info.value.status == Status.STATUS_OUT_OF_RANGE and not info.value.sent
    for wrong in (True, "45", None, 45j):
        with pytest.raises(protoduino.ArgumentTypeError):
            servo.write(wrong)  # type: ignore[arg-type]
    assert len(fake.arrivals()) == before


def test_pins_by_their_board_names(board: Board, fake: PtyDevice) -> None:
    """ "A0".."A5" are the device's own analog pins in its table's order (14..19 here, as on
    the Uno), wherever a method takes a pin; a name it lacks is a pin it does not have."""
    assert board.pin_number("A0") == 14 and board.pin_number("a5") == 19
    assert board.analog_input("A1").pin == 15
    assert fake.arrivals("analog_input_init")[-1].msg.analog_input_init.pin == 15
    assert board.digital_output("A2").pin == 16
    assert fake.arrivals("digital_init")[-1].msg.digital_init.pin == 16
    board.release("A2")
    assert fake.arrivals("release")[-1].msg.release.pin == 16
    before = len(fake.arrivals())
    with pytest.raises(protoduino.CommandRejectedError) as missing:
        board.servo("A6")
    assert missing.value.status == Status.STATUS_INVALID_PIN and not missing.value.sent
    assert "pin A6 does not exist (its analog pins by name: A0..A5)" in str(missing.value)
    with pytest.raises(TypeError):
        board.digital_input("D3")
    assert len(fake.arrivals()) == before
