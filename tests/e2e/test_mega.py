"""The Mega 2560 (issue 36 items 1 and 2): the firmware's ``make avr BOARD=mega`` build on the
emulated ATmega2560 (``SimBoard("avr", board="mega")``), judged at its pins through the trace.

The build serves every pin, 0..69 (firmware/README.md, The Mega 2560; pin sets of any width
since protocol version 8): the Mega's own ports A, C, G, L, B and K (pins 22..53, A8..A15 =
62..69) carry digital outputs, inputs and servos (24 of them: Timer1's and Timer5's interrupts
write the pulses through the port), Timer2 makes PWM on pins 9 and 10, Timer3 on 5, 2, 3,
Timer4 on 6, 7, 8, Timer1 on 11 and 12 and Timer5 on 44..46 while no servo runs on them, Timer0
keeps the clock (pins 4 and 13 refused), the six external interrupts count, A0..A15 read
analog. The host has no table of the Mega's: every refusal here comes from the pin table of
its DeviceInfo.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from boardprocess import detached_sim_info, missing_tool
from protoduino import Board, EventKind, PwmOutput
from protoduino._generated import protoduino_pb2 as pb
from protoduino.errors import CommandRejectedError, NotSupportedError, TimerInUseError
from protoduino.messages import ArduinoIn, Status
from protoduino.simboard import SimBoard
from protoduino_dev import build, rambudget
from protoduino_dev.runnerstats import snapshot
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin, wait_until

pytestmark = pytest.mark.avr

#: Bounds a failing test's wait only; the verdicts are the trace's.
BOUND = 30.0


def _need_tools() -> None:
    missing = missing_tool("make", "cc", "avr-gcc", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")


@pytest.fixture
def mega(tmp_path: Path) -> Iterator[SimBoard]:
    _need_tools()
    sim = SimBoard("avr", board="mega", trace=tmp_path / "trace.jsonl")
    sim.start()
    try:
        yield sim
    finally:
        sim.stop()


def _values(sim: SimBoard, pin: int, mode: str) -> list[int]:
    return [int(e["value"]) for e in sim.trace() if e["pin"] == pin and e["mode"] == mode]


def _wait(sim: SimBoard, pin: int, mode: str, ok: Callable[[list[int]], bool]) -> list[int]:
    assert wait_until(lambda: ok(_values(sim, pin, mode)), BOUND), _values(sim, pin, mode)
    return _values(sim, pin, mode)


def _last(value: int) -> Callable[[list[int]], bool]:
    """The pin's last value is ``value``."""
    return lambda values: values[-1:] == [value]


def _equals(value: int) -> Callable[[int], bool]:
    return lambda count: count == value


def test_the_mega_states_its_pins_and_the_host_refuses_from_them(mega: SimBoard) -> None:
    """Its DeviceInfo names the board and its pin table; the host, which has no Mega table,
    refuses from that table what the device would refuse, for the table's reason."""
    with Board.open(mega.port) as board:
        info = board.info
        assert (info.board, info.num_pins, info.max_servos) == ("mega", 70, 24)
        assert info.pwm_pins == (2, 3, 5, 6, 7, 8, 9, 10, 11, 12, 44, 45, 46)
        assert info.analog_pins == tuple(range(54, 70))  # A0..A15
        assert info.counter_pins == (2, 3, 18, 19, 20, 21)
        pins = info.pins
        assert pins[0] == pins[1] == 0  # the link: UART0
        assert pins[22:32] == bytes([pb.PIN_DIGITAL] * 10)
        assert all(pins[p] & pb.PIN_PWM for p in (9, 10, 11, 12))
        assert not pins[22] & pb.PIN_PWM  # PA0: no timer output
        with pytest.raises(TimerInUseError) as clock:
            board.pwm_output(13)  # OC0A: Timer0 is the clock
        assert not clock.value.sent
        with pytest.raises(NotSupportedError) as no_pwm:
            board.pwm_output(22)
        assert not no_pwm.value.sent
        msg = ArduinoIn()
        msg.pwm_init.pin = 13
        with pytest.raises(TimerInUseError) as device:
            board.request(msg)  # no host check on the way: the device's own answer
        assert device.value.status == Status.STATUS_TIMER_IN_USE
        board.servo(30)
        with pytest.raises(TimerInUseError):
            board.pwm_output(11)  # OC1A: Timer1 makes the servo pulses now


