"""Bad input from the host side, through the public API only: what the other suites leave out.

test_board_fake.py and test_board_sim.py cover the range checks and their
statuses (host and device agree); test_sim_e2e.py covers malformed commands on
the wire. Here: values of the wrong type for every argument, options that make
no sense, every call on a closed board, and the device's own refusals reaching
the API (``sent=True``) when the host's view is stale: the device kept an
earlier session's configuration, or a Servo object outlived its pin's re-Init.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import protoduino
import protoduino_dev  # noqa: F401  (registers faulty://, which the bad-URL cases use)
import pytest
from protoduino import Board
from protoduino.commands import SERVO
from protoduino.messages import Status
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice
from simfixtures import pins_for

WRONG_TYPES: list[tuple[str, Callable[[Board], object]]] = [
    ("servo pin bool", lambda b: b.servo(True)),
    ("servo pin float", lambda b: b.servo(9.0)),  # type: ignore[arg-type]
    ("servo pin None", lambda b: b.servo(None)),  # type: ignore[arg-type]
    ("servo safe str", lambda b: b.servo(9, safe="90")),  # type: ignore[arg-type]
    ("servo safe float", lambda b: b.servo(9, safe=90.0)),  # type: ignore[arg-type]
    ("servo safe_us str", lambda b: b.servo(9, safe_us="1500")),  # type: ignore[arg-type]
    ("servo min_us float", lambda b: b.servo(9, min_us=1000.5)),  # type: ignore[arg-type]
    ("servo max_us None", lambda b: b.servo(9, max_us=None)),  # type: ignore[arg-type]
    ("digital pin str", lambda b: b.digital_output("13")),  # a digit string is no pin name
    ("digital pin float", lambda b: b.digital_output(13.0)),  # type: ignore[arg-type]
    ("digital safe str", lambda b: b.digital_output(13, safe="no")),  # type: ignore[arg-type]
    ("digital safe None", lambda b: b.digital_output(13, safe=None)),  # type: ignore[arg-type]
    ("ping payload str", lambda b: b.ping("abc")),  # type: ignore[arg-type]
    ("ping payload int", lambda b: b.ping(5)),  # type: ignore[arg-type]
    ("ping payload list", lambda b: b.ping([1, 2])),  # type: ignore[arg-type]
]


@pytest.mark.parametrize(("why", "action"), WRONG_TYPES, ids=[w[0] for w in WRONG_TYPES])
def test_wrong_types_raise_type_error_and_send_nothing(
    board: Board, fake: PtyDevice, why: str, action: Callable[[Board], object]
) -> None:
    before = len(fake.arrivals())
    with pytest.raises(TypeError):
        action(board)
    assert len(fake.arrivals()) == before


def test_wrong_types_on_output_objects(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    led = board.digital_output(13)
    before = len(fake.arrivals())
    bad: list[Callable[[], None]] = [
        lambda: servo.write(True),  # a bool is no angle
        lambda: servo.write("90"),  # type: ignore[arg-type]
        lambda: servo.write(None),  # type: ignore[arg-type]
        lambda: servo.write_us(b"1500"),  # type: ignore[arg-type]
        lambda: servo.write_us(False),
        lambda: led.write("on"),  # type: ignore[arg-type]
        lambda: led.write(None),  # type: ignore[arg-type]
        lambda: led.write(0.5),  # type: ignore[arg-type]
    ]
    for action in bad:
        with pytest.raises(TypeError):
            action()
    assert len(fake.arrivals()) == before
    led.write(1)  # type: ignore[arg-type]  # an int level is a level
    assert fake.values[13] == 1


@pytest.mark.parametrize("level", [2, -1, 255])
def test_digital_levels_other_than_0_and_1_are_refused(
    board: Board, fake: PtyDevice, level: int
) -> None:
    """bool(2) is True: an int that is not 0 or 1 is refused, not read as "on"."""
    led = board.digital_output(13)
    led.write(0)  # type: ignore[arg-type]
    before = len(fake.arrivals())
    with pytest.raises(protoduino.CommandRejectedError, match="not a level") as info:
        led.write(level)  # type: ignore[arg-type]
    assert info.value.status == Status.STATUS_OUT_OF_RANGE and not info.value.sent
    with pytest.raises(protoduino.CommandRejectedError, match="not a level"):
        board.digital_output(12, safe=level)  # type: ignore[arg-type]
    assert len(fake.arrivals()) == before
    assert fake.values[13] == 0


@pytest.mark.parametrize(
    "options",
    [{"ack_timeout": 0}, {"ack_timeout": -1.0}, {"max_retries": -1}, {"window": 0}],
    ids=str,
)
def test_nonsense_options_are_refused_before_anything_starts(
    fake: PtyDevice, options: dict[str, Any]
) -> None:
    with pytest.raises(ValueError, match="required"):
        Board.open(fake.port, **options)
    assert not fake.arrivals() and fake.resets == 0  # the port was never even opened


@pytest.mark.parametrize(
    ("url", "text"),
    [
        ("faulty://{port}?ber=2", "must be a probability"),
        ("faulty://{port}?nonsense=1", "unknown faulty:// parameter"),
        ("faulty://?ber=0.1", "needs an inner URL"),
        ("nosuchscheme://x", "cannot open"),
    ],
)
def test_bad_urls_are_transport_errors(fake: PtyDevice, url: str, text: str) -> None:
    with pytest.raises(protoduino.TransportError, match=text):
        Board.open(url.format(port=fake.port), handshake_timeout=0.5)


def test_every_call_on_a_closed_board_raises_board_closed(fake: PtyDevice) -> None:
    board = Board.open(fake.port, ping=False)
    servo = board.servo(9)
    led = board.digital_output(13)
    board.close()
    before = len(fake.arrivals())
    calls: list[Callable[[], object]] = [
        lambda: servo.write(10),
        lambda: servo.write_us(1500),
        led.on,
        led.off,
        lambda: board.servo(10),
        lambda: board.digital_output(12),
        board.ping,
        board.stop,
    ]
    for call in calls:
        with pytest.raises(protoduino.BoardClosedError):
            call()
    assert len(fake.arrivals()) == before


# --- the device's own refusals through the API ---------------------------------------


@pytest.mark.mega
def test_device_refusals_when_the_hosts_view_is_stale(sim_board: SimBoard) -> None:
    """A resumed session keeps the device's outputs: a new Board resuming it does not know them."""
    with Board.open(sim_board.port) as first:
        first.digital_output(13)
        first.servo(9)
        for pin in pins_for(first, SERVO, first.info.max_servos - 1, avoid=(9, 10, 13)):
            first.servo(pin)  # every servo slot the device states (the Uno's 8, the Mega's 24)
        session = first.session
    with Board.open(sim_board.port, session=session) as second:
        with pytest.raises(protoduino.CommandRejectedError) as info:
            second.servo(13)  # the host sees a free pin; the device a digital output
        assert info.value.status == Status.STATUS_PIN_IN_USE and info.value.sent
        with pytest.raises(protoduino.CommandRejectedError) as info:
            second.servo(10)  # the host counts no servo; the device has every slot taken
        assert info.value.status == Status.STATUS_NO_FREE_RESOURCE and info.value.sent
        assert second.stats.rejected == 2
        second.servo(9).write(45)  # re-initialising one of the device's servos is fine
    with Board.open(sim_board.port) as third:  # a new session: the device released them all
        third.servo(13)
        third.servo(10)


@pytest.mark.mega
def test_a_servo_object_outlived_by_a_reinit(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port) as board:
        wide = board.servo(9)  # 544..2400
        board.servo(9, min_us=1000, max_us=2000)  # the same pin, narrower
        with pytest.raises(protoduino.CommandRejectedError) as info:
            wide.write_us(600)  # fine by the old object's limits, not by the device's
        assert info.value.status == Status.STATUS_OUT_OF_RANGE and info.value.sent
        wide.write_us(1500)  # within both
