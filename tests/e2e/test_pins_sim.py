"""PWM, inputs, counters and interlocks through the Board API on the simulated boards.

Outputs are judged at the pin (the trace): the native board traces the duty it is told;
the emulated Uno (the real firmware in simavr) traces the duty it measures at the pin,
from the timers' compare outputs. Both write ``{"pin": N, "mode": "pwm", "value": DUTY}``.
Inputs are driven through the board's control socket (on the emulated Uno: the AVR's
own pins, interrupts and ADC) and judged through the API: what the firmware's input code
reported is what ``read()``, ``wait_for`` and ``on_change`` see.

A test marked ``mega`` runs on the emulated Mega too: it takes its pins from the board's
DeviceInfo (simfixtures.pins_for), so the same test serves every board, and a test of a
kind of pin the board states none of (the Mega's analog inputs, today) is skipped, saying so.
"""

from __future__ import annotations

import asyncio
import itertools
import random
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import protoduino
import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino import Board, Event, EventKind, aio
from protoduino._generated import protoduino_pb2 as pb
from protoduino.commands import ANALOG_INPUT, COUNTER, DIGITAL, DIGITAL_INPUT, PWM
from protoduino.constants import PacketType
from protoduino.errors import (
    FeatureMissingError,
    InterlockActiveError,
    NotSupportedError,
    TimerInUseError,
)
from protoduino.inputs import Reading
from protoduino.messages import ArduinoIn, Status, parse_out, pins_in
from protoduino.packets import Packet
from protoduino.simboard import SimBoard, runner_command
from protoduino_dev import build
from simfixtures import pins_for, wait_for_pin, wait_until

#: Bounds a failing test's wait only; the verdicts are the trace's.
BOUND = 30.0
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def sim(sim_board: SimBoard) -> SimBoard:
    return sim_board


@pytest.fixture
def board(sim: SimBoard) -> Iterator[Board]:
    with Board.open(sim.port) as b:
        yield b


def pwm_values(trace: list[dict[str, Any]], pin: int) -> list[int]:
    return [int(e["value"]) for e in trace if e["pin"] == pin and e.get("mode") == "pwm"]


def wait_pwm(sim: SimBoard, pin: int, ok: Callable[[list[int]], bool], since: int = 0) -> None:
    """Wait until the PWM duties ``pin`` took in the trace (from line ``since``) satisfy ``ok``."""
    deadline = time.monotonic() + BOUND
    while not ok(pwm_values(sim.trace()[since:], pin)):
        if time.monotonic() > deadline:
            raise AssertionError(f"pin {pin}: PWM in the trace {pwm_values(sim.trace(), pin)}")
        time.sleep(0.02)


def events(board: Board) -> list[Event]:
    seen: list[Event] = []
    board.on_event(seen.append)
    return seen


def wait_event(seen: list[Event], kind: EventKind) -> Event:
    deadline = time.monotonic() + BOUND
    while True:
        found = [e for e in list(seen) if e.kind is kind]
        if found:
            return found[-1]
        assert time.monotonic() < deadline, f"no {kind} event; got {seen}"
        time.sleep(0.02)


def _wait_trips(seen: list[Event], count: int) -> None:
    """Until the board has reported ``count`` interlock trips."""
    deadline = time.monotonic() + BOUND
    while (
        sum(
            e.kind is EventKind.FAILSAFE
            and e.details["active"]
            and e.details["cause"] == "interlock"
            for e in list(seen)
        )
        < count
    ):
        assert time.monotonic() < deadline, f"{count} interlock trips not reported; got {seen}"
        time.sleep(0.02)


