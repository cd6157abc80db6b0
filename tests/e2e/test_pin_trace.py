"""The trace says what the pin did (issue 36, item 6), on both boards.

A pin's mode in the trace is what the firmware configured (on the emulated Uno the runner
reads it from the MCU's RAM: the PWM driver's pins, the servo driver's channel table), not
a guess from the waveform's shape, and no level change is dropped: the same lines on the
native board and on the emulated Uno for the same writes. The fastest writes come from a
test service (tests/e2e/toggler) that toggles a pin 1 to 3 ms apart on the board's own
clock, faster than a host could and as fast as a servo's pulses come.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino.commands import PWM
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, pins_for, wait_for_pin
from userbuilds import client, need, program

BACKENDS = ["native", "avr"]
PIN = 12
#: Level changes the service makes: 1, 0, 1, ... ending low.
EDGES = 30
#: The service's gaps after its second edge, in the board's milliseconds (toggler.c).
GAPS_MS = (3, 1, 2)
#: How late the service's poll may run after the millisecond tick that wakes the emulated
#: MCU (a frame being decoded meanwhile), in emulated seconds.
POLL_SLACK_S = 0.0005
#: The emulated Uno's clock tick: Timer0's overflow (16 MHz / 64 / 256), which adds 1 ms to
#: the board's milliseconds, and 2 once every 41 or 42 ticks (the 24 us a tick runs over, as
#: the Arduino core's millis() does: firmware/avr/pd_avr_clock.c).
TICK_S = 0.001024


@pytest.fixture(params=BACKENDS)
def toggler_sim(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SimBoard]:
    backend: str = request.param
    need(backend)
    sim = SimBoard(backend, trace=tmp_path / "trace.jsonl", firmware=program("toggler", backend))
    sim.start()
    try:
        yield sim
    finally:
        sim.stop()


def test_a_pin_toggled_every_few_milliseconds_shows_every_edge_as_digital(
    toggler_sim: SimBoard, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Today's emulated Uno took highs of 1-3 ms for servo pulses: `servo` lines, edges
    dropped. Every level change is a digital line, at its time on the emulated clock."""
    mod = client("toggler", monkeypatch)
    pbu: Any = mod.pb
    with protoduino.Board.open(toggler_sim.port) as board:
        assert mod.Toggler(board).start(pbu.Run(pin=PIN, edges=EDGES)).pin == PIN
        wait_for_pin(toggler_sim, PIN, lambda v: len(v) >= EDGES)
    rows = [e for e in toggler_sim.trace() if e["pin"] == PIN]
    assert [(e["mode"], e["value"]) for e in rows] == [("digital", n % 2 ^ 1) for n in range(EDGES)]
    if toggler_sim.backend == "avr":  # the emulated clock: each edge at its millisecond tick
        gaps = [b["t"] - a["t"] for a, b in itertools.pairwise(rows)]
        assert 0 < gaps[0] <= TICK_S + POLL_SLACK_S, gaps
        short = 0  # gaps of N ms in N - 1 ticks: the clock stepped by 2 ms in them
        for n, gap in enumerate(gaps[1:]):
            ticks = round(gap / TICK_S)
            assert abs(gap - ticks * TICK_S) <= POLL_SLACK_S, (n, gaps)
            assert ticks in (GAPS_MS[n % 3], GAPS_MS[n % 3] - 1), (n, gaps)
            short += ticks < GAPS_MS[n % 3]
        assert short <= 1 + sum(gaps[1:]) / TICK_S // 41, (short, gaps)


@pytest.mark.mega
def test_a_servo_released_then_a_digital_output_on_its_pin_gives_the_same_lines_on_both_boards(
    sim_board: SimBoard,
) -> None:
    """The emulated Uno reads the servo driver's table: attached, the pin is a servo from its
    first pulse (no digital line before it); detached, a value-0 servo line; then a digital
    output there is digital at its first edge, with no line the native board does not write."""
    with protoduino.Board.open(sim_board.port) as board:
        board.servo(9, safe_us=1500)
        wait_for_pin(sim_board, 9, lambda v: len(v) > 0 and abs(v[-1] - 1500) <= PULSE_TOLERANCE_US)
        board.release(9)
        wait_for_pin(sim_board, 9, lambda v: v[-1:] == [0])
        output = board.digital_output(9, safe=True)
        wait_for_pin(sim_board, 9, lambda v: v[-1:] == [1])
        output.write(False)
        wait_for_pin(sim_board, 9, lambda v: v[-2:] == [1, 0])
    rows = [(e["mode"], e["value"]) for e in sim_board.trace() if e["pin"] == 9]
    assert [mode for mode, _ in rows] == ["servo", "servo", "digital", "digital"], rows
    assert abs(rows[0][1] - 1500) <= PULSE_TOLERANCE_US, rows
    assert [value for _, value in rows[1:]] == [0, 1, 0], rows


def test_a_digital_output_beside_a_pwm_pin_of_its_timer_is_digital_on_both_boards(
    sim_board: SimBoard,
) -> None:
    """Pins 3 and 11 share Timer2. With 3 making PWM, the emulated Uno took 11, a digital
    output, for PWM (its timer's mode said so): `pwm` 0 and 255 once steady, never `digital`.
    The runner reads which pins the firmware's PWM driver runs: 11 is digital, every edge,
    and 3 is PWM at any duty, 255 (a steady level) included."""
    with protoduino.Board.open(sim_board.port) as board:
        motor = board.pwm_output(3)
        motor.write(100)
        wait_for_pin(sim_board, 3, lambda v: v[-1:] == [100])
        lamp = board.digital_output(11)
        lamp.write(True)
        wait_for_pin(sim_board, 11, lambda v: v[-1:] == [1])
        lamp.write(False)
        wait_for_pin(sim_board, 11, lambda v: v[-2:] == [1, 0])
        motor.write(255)
        wait_for_pin(sim_board, 3, lambda v: v[-1:] == [255])
    trace = sim_board.trace()
    lamp_rows = [(e["mode"], e["value"]) for e in trace if e["pin"] == 11]
    assert lamp_rows == [("digital", 0), ("digital", 1), ("digital", 0)], lamp_rows
    motor_rows = [(e["mode"], e["value"]) for e in trace if e["pin"] == 3]
    assert {mode for mode, _ in motor_rows} == {"pwm"}, motor_rows
    assert [value for _, value in motor_rows][-2:] == [100, 255], motor_rows


@pytest.mark.mega
def test_a_pwm_duty_of_0_held_for_a_moment_shows_on_both_boards(sim_board: SimBoard) -> None:
    """Duty 0 disconnects the timer and holds the pin low. The emulated Uno showed it only
    after 5 ms without an edge, so a 0 written between two other duties (two commands in
    one burst, a millisecond or two apart on the board) was dropped. The runner reads that
    the PWM driver holds the level: the 0 is a line at once, as on the native board."""
    with protoduino.Board.open(sim_board.port) as board:
        (pin,) = pins_for(board, PWM)
        motor = board.pwm_output(pin)
        wait_for_pin(sim_board, pin, lambda v: v == [0])
        motor.write(100)
        wait_for_pin(sim_board, pin, lambda v: v[-1:] == [100])
        brief = motor.submit(0)
        motor.write(100)
        brief.result(timeout=10)
        wait_for_pin(sim_board, pin, lambda v: len(v) >= 4)
    rows = [(e["mode"], e["value"]) for e in sim_board.trace() if e["pin"] == pin]
    assert rows == [("pwm", 0), ("pwm", 100), ("pwm", 0), ("pwm", 100)], rows