def test_digital_outputs_on_the_mega_ports_at_the_pins(mega: SimBoard) -> None:
    """Pins 22..31 (ports A and C) in one pose: each pin shows its level in the trace."""
    with Board.open(mega.port) as board:
        outs = {pin: board.digital_output(pin) for pin in range(22, 32)}
        board.pose({out: pin % 2 == 1 for pin, out in outs.items()})
        for pin in range(22, 32):
            wait_for_pin(mega, pin, _last(pin % 2), BOUND)
        board.pose({out: pin % 2 == 0 for pin, out in outs.items()})
        for pin in range(22, 32):
            wait_for_pin(mega, pin, _last(1 - pin % 2), BOUND)


#: Pins past the 32 a version 7 pin mask held: ports G, L, B (40..53) and K (A8..A15, 62..69).
HIGH_PINS = (*range(40, 54), *range(62, 70))


def test_digital_outputs_past_pin_31_at_the_pins(mega: SimBoard) -> None:
    """Pins 40..53 and A8..A15 used digitally (62..69), in one pose (the Pose's pin sets reach
    byte 8): each pin shows its level in the trace, and ReadOutputs reads them back."""
    with Board.open(mega.port) as board:
        outs = {pin: board.digital_output(pin) for pin in HIGH_PINS}
        board.pose({out: pin % 3 == 0 for pin, out in outs.items()})
        for pin in HIGH_PINS:
            wait_for_pin(mega, pin, _last(int(pin % 3 == 0)), BOUND)
        states = board.read_outputs()
        assert {p: (s.mode, s.value) for p, s in states.items()} == {
            pin: ("digital", int(pin % 3 == 0)) for pin in HIGH_PINS
        }
        outs[69].write(False)
        outs[68].write(True)
        wait_for_pin(mega, 69, _last(0), BOUND)
        wait_for_pin(mega, 68, _last(1), BOUND)


@pytest.mark.parametrize(
    "pins",
    [tuple(range(24, 32)), (44, 49, 53, 62, 69)],
    ids=["ports A and C", "past pin 31"],
)
def test_servos_in_one_pose_at_the_pins(mega: SimBoard, pins: tuple[int, ...]) -> None:
    """Servos on pins 24..31 (PA2..PA7, PC7, PC6), and past the 32 pins a version 7 pin mask
    held: 44, 49, 53 (ports L and B) and A8, A15 (62, 69): the widths of one pose at the pins."""
    with Board.open(mega.port) as board:
        servos = {pin: board.servo(pin) for pin in pins}
        degrees = {pin: (pin * 7) % 170 + 5 for pin in servos}
        widths = {pin: servos[pin].to_us(deg) for pin, deg in degrees.items()}
        board.pose({servos[pin]: deg for pin, deg in degrees.items()})

        def at(pin: int) -> Callable[[list[int]], bool]:
            return lambda v: bool(v) and abs(v[-1] - widths[pin]) <= PULSE_TOLERANCE_US

        for pin in servos:
            _wait(mega, pin, "servo", at(pin))


def test_digital_inputs_past_pin_31(mega: SimBoard) -> None:
    """Pins 45 (PL4) and 66 (A12, PK4): the levels the control socket holds there reach the
    host in the InputReport's pin sets."""
    with Board.open(mega.port) as board:
        switches = {pin: board.digital_input(pin) for pin in (45, 66)}
        for pin, switch in switches.items():
            mega.control.level(pin, 1)
            assert switch.wait_for(True, timeout=BOUND) is True  # the bound only ends a failure
            mega.control.level(pin, 0)
            assert switch.wait_for(False, timeout=BOUND) is False