@pytest.mark.mega
def test_pwm_duty_at_the_pin_and_stop(board: Board, sim: SimBoard) -> None:
    (pin,) = pins_for(board, PWM)
    motor = board.pwm_output(pin, safe=0)
    motor.write(128.4)  # rounded to 128
    wait_pwm(sim, pin, lambda v: v[-1:] == [128])
    motor.write(254)
    wait_pwm(sim, pin, lambda v: v[-1:] == [254])
    states = board.read_outputs()
    assert (states[pin].mode, states[pin].value) == ("pwm", 254)
    mark = len(sim.trace())
    board.stop()
    wait_pwm(sim, pin, lambda v: v[-1:] == [0], since=mark)
    assert motor.value == 0 and board.read_outputs()[pin].value == 0


@pytest.mark.mega
def test_pose_sets_pwm_with_the_others_and_the_failsafe_makes_it_safe(sim: SimBoard) -> None:
    with Board.open(sim.port, failsafe_timeout=0.3) as board:
        seen = events(board)
        pwm_pins = pins_for(board, PWM)
        motor = board.pwm_output(pwm_pins[-1], safe=7)
        (led_pin,) = pins_for(board, DIGITAL, avoid=pwm_pins[-1:])
        led = board.digital_output(led_pin)
        board.pose({motor: 200, led: True})
        wait_pwm(sim, motor.pin, lambda v: v[-1:] == [200])
        mark = len(sim.trace())
        board.pinging = False  # the device hears nothing more: its failsafe fires
        event = wait_event(seen, EventKind.FAILSAFE)
        assert event.details["active"] and event.details["cause"] == "ping_timeout"
        wait_pwm(sim, motor.pin, lambda v: v[-1:] == [7], since=mark)
        assert motor.value == 7


@pytest.mark.mega
def test_the_failsafe_makes_the_servo_timers_pwm_pins_safe(sim: SimBoard) -> None:
    """PWM on the pins of the timers that otherwise make the servo pulses (the Uno's 9 and 10,
    the Mega's 11, 12 and 44..46: from DeviceInfo) goes to its safe duty at a failsafe. The
    failsafe hurries the servos' next frame on; on a timer running PWM that wrote a frame time
    into OCR1A, and the emulated Uno's pin 9 showed duty 255 where its safe duty was 7."""
    with Board.open(sim.port, failsafe_timeout=0.3) as board:
        seen = events(board)
        pins = [p for p in board.info.timer_pins("servos") if board.info.can(p, PWM)]
        if not pins:
            pytest.skip(f"the {board.info.board} board's PWM pins need no servo timer")
        motors = {pin: board.pwm_output(pin, safe=7 + pin) for pin in pins}
        board.pose({motor: 200 for motor in motors.values()})
        for pin in pins:
            wait_pwm(sim, pin, lambda v: v[-1:] == [200])
        mark = len(sim.trace())
        board.pinging = False  # the device hears nothing more: its failsafe fires
        wait_event(seen, EventKind.FAILSAFE)
        for pin in pins:
            safe = 7 + pin
            wait_pwm(sim, pin, lambda v: v[-1:] == [safe], since=mark)  # noqa: B023 (waited here)


def _first(lines: list[dict[str, Any]], pin: int, ok: Callable[[dict[str, Any]], bool]) -> Any:
    """When ``pin`` first took a value ``ok`` accepts in ``lines``: (board time, line), so
    that changes at one instant keep the order the board wrote them in."""
    return next((e["t"], i) for i, e in enumerate(lines) if e["pin"] == pin and ok(e))


