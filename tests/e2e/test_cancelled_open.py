"""A cancelled open leaves nothing running (issue 20, item 3), on both boards, judged at the pin.

Before, ``asyncio.wait_for(aio.open(port), 0.005)`` timed out while its worker thread went
on opening: the board came up behind the caller's back, its I/O and event threads pinged on,
the port stayed locked, and, opened with an earlier process's session, it kept that process's
servo driven long after the process died. Here each open is cut at a chosen point of the
open itself (the n-th frame on the line, from a frame monitor: the RESET, the RESET_ACK,
GetInfo, its Ack, ConfigureFailsafe, ...), by a task cancellation or by a KeyboardInterrupt.
After each: no protoduino thread, and the port opens again at once. After all of them the
device's failsafe must fire, because nothing pings any more: the verdict is the trace's, on
the board's clock (no later than the failsafe timeout after the board time at which the
last open had ended, read from the board's control socket).
"""

from __future__ import annotations

import asyncio
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import protoduino
import pytest
from protoduino import Board, aio
from protoduino.simboard import SimBoard
from protoduino.transport import FrameRecord
from simfixtures import PULSE_TOLERANCE_US, pin_values, wait_for_pin

#: A short failsafe, so that the verdict comes quickly; the cancelled opens use it too.
T = 1.0
SAFE_90_US = 1472
#: The device checks its timer every millisecond; a servo shows its safe width at the next
#: 20 ms frame (the emulated Uno's channel up to 2.6 ms into it).
POLL = 0.003
FRAME = 0.020 + 0.003
#: Frames into the open at which it is cut: every step of the open and a few beyond.
CUT_AT = range(1, 9)


class CutAt:
    """A frame monitor that runs ``action`` (once) at the ``n``-th frame on the line."""

    def __init__(self, n: int, action: Callable[[], None]) -> None:
        self.n, self.action, self.seen = n, action, 0
        self.fired = threading.Event()

    def __call__(self, record: FrameRecord) -> None:
        self.seen += 1
        if self.seen == self.n:
            self.fired.set()
            self.action()


def _protoduino_threads() -> list[str]:
    return sorted(t.name for t in threading.enumerate() if t.name.startswith("protoduino-"))


def _rig(sim: SimBoard) -> int:
    """A process's outputs left to the failsafe: pin 12 on (safe off), servo 9 at 10 degrees."""
    with Board.open(sim.port, failsafe_timeout=T) as board:
        servo = board.servo(9, safe=90)
        servo.write(10)
        board.digital_output(12, safe=False).on()
        width = servo.to_us(10)
        wait_for_pin(sim, 12, lambda v: v[-1:] == [1])
        wait_for_pin(sim, 9, lambda v: bool(v) and abs(v[-1] - width) <= PULSE_TOLERANCE_US)
        return board.session


def _nothing_left(sim: SimBoard, session: int) -> None:
    """No protoduino thread runs, and the port opens again at once (its lock was released)."""
    assert _protoduino_threads() == []
    # The same session (a new one would release the outputs the failsafe is to make safe).
    with Board.open(sim.port, session=session, ping=False, failsafe_timeout=T):
        pass
    assert _protoduino_threads() == []


def _failsafe_fires(sim: SimBoard) -> None:
    """Nothing pings: the failsafe makes pins 12 and 9 safe within T of the board time now."""
    quiet = sim.set_level(2, 0)  # the board's clock, after every open ended
    lines = wait_for_pin(sim, 12, lambda v: v[-1:] == [0], timeout=30.0 + T)
    assert lines[-2:] == [1, 0]
    fall = [c["t"] for c in sim.trace() if c["pin"] == 12][-1]
    assert fall <= quiet + T + POLL, (fall, quiet)
    wait_for_pin(sim, 9, lambda v: bool(v) and abs(v[-1] - SAFE_90_US) <= PULSE_TOLERANCE_US)
    safe = [c for c in sim.trace() if c["pin"] == 9][-1]
    assert safe["t"] <= fall + FRAME
    assert pin_values(sim.trace(), 12)[-1] == 0


def test_a_cancelled_aio_open_leaves_nothing_running(sim_board: SimBoard) -> None:
    session = _rig(sim_board)
    options: dict[str, Any] = {"session": session, "failsafe_timeout": T}

    async def cut(n: int) -> bool:
        """One open cancelled at its n-th frame; whether the cancellation caught it open."""
        loop = asyncio.get_running_loop()
        task: asyncio.Task[aio.Board] | None = None

        def cancel() -> None:
            assert task is not None
            loop.call_soon_threadsafe(task.cancel)

        task = asyncio.ensure_future(aio.open(sim_board.port, monitor=CutAt(n, cancel), **options))
        try:
            board = await task
        except asyncio.CancelledError:
            return True
        await board.close()  # the open won the race: the cancel came after it returned
        return False

    async def main() -> int:
        caught = 0
        for n in CUT_AT:
            caught += await cut(n)
            _nothing_left(sim_board, session)
        # The issue's own case: a deadline that expires in the middle of the open.
        for deadline in (0.0, 0.005, 0.02):
            try:
                board = await asyncio.wait_for(aio.open(sim_board.port, **options), deadline)
            except TimeoutError:
                caught += 1
            else:
                await board.close()
            _nothing_left(sim_board, session)
        return caught

    caught = asyncio.run(main())
    assert caught >= len(CUT_AT)  # most cuts fall inside the open itself
    _failsafe_fires(sim_board)


@pytest.fixture
def ctrl_c() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt, as in a terminal, even where the suite runs with
    SIGINT ignored (started in the background by a non-interactive shell, a CI runner)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.usefixtures("ctrl_c")
def test_an_interrupted_open_leaves_nothing_running(sim_board: SimBoard) -> None:
    """Ctrl-C (a KeyboardInterrupt in the main thread) at any point of ``Board.open``."""
    session = _rig(sim_board)
    caught = 0
    for n in CUT_AT:
        cut = CutAt(n, lambda: os.kill(os.getpid(), signal.SIGINT))
        board: Board | None = None
        try:
            board = Board.open(
                sim_board.port, session=session, failsafe_timeout=T, monitor=cut, ping=True
            )
            # The open returned before the n-th frame: the interrupt lands here instead.
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline:
                time.sleep(0.01)
            pytest.fail(f"frame {n} never came")
        except KeyboardInterrupt:
            caught += board is None
        finally:
            if board is not None:
                board.close()
        _nothing_left(sim_board, session)
    # The first six frames (RESET, RESET_ACK, GetInfo, its Ack, ConfigureFailsafe, its Ack)
    # are seen before the open can return: the interrupt lands in it every time.
    assert caught >= 6
    _failsafe_fires(sim_board)


def test_open_cancel_before_and_after(sim_board: SimBoard) -> None:
    """OpenCancel: cancelled first the open starts nothing; cancelled after, it closes the board."""
    early = protoduino.board.OpenCancel()
    early.cancel()
    with pytest.raises(protoduino.BoardClosedError):
        Board.open(sim_board.port, cancel=early)
    assert _protoduino_threads() == []
    late = protoduino.board.OpenCancel()
    board = Board.open(sim_board.port, cancel=late)
    assert not board.closed
    late.cancel()
    assert board.closed and _protoduino_threads() == []