def test_the_host_refuses_pin_70_from_the_mega_info(mega: SimBoard) -> None:
    """Pin 70 is past the Mega's num_pins: refused before anything is sent; the device refuses
    it too, for the same reason."""
    with Board.open(mega.port) as board:
        for make in (board.digital_output, board.servo, board.digital_input):
            with pytest.raises(CommandRejectedError) as host:
                make(70)
            assert host.value.status == Status.STATUS_INVALID_PIN and not host.value.sent
        msg = ArduinoIn()
        msg.digital_init.pin = 70
        with pytest.raises(CommandRejectedError) as device:
            board.request(msg)
        assert device.value.status == Status.STATUS_INVALID_PIN and device.value.sent


def test_the_mega_states_its_two_servo_timers(mega: SimBoard) -> None:
    """Its DeviceInfo says the servos hold Timer1 and Timer5 (12 channels each) and the clock
    Timer0, and that Timer1's PWM pins, 11 and 12, and Timer5's, 44..46, need theirs."""
    with Board.open(mega.port) as board:
        info = board.info
        assert info.timers == bytes(
            [
                pb.TIMER_CLOCK,
                pb.TIMER_SERVOS,
                pb.TIMER_FREE,
                pb.TIMER_FREE,
                pb.TIMER_FREE,
                pb.TIMER_SERVOS,
            ]
        )
        assert [info.timer_use(t) for t in (1, 5)] == ["servos", "servos"]
        assert info.timer_pins("servos") == (11, 12, 44, 45, 46)
        assert [info.timer(p) for p in (4, 11, 12, 13, 44, 45, 46)] == [0, 1, 1, 0, 5, 5, 5]


def test_twenty_four_servos_from_three_poses(mega: SimBoard) -> None:
    """24 servos on pins 4..27, both timers' channels, set by three poses of eight (the Pose's
    most items): every width at its pin is the one posed, and ReadOutputs (120 B of servos, a
    reply of more than 127 B) says the same of all 24. Pins 18 and 19 are INT3 and INT2: before
    the runner stopped simavr polling every external interrupt's low level, servos there
    silenced the emulated Mega's link."""
    pins = list(range(4, 28))
    with Board.open(mega.port) as board:
        servos = {pin: board.servo(pin) for pin in pins}
        degrees = {pin: 5 + 7 * n for n, pin in enumerate(pins)}  # 5 .. 166: 24 widths
        widths = {pin: servos[pin].to_us(deg) for pin, deg in degrees.items()}
        for first in range(0, 24, 8):
            board.pose({servos[pin]: degrees[pin] for pin in pins[first : first + 8]})

        def at(pin: int) -> Callable[[list[int]], bool]:
            return lambda v: bool(v) and abs(v[-1] - widths[pin]) <= PULSE_TOLERANCE_US

        for pin in pins:
            _wait(mega, pin, "servo", at(pin))
        states = board.read_outputs()
        assert {pin: (s.mode, s.value, s.target) for pin, s in states.items()} == {
            pin: ("servo", widths[pin], widths[pin]) for pin in pins
        }
        with pytest.raises(CommandRejectedError) as full:
            board.servo(2)  # a 25th: the host refuses from max_servos alone
        assert full.value.status == Status.STATUS_NO_FREE_RESOURCE and not full.value.sent


def test_pwm_on_timer2_and_timer1_pins(mega: SimBoard) -> None:
    """Pins 9 and 10 (Timer2's OC2B, OC2A) and 11, 12 (Timer1's OC1A, OC1B): the duty
    measured at each pin is the one written."""
    duties = {9: 60, 10: 200, 11: 128, 12: 30}
    with Board.open(mega.port) as board:
        for pin, duty in duties.items():
            board.pwm_output(pin).write(duty)
        for pin, duty in duties.items():
            _wait(mega, pin, "pwm", _last(duty))


