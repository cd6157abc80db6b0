"""protoduino.testing: a Board on an in-process device, as a user's own tests would use it.

No port, no pty, no thread: each test checks that no thread started, and times are read on
the device's clock, which moves only when a call waits or the test runs it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future

import pytest
from protoduino import Board, Event, EventKind
from protoduino._generated import protoduino_pb2 as pb
from protoduino.constants import ACK_TIMEOUT, MAX_RETRIES, PING_INTERVAL
from protoduino.errors import AckTimeoutError, CommandRejectedError
from protoduino.messages import ArduinoIn, Status
from protoduino.testing import DedupeWindow, VirtualDevice


@pytest.fixture
def device() -> Iterator[VirtualDevice]:
    yield VirtualDevice()


def sent(device: VirtualDevice, kind: str) -> int:
    return len(device.arrivals(kind))


def test_a_board_opens_and_its_commands_reach_the_device(device: VirtualDevice) -> None:
    start = device.clock()
    threads = set(threading.enumerate())
    with device.open_board(ping=False) as board:
        assert set(threading.enumerate()) == threads  # no I/O thread, no event thread
        assert isinstance(board, Board) and board.info.board == "virtual"
        arm = board.servo(9, safe=90)
        arm.write(45)
        led = board.digital_output(13)
        led.on()
        assert device.last("servo_control").servo_control.degrees == 45
        assert device.last("digital_control").digital_control.level is True
        assert [m.servo_init.pin for m in device.commands("servo_init")] == [9]
    assert device.clock() == start  # every answer came at once: no time passed
    assert not device.connected


def test_an_input_the_device_drives_is_read_at_once(device: VirtualDevice) -> None:
    with device.open_board(ping=False) as board:
        button = board.digital_input(7, pull_up=True)
        assert button.read() is True
        device.set_level(7, 0)
        assert button.read() is False


def test_callbacks_and_futures_run_when_time_passes(device: VirtualDevice) -> None:
    with device.open_board(ping=False) as board:
        events: list[Event] = []
        board.on_event(events.append)
        servo = board.servo(3)
        future: Future[None] = servo.submit(120)
        device.run(0)
        assert future.done() and future.result() is None
        device.reboot()
        device.run(0.5)
        assert EventKind.REBOOTED in [e.kind for e in events]
        assert [m.servo_init.pin for m in device.commands("servo_init")] == [3, 3]  # restored


def test_a_lost_ack_costs_exactly_one_ack_timeout(device: VirtualDevice) -> None:
    with device.open_board(ping=False) as board:
        servo = board.servo(9)
        device.lose = 1
        start = device.clock()
        servo.write(30)
        assert device.clock() - start == pytest.approx(ACK_TIMEOUT)
        assert sent(device, "servo_control") == 2
        assert len(device.commands("servo_control")) == 1  # the dedupe window held it
        assert board.stats.retransmits == 1


def test_a_silent_device_fails_the_call_at_its_bound(device: VirtualDevice) -> None:
    with device.open_board(ping=False) as board:
        servo = board.servo(9)
        device.silent = True
        start = device.clock()
        with pytest.raises(AckTimeoutError):
            servo.write(30)
        assert device.clock() - start == pytest.approx(ACK_TIMEOUT * (MAX_RETRIES + 1))


def test_the_automatic_ping_keeps_its_interval(device: VirtualDevice) -> None:
    with device.open_board() as board:
        assert board.pinging
        first = sent(device, "ping")
        device.run(PING_INTERVAL * 3)
        assert sent(device, "ping") == first + 3


def failsafes(events: list[Event]) -> list[tuple[bool, str, int]]:
    return [
        (e.details["active"], e.details["cause"], e.details["epoch"])
        for e in events
        if e.kind is EventKind.FAILSAFE
    ]


def test_the_failsafe_fires_at_its_timeout_and_a_liveness_message_clears_it(
    device: VirtualDevice,
) -> None:
    with device.open_board(ping=False, failsafe_timeout=0.5) as board:
        events: list[Event] = []
        board.on_event(events.append)
        servo = board.servo(9, safe=90)
        servo.write(30)
        start = device.clock()
        device.run(0.5)  # silence: the timer restarted by ConfigureFailsafe runs out
        assert device.failsafe_active and device.failsafe_epoch == 1
        assert failsafes(events) == [(True, "ping_timeout", 1)]
        assert device.clock() - start == pytest.approx(0.5)
        with pytest.raises(CommandRejectedError) as refused:
            servo.write(40)  # no timer behind a value
        assert refused.value.status == Status.STATUS_FAILSAFE_EXPIRED
        board.ping()  # carries epoch 1, which the host heard: re-armed
        device.run(0)
        assert not device.failsafe_active
        assert failsafes(events)[-1] == (False, "none", 1)  # the board names no cause on clear
        servo.write(40)
        assert device.last("servo_control").servo_control.degrees == 40


def test_a_liveness_message_of_an_older_epoch_re_arms_nothing(device: VirtualDevice) -> None:
    with device.open_board(ping=False, failsafe_timeout=0.5, liveness="heartbeat") as board:
        events: list[Event] = []
        board.on_event(events.append)
        device.run(0.4)
        device.lose = 1  # the failsafe's event is lost on the way
        device.run(0.2)
        assert device.failsafe_active and failsafes(events) == []
        board.heartbeat()  # written with epoch 0: it counts for nothing ...
        device.run(0)
        assert device.failsafe_active
        # ... but its Ack told the host of the failsafe, once, and its epoch
        assert failsafes(events) == [(True, "heartbeat_timeout", 1)]
        board.heartbeat()  # now with epoch 1
        device.run(0)
        assert not device.failsafe_active
        assert failsafes(events)[-1] == (False, "none", 1)


def test_a_stop_is_a_failsafe_of_its_own_epoch(device: VirtualDevice) -> None:
    with device.open_board(ping=False) as board:
        events: list[Event] = []
        board.on_event(events.append)
        servo = board.servo(9)
        board.stop()
        device.run(0)
        assert failsafes(events) == [(True, "stop", 1)]
        servo.write(20)  # the timer still runs: a Control after a Stop is protected, not refused
        assert device.last("servo_control").servo_control.degrees == 20


def _recorded(window: DedupeWindow, ids: list[int], newest: int) -> None:
    """Commands ``ids`` executed in that order (OK), then a Ping of id ``newest``."""
    for mid in ids:
        assert window.lookup(mid) is None
        window.done(mid, Status.STATUS_OK)
    window.done(newest, None)


def test_dedupe_window_overflow_evicts_slot_next_as_the_firmware() -> None:
    """tests/c/test_dispatch.c's test_dedupe_full_window_evicts_slot_next, step for step:
    with the slots out of insertion order, a full window overwrites slot ``next``, not the
    entry inserted first."""
    window = DedupeWindow()
    window.sync(1, clear=True)  # N = 127
    # Id 2, then 1 (its first transmission lost), then 3..16: slots 0..15, next 0, N 16.
    _recorded(window, [2, 1, *range(3, 17)], newest=16)
    assert window.ids == [2, 1, *range(3, 17)] and window.next == 0
    window.done(17, None)  # a Ping: N 17, id 1 (16 back) dropped: slot 1 free
    assert window.ids[1] == 0 and window.newest == 17
    window.done(17, Status.STATUS_OK)  # a command under 17 takes the free slot after next
    assert window.ids == [2, 17, *range(3, 17)] and window.next == 2
    # An id out of reach (44 behind N: no repeat, and N stays) with the window full: the
    # firmware overwrites slot 2 (id 3); the id inserted first (2) stays.
    assert window.lookup(100) is None
    window.done(100, Status.STATUS_NOT_INITIALISED)
    assert window.newest == 17 and window.next == 3
    assert window.ids == [2, 17, 100, *range(4, 17)]
    assert window.lookup(2) == Status.STATUS_OK and window.lookup(3) is None


def test_dedupe_window_lookup_changes_nothing_and_every_id_moves_n() -> None:
    window = DedupeWindow()
    window.sync(11, clear=True)  # N = 10
    window.done(5, Status.STATUS_OK)  # older: recorded, N stays
    assert window.lookup(5) == Status.STATUS_OK and window.newest == 10
    assert window.lookup(40) is None and window.newest == 10  # a lookup moves nothing
    window.done(40, None)  # not recorded (idempotent, or it did not decode), N moves
    assert window.newest == 40 and window.entries == {}  # 5 fell 35 behind: dropped
    window.done(40 + 64, Status.STATUS_OK)  # 64 ahead: behind, N stays
    assert window.newest == 40 and window.lookup(104) is None  # out of reach


def test_read_outputs_reports_what_the_device_drives(device: VirtualDevice) -> None:
    with device.open_board(ping=False) as board:
        arm = board.servo(9, safe=90)  # 544..2400 us: 90 degrees is 544 + 928 us
        arm.write(45)  # 544 + 45 * 1856 / 180 = 1008 us
        board.servo(10, safe_us=1500, min_us=1000, max_us=2000)
        board.digital_output(13, safe=True)
        motor = board.pwm_output(3, safe=10)
        motor.write(200)
        found = {pin: (s.mode, s.value, s.target) for pin, s in board.read_outputs().items()}
        assert found == {
            3: ("pwm", 200, 200),
            9: ("servo", 1008, 1008),
            10: ("servo", 1500, 1500),
            13: ("digital", 1, 1),
        }
        board.stop()  # every output at its safe value
        safe = {pin: (s.mode, s.value) for pin, s in board.read_outputs().items()}
        assert safe == {3: ("pwm", 10), 9: ("servo", 1472), 10: ("servo", 1500), 13: ("digital", 1)}


def test_the_device_refuses_what_it_would_refuse_after_the_boards_checks(
    device: VirtualDevice,
) -> None:
    """board.request sends a message as given (no host check): the device's own checks."""
    device.features &= ~(1 << pb.FEATURE_COUNTER)  # a firmware built without counters
    with device.open_board(ping=False) as board:
        board.servo(9)

        def refusal(fill: Callable[[ArduinoIn], object]) -> int:
            msg = ArduinoIn()
            fill(msg)
            with pytest.raises(CommandRejectedError) as refused:
                board.request(msg)
            return refused.value.status

        assert refusal(lambda m: m.counter_init.SetInParent()) == Status.STATUS_NOT_SUPPORTED
        assert refusal(lambda m: setattr(m.pwm_init, "pin", 10)) == Status.STATUS_TIMER_IN_USE
        assert refusal(lambda m: setattr(m.pwm_init, "pin", 4)) == Status.STATUS_NOT_SUPPORTED
        assert refusal(lambda m: setattr(m.digital_init, "pin", 9)) == Status.STATUS_PIN_IN_USE
        assert refusal(lambda m: setattr(m.digital_init, "pin", 1)) == Status.STATUS_RESERVED_PIN
        assert refusal(lambda m: setattr(m.digital_init, "pin", 20)) == Status.STATUS_INVALID_PIN
        assert refusal(lambda m: setattr(m.pwm_control, "pin", 3)) == Status.STATUS_NOT_INITIALISED
        assert refusal(lambda m: m.analog_input_init.SetInParent()) == Status.STATUS_RESERVED_PIN
