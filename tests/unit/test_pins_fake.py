"""PWM outputs, inputs and interlocks through the Board API, against the pty fake (PtyDevice).

The fake reports its inputs as the firmware does (the value right after an input's
Init Ack, then on every change), so these tests judge the host alone: its checks
before sending, what it sends, how it decodes reports, the newest-wins delivery and
the restore rules. The same API against the real firmware is tests/e2e/test_pins_sim.py.
"""

from __future__ import annotations

import threading
import time
from decimal import Decimal
from fractions import Fraction
from typing import Any

import protoduino
import pytest
from protoduino import Board, EventKind
from protoduino._generated import protoduino_pb2 as pb
from protoduino.errors import (
    FeatureMissingError,
    InputTimeoutError,
    InterlockActiveError,
    NotSupportedError,
    TimerInUseError,
)
from protoduino.inputs import Reading
from protoduino.messages import ArduinoOut, Status
from protoduino.testing import PtyDevice, ack, mask
from test_board_fake import Recorder


def sent(fake: PtyDevice, kind: str) -> list[Any]:
    return [r.msg for r in fake.arrivals(kind)]


# --- PWM -------------------------------------------------------------------------------


def test_pwm_output_init_write_and_rounding(board: Board, fake: PtyDevice) -> None:
    motor = board.pwm_output(3, safe=10)
    (init,) = sent(fake, "pwm_init")
    assert (init.pwm_init.pin, init.pwm_init.safe_duty) == (3, 10)
    assert fake.pins[3] == "pwm" and motor.value == 10
    motor.write(200)
    assert fake.values[3] == 200 and motor.value == 200
    motor.write(127.5)  # halves go to the even neighbour, as Python's round()
    assert fake.values[3] == 128
    motor.write(128.5)
    assert fake.values[3] == 128
    motor.submit(0.4).result(5)
    assert fake.values[3] == 0 and motor.value == 0
    motor.write(Decimal("99.5"))  # Decimal is no numbers.Real, but a real number all the same
    motor.write(Fraction(401, 2))
    assert [m.pwm_control.duty for m in sent(fake, "pwm_control")][-2:] == [100, 200]


@pytest.mark.parametrize("duty", [256, -1, float("nan"), float("inf"), 255.6])
def test_pwm_duty_out_of_range_is_refused_before_sending(
    board: Board, fake: PtyDevice, duty: float
) -> None:
    motor = board.pwm_output(11)
    before = len(fake.arrivals())
    with pytest.raises(protoduino.CommandRejectedError) as info:
        motor.write(duty)
    assert info.value.status == Status.STATUS_OUT_OF_RANGE and not info.value.sent
    assert len(fake.arrivals()) == before


def test_pwm_argument_types(board: Board) -> None:
    motor = board.pwm_output(11)
    for bad in ("100", True, None, b"\x01"):
        with pytest.raises(TypeError):
            motor.write(bad)  # type: ignore[arg-type]
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pwm_output(10, safe=300)
    assert info.value.status == Status.STATUS_OUT_OF_RANGE


def test_pwm_on_a_pin_without_pwm_is_not_supported(board: Board, fake: PtyDevice) -> None:
    with pytest.raises(NotSupportedError) as info:
        board.pwm_output(4)
    assert info.value.status == Status.STATUS_NOT_SUPPORTED and not info.value.sent
    assert "3, 5, 6, 9, 10, 11" in str(info.value)
    assert not isinstance(info.value, FeatureMissingError)
    assert sent(fake, "pwm_init") == []


