"""Protocol version 5's message ids on both boards: sequential 1..127, wrapping, exactly once.

A session's ids wrap every 127; the device tells a retransmission from a new command by its
window and how far behind its newest id it is (docs/protocol.md section 7, *Message ids*).
Judged at the pin (the trace): every write of a pipelined run over a lossy line executed
exactly once, in order, across several wraps; and a second host session's ids, which start
at 1 again, run although the first session left the same ids in the device's window.
"""

from __future__ import annotations

import functools
from concurrent.futures import Future, wait

import protoduino_dev  # noqa: F401  (registers faulty://)
import pytest
from protoduino import Board
from protoduino.simboard import SimBoard
from simfixtures import pin_values, wait_until

#: Runs on the emulated Mega too: the ids across wraps on its build (tests/README.md).
pytestmark = pytest.mark.mega

#: The outputs of the lossy session (2..19: every pin but the serial ones). A write may run
#: after a later one when its first transmission is lost (the host keeps several in
#: flight), but never more than DEDUPE_WINDOW - 1 ids later: so consecutive writes to one
#: pin, 18 ids apart, always run in order, and each pin's changes count its executions.
PINS = list(range(2, 20))
#: Writes to each pin: 18 x 17 = 306 ids in all, more than two wraps.
ROUNDS = 17


@pytest.fixture
def sim(sim_board: SimBoard) -> SimBoard:
    return sim_board


def changes(values: list[int]) -> list[int]:
    """The levels a pin went through (a value equal to the one before is no change)."""
    out: list[int] = []
    for value in values:
        if not out or out[-1] != value:
            out.append(value)
    return out


def test_every_command_runs_once_across_wraps_on_a_lossy_line(sim: SimBoard) -> None:
    url = f"faulty://{sim.port}?drop=0.004&seed=23"
    with Board.open(url) as board:
        outputs = [board.digital_output(pin) for pin in PINS]  # safe low
        since = len(sim.trace())
        futures: list[Future[None]] = []
        for k in range(ROUNDS):
            for out in outputs:
                futures.append(out.submit(k % 2 == 0))  # high, low, high, ... pipelined
            wait(futures[-len(outputs) :], timeout=60)
        done, _ = wait(futures, timeout=120)
        assert len(done) == len(futures)
        assert all(f.exception() is None for f in futures)
        stats = board.stats
        levels = board.read_outputs()
    assert stats.retransmits > 0 or stats.seq_lost > 0 or sum(stats.dropped.values()) > 0
    expected = [1, 0] * (ROUNDS // 2) + [1]
    assert all(levels[pin].value == 1 for pin in PINS)

    def ran_once(pin: int) -> bool:
        # From the Init's safe low on (the emulated Uno's trace may show it after `since`).
        return changes([0, *pin_values(sim.trace()[since:], pin)]) == [0, *expected]

    # Exactly once, at the pins: a write taken for a repeat and not run removes a change,
    # one run twice (after the next write to its pin) adds one.
    late = [pin for pin in PINS if not wait_until(functools.partial(ran_once, pin))]
    assert not late, {pin: changes(pin_values(sim.trace()[since:], pin)) for pin in late}


def test_a_second_session_ids_from_1_run(sim: SimBoard) -> None:
    # The first session ends with its writes on ids ..., 127, 1, 2, 3, 4, 5 in the window;
    # the second starts at 1 again. Its RESET opens a new session, which clears the window,
    # so its Init and its write run instead of being answered as repeats.
    with Board.open(sim.port) as first:
        led = first.digital_output(13)
        level = True
        for _ in range(3 * 127):
            led.write(level)
            level = not level
            if first.rpc_state().next_id == 6:
                break
        assert first.rpc_state().next_id == 6
    since = len(sim.trace())
    with Board.open(sim.port) as second:
        assert second.rpc_state().next_id <= 6  # its own ids: GetInfo 1, ConfigureFailsafe 2
        led2 = second.digital_output(13, safe=True)
        led2.write(False)
        outputs = second.read_outputs()
    assert outputs[13].value == 0
    assert wait_until(lambda: changes(pin_values(sim.trace()[since:], 13))[-2:] == [1, 0])