@pytest.mark.mega
def test_a_pose_never_drives_a_motor_the_wrong_way(sim: SimBoard) -> None:
    """Issue 32: an H-bridge's direction pin and its PWM in one pose, listed either way.
    Started in the other direction, the direction pin changes before the duty leaves 0;
    stopped with the direction flipped back, the duty is 0 before the direction pin
    changes. Judged at the pins on the board's clock (the trace's t)."""
    with Board.open(sim.port) as board:
        (pwm,) = pins_for(board, PWM)
        # The direction pin above the PWM pin, as the Uno's 3 and 4: with pin 2 instead, the
        # emulated Uno's trace holds the stop's two changes at one microsecond with the
        # direction's line first, which the order at one instant below reads as the wrong way.
        (way,) = pins_for(board, DIGITAL, avoid=tuple(range(pwm + 1)))
        motor = board.pwm_output(pwm, safe=0)
        ahead = board.digital_output(way, safe=True)  # the direction pin: high, forward
        wait_for_pin(sim, way, lambda v: v[-1:] == [1])
        for ahead_first in (False, True):
            mark = len(sim.trace())
            start: dict[protoduino.board.PoseOutput, int | bool] = (
                {ahead: False, motor: 180} if ahead_first else {motor: 180, ahead: False}
            )
            board.pose(start)  # backwards
            wait_pwm(sim, pwm, lambda v: v[-1:] == [180], since=mark)
            lines = sim.trace()[mark:]
            turned = _first(lines, way, lambda e: e["value"] == 0)
            runs = _first(lines, pwm, lambda e: e.get("mode") == "pwm" and e["value"] > 0)
            assert turned <= runs, f"the duty left 0 at {runs}, the direction turned at {turned}"
            mark = len(sim.trace())
            stop: dict[protoduino.board.PoseOutput, int | bool] = (
                {ahead: True, motor: 0} if ahead_first else {motor: 0, ahead: True}
            )
            board.pose(stop)  # stopped, facing forward again
            wait_for_pin(sim, way, lambda v: v[-1:] == [1])
            wait_pwm(sim, pwm, lambda v: v[-1:] == [0], since=mark)
            lines = sim.trace()[mark:]
            stopped = _first(lines, pwm, lambda e: e.get("mode") == "pwm" and e["value"] == 0)
            turned = _first(lines, way, lambda e: e["value"] == 1)
            assert stopped <= turned, f"the direction turned at {turned}, the duty 0 at {stopped}"


def _request(board: Board, msg: ArduinoIn) -> int:
    """The device's own status for ``msg`` (no host check on the way)."""
    try:
        board.request(msg)
    except protoduino.CommandRejectedError as error:
        return error.status
    return Status.STATUS_OK


#: The Uno's pin table as its DeviceInfo states it (docs/protocol.md section 7, *The pin table*).
UNO_PINS = bytes(
    [0, 0, 0x09, 0x0B, 0x19, 0x1B, 0x1B, 0x19, 0x19, 0x5B, 0x5B, 0x1B, 0x19, 0x19] + [5] * 6
)


def test_the_board_states_its_pin_table(board: Board) -> None:
    """Both boards state the Uno's pins and timers (DeviceInfo.pins, timers): what the host
    knows of the board's pins it has from there."""
    info = board.info
    assert (info.pins, info.timers) == (UNO_PINS, bytes([pb.TIMER_FREE, pb.TIMER_SERVOS]))
    assert (info.pwm_pins, info.analog_pins, info.counter_pins) == (
        (3, 5, 6, 9, 10, 11),
        (14, 15, 16, 17, 18, 19),
        tuple(range(2, 14)),
    )
    assert [info.timer(p) for p in (3, 5, 9)] == [None, None, 1]


def test_host_refusals_are_the_devices(board: Board) -> None:
    """Each PWM refusal the host makes before sending is the one the device makes, and says
    which pin, what it cannot do and why, from the device's pin table."""
    cases: list[tuple[int, type[protoduino.CommandRejectedError], int, str]] = [
        (4, NotSupportedError, Status.STATUS_NOT_SUPPORTED, "pin 4 cannot be a pwm pin on this"),
    ]
    board.servo(2)
    servos = "PWM needs Timer1, which makes the servo pulses while a servo runs (pin 2;"
    cases.append((9, TimerInUseError, Status.STATUS_TIMER_IN_USE, f"pin 9's {servos}"))
    for pin, error, status, why in cases:
        with pytest.raises(error) as refused:
            board.pwm_output(pin)
        assert refused.value.status == status and not refused.value.sent
        assert why in str(refused.value)
        msg = ArduinoIn()
        msg.pwm_init.pin = pin
        assert _request(board, msg) == status, pin
    with pytest.raises(protoduino.CommandRejectedError) as refused:
        board.pwm_output(3).write(256)
    msg = ArduinoIn()
    msg.pwm_control.pin, msg.pwm_control.duty = 3, 256
    assert _request(board, msg) == refused.value.status == Status.STATUS_OUT_OF_RANGE