@pytest.mark.parametrize(
    ("feature", "configure"),
    [
        ("pwm", lambda b: b.pwm_output(3)),
        ("servo", lambda b: b.servo(9)),
        ("digital_output", lambda b: b.digital_output(13)),
        ("digital_input", lambda b: b.digital_input(2)),
        ("digital_input", lambda b: b.clear_interlock()),
        ("analog_input", lambda b: b.analog_input(14)),
        ("counter", lambda b: b.counter(2)),
    ],
)
def test_a_mode_the_firmware_lacks_is_refused_naming_the_feature(
    fake: PtyDevice, feature: str, configure: Any
) -> None:
    fake.features &= ~(1 << pb.Feature.Value(f"FEATURE_{feature.upper()}"))
    with Board.open(fake.port, ack_timeout=0.1, ping=False) as board:
        assert feature not in board.info.features
        before = len(fake.arrivals())
        with pytest.raises(FeatureMissingError) as info:
            configure(board)
        assert info.value.feature == feature and not info.value.sent
        assert info.value.status == Status.STATUS_NOT_SUPPORTED
        text = str(info.value)
        assert f"FEATURE_{feature.upper()}" in text and "FEATURES" in text
        assert f"PD_FEATURE_{feature.upper()}" in text
        assert len(fake.arrivals()) == before  # nothing sent


def test_device_info_lists_features_and_pins(board: Board) -> None:
    info = board.info
    assert info.features == {
        "servo", "digital_output", "digital_input", "analog_input", "pwm", "counter"
    }  # fmt: skip
    assert info.pwm_pins == (3, 5, 6, 9, 10, 11)
    assert info.analog_pins == (14, 15, 16, 17, 18, 19)
    assert 2 in info.counter_pins


def test_timer1_is_shared_by_servos_and_pwm_on_9_and_10(fake: PtyDevice) -> None:
    with Board.open(fake.port, ack_timeout=0.1, ping=False) as board:
        servo = board.servo(2)
        for pin in (9, 10):
            with pytest.raises(TimerInUseError) as info:
                board.pwm_output(pin)
            assert info.value.status == Status.STATUS_TIMER_IN_USE and not info.value.sent
        board.pwm_output(3)  # Timer2: free
        for pin in (5, 6):  # Timer0: PWM beside the clock, as the Arduino core does it
            board.pwm_output(pin)
        servo.release()
        board.pwm_output(10)
        with pytest.raises(TimerInUseError):
            board.servo(4)
        assert sorted(fake.pins) == [3, 5, 6, 10]


def test_a_board_with_another_pin_table_is_served_with_no_host_edit(fake: PtyDevice) -> None:
    """A board the host has never heard of: its pins and timers come from its DeviceInfo
    (pins, timers) alone, and the host refuses before sending as the device would, naming
    the pin, what it cannot do and why."""
    fake.board_name = "other"
    fake.num_pins = 24
    fake.reserved_pins = [0, 1]
    fake.pwm_pins = [4, 7, 12]
    fake.analog_pins = [20, 21, 22, 23]
    fake.counter_pins = [18]
    fake.servo_timer_pins, fake.servo_timer = [4, 7], 3
    fake.clock_timer_pins, fake.clock_timer = [8], 2
    with Board.open(fake.port, ack_timeout=0.1, ping=False) as board:
        info = board.info
        assert (info.pwm_pins, info.analog_pins, info.counter_pins) == (
            (4, 7, 12),
            (20, 21, 22, 23),
            (18,),
        )
        assert (info.timer(4), info.timer(8), info.timer(12)) == (3, 2, None)
        assert (info.timer_use(2), info.timer_use(3), info.timer_use(0)) == (
            "clock",
            "servos",
            "free",
        )
        assert board.pin_number("A1") == 21
        before = len(fake.arrivals())
        with pytest.raises(
            NotSupportedError,
            match=r"pin 3 cannot be a pwm pin on this other \(those are 4, 7, 12\)",
        ):
            board.pwm_output(3)
        with pytest.raises(
            TimerInUseError,
            match=r"pin 8's PWM needs Timer2, which runs the device's millisecond clock",
        ):
            board.pwm_output(8)
        with pytest.raises(NotSupportedError, match="pin 14 cannot be an analog input pin"):
            board.analog_input(14)
        assert len(fake.arrivals()) == before  # refused by the host, nothing sent
        board.pwm_output(12)  # a timer the device does not hold
        board.servo(9)
        with pytest.raises(
            TimerInUseError,
            match=r"pin 7's PWM needs Timer3, which makes the servo pulses while a servo runs "
            r"\(pin 9;",
        ) as refused:
            board.pwm_output(7)
        assert not refused.value.sent
        board.analog_input("A3")
        board.counter(18)
        assert sorted(fake.pins) == [9, 12, 18, 23]


