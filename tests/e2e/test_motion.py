"""Poses, speed limits, the device's readback: host checks on the fake device, the rest at the pins.

The pin verdicts come from the boards' traces on their own clocks: on the
emulated Uno a servo's trace time is the rising edge of the first pulse with
the new width, so the servos of one pose changing in the same 20 ms frame
start within the pulses before them (well under 10 ms), while a change one
frame later would start at least 12 ms apart.
"""

from __future__ import annotations

import asyncio
import functools
import itertools
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino import Board, aio, effective_speed
from protoduino.messages import Status, pin_set
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice, ack
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin

#: Runs on the emulated Mega too: its servos and poses at its pins (tests/README.md).
pytestmark = pytest.mark.mega

BOUND = 10.0


def us(degrees: int, lo: int = 544, hi: int = 2400) -> int:
    return lo + degrees * (hi - lo) // 180


# --- poses: the host side ----------------------------------------------------------


def test_pose_message_and_readback(board: Board, fake: PtyDevice) -> None:
    a, b = board.servo(3), board.servo(5, min_us=1000, max_us=2000)
    led = board.digital_output(13)
    board.pose({a: 10, b: 180, led: True})
    (sent,) = fake.arrivals("pose")
    items = sent.msg.pose.items
    assert [i.WhichOneof("output") for i in items] == ["servo", "servo"]
    assert (items[0].servo.pin, items[0].servo.degrees) == (3, 10)
    assert (items[1].servo.pin, items[1].servo.degrees) == (5, 180)
    # A digital output travels in the pin sets (protocol version 6), not as an item.
    assert (sent.msg.pose.digital_pins, sent.msg.pose.digital_levels) == (
        pin_set(1 << 13),
        pin_set(1 << 13),
    )
    assert (a.value, b.value, led.value) == (us(10), 2000, True)
    assert board.submit_pose({a: 20}).result(BOUND) is None
    assert a.value == us(20)


def test_pose_checked_before_sending(board: Board, fake: PtyDevice) -> None:
    a, b = board.servo(3), board.servo(5)
    led = board.digital_output(13)
    before = len(fake.arrivals())
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose({a: 10, b: 181, led: True})
    assert info.value.output is b and info.value.sent is False
    assert info.value.status == Status.STATUS_OUT_OF_RANGE and "pin=5" in str(info.value)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose({})
    assert info.value.status == Status.STATUS_INVALID_ARGUMENT
    nine: dict[protoduino.board.PoseOutput, int] = {board.servo(pin): 0 for pin in range(2, 10)}
    nine[protoduino.Servo(board, 10, 544, 2400)] = 0  # a ninth (the board has 8 slots)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose(nine)  # more than 8 items: servos and PWM outputs
    assert getattr(info.value.output, "pin", None) == 10 and info.value.sent is False
    before = len(fake.arrivals())
    twin = protoduino.Servo(board, 3, 544, 2400)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose({a: 10, twin: 20})
    assert info.value.output is twin and info.value.status == Status.STATUS_INVALID_ARGUMENT
    with pytest.raises(TypeError):
        board.pose({a: "4.5"})  # type: ignore[dict-item]
    with pytest.raises(TypeError):
        board.pose({led: "on"})  # type: ignore[dict-item]
    with pytest.raises(TypeError):
        board.pose([(a, 10)])  # type: ignore[arg-type]
    assert len(fake.arrivals()) == before  # nothing went out
    assert a.value == us(90)


def test_pose_digital_outputs_in_the_masks(board: Board, fake: PtyDevice) -> None:
    """Any number of digital outputs besides at most 8 servos and PWM outputs: the masks hold
    them, a bit per pin; the readback takes their levels."""
    servos = [board.servo(pin) for pin in range(2, 10)]
    leds = [board.digital_output(pin) for pin in (17, 11, 13, 12)]
    targets: dict[protoduino.board.PoseOutput, float] = {s: 45 for s in servos}
    targets.update({led: led.pin % 2 == 1 for led in leds})
    board.pose(targets)
    (sent,) = fake.arrivals("pose")
    assert [i.servo.pin for i in sent.msg.pose.items] == list(range(2, 10))
    want_pins = sum(1 << p for p in (11, 12, 13, 17))
    want_levels = sum(1 << p for p in (11, 13, 17))
    assert (sent.msg.pose.digital_pins, sent.msg.pose.digital_levels) == (
        pin_set(want_pins),
        pin_set(want_levels),
    )
    assert [led.value for led in leds] == [True, True, True, False]
    assert fake.values[17] == 1 and fake.values[12] == 0


