"""A Pose's digital masks (protocol version 6) at the pins, on both boards.

The host puts a pose's digital outputs in ``Pose.digital_pins`` / ``digital_levels``; the
device checks every one of them (after the items, upwards) before it applies any. The
verdicts are the boards' traces: what each pin did, on the board's own clock.
"""

from __future__ import annotations

import functools

import protoduino
import pytest
from protoduino import Board
from protoduino.messages import Status
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, pin_values, wait_for_pin

LEDS = (2, 3, 4, 7, 8, 12)


def us(degrees: int) -> int:
    return 544 + degrees * (2400 - 544) // 180


def ends_with(want: int, values: list[int]) -> bool:
    return bool(values) and values[-1] == want


def ends_near(want: int, values: list[int]) -> bool:
    return bool(values) and abs(values[-1] - want) <= PULSE_TOLERANCE_US


def test_compact_pose_sets_every_pin(sim_board: SimBoard) -> None:
    """Six digital outputs and a servo in one pose: every pin ends at its value, and a pin
    set low is never driven high on the way."""
    with Board.open(sim_board.port) as board:
        servo = board.servo(9)
        leds = [board.digital_output(pin) for pin in LEDS]
        wait_for_pin(sim_board, 9, functools.partial(ends_near, us(90)))
        for round_, levels in enumerate([(1, 0, 1, 1, 0, 1), (0, 1, 0, 0, 1, 0)]):
            targets: dict[protoduino.board.PoseOutput, int] = dict(zip(leds, levels, strict=True))
            targets[servo] = 30 + 60 * round_
            board.pose(targets)
            for led, level in zip(leds, levels, strict=True):
                wait_for_pin(sim_board, led.pin, functools.partial(ends_with, level))
            wait_for_pin(sim_board, 9, functools.partial(ends_near, us(30 + 60 * round_)))
        trace = sim_board.trace()
        # Pins 8 and 2 (low, then high; high, then low): exactly one change each way.
        assert pin_values(trace, 8)[-2:] == [0, 1] and 1 not in pin_values(trace, 8)[:-1]
        assert pin_values(trace, 2)[-2:] == [1, 0] and pin_values(trace, 2).count(1) == 1
        assert [led.value for led in leds] == [False, True, False, False, True, False]


def test_refused_compact_pose_changes_no_pin(sim_board: SimBoard) -> None:
    """The fifth pin of the mask is no digital output on the device: the device refuses the
    pose at it (refused_item 1 + 5, after the servo item) and no pin moves, not the four
    pins below it nor the servo."""
    with Board.open(sim_board.port) as board:
        servo = board.servo(9)
        leds = [board.digital_output(pin) for pin in (2, 3, 4, 7)]
        marker = board.digital_output(12)
        stranger = protoduino.DigitalOutput(board, 8)  # never configured on the device
        wait_for_pin(sim_board, 9, functools.partial(ends_near, us(90)))
        targets: dict[protoduino.board.PoseOutput, int] = {led: 1 for led in leds}
        targets[stranger] = 1
        targets[servo] = 0
        with pytest.raises(protoduino.CommandRejectedError) as info:
            board.pose(targets)
        assert info.value.output is stranger and info.value.sent
        assert info.value.status == Status.STATUS_NOT_INITIALISED
        marker.on()  # once pin 12 shows it, the pose's moment has passed
        wait_for_pin(sim_board, 12, functools.partial(ends_with, 1))
        trace = sim_board.trace()
        for pin in (2, 3, 4, 7, 8):
            assert 1 not in pin_values(trace, pin), f"pin {pin}: {pin_values(trace, pin)}"
        assert all(abs(v - us(0)) > 10 for v in pin_values(trace, 9))
        assert [led.value for led in leds] == [False] * 4
