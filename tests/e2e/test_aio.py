"""protoduino.aio: awaitable open, commands and events over the same board core.

Each test drives its own loop with asyncio.run (no pytest plugin needed).
"""

from __future__ import annotations

import asyncio
import functools
import threading
from typing import Any

import protoduino
import pytest
from protoduino import EventKind, aio
from protoduino.messages import ArduinoOut, Status
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice, ack
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin

#: Bounds a failing test's wait only.
BOUND = 10.0


def info_msg(count: int) -> Any:
    """An informational DATA message (a DecodeError), told apart by its count."""
    out = ArduinoOut()
    out.decode_error.count = count
    return out


def test_commands_and_values(fake: PtyDevice) -> None:
    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=0.1, ping=False) as board:
            assert board.info.board == "virtual"
            servo = await board.servo(9, safe=10)
            assert isinstance(servo.sync, protoduino.Servo) and servo.pin == 9
            await servo.write(45)
            led = await board.digital_output(13)
            await led.on()
            assert fake.values == {9: 45, 13: 1}
            await servo.write_us(1500)
            await led.off()
            assert fake.values == {9: 1500, 13: 0}
            assert await board.ping(b"x") > 0
            await board.stop()
            assert fake.arrivals("stop")
            assert board.stats.timeouts == 0
        assert board.closed

    asyncio.run(asyncio.wait_for(main(), BOUND))


def test_the_loop_keeps_running_while_commands_wait(fake: PtyDevice) -> None:
    """Awaiting a held Ack leaves the loop free; gather runs commands side by side."""
    released = threading.Event()

    def hold(msg: Any) -> list[Any]:
        replies = fake.default_reply(msg)
        if msg.WhichOneof("data") == "servo_control":
            threading.Thread(target=send, args=(replies,)).start()
            return []
        return replies

    # One sender at a time: each takes its SEQ and writes its frame under this lock (two
    # threads could otherwise write SEQ 6 before 5, which the host takes for a desync).
    sending = threading.Lock()

    def send(replies: list[Any]) -> None:
        released.wait(BOUND)
        with sending:
            for out in replies:
                fake.send_data(out)

    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=BOUND, ping=False) as board:
            servos = [await board.servo(pin) for pin in (3, 5, 6)]
            fake.handler = hold
            before = len(fake.arrivals())
            writes = asyncio.gather(*(s.write(20 + s.pin) for s in servos))
            ticks = 0
            while len(fake.arrivals()) < before + 3:  # the loop runs: this loop ticks
                ticks += 1
                await asyncio.sleep(0.01)
            assert not writes.done()
            released.set()
            await writes
            assert ticks > 0
            assert fake.values == {3: 23, 5: 25, 6: 26}

    asyncio.run(asyncio.wait_for(main(), BOUND))


def test_errors_are_the_blocking_calls(fake: PtyDevice) -> None:
    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=0.1, ping=False) as board:
            servo = await board.servo(9)
            with pytest.raises(protoduino.CommandRejectedError) as info:
                await servo.write(181)
            assert info.value.sent is False
            with pytest.raises(protoduino.CommandRejectedError) as info:
                await board.servo(1)
            assert info.value.status == Status.STATUS_RESERVED_PIN
            fake.handler = lambda msg: [ack(msg.message_id, Status.STATUS_OUT_OF_RANGE)]
            with pytest.raises(protoduino.CommandRejectedError) as info:
                await servo.write(10)
            assert info.value.sent is True
            fake.handler = lambda msg: []
            with pytest.raises(protoduino.AckTimeoutError):
                await servo.write(10)

    asyncio.run(asyncio.wait_for(main(), BOUND))


def test_cancelled_wait_does_not_recall_the_command(fake: PtyDevice) -> None:
    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=0.1, ping=False) as board:
            servo = await board.servo(9)
            task = asyncio.create_task(servo.write(33))
            await asyncio.sleep(0)  # the task starts: the command is submitted
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert await asyncio.to_thread(fake.wait_for, lambda: fake.values.get(9) == 33, BOUND)

    asyncio.run(asyncio.wait_for(main(), BOUND))