def _pwm_at_the_pins(mega: SimBoard, board: Board, duties: dict[int, int]) -> dict[int, PwmOutput]:
    """PWM outputs on ``duties``' pins, each written its duty and seen at its pin."""
    outs = {pin: board.pwm_output(pin) for pin in duties}
    for pin, duty in duties.items():
        outs[pin].write(duty)
    for pin, duty in duties.items():
        _wait(mega, pin, "pwm", _last(duty))
    return outs


def test_pwm_on_timer3_and_timer4_pins(mega: SimBoard) -> None:
    """Pins 5, 2, 3 (Timer3's OC3A..C) and 6, 7, 8 (Timer4's): the duty measured at each pin
    is the one written, and stays so while servos run on both servo timers (Timers 3 and 4
    make no servo pulses); Timer1's 11 is refused then, by the host from the pin table."""
    duties = {5: 60, 2: 200, 3: 128, 6: 30, 7: 250, 8: 1}
    with Board.open(mega.port) as board:
        outs = _pwm_at_the_pins(mega, board, duties)
        servos = [board.servo(pin) for pin in (*range(20, 32), 4, 13)]  # 13, 14: Timer5's
        with pytest.raises(TimerInUseError) as timer1:
            board.pwm_output(11)
        assert not timer1.value.sent
        board.pose({outs[pin]: 255 - duty for pin, duty in duties.items()})
        for pin, duty in duties.items():
            _wait(mega, pin, "pwm", _last(255 - duty))
        width = servos[-1].to_us(90)
        _wait(mega, 13, "servo", lambda v: bool(v) and abs(v[-1] - width) <= PULSE_TOLERANCE_US)


def test_pwm_on_timer5_pins_past_pin_31(mega: SimBoard) -> None:
    """Pins 46, 45, 44 (Timer5's OC5A..C, a servo timer): the duty measured at each pin is the
    one written while no servo runs, and a servo is refused then (its timer makes PWM)."""
    with Board.open(mega.port) as board:
        _pwm_at_the_pins(mega, board, {46: 40, 45: 128, 44: 220})
        with pytest.raises(TimerInUseError):
            board.servo(30)


def test_digital_inputs_on_the_mega(mega: SimBoard) -> None:
    """Pin 10 (PB4, a pin-change interrupt) and pin 30 (PC7, none: read at the clock tick)
    read the levels the control socket holds there."""
    with Board.open(mega.port) as board:
        for pin in (10, 30):
            mega.control.level(pin, 1)
            switch = board.digital_input(pin)
            assert switch.wait_for(True, timeout=BOUND) is True  # the bound only ends a failure
            mega.control.level(pin, 0)
            assert switch.wait_for(False, timeout=BOUND) is False
            assert switch.read() is False


def test_counters_on_the_six_external_interrupts(mega: SimBoard) -> None:
    """Pins 2, 3 (INT4, INT5: senses in EICRB) and 18..21 (INT3..INT0: EICRA), two at a
    time (the core's counter slots): each counts the pulses the control socket makes on it."""
    with Board.open(mega.port) as board:
        for pins in ((2, 3), (18, 19), (20, 21)):
            counters = {pin: board.counter(pin) for pin in pins}
            for pin in pins:
                mega.control.pulses(pin, pin + 10, 2000)
            for pin, counter in counters.items():
                assert counter.wait_for(_equals(pin + 10), timeout=BOUND) == pin + 10
            for pin in pins:
                board.release(pin)