def test_a_nano_s_a6_and_a7_are_analog_inputs_only(fake: PtyDevice) -> None:
    """The Nano's profile (two more ADC inputs, A6 and A7, with no port behind them): from
    its pin table alone, "A7" is pin 21 and an analog input, and every other mode there is
    refused before sending, as the device refuses it."""
    fake.board_name = "nano"
    fake.num_pins = 22
    fake.analog_pins = list(range(14, 22))
    fake.analog_only_pins = [20, 21]
    with Board.open(fake.port, ack_timeout=0.1, ping=False) as board:
        assert board.info.analog_pins == tuple(range(14, 22))
        assert board.pin_number("A7") == 21
        before = len(fake.arrivals())
        for configure, what in (
            (lambda: board.digital_output(20), "a digital pin"),
            (lambda: board.servo("A7"), "a servo pin"),
            (lambda: board.digital_input("A6"), "a digital input pin"),
            (lambda: board.pwm_output(21), "a pwm pin"),
        ):
            with pytest.raises(NotSupportedError, match=f"cannot be {what} on this nano"):
                configure()
        assert len(fake.arrivals()) == before  # refused by the host, nothing sent
        board.analog_input("A7")
        board.digital_output("A5")  # 19 has its port: digital as on the Uno
        assert sorted(fake.pins) == [19, 21]


def test_a_device_refusal_has_its_named_error(board: Board, fake: PtyDevice) -> None:
    motor = board.pwm_output(3)

    def refuse(msg: Any) -> list[Any]:
        statuses = {
            "pwm_control": Status.STATUS_INTERLOCK_ACTIVE,
            "pwm_init": Status.STATUS_TIMER_IN_USE,
            "counter_init": Status.STATUS_NOT_SUPPORTED,
        }
        status = statuses.get(msg.WhichOneof("data"))
        return [ack(msg.message_id, status)] if status else fake.default_reply(msg)

    fake.handler = refuse
    with pytest.raises(InterlockActiveError) as interlock:
        motor.write(100)
    assert interlock.value.sent and interlock.value.status == Status.STATUS_INTERLOCK_ACTIVE
    with pytest.raises(TimerInUseError):
        board.pwm_output(9)
    with pytest.raises(NotSupportedError):
        board.counter(2)
    assert motor.value == 0  # a refused value is not the output's