def test_device_refusal_of_a_mask_pin_names_the_output(board: Board, fake: PtyDevice) -> None:
    """refused_item counts the items from 1, then the masks' pins upwards (the device's
    order), whatever order the mapping had."""
    a = board.servo(3)
    leds = {pin: board.digital_output(pin) for pin in (13, 4, 8)}

    def refuse(position: int) -> Any:
        def handler(msg: Any) -> list[Any]:
            out = ack(msg.message_id, Status.STATUS_NOT_INITIALISED)
            out.ack.refused_item = position
            return [out]

        return handler

    targets: dict[protoduino.board.PoseOutput, int] = {leds[13]: 1, a: 10, leds[4]: 0, leds[8]: 1}
    for position, want in [(1, a), (2, leds[4]), (3, leds[8]), (4, leds[13])]:
        fake.handler = refuse(position)
        with pytest.raises(protoduino.CommandRejectedError) as info:
            board.pose(targets)
        assert info.value.output is want and info.value.sent is True
    assert [led.value for led in leds.values()] == [False, False, False]  # nothing recorded


def test_pose_of_another_board(board: Board, tmp_path: Path) -> None:
    (tmp_path / "other").mkdir()
    with PtyDevice(tmp_path / "other") as other_fake, Board.open(other_fake.port) as other:
        theirs = other.servo(3)
        with pytest.raises(ValueError, match="another board"):
            board.pose({theirs: 10})


def test_device_refusal_names_the_output(board: Board, fake: PtyDevice) -> None:
    a, b = board.servo(3), board.servo(5)

    def refuse_second(msg: Any) -> list[Any]:
        out = ack(msg.message_id, Status.STATUS_NOT_INITIALISED)
        out.ack.refused_item = 2
        return [out]

    fake.handler = refuse_second
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose({a: 10, b: 20})
    assert info.value.output is b and info.value.sent is True
    assert info.value.status == Status.STATUS_NOT_INITIALISED
    error = board.submit_pose({a: 10, b: 20}).exception(BOUND)
    assert isinstance(error, protoduino.CommandRejectedError) and error.output is b
    assert (a.value, b.value) == (us(90), us(90))  # nothing recorded


def test_pose_values_are_restored_after_a_reboot(fake: PtyDevice) -> None:
    """With ``restore="last"``; by default a reboot brings the outputs back safe only."""
    with Board.open(fake.port, restore="last") as board:
        a = board.servo(3)
        led = board.digital_output(13)
        board.pose({a: 33, led: True})
        restored = len(fake.arrivals())
        fake.reboot()
        assert fake.wait_for(lambda: fake.values == {3: 33, 13: 1}, BOUND)
        kinds = [r.kind for r in fake.arrivals()[restored:] if r.kind != "ping"]
        assert kinds[:5] == [
            "configure_failsafe",
            "servo_init",
            "digital_init",
            "servo_control",
            "digital_control",
        ]


def test_a_pose_after_an_unseen_reboot_restores_the_session(board: Board, fake: PtyDevice) -> None:
    """The device forgot everything without an EVENT BOOT: the pose's refused item (a
    configured output) starts the restore, then the pose runs once, under a new id."""
    a, b = board.servo(3), board.servo(5)
    led = board.digital_output(13)
    fake.forget()  # a reset whose BOOT was lost: state gone, link still up
    board.pose({a: 10, b: 20, led: True})
    assert fake.pins == {3: "servo", 5: "servo", 13: "digital"}
    assert fake.values == {3: 10, 5: 20, 13: 1}
    refused, again = fake.arrivals("pose")
    assert refused.msg.message_id != again.msg.message_id
    assert board.stats.reboots == 1 and board.stats.rejected == 0
    unconfigured = protoduino.Servo(board, 10, 544, 2400)  # never configured: a refusal
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.pose({a: 30, unconfigured: 40})
    assert info.value.output is unconfigured and board.stats.reboots == 1


# --- speed limits: the host side ---------------------------------------------------