def test_the_failsafe_drives_the_mega_outputs_safe(mega: SimBoard) -> None:
    """A Ping-fed failsafe timing out: the digital output, the PWM output and the servo go
    to their safe values at the pins."""
    with Board.open(mega.port, failsafe_timeout=0.3) as board:
        seen: list[Any] = []
        board.on_event(seen.append)
        lamp = board.digital_output(25, safe=False)
        motor = board.pwm_output(9, safe=7)
        arm = board.servo(31, safe_us=1500)
        board.pose({lamp: True, motor: 200, arm: 160})
        wait_for_pin(mega, 25, lambda v: v[-1:] == [1], BOUND)
        _wait(mega, 9, "pwm", lambda v: v[-1:] == [200])
        moved = arm.to_us(160)
        _wait(mega, 31, "servo", lambda v: bool(v) and abs(v[-1] - moved) <= PULSE_TOLERANCE_US)
        board.pinging = False  # the device hears nothing more: its failsafe fires
        assert wait_until(lambda: any(e.kind == EventKind.FAILSAFE for e in seen), BOUND)
        wait_for_pin(mega, 25, lambda v: v[-1:] == [0], BOUND)
        _wait(mega, 9, "pwm", lambda v: v[-1:] == [7])
        _wait(mega, 31, "servo", lambda v: abs(v[-1] - 1500) <= PULSE_TOLERANCE_US)


@pytest.mark.parametrize("backend", ["avr", "native"])
def test_protoduino_sim_starts_the_mega(tmp_path: Path, backend: str) -> None:
    """`protoduino sim --backend avr --board mega` (the one documented option) runs the emulated
    Mega, `protoduino sim --board mega` the simulated board with its pins: `protoduino info`
    reads the board and its 70 pins from either."""
    _need_tools()
    stated = detached_sim_info(tmp_path / "sim.pid", "--backend", backend, "--board", "mega")
    assert (stated["board"], stated["num_pins"]) == ("mega", 70), stated


@pytest.fixture
def megas(tmp_path: Path) -> Iterator[dict[str, SimBoard]]:
    """The emulated Mega and the simulated board with the Mega's pins, side by side."""
    _need_tools()
    boards = {
        backend: SimBoard(backend, board="mega", trace=tmp_path / f"{backend}.jsonl")
        for backend in ("avr", "native")
    }
    try:
        for sim in boards.values():
            sim.start()
        yield boards
    finally:
        for sim in boards.values():
            sim.stop()


def test_the_native_mega_states_the_mega_build_s_pins(megas: dict[str, SimBoard]) -> None:
    """`SimBoard("native", board="mega")` serves the Mega build's own table (one declaration of
    the Mega's pins, avr/pd_avr_mega.c): its DeviceInfo is the emulated Mega's but for the
    link's buffer."""
    infos = {}
    for backend, sim in megas.items():
        with Board.open(sim.port) as board:
            infos[backend] = board.info
    native, avr = infos["native"], infos["avr"]
    assert (native.board, native.num_pins) == ("mega", 70)
    assert (native.pins, native.timers) == (avr.pins, avr.timers)
    assert (native.reserved_pins, native.max_servos, native.features) == (
        avr.reserved_pins,
        avr.max_servos,
        avr.features,
    )


#: Digital writes on pins of every port past 31 and on A15: levels in the order written.
MEGA_WRITES = ((22, 1), (40, 1), (53, 1), (69, 1), (40, 0), (62, 1), (69, 0), (53, 0))


def test_the_same_mega_writes_give_the_same_trace_lines_on_both(
    megas: dict[str, SimBoard],
) -> None:
    """The same digital writes and servo widths on the emulated Mega and the native one: each
    pin's trace lines (its mode and values, in order; a servo's width within the emulated
    pin's measurement) are the same on both."""
    pins = sorted({pin for pin, _ in MEGA_WRITES})
    for sim in megas.values():
        with Board.open(sim.port) as board:
            outs = {pin: board.digital_output(pin) for pin in pins}
            arm = board.servo(44)
            for pin, level in MEGA_WRITES:
                outs[pin].write(bool(level))
                wait_for_pin(sim, pin, _last(level), BOUND)
            arm.write_us(1200)
            _wait(sim, 44, "servo", lambda v: bool(v) and abs(v[-1] - 1200) <= PULSE_TOLERANCE_US)
    lines = {
        backend: {
            pin: [(e["mode"], int(e["value"])) for e in sim.trace() if e["pin"] == pin]
            for pin in pins
        }
        for backend, sim in megas.items()
    }
    assert lines["native"] == lines["avr"]
    want = {
        pin: [("digital", 0)] + [("digital", v) for p, v in MEGA_WRITES if p == pin] for pin in pins
    }
    assert lines["native"] == want
    servo = {backend: _values(sim, 44, "servo") for backend, sim in megas.items()}
    assert servo["native"][-1] == 1200
    assert abs(servo["avr"][-1] - servo["native"][-1]) <= PULSE_TOLERANCE_US