def test_events_iterate_until_close(fake: PtyDevice) -> None:
    async def main() -> list[int]:
        board = await aio.open(fake.port, ack_timeout=0.1, ping=False)
        events = board.events()
        fake.send_data(info_msg(1))
        fake.send_data(info_msg(2))
        counts = []
        async for event in events:
            if event.kind is EventKind.DECODE_ERROR:
                counts.append(event.details["count"])
            if len(counts) == 2:
                await board.close()  # the iteration ends after what is buffered
        return counts

    assert asyncio.run(asyncio.wait_for(main(), BOUND)) == [1, 2]


def test_event_buffer_is_bounded(fake: PtyDevice) -> None:
    async def main() -> None:
        async with await aio.open(fake.port, ack_timeout=0.1, ping=False) as board:
            async with board.events(maxsize=2) as events:
                for count in (1, 2, 3, 4):
                    fake.send_data(info_msg(count))
                while events.dropped < 2:  # the consumer stalls: the oldest go
                    await asyncio.sleep(0.01)
                got = [(await anext(events)).details["count"] for _ in range(2)]
                assert got == [3, 4]
            with pytest.raises(StopAsyncIteration):
                await anext(events)
            with pytest.raises(ValueError):
                board.events(maxsize=0)

    asyncio.run(asyncio.wait_for(main(), BOUND))


def ends_near(want: int, values: list[int]) -> bool:
    return bool(values) and abs(values[-1] - want) <= PULSE_TOLERANCE_US


def test_aio_reaches_the_pins(sim_board: SimBoard) -> None:
    pins = (3, 5, 6, 9)

    async def main() -> None:
        async with await aio.open(sim_board.port) as board:
            servos = await asyncio.gather(*(board.servo(pin) for pin in pins))
            led = await board.digital_output(13)
            for degrees in (0, 60, 120):
                await asyncio.gather(*(s.write(degrees + s.pin) for s in servos), led.on())
            assert await board.ping() > 0

    asyncio.run(asyncio.wait_for(main(), 60))
    for pin in pins:
        want = 544 + (120 + pin) * (2400 - 544) // 180
        wait_for_pin(sim_board, pin, functools.partial(ends_near, want))
    wait_for_pin(sim_board, 13, lambda v: 1 in v)


def test_heartbeat_and_release_do_not_block_the_loop(fake: PtyDevice) -> None:
    """Issue 20, item 12: heartbeat(), release(), release_all() are awaited, the loop free."""
    released = threading.Event()
    held = ("heartbeat", "release", "release_all")

    def hold(msg: Any) -> list[Any]:
        replies = fake.default_reply(msg)
        if msg.WhichOneof("data") in held:
            threading.Thread(target=send, args=(replies,)).start()
            return []
        return replies

    # One sender at a time: each takes its SEQ and writes its frame under this lock (two
    # threads could otherwise write SEQ 6 before 5, which the host takes for a desync).
    sending = threading.Lock()

    def send(replies: list[Any]) -> None:
        released.wait(BOUND)
        with sending:
            for out in replies:
                fake.send_data(out)

    async def main() -> None:
        async with await aio.open(
            fake.port, ack_timeout=BOUND, ping=False, liveness="heartbeat"
        ) as board:
            servo = await board.servo(9)
            led = await board.digital_output(13)
            await board.digital_output(12)
            fake.handler = hold
            before = len(fake.arrivals())
            calls = asyncio.gather(
                board.heartbeat(), servo.release(), board.release(12), led.release()
            )
            ticks = 0
            while len(fake.arrivals()) < before + 4:  # the loop runs while the Acks are held
                ticks += 1
                await asyncio.sleep(0.01)
            assert not calls.done() and ticks > 0
            released.set()
            await calls
            assert servo.value is None and led.value is None  # forgotten at the Acks
            await board.digital_output(13)
            await board.release_all()
            kinds = [r.kind for r in fake.arrivals()[before:]]
            assert kinds.count("heartbeat") == 1 and kinds.count("release") == 3, kinds
            assert kinds[-1] == "release_all"

    asyncio.run(asyncio.wait_for(main(), BOUND))