def test_speed_limit_in_the_init(board: Board, fake: PtyDevice) -> None:
    fast = board.servo(3, max_speed_us=500)
    assert fast.max_speed_us == 500
    slow = board.servo(5, max_speed=60)  # degrees/s: 60 * 1856 / 180 = 618.7 -> 619 us/s
    assert slow.max_speed_us == effective_speed(619) == 600  # whole us per 20 ms frame
    free = board.servo(6)
    assert free.max_speed_us == 0
    speeds = [r.msg.servo_init.max_speed for r in fake.arrivals("servo_init")]
    assert speeds == [500, 619, 0]
    assert effective_speed(1) == 50 and effective_speed(12750) == 12750
    before = len(fake.arrivals())
    for kwargs in ({"max_speed_us": 12751}, {"max_speed_us": 0}, {"max_speed": -1.0}):
        with pytest.raises(protoduino.CommandRejectedError) as info:
            board.servo(9, **kwargs)
        assert info.value.status == Status.STATUS_INVALID_ARGUMENT and not info.value.sent
    with pytest.raises(TypeError):
        board.servo(9, max_speed=10, max_speed_us=100)
    assert len(fake.arrivals()) == before


# --- at the pins: both boards ---------------------------------------------------------

PINS = (3, 5, 6, 9)


def ends_near(want: int, values: list[int]) -> bool:
    return bool(values) and abs(values[-1] - want) <= PULSE_TOLERANCE_US


def change_time(trace: list[dict[str, Any]], pin: int, want: int, after: float) -> float:
    """The trace time at which ``pin`` first showed ``want`` after ``after``."""
    for e in trace:
        if e["pin"] == pin and e["t"] > after and abs(int(e["value"]) - want) <= PULSE_TOLERANCE_US:
            return float(e["t"])
    raise AssertionError(f"pin {pin} never showed {want}")


def test_pose_changes_every_joint_in_one_frame(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port) as board:
        servos = [board.servo(pin) for pin in PINS]
        led = board.digital_output(13)
        for s in servos:
            wait_for_pin(sim_board, s.pin, functools.partial(ends_near, us(90)))
        start = sim_board.trace()[-1]["t"]
        for round_ in range(3):  # a few poses, at whatever phase of the frame they land
            targets: dict[protoduino.board.PoseOutput, float] = {
                s: 20 + 40 * round_ + i for i, s in enumerate(servos)
            }
            targets[led] = round_ % 2 == 0
            board.pose(targets)
            for i, s in enumerate(servos):
                want = us(20 + 40 * round_ + i)
                wait_for_pin(sim_board, s.pin, functools.partial(ends_near, want))
            trace = sim_board.trace()
            times = [
                change_time(trace, s.pin, us(20 + 40 * round_ + i), start)
                for i, s in enumerate(servos)
            ]
            spread = max(times) - min(times)
            assert spread < 0.010, f"pose {round_}: joints changed {spread * 1000:.1f} ms apart"
            start = max(times)


def test_pose_all_or_nothing_at_the_pins(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port) as board:
        a = board.servo(3)
        led = board.digital_output(13)
        wait_for_pin(sim_board, 3, functools.partial(ends_near, us(90)))
        unconfigured = protoduino.Servo(board, 10, 544, 2400)  # the device has no servo on 10
        with pytest.raises(protoduino.CommandRejectedError) as info:
            board.pose({a: 0, led: True, unconfigured: 45})
        assert info.value.output is unconfigured and info.value.sent
        assert info.value.status == Status.STATUS_NOT_INITIALISED
        assert board.ping() > 0  # a later command's Ack: the pose's moment has passed
        board.pose({a: 180})  # a marker: once pin 3 shows it, pin 13 would have shown a 1
        wait_for_pin(sim_board, 3, functools.partial(ends_near, us(180)))
        trace = sim_board.trace()
        assert not any(int(e["value"]) for e in trace if e["pin"] == 13)
        assert not any(e["pin"] == 10 for e in trace)
        assert all(abs(int(e["value"]) - us(0)) > 10 for e in trace if e["pin"] == 3)


def ramp(trace: list[dict[str, Any]], pin: int, after: float) -> list[tuple[float, int]]:
    return [(float(e["t"]), int(e["value"])) for e in trace if e["pin"] == pin and e["t"] > after]