#: Analog inputs on both halves of the ADC's multiplexer (A8..A15 need ADCSRB's MUX5): six,
#: the core's analog slots (PD_MAX_ANALOG_INPUTS) and an InputReport's most values.
ANALOG = {"A0": 100, "A7": 300, "A8": 555, "A9": 700, "A14": 901, "A15": 1023}


@pytest.mark.parametrize("backend", ["avr", "native"])
def test_analog_inputs_a0_to_a15(tmp_path: Path, backend: str) -> None:
    """A0..A15 are pins 54..69 in the Mega's DeviceInfo; the control socket's counts on six
    of them (A0, A7; A8, A9, A14, A15 through MUX5) reach the host's analog inputs, and a new
    value on A15 follows."""
    _need_tools()
    sim = SimBoard(backend, board="mega")
    sim.start()
    with sim, Board.open(sim.port) as board:
        assert board.info.analog_pins == tuple(range(54, 70))
        assert [board.pin_number(f"A{n}") for n in (0, 8, 15)] == [54, 62, 69]
        for name, counts in ANALOG.items():
            sim.control.analog(board.pin_number(name), counts)
        inputs = {name: board.analog_input(name) for name in ANALOG}
        for name, counts in ANALOG.items():
            assert inputs[name].wait_for(_equals(counts), timeout=BOUND) == counts
        sim.control.analog(69, 42)
        assert inputs["A15"].wait_for(_equals(42), timeout=BOUND) == 42
        assert inputs["A14"].read() == 901


#: The Mega 2560's RAM (0x200 .. RAMEND = 0x21FF).
MEGA_RAM = 8_192


def test_the_mega_ram_budget_holds(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The Uno's deepest-stack scenario (rambudget.exercise: every command at its largest, four
    in flight, counters, digital and analog inputs (A0, A15) reporting) on the
    emulated Mega, whose runner records the lowest stack pointer: static data + the deepest
    stack + 256 B free fit the Mega's 8,192 B."""
    _need_tools()
    stats = tmp_path / "stats.jsonl"
    sim = SimBoard(
        "avr", board="mega", options=("--stats", str(stats), "--stack", str(tmp_path / "stack"))
    )
    sim.start()
    try:
        with Board.open(sim.port, window=4) as board:
            # Counters on INT4 and INT0 (pins 2 and 21): the Mega has no pin-change counter.
            rambudget.exercise(board, sim.control, analog_pins=(54, 69), counter_pins=(2, 21))
        row = snapshot(sim.pid, stats)
    finally:
        sim.stop()
    sections = rambudget.sections(build.build_firmware_board("mega"))
    static = sections.get(".data", 0) + sections.get(".bss", 0) + sections.get(".noinit", 0)
    assert row["ramend"] == MEGA_RAM + 0x200 - 1 and row["sp_min"] < row["ramend"], row
    stack = int(row["ramend"]) - int(row["sp_min"])
    free = MEGA_RAM - static - stack
    with capsys.disabled():
        sys.stdout.write(
            f"\nMega RAM: static {static} B + deepest stack {stack} B; "
            f"{free} B free of {MEGA_RAM}\n"
        )
    assert free >= rambudget.FREE_BYTES
