"""A user's own unit tests of robot logic, written with the public fake (protoduino.testing).

The robot below is what a user writes: a battery monitor on an analog input and an odometer
on a wheel encoder's counter. The tests drive the inputs with the names the simulated boards
use (``set_analog``, ``pulses``, ``set_level``) and judge on the fake's manual clock, which
moves only when a call waits or the test runs it: creating an input costs no time at all.
"""

from __future__ import annotations

import threading

import pytest
from protoduino import Board
from protoduino.errors import CommandRejectedError, InputTimeoutError
from protoduino.messages import Status
from protoduino.testing import VirtualDevice

#: The robot's figures: a 2:1 divider on a 2S pack, 5 V reference; 20 edges a turn.
VOLTS_PER_COUNT = 5.0 / 1023 * 2
LOW_BATTERY_V = 7.0
EDGES_PER_TURN = 20
WHEEL_M_PER_TURN = 0.2


class Robot:
    """What a user's own code looks like: it only calls the board's API."""

    def __init__(self, board: Board) -> None:
        self.battery = board.analog_input(14, threshold=2)
        self.wheel = board.counter(2)
        self.drive = board.pwm_output(3, safe=0)

    def battery_volts(self) -> float:
        counts = self.battery.read()
        assert counts is not None
        return counts * VOLTS_PER_COUNT

    def distance_m(self) -> float:
        edges = self.wheel.read()
        assert edges is not None
        return edges / EDGES_PER_TURN * WHEEL_M_PER_TURN

    def step(self) -> None:
        """Drive on unless the battery is low."""
        self.drive.write(0 if self.battery_volts() < LOW_BATTERY_V else 180)


def test_battery_and_encoder_logic_on_the_fake_and_its_manual_clock() -> None:
    device = VirtualDevice()
    threads = set(threading.enumerate())
    start = device.clock()
    with device.open_board(ping=False) as board:
        assert set(threading.enumerate()) == threads  # no port, no thread
        device.set_analog(14, 800)  # before the Init: the first report carries it
        robot = Robot(board)
        assert device.clock() == start  # every input's first value came with its Ack
        assert robot.battery.read() == 800 and robot.wheel.read() == 0
        robot.step()
        assert device.values[3] == 180  # 7.8 V: drive
        device.pulses(2, 30)
        device.pulses(2, 10)
        assert robot.distance_m() == pytest.approx(0.4)  # two turns
        device.set_analog(14, 700)  # 6.8 V
        robot.step()
        assert device.values[3] == 0
        assert [m.pwm_control.duty for m in device.commands("pwm_control")] == [180, 0]
    assert device.clock() == start


def test_an_encoder_on_a_pin_without_a_counter_is_refused_as_the_uno_refuses() -> None:
    device = VirtualDevice()
    with device.open_board(ping=False) as board:
        with pytest.raises(CommandRejectedError) as refused:
            board.counter(14)  # the Uno counts on the digital pins 2..13 only
        assert refused.value.status == Status.STATUS_NOT_SUPPORTED
        board.counter(2)
        board.counter(7)  # a pin-change interrupt's
        assert [pin for pin, mode in device.pins.items() if mode == "counter"] == [2, 7]


def test_a_bumper_interlock_stops_the_drive_on_the_device() -> None:
    device = VirtualDevice()
    with device.open_board(ping=False) as board:
        drive = board.pwm_output(3, safe=0)
        board.digital_input(4, pull_up=True, interlock="low")
        drive.write(200)
        device.set_level(4, 0)  # the bumper closes: every output safe, latched
        assert device.values == {} and device.latched == 4
        with pytest.raises(CommandRejectedError) as refused:
            drive.write(200)
        assert refused.value.status == Status.STATUS_INTERLOCK_ACTIVE
        device.set_level(4, 1)
        board.clear_interlock()
        drive.write(120)
        assert device.values == {3: 120}


def test_a_lost_first_report_costs_one_round_time_on_the_fake_clock_not_the_wall() -> None:
    device = VirtualDevice()
    with device.open_board(ping=False) as board:
        device.handler = lambda msg: device.default_reply(msg)[:1]  # the Ack, no report
        start = device.clock()
        wheel = board.counter(2)
        assert device.clock() - start == pytest.approx(board.round_time)
        assert wheel.read() is None  # until the next report
        device.handler = device.default_reply
        device.pulses(2, 3)
        assert wheel.read() == 3


def test_pulses_count_as_the_simulated_boards_count_them() -> None:
    """SimBoard.pulses(pin, count, hz): each pulse leaves the level and comes back, so a
    counter of both edges counts two a pulse; the fake takes the same call."""
    device = VirtualDevice()
    with device.open_board(ping=False) as board:
        rising = board.counter(2)
        both = board.counter(3, edge="both")
        device.pulses(2, 5, 100)
        device.pulses(3, 5, 100)
        assert (rising.read(), both.read()) == (5, 10)


def test_an_inputs_age_is_read_on_the_fakes_clock() -> None:
    """A robot that distrusts a stale battery value: the age is the board's clock's, so a
    test moves it with the device's clock."""
    device = VirtualDevice()
    with device.open_board(ping=False) as board:
        battery = board.analog_input(14)
        assert battery.age == 0.0
        device.run(2.5)  # nothing reported for 2.5 s (the fake sends no analog heartbeat)
        assert battery.age == pytest.approx(2.5)
        device.set_analog(14, 600)
        assert battery.age == 0.0


def test_an_inputs_wait_for_waits_on_the_fakes_clock() -> None:
    """A robot that waits for its button with a timeout: the wait runs the fake's clock, so
    its timeout is exact and costs no wall time."""
    device = VirtualDevice()
    with device.open_board(ping=False) as board:
        button = board.digital_input(7, pull_up=True)
        assert button.wait_for(True, timeout=5.0) is True  # already: at once
        start = device.clock()
        with pytest.raises(InputTimeoutError):
            button.wait_for(False, timeout=5.0)
        assert device.clock() - start == pytest.approx(5.0)  # the manual clock ran