def check_ramp(points: list[tuple[float, int]], start: int, end: int, speed: int) -> None:
    """Steps of at most one frame's worth, taking |end - start| / speed seconds in all."""
    values = [start] + [v for _, v in points]
    step = speed // 50
    # The device steps every 20 ms of its own millisecond clock, the first step as soon as the
    # command arrives; the pin shows a width per Timer1 frame. At the start the two are in any
    # phase, so the first frame may already carry the second step (seen on the emulated Uno:
    # 1500 -> 1520 at 10 us per frame); after that the step period (20 ms and the loop's
    # latency) is never shorter than a frame.
    first, *rest = itertools.pairwise(values)
    assert abs(first[1] - first[0]) <= 2 * step + PULSE_TOLERANCE_US, f"a first jump of {first}"
    for before, after in rest:
        assert abs(after - before) <= step + PULSE_TOLERANCE_US, f"a jump of {after - before} us"
    assert abs(values[-1] - end) <= PULSE_TOLERANCE_US
    took = points[-1][0] - points[0][0]
    frames = abs(end - start) / step
    # From the first step to the last: frames - 1 frame times; the device steps on
    # its millisecond clock, a frame or so either way at the ends.
    assert (frames - 3) * 0.020 <= took <= (frames + 1) * 0.020, f"{took:.3f} s for {frames} steps"


def test_speed_limit_at_the_pin(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port) as board:
        servo = board.servo(9, safe_us=1500, max_speed_us=500)  # 10 us per frame
        wait_for_pin(sim_board, 9, functools.partial(ends_near, 1500))
        mark = sim_board.trace()[-1]["t"]
        servo.write_us(1800)
        assert servo.value == 1800  # the acknowledged target
        wait_for_pin(sim_board, 9, functools.partial(ends_near, 1800))
        check_ramp(ramp(sim_board.trace(), 9, mark), 1500, 1800, 500)
        states = board.read_outputs()
        assert states[9] == protoduino.OutputState(9, "servo", 1800, 1800)
        # Stop returns it to safe at the same speed; the readback shows it on its way.
        mark = sim_board.trace()[-1]["t"]
        board.stop()
        moving = board.read_outputs()[9]
        assert moving.target == 1500 and 1500 < moving.value <= 1800
        wait_for_pin(sim_board, 9, functools.partial(ends_near, 1500))
        check_ramp(ramp(sim_board.trace(), 9, mark), 1800, 1500, 500)


def test_failsafe_returns_at_the_speed_limit(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port, failsafe_timeout=2.0) as board:
        servo = board.servo(9, safe_us=1500, max_speed_us=1000)  # 20 us per frame
        servo.write_us(1700)
        wait_for_pin(sim_board, 9, functools.partial(ends_near, 1700))
        mark = sim_board.trace()[-1]["t"]
        board.pinging = False  # the failsafe fires after 2 s of silence (10 s by default)
        wait_for_pin(sim_board, 9, functools.partial(ends_near, 1500), timeout=30)
        check_ramp(ramp(sim_board.trace(), 9, mark), 1700, 1500, 1000)


def test_read_outputs_in_a_resumed_session(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port) as board:
        board.servo(3).write(45)
        board.digital_output(13).on()
        board.servo(5, safe_us=1234)
        assert board.read_outputs() == {
            3: protoduino.OutputState(3, "servo", us(45), us(45)),
            5: protoduino.OutputState(5, "servo", 1234, 1234),
            13: protoduino.OutputState(13, "digital", 1, 1),
        }
        session = board.session
    # Resuming the session (as the command line does): it knows nothing yet, asks the device.
    with Board.open(sim_board.port, session=session) as again:
        inherited = again.read_outputs()
        assert inherited[3].value == us(45) and inherited[13].value == 1
        assert inherited[5].value == 1234
    with Board.open(sim_board.port) as new:  # a new session: the device released them all
        assert new.read_outputs() == {}


def test_aio_pose_and_readback(sim_board: SimBoard) -> None:
    async def main() -> dict[int, protoduino.OutputState]:
        async with await aio.open(sim_board.port) as board:
            a, b = await asyncio.gather(board.servo(3), board.servo(5, max_speed=600))
            assert b.max_speed_us > 0
            await board.pose({a: 30, b.sync: 150})
            return await board.read_outputs()

    states = asyncio.run(asyncio.wait_for(main(), 60))
    assert states[3].value == us(30) and states[5].target == us(150)
    wait_for_pin(sim_board, 3, functools.partial(ends_near, us(30)))
