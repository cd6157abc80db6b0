"""protoduino.aio's PWM outputs and inputs against the pty fake (PtyDevice).

Each test drives its own loop with asyncio.run. "Without blocking the loop" is judged
by another task making progress while an input is awaited, not by time.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest
from protoduino import aio
from protoduino.errors import BoardClosedError, InputTimeoutError
from protoduino.testing import PtyDevice

#: Bounds a failing test's wait only.
BOUND = 30.0


async def until(condition: Callable[[], bool]) -> None:
    """Let the loop run until ``condition()`` holds (bounded by BOUND)."""
    async with asyncio.timeout(BOUND):
        while not condition():
            await asyncio.sleep(0.001)


def test_pwm_and_pose(fake: PtyDevice) -> None:
    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=0.1, ping=False) as board:
            motor = await board.pwm_output(3, safe=0)
            await motor.write(99.5)  # halves to even: 100
            assert fake.values == {3: 100} and motor.value == 100
            led = await board.digital_output(13)
            await board.pose({motor: 7, led: True})
            assert fake.values == {3: 7, 13: 1}

    asyncio.run(main())


def test_inputs_read_at_once_and_wait_without_blocking_the_loop(fake: PtyDevice) -> None:
    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=0.1, ping=False) as board:
            button = await board.digital_input(2, pull_up=True)
            assert button.read() is True  # known once the open returned: no await
            waiting = asyncio.create_task(button.wait_for(False, timeout=BOUND))
            ticks = 0
            while board.sync.inputs.listeners("digital", 2) == 0:  # the wait is set up
                ticks += 1
                await asyncio.sleep(0)
            assert ticks > 0 and not waiting.done()  # this task ran while the other waited
            fake.set_level(2, 0)
            assert await waiting is False
            with pytest.raises(InputTimeoutError):
                await button.wait_for(True, timeout=0.05)
            fake.analog[15] = 512
            pot = await board.analog_input(15, rate_hz=200)
            assert pot.read() == 512
            fake.set_analog(15, 700)
            assert await pot.wait_for(lambda v: v > 600, timeout=BOUND) == 700
            wheel = await board.counter(3, edge="falling")
            assert wheel.read() == 0
            fake.pulses(3, 42)
            assert await wheel.wait_for(lambda n: n == 42, timeout=BOUND) == 42

    asyncio.run(main())


def test_changes_iterate_newest_wins_and_end_at_close(fake: PtyDevice) -> None:
    async def main() -> None:
        board = await aio.open(fake.port, ack_timeout=0.1, ping=False)
        pot = await board.analog_input(14)
        changes = pot.changes(maxsize=2)
        burst = []
        for value in range(1, 11):
            fake.analog[14] = value
            burst.append(fake.report(analog=[14]))
        fake.send_burst(burst)  # ten changes while nobody consumes
        await until(lambda: changes.dropped == 8)
        assert [(await anext(changes)).value for _ in range(2)] == [9, 10]
        fake.set_analog(14, 11)
        reading = await anext(changes)
        assert reading.value == 11 and reading.pin == 14 and reading.age >= 0
        await board.close()
        with pytest.raises(StopAsyncIteration):
            await anext(changes)
        with pytest.raises(BoardClosedError):
            await pot.wait_for(lambda v: v == 99, timeout=BOUND)

    asyncio.run(main())