@pytest.mark.mega
def test_restore_last_drives_the_last_duty_after_a_reboot(sim: SimBoard) -> None:
    with Board.open(sim.port, restore="last") as board:
        seen = events(board)
        (pin,) = pins_for(board, PWM)
        motor = board.pwm_output(pin, safe=0)
        motor.write(180)
        wait_pwm(sim, pin, lambda v: v[-1:] == [180])
        mark = len(sim.trace())
        sim.reboot()
        wait_event(seen, EventKind.RESTORED)
        # Released by the reboot, up at its safe duty, then the last duty again.
        wait_pwm(sim, pin, lambda v: v[-1:] == [180] and 0 in v, since=mark)


def test_a_firmware_without_servos_is_refused_by_the_host(tmp_path: Path) -> None:
    """Built with FEATURES="digital_output pwm": the host refuses a servo before sending,
    naming the feature and how to build it in; what the build has still works."""
    missing = missing_tool("make", "cc", "avr-gcc", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build.build_runner()
    build.make(ROOT / "firmware", "avr", "FEATURES=digital_output pwm")
    elf = ROOT / "build" / "avr-digital_output-pwm" / "protoduino.elf"
    trace = tmp_path / "trace.jsonl"
    runner = BoardProcess(runner_command(elf, trace=trace), startup=10.0)
    try:
        with Board.open(runner.port) as board:
            assert board.info.features == {"digital_output", "pwm"}
            before = board.stats.commands
            with pytest.raises(FeatureMissingError) as refused:
                board.servo(9)
            assert refused.value.feature == "servo" and not refused.value.sent
            assert 'FEATURES="servo digital_output' in str(refused.value)
            assert board.stats.commands == before  # nothing went to the device
            for make in (lambda: board.digital_input(2), lambda: board.counter(2)):
                with pytest.raises(FeatureMissingError):
                    make()
            board.pwm_output(9).write(77)
    finally:
        runner.stop(strict=False)


# --- inputs ----------------------------------------------------------------------------


def equals(wanted: int) -> Callable[[int], bool]:
    return lambda value: value == wanted


@pytest.mark.mega
def test_digital_input_follows_the_pin(board: Board, sim: SimBoard) -> None:
    (pin,) = pins_for(board, DIGITAL_INPUT)
    sim.set_level(pin, 1)
    button = board.digital_input(pin, pull_up=True, debounce_ms=5)
    assert button.read() is True
    changes: list[Reading] = []
    button.on_change(changes.append)
    for level in (0, 1, 0):
        sim.set_level(pin, level)
        assert button.wait_for(bool(level), timeout=BOUND) is bool(level)
    deadline = time.monotonic() + BOUND
    while [r.value for r in changes] != [False, True, False]:
        assert time.monotonic() < deadline, changes
        time.sleep(0.01)
    times = [r.time_ms for r in changes]
    assert times == sorted(times)  # the device's clock, in the order the edges came
    assert board.stats.input_reports >= 4


@pytest.mark.mega
def test_analog_input_reports_what_the_adc_reads(board: Board, sim: SimBoard) -> None:
    (pin,) = pins_for(board, ANALOG_INPUT)
    sim.set_analog(pin, 100)
    pot = board.analog_input(pin, rate_hz=200, threshold=2)
    assert pot.read() == 100
    for counts in (512, 1023, 0, 7):
        sim.set_analog(pin, counts)
        assert pot.wait_for(equals(counts), timeout=BOUND) == counts
    sim.set_analog(pin, 8)  # within the threshold: no report for it
    sim.set_analog(pin, 300)
    assert pot.wait_for(lambda v: v == 300, timeout=BOUND) == 300


def test_six_analog_channels_at_once(board: Board, sim: SimBoard) -> None:
    pots = {pin: board.analog_input(pin, rate_hz=200) for pin in board.info.analog_pins}
    assert sorted(pots) == [14, 15, 16, 17, 18, 19]
    for pin in pots:
        sim.set_analog(pin, 10 * pin)
    for pin, pot in pots.items():
        assert pot.wait_for(equals(10 * pin), timeout=BOUND) == 10 * pin


@pytest.mark.mega
def test_counter_counts_every_pulse(board: Board, sim: SimBoard) -> None:
    pin = pins_for(board, COUNTER, 2)[-1]
    sim.set_level(pin, 0)
    wheel = board.counter(pin, edge="rising", rate_hz=50)
    assert wheel.read() == 0
    sim.pulses(pin, 500, 2000)  # 0.25 s of a 2 kHz encoder
    assert wheel.wait_for(lambda n: n >= 500, timeout=BOUND) == 500
    sim.pulses(pin, 100, 1000)
    assert wheel.wait_for(lambda n: n >= 600, timeout=BOUND) == 600


# --- interlocks ------------------------------------------------------------------------


def test_a_bumper_stops_the_motors_on_the_device(sim: SimBoard) -> None:
    """The issue's new user: a bumper that must stop the drive motors whatever the host does.
    Judged at the pin: on the emulated Uno the motor's PWM is at 0 within 1 ms of the edge
    (board time, the trace's clock)."""
    with Board.open(sim.port) as board:
        seen = events(board)
        motors = pins_for(board, PWM, 2)
        (bump,) = pins_for(board, DIGITAL_INPUT, avoid=motors)
        left, right = (board.pwm_output(pin, safe=0) for pin in motors)
        sim.set_level(bump, 1)
        bumper = board.digital_input(bump, pull_up=True, interlock="low")
        board.pose({left: 200, right: 150})
        wait_pwm(sim, left.pin, lambda v: v[-1:] == [200])
        wait_pwm(sim, right.pin, lambda v: v[-1:] == [150])
        mark = len(sim.trace())
        hit = sim.set_level(bump, 0)  # the bumper closes (to ground)
        wait_pwm(sim, left.pin, lambda v: v[-1:] == [0], since=mark)
        wait_pwm(sim, right.pin, lambda v: v[-1:] == [0], since=mark)
        # Each motor's first PWM 0 after it ran: the time its pin went low for good (the
        # emulated Uno dates it at the end of the last pulse, which may come before the
        # bumper's edge: then no pulse followed the edge).
        stopped = [
            next(e["t"] for e in sim.trace()[mark:] if e["pin"] == pin and e["value"] == 0)
            for pin in motors
        ]
        reaction = max(0.0, max(stopped) - hit)
        assert reaction <= 0.001, f"{reaction * 1000:.3f} ms from the bumper to the motors"
        event = wait_event(seen, EventKind.FAILSAFE)
        assert event.details["active"] and event.details["cause"] == "interlock"
        assert event.details["pin"] == bump
        assert left.value == 0 and right.value == 0
        # The trip's device time: the bumper's own report of the edge.
        assert bumper.wait_for(False, timeout=BOUND) is False
        tripped = bumper.reading()
        assert tripped is not None and tripped.value is False and tripped.time_ms > 0
        with pytest.raises(InterlockActiveError) as refused:
            left.write(100)
        assert refused.value.sent  # the device refused it
        with pytest.raises(InterlockActiveError):
            board.pose({left: 100, right: 100})
        with pytest.raises(InterlockActiveError):
            board.clear_interlock()  # the bumper is still pressed
        sim.set_level(bump, 1)
        assert bumper.wait_for(True, timeout=BOUND) is True
        board.clear_interlock()
        assert pwm_values(sim.trace()[mark:], left.pin)[-1] == 0  # safe until commanded
        left.write(120)
        wait_pwm(sim, left.pin, lambda v: v[-1:] == [120], since=mark)


#: Bumper hits per board in the reaction test, each at another phase of the PWM period.
BUMPER_TRIALS = 16


def test_the_bumper_stops_the_motor_within_1_ms_at_any_phase(sim: SimBoard) -> None:
    """The 1 ms bound at the pin holds wherever in the PWM period (1.024 ms on the Uno) the
    edge falls: a duty change that waits for the period's end would miss it there."""
    rng = random.Random(21)
    reactions: list[float] = []
    with Board.open(sim.port) as board:
        seen: list[Event] = []
        board.on_event(seen.append)
        (pwm,) = pins_for(board, PWM)
        (bump,) = pins_for(board, DIGITAL_INPUT, avoid=(pwm,))
        motor = board.pwm_output(pwm, safe=0)
        sim.set_level(bump, 1)
        bumper = board.digital_input(bump, pull_up=True, interlock="low")
        for trial in range(BUMPER_TRIALS):
            if trial:
                sim.set_level(bump, 1)
                bumper.wait_for(True, timeout=BOUND)
                board.clear_interlock()
            mark = len(sim.trace())
            motor.write(200)
            wait_pwm(sim, pwm, lambda v: v[-1:] == [200], since=mark)
            running = len(sim.trace())
            time.sleep(rng.uniform(0.0, 0.005))  # only moves the phase; the verdict is the trace's
            hit = sim.set_level(bump, 0)
            wait_pwm(sim, pwm, lambda v: 0 in v, since=running)
            low = next(e["t"] for e in sim.trace()[running:] if e["pin"] == pwm and e["value"] == 0)
            reactions.append(max(0.0, low - hit))
            # Only a host that has heard of a trip may clear it (its ClearInterlock carries
            # the trip's failsafe epoch): wait for the FAILSAFE event, which a Ping's Ack
            # brings if the device's notice was dropped on a busy line.
            _wait_trips(seen, trial + 1)
    slow = [f"{r * 1e6:.0f} us" for r in reactions if r > 0.001]
    assert not slow, f"{len(slow)} of {BUMPER_TRIALS} hits took over 1 ms: {slow}"


#: Bumper trips per board in the event-order test (issue 32 saw 9 of 10 wrong on one board).
EVENT_ORDER_TRIPS = 6


@pytest.mark.mega
def test_the_bumper_reads_pressed_when_its_failsafe_event_is_delivered(sim: SimBoard) -> None:
    """Issue 32: the interlock's FAILSAFE event reached the host before the report of the
    press, so at the event the bumper still read "released" and docs/api.md's recovery
    (wait for the release, then clear_interlock) was refused. Judged by events: what the
    board's view of the input says inside the event's own callback, trip after trip."""
    with Board.open(sim.port) as board:
        (pwm,) = pins_for(board, PWM)
        (bump,) = pins_for(board, DIGITAL_INPUT, avoid=(pwm,))
        motor = board.pwm_output(pwm, safe=0)
        sim.set_level(bump, 1)
        bumper = board.digital_input(bump, pull_up=True, interlock="low")
        at_event: list[bool | None] = []

        def on_event(event: Event) -> None:
            if event.kind is EventKind.FAILSAFE and event.details["cause"] == "interlock":
                at_event.append(bumper.read())

        def heard(trips: int) -> Callable[[], bool]:
            return lambda: len(at_event) >= trips

        board.on_event(on_event)
        for trip in range(EVENT_ORDER_TRIPS):
            motor.write(200)
            sim.set_level(bump, 0)  # pressed
            assert wait_until(heard(trip + 1), BOUND), "no interlock event"
            sim.set_level(bump, 1)  # released: the pattern of docs/api.md
            assert bumper.wait_for(True, timeout=BOUND) is True
            board.clear_interlock()  # refused when the wait above saw the stale level
        assert at_event == [False] * EVENT_ORDER_TRIPS


@pytest.mark.mega
def test_aio_inputs_without_blocking_the_loop(sim: SimBoard) -> None:
    async def main() -> None:
        async with await aio.open(sim.port) as board:
            (pwm,) = pins_for(board.info, PWM)
            (pin,) = pins_for(board.info, DIGITAL_INPUT, avoid=(pwm,))
            await asyncio.to_thread(sim.set_level, pin, 1)
            button = await board.digital_input(pin, pull_up=True)
            assert button.read() is True
            motor = await board.pwm_output(pwm)
            await motor.write(64)
            async with button.changes() as changes:
                await asyncio.to_thread(sim.set_level, pin, 0)
                async with asyncio.timeout(BOUND):
                    reading = await anext(changes)
            assert reading.value is False and reading.pin == pin
            await asyncio.to_thread(sim.set_level, pin, 1)
            assert await button.wait_for(True, timeout=BOUND) is True
        wait_pwm(sim, pwm, lambda v: 64 in v)

    asyncio.run(main())


def test_host_input_refusals_are_the_devices(board: Board) -> None:
    """Each input refusal the host makes before sending is the one the device makes, in the
    device's order of checks (docs/protocol.md section 7, rules 13 and 14)."""
    board.servo(9)

    def analog(pin: int, threshold: int = 0, interval_ms: int = 10) -> ArduinoIn:
        msg = ArduinoIn()
        init = msg.analog_input_init
        init.pin, init.threshold, init.interval_ms = pin, threshold, interval_ms
        return msg

    def digital(pin: int, debounce_ms: int = 0) -> ArduinoIn:
        msg = ArduinoIn()
        msg.digital_input_init.pin, msg.digital_input_init.debounce_ms = pin, debounce_ms
        return msg

    def counter(pin: int) -> ArduinoIn:
        msg = ArduinoIn()
        msg.counter_init.pin = pin
        return msg

    def pwm_init(pin: int, safe: int) -> ArduinoIn:
        msg = ArduinoIn()
        msg.pwm_init.pin, msg.pwm_init.safe_duty = pin, safe
        return msg

    cases: list[tuple[Callable[[], object], ArduinoIn]] = [
        (lambda: board.analog_input(2), analog(2)),  # no ADC there
        (lambda: board.analog_input(14, threshold=1024), analog(14, threshold=1024)),
        (lambda: board.analog_input(14, rate_hz=1000 / 60001), analog(14, interval_ms=60001)),
        (lambda: board.digital_input(2, debounce_ms=256), digital(2, debounce_ms=256)),
        (lambda: board.digital_input(9), digital(9)),  # a servo holds it
        (lambda: board.counter(14), counter(14)),  # no interrupt there
        (lambda: board.counter(9), counter(9)),
        # Two faults at once: the device's order decides which one is named.
        (lambda: board.digital_input(1, debounce_ms=300), digital(1, debounce_ms=300)),
        (lambda: board.digital_input(25), digital(25)),
        (lambda: board.analog_input(25, threshold=2000), analog(25, threshold=2000)),
        (lambda: board.analog_input(1, threshold=2000), analog(1, threshold=2000)),
        (lambda: board.analog_input(1), analog(1)),
        (lambda: board.pwm_output(5, safe=300), pwm_init(5, 300)),
        (lambda: board.pwm_output(9, safe=300), pwm_init(9, 300)),  # a servo runs
        (lambda: board.pwm_output(4, safe=300), pwm_init(4, 300)),
    ]
    for host, device in cases:
        with pytest.raises(protoduino.CommandRejectedError) as refused:
            host()
        assert not refused.value.sent
        assert _request(board, device) == refused.value.status, device


def test_reports_keep_flowing_while_commands_flow_back_to_back(sim: SimBoard) -> None:
    """Freshness under load: Acks go first, but a host sending commands back to back must
    still hear its inputs. Judged on the device's clock (the reports' time_ms): every analog
    channel is reported throughout, never more than GAP_MS apart."""
    gap_ms = 50
    with Board.open(sim.port) as board:
        pots = [
            board.analog_input(pin, rate_hz=200, heartbeat=0.005) for pin in board.info.analog_pins
        ]
        times: dict[int, list[int]] = {pot.pin: [] for pot in pots}

        def record(rec: Any) -> None:  # the I/O thread: collect the reports' device times
            item = rec.item
            if rec.direction != "rx" or not isinstance(item, Packet):
                return
            if item.type is not PacketType.DATA:
                return
            msg = parse_out(item.payload)
            if msg.WhichOneof("data") == "input_report":
                for pin, seen in times.items():
                    if pin in pins_in(msg.input_report.analog_pins):
                        seen.append(msg.input_report.time_ms)

        board.add_frame_monitor(record)
        pings = 0
        deadline = time.monotonic() + BOUND
        while time.monotonic() < deadline:
            board.ping()
            pings += 1
            spans = [t[-1] - t[0] for t in times.values() if t]
            if len(spans) == len(times) and min(spans) >= 500:  # half a second of device time
                break
        for pin, seen in times.items():
            assert seen, f"pin {pin}: no report in {pings} back-to-back pings"
            gaps = [b - a for a, b in itertools.pairwise(seen)]
            assert max(gaps, default=0) <= gap_ms, f"pin {pin}: reports {gaps} ms apart"


@pytest.mark.mega
def test_restore_last_never_brings_back_a_duty_from_before_an_interlock(sim: SimBoard) -> None:
    """restore="last" after a reboot sends the last values, but a value the interlock
    overrode is gone: the motor comes back at its safe duty, judged at the pin."""
    with Board.open(sim.port, restore="last") as board:
        seen = events(board)
        (pwm,) = pins_for(board, PWM)
        (bump,) = pins_for(board, DIGITAL_INPUT, avoid=(pwm,))
        motor = board.pwm_output(pwm, safe=0)
        motor.write(180)
        wait_pwm(sim, pwm, lambda v: v[-1:] == [180])
        sim.set_level(bump, 1)
        bumper = board.digital_input(bump, pull_up=True, interlock="low")
        sim.set_level(bump, 0)
        wait_event(seen, EventKind.FAILSAFE)
        sim.set_level(bump, 1)
        bumper.wait_for(True, timeout=BOUND)
        board.clear_interlock()
        mark = len(sim.trace())
        sim.reboot()
        wait_event(seen, EventKind.RESTORED)
        assert board.read_outputs()[pwm].value == 0  # the device drives the safe duty
        assert motor.value == 0
        motor.write(50)  # a later change: every earlier one is in the trace before it
        wait_pwm(sim, pwm, lambda v: v[-1:] == [50], since=mark)
        assert 180 not in pwm_values(sim.trace()[mark:], pwm)


@pytest.mark.mega
def test_the_interlock_is_back_after_a_reboot(sim: SimBoard) -> None:
    """A device that rebooted forgot its interlock; the restore gives it back before the
    motor can run again, so the bumper still stops it (judged at the pin)."""
    with Board.open(sim.port) as board:
        seen = events(board)
        (pwm,) = pins_for(board, PWM)
        (bump,) = pins_for(board, DIGITAL_INPUT, avoid=(pwm,))
        motor = board.pwm_output(pwm, safe=0)
        sim.set_level(bump, 1)
        board.digital_input(bump, pull_up=True, interlock="low")
        sim.reboot()
        wait_event(seen, EventKind.RESTORED)
        motor.write(220)
        wait_pwm(sim, pwm, lambda v: v[-1:] == [220])
        mark = len(sim.trace())
        sim.set_level(bump, 0)
        wait_pwm(sim, pwm, lambda v: v[-1:] == [0], since=mark)
        event = wait_event(seen, EventKind.FAILSAFE)
        assert event.details["cause"] == "interlock" and event.details["pin"] == bump
        with pytest.raises(InterlockActiveError):
            motor.write(220)