def test_pose_with_pwm_items(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    led = board.digital_output(13)
    motor = board.pwm_output(3)
    board.pose({servo: 30, led: True, motor: 99.6})
    (pose,) = sent(fake, "pose")
    assert [i.WhichOneof("output") for i in pose.pose.items] == ["servo", "pwm"]
    assert pose.pose.items[1].pwm.duty == 100
    # version 6's pin sets, bytes since version 8: pin 13 is bit 5 of byte 1
    assert (pose.pose.digital_pins, pose.pose.digital_levels) == (b"\x00\x20", b"\x00\x20")
    assert fake.values == {9: 30, 13: 1, 3: 100}
    assert motor.value == 100
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose({servo: 40, motor: 300})
    assert info.value.output is motor and not info.value.sent


def test_read_outputs_decodes_pwm(board: Board, fake: PtyDevice) -> None:
    def outputs(msg: Any) -> list[Any]:
        if msg.WhichOneof("data") != "read_outputs":
            return fake.default_reply(msg)
        out = ack(msg.message_id)
        states = out.ack.outputs
        states.pwm_pins = mask([3, 11])
        states.pwm_duties.extend([17, 255])
        states.digital_pins = mask([13])
        states.digital_levels = mask([13])
        return [out]

    fake.handler = outputs
    found = board.read_outputs()
    assert [(s.pin, s.mode, s.value) for s in found.values()] == [
        (3, "pwm", 17), (11, "pwm", 255), (13, "digital", 1)
    ]  # fmt: skip


def test_pwm_restore_last_replays_the_last_duty_but_never_one_before_a_failsafe(
    fake: PtyDevice,
) -> None:
    with Board.open(fake.port, ack_timeout=0.1, ping=False, restore="last") as board:
        rec = Recorder(board)
        motor = board.pwm_output(3, safe=5)
        motor.write(180)
        fake.reboot()
        rec.wait(EventKind.RESTORED)
        assert fake.pins == {3: "pwm"} and fake.values == {3: 180}
        assert sent(fake, "pwm_init")[-1].pwm_init.safe_duty == 5
        fake.expire_failsafe()
        rec.wait(EventKind.FAILSAFE)
        assert motor.value == 5
        fake.reboot()
        rec.wait(EventKind.RESTORED, count=2)
        assert fake.values == {}  # only the Init: the motor stays at its safe duty


# --- inputs ----------------------------------------------------------------------------


def test_digital_input_knows_its_level_at_once_and_follows_changes(
    board: Board, fake: PtyDevice
) -> None:
    fake.time_ms = 1234
    button = board.digital_input(2, pull_up=True, debounce_ms=20)
    (init,) = sent(fake, "digital_input_init")
    assert (init.digital_input_init.pull_up, init.digital_input_init.debounce_ms) == (True, 20)
    assert init.digital_input_init.interlock == pb.TRIP_NONE
    assert button.read() is True  # the report that followed the Ack; no round trip now
    reading = button.reading()
    assert reading is not None and reading.time_ms == 1234
    assert button.age is not None and 0 <= button.age < 30
    changes: list[Reading] = []
    got = threading.Event()

    def changed(reading: Reading) -> None:
        changes.append(reading)
        got.set()

    button.on_change(changed)
    fake.time_ms = 1300
    fake.set_level(2, 0)
    assert button.wait_for(False, timeout=30) is False
    assert got.wait(30)
    assert changes[-1].value is False and changes[-1].time_ms == 1300
    assert board.stats.input_reports == 2


def test_wait_for_returns_at_once_sees_short_pulses_and_times_out(
    board: Board, fake: PtyDevice
) -> None:
    button = board.digital_input(2)
    assert button.wait_for(True, timeout=0) is True  # already so
    with pytest.raises(InputTimeoutError):
        button.wait_for(False, timeout=0.05)
    result: list[bool] = []
    waiter = threading.Thread(target=lambda: result.append(button.wait_for(False, timeout=30)))
    waiter.start()
    deadline = time.monotonic() + 30
    while board.inputs.listeners("digital", 2) == 0:  # the waiter is listening
        assert time.monotonic() < deadline
        time.sleep(0.001)
    fake.levels[2] = 0
    fake.send_burst([fake.report(), fake.report()])
    fake.levels[2] = 1
    fake.send_burst([fake.report()])  # the low was short: a newer level replaced it
    waiter.join(30)
    assert result == [False]
    with pytest.raises(TypeError):
        button.wait_for(2)  # type: ignore[arg-type]
    assert button.wait_for(lambda level: level, timeout=30) is True


def test_analog_input_and_counter(board: Board, fake: PtyDevice) -> None:
    fake.analog[14] = 300
    pot = board.analog_input(14, rate_hz=250, threshold=4, heartbeat=2.0)
    (init,) = sent(fake, "analog_input_init")
    a = init.analog_input_init
    assert (a.pin, a.interval_ms, a.threshold, a.heartbeat_ms) == (14, 4, 4, 2000)
    assert pot.read() == 300
    fake.set_analog(14, 1023)
    assert pot.wait_for(lambda v: v > 1000, timeout=30) == 1023
    wheel = board.counter(3, edge="both", pull_up=True, rate_hz=100)
    (init,) = sent(fake, "counter_init")
    c = init.counter_init
    assert (c.pin, c.edge, c.pull_up, c.interval_ms) == (3, pb.EDGE_BOTH, True, 10)
    assert wheel.read() == 0
    fake.pulses(3, 50)  # both edges: two a pulse
    assert wheel.wait_for(lambda n: n >= 100, timeout=30) == 100
    assert pot.read() == 1023  # a report without pin 14 leaves its value alone


BAD = Status.STATUS_INVALID_ARGUMENT
INPUT_REJECTIONS: list[tuple[str, Any, int]] = [
    ("analog on a digital pin", lambda b: b.analog_input(2), Status.STATUS_NOT_SUPPORTED),
    ("counter on an analog-only pin", lambda b: b.counter(14), Status.STATUS_NOT_SUPPORTED),
    ("debounce too long", lambda b: b.digital_input(2, debounce_ms=256), BAD),
    ("negative debounce", lambda b: b.digital_input(2, debounce_ms=-1), BAD),
    ("bad interlock", lambda b: b.digital_input(2, interlock="up"), BAD),
    ("threshold too big", lambda b: b.analog_input(14, threshold=1024), BAD),
    ("rate too high", lambda b: b.analog_input(14, rate_hz=2000), BAD),
    ("rate zero", lambda b: b.analog_input(14, rate_hz=0), BAD),
    ("rate NaN", lambda b: b.analog_input(14, rate_hz=float("nan")), 7),
    ("heartbeat too long", lambda b: b.analog_input(14, heartbeat=61), BAD),
    ("bad edge", lambda b: b.counter(2, edge="up"), BAD),
    ("reserved pin", lambda b: b.digital_input(1), Status.STATUS_RESERVED_PIN),
    ("no such pin", lambda b: b.digital_input(20), Status.STATUS_INVALID_PIN),
]


@pytest.mark.parametrize(
    ("what", "call", "status"), INPUT_REJECTIONS, ids=[r[0] for r in INPUT_REJECTIONS]
)
def test_input_arguments_are_checked_before_sending(
    board: Board, fake: PtyDevice, what: str, call: Any, status: int
) -> None:
    before = len(fake.arrivals())
    with pytest.raises(protoduino.CommandRejectedError) as info:
        call(board)
    assert info.value.status == status and not info.value.sent, what
    assert len(fake.arrivals()) == before


def test_input_pins_are_owned_like_outputs(board: Board, fake: PtyDevice) -> None:
    board.servo(9)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.digital_input(9)
    assert info.value.status == Status.STATUS_PIN_IN_USE
    button = board.digital_input(2)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.counter(2)
    assert info.value.status == Status.STATUS_PIN_IN_USE
    board.digital_input(2, debounce_ms=5)  # the same mode again: a new configuration
    button.release()
    assert button.read() is None and 2 not in fake.pins
    board.digital_output(2)  # free for any mode


def test_inputs_are_restored_after_a_reboot(board: Board, fake: PtyDevice) -> None:
    rec = Recorder(board)
    button = board.digital_input(2, pull_up=True, interlock="low")
    board.analog_input(15)
    fake.reboot()
    rec.wait(EventKind.RESTORED)
    replay = [r.kind for r in fake.arrivals()][-3:]
    assert replay == ["configure_failsafe", "digital_input_init", "analog_input_init"]
    assert sent(fake, "digital_input_init")[-1].digital_input_init.interlock == pb.TRIP_LOW
    assert fake.pins == {2: "digital_input", 15: "analog_input"}
    fake.set_level(2, 0)
    assert button.wait_for(False, timeout=30) is False


def test_callbacks_are_newest_wins_and_stay_bounded(board: Board, fake: PtyDevice) -> None:
    """A callback stuck while 500 changes arrive is then called with the latest value,
    not 500 times: the event queue holds one job per input at most."""
    pot = board.analog_input(14)
    release = threading.Event()
    entered = threading.Event()
    seen: list[int] = []

    def slow(reading: Reading) -> None:
        seen.append(reading.value)
        entered.set()
        release.wait(30)

    pot.on_change(slow)
    fake.set_analog(14, 1)
    assert entered.wait(30)  # the event thread is now stuck in the callback
    burst = []
    for value in range(2, 502):
        fake.analog[14] = value
        burst.append(fake.report(analog=[14]))
    fake.send_burst(burst)
    assert pot.wait_for(lambda v: v == 501, timeout=30) == 501
    release.set()
    deadline = time.monotonic() + 30
    while seen[-1] != 501 and time.monotonic() < deadline:
        time.sleep(0.01)
    # 2 queued the one job; 3..501 found it queued. It ran once, with the latest value.
    assert seen == [1, 501]
    assert board.stats.input_changes_skipped == 499


def test_device_coalescing_is_counted_and_a_malformed_report_is_dropped(
    board: Board, fake: PtyDevice
) -> None:
    pot = board.analog_input(14)
    fake.coalesced = 7
    fake.set_analog(14, 500)
    assert pot.wait_for(lambda v: v == 500, timeout=30) == 500
    assert board.stats.inputs_coalesced == 7
    bad = ArduinoOut()
    bad.input_report.analog_pins = mask([14, 15])
    bad.input_report.analog_values.append(9)  # two pins, one value
    fake.send_data(bad)
    fake.set_analog(14, 501)
    assert pot.wait_for(lambda v: v == 501, timeout=30) == 501
    assert board.stats.input_reports == 3  # the bad one is not counted as a report


def test_close_ends_a_wait(fake: PtyDevice) -> None:
    board = Board.open(fake.port, ack_timeout=0.1, ping=False)
    button = board.digital_input(2)
    errors: list[BaseException] = []

    def wait() -> None:
        try:
            button.wait_for(False, timeout=60)
        except BaseException as error:
            errors.append(error)

    waiter = threading.Thread(target=wait)
    waiter.start()
    deadline = time.monotonic() + 30
    while board.inputs.listeners("digital", 2) == 0:
        assert time.monotonic() < deadline
        time.sleep(0.001)
    board.close()
    waiter.join(30)
    assert len(errors) == 1 and isinstance(errors[0], protoduino.BoardClosedError)


# --- interlocks ------------------------------------------------------------------------


def test_interlock_event_names_its_pin_and_forgets_values(board: Board, fake: PtyDevice) -> None:
    rec = Recorder(board)
    motor = board.pwm_output(3)
    motor.write(200)
    bumper = board.digital_input(2, pull_up=True, interlock="low")
    assert bumper.interlock == "low"
    assert sent(fake, "digital_input_init")[0].digital_input_init.interlock == pb.TRIP_LOW
    fake.set_level(2, 0)  # the bumper closes: the device trips
    event = rec.wait(EventKind.FAILSAFE)
    assert event.details == {"active": True, "cause": "interlock", "epoch": 1, "pin": 2}
    assert "interlock on pin 2" in event.text
    assert motor.value == 0 and fake.values == {}  # the device drove it safe; the host knows
    fake.set_level(2, 1)
    board.clear_interlock()
    # It carries the epoch of the trip this host saw: a held-up one never clears a later trip.
    assert [m.clear_interlock.failsafe_epoch for m in sent(fake, "clear_interlock")] == [1]
    cleared = rec.wait(EventKind.FAILSAFE, count=2)
    assert cleared.details == {"active": False, "cause": "none", "epoch": 1}
    board.submit_clear_interlock().result(30)
    assert len(sent(fake, "clear_interlock")) == 2


def test_a_wait_survives_a_release_and_a_new_configuration(board: Board, fake: PtyDevice) -> None:
    """Releasing a pin drops its value, not who listens: a wait hears the pin configured anew."""
    pot = board.analog_input(14)
    result: list[int] = []
    waiter = threading.Thread(target=lambda: result.append(pot.wait_for(lambda v: v == 900, 30)))
    waiter.start()
    deadline = time.monotonic() + 30
    while board.inputs.listeners("analog", 14) == 0:
        assert time.monotonic() < deadline
        time.sleep(0.001)
    board.release_all()
    assert pot.read() is None
    fake.analog[14] = 900
    again = board.analog_input(14)  # its first report carries 900
    waiter.join(30)
    assert result == [900] and again.read() == 900
