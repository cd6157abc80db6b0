"""asyncio API: the same board, awaited.

A thin layer over :class:`protoduino.Board`: each command is the board's own
``submit`` form, its :class:`concurrent.futures.Future` wrapped for the running
loop (:func:`asyncio.wrap_future`). There is no second link or request layer
here, so the blocking and the awaited calls have the same checks, bounds,
retries, session restore and errors, and may be mixed on one board (from other
threads too).

Only opening and closing run on a worker thread (:func:`asyncio.to_thread`): the
handshake is the link's own blocking loop, and closing joins the board's
threads. A cancelled open is abandoned on that thread and closed (see
:func:`open`): nothing of it runs on. Cancelling an awaited command does not
recall it: once submitted it is sent and acknowledged like any other; only the
wait is abandoned.

Events: ``async for event in board.events()`` sees every :class:`Event` from
the moment it starts iterating until the board is closed (then the iteration
ends); leaving an ``async with board.events() as events:`` block (or
``events.close()``) ends it earlier. Each iterator buffers up to ``maxsize``
events for a consumer that falls behind; beyond that the oldest is dropped and counted in
:attr:`EventStream.dropped`, so a stalled consumer never grows memory without
bound nor blocks the board's event thread.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
from collections.abc import Mapping
from concurrent.futures import Future
from types import TracebackType
from typing import Any, SupportsFloat, TypeVar

from . import board as _board
from .board import OutputState
from .constants import SERVO_DEFAULT_MAX_US, SERVO_DEFAULT_MIN_US
from .errors import ArgumentError
from .events import Event, Stats
from .messages import ArduinoIn
from .rpc import Ack

T = TypeVar("T")

#: Events one iterator keeps for a slow consumer before dropping the oldest.
EVENT_BUFFER = 256


async def _wait(future: Future[T]) -> T:
    return await asyncio.wrap_future(future)


async def open(url: str, **options: Any) -> Board:
    """Open ``url`` like :meth:`protoduino.Board.open` (same keywords); the loop runs on.

    Cancelling it (``asyncio.wait_for(aio.open(url), 0.5)`` timing out, ``task.cancel()``)
    at any point leaves nothing running: the open runs on a worker thread, which a
    cancellation cannot stop, so it is abandoned there (:class:`protoduino.board.OpenCancel`)
    and the cancellation completes once the board's threads are gone and the port is free.
    A board the open had just returned is closed likewise.
    """
    cancel = _board.OpenCancel()
    opening = asyncio.ensure_future(
        asyncio.to_thread(_board.Board.open, url, cancel=cancel, **options)
    )
    try:
        sync = await asyncio.shield(opening)
    except asyncio.CancelledError:
        closing = asyncio.ensure_future(asyncio.to_thread(cancel.cancel))
        await _settle(closing, opening)
        raise
    return Board(sync)


async def _settle(*futures: asyncio.Future[Any]) -> None:
    """Wait until every one of ``futures`` is done, whatever they raise, even if cancelled again.

    A second cancellation while the open is being abandoned must not leave it half
    done: the caller re-raises its own cancellation once everything stopped.
    """
    both = asyncio.gather(*futures, return_exceptions=True)
    while not both.done():
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.shield(both)


class Servo:
    """An awaitable servo; get one from :meth:`Board.servo`. ``.sync`` is the blocking one."""

    def __init__(self, sync: _board.Servo) -> None:
        self.sync = sync
        self.pin = sync.pin
        self.min_us = sync.min_us
        self.max_us = sync.max_us
        self.max_speed_us = sync.max_speed_us

    @property
    def value(self) -> int | None:
        return self.sync.value

    async def write(self, degrees: SupportsFloat) -> None:
        await _wait(self.sync.submit(degrees))

    async def write_us(self, us: SupportsFloat) -> None:
        await _wait(self.sync.submit_us(us))

    async def release(self) -> None:
        await _wait(self.sync.submit_release())

    def __repr__(self) -> str:
        return f"aio.{self.sync!r}"


class DigitalOutput:
    """An awaitable digital output; get one from :meth:`Board.digital_output`."""

    def __init__(self, sync: _board.DigitalOutput) -> None:
        self.sync = sync
        self.pin = sync.pin

    @property
    def value(self) -> bool | None:
        return self.sync.value

    async def write(self, level: bool) -> None:
        await _wait(self.sync.submit(level))

    async def on(self) -> None:
        await self.write(True)

    async def off(self) -> None:
        await self.write(False)

    async def release(self) -> None:
        await _wait(self.sync.submit_release())

    def __repr__(self) -> str:
        return f"aio.{self.sync!r}"


_Output = Servo | DigitalOutput | _board.Servo | _board.DigitalOutput


def _sync(output: _Output) -> _board.Servo | _board.DigitalOutput:
    return output.sync if isinstance(output, Servo | DigitalOutput) else output


class EventStream:
    """An async iterator of a board's events (see the module docstring)."""

    def __init__(self, board: Board, maxsize: int) -> None:
        self._loop = asyncio.get_running_loop()
        self._buffer: collections.deque[Event | None] = collections.deque()
        self._maxsize = maxsize
        self._ready = asyncio.Event()
        self._board = board
        #: Events dropped because this iterator's consumer fell behind.
        self.dropped = 0
        self._unsubscribe = board.sync.on_event(self._from_thread)
        board._streams.add(self)

    def _from_thread(self, event: Event) -> None:  # the board's event thread
        try:
            self._loop.call_soon_threadsafe(self._put, event)
        except RuntimeError:  # the loop is closed: nobody is listening any more
            self._unsubscribe()

    def _put(self, event: Event | None) -> None:  # the loop's thread
        if event is not None and len(self._buffer) >= self._maxsize:
            self._buffer.popleft()
            self.dropped += 1
        self._buffer.append(event)
        self._ready.set()

    def close(self) -> None:
        """End the iteration (after the events already buffered)."""
        self._unsubscribe()
        self._board._streams.discard(self)
        self._put(None)

    async def __aenter__(self) -> EventStream:
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def __aiter__(self) -> EventStream:
        return self

    async def __anext__(self) -> Event:
        while not self._buffer:
            self._ready.clear()
            await self._ready.wait()
        event = self._buffer.popleft()
        if event is None:
            self._buffer.append(None)  # stays ended
            raise StopAsyncIteration
        return event


class Board:
    """An awaitable board; get one with :func:`open`. ``.sync`` is the blocking Board."""

    def __init__(self, sync: _board.Board) -> None:
        self.sync = sync
        self._streams: set[EventStream] = set()

    @classmethod
    async def open(cls, url: str, **options: Any) -> Board:
        return await open(url, **options)

    async def __aenter__(self) -> Board:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def close(self) -> None:
        """Close the board (see :meth:`protoduino.Board.close`) and end every event iterator."""
        await asyncio.to_thread(self.sync.close)
        for stream in list(self._streams):
            stream.close()

    @property
    def closed(self) -> bool:
        return self.sync.closed

    @property
    def info(self) -> _board.DeviceInfo:
        return self.sync.info

    @property
    def stats(self) -> Stats:
        return self.sync.stats

    @property
    def pinging(self) -> bool:
        return self.sync.pinging

    @pinging.setter
    def pinging(self, on: bool) -> None:
        self.sync.pinging = on

    async def servo(
        self,
        pin: int,
        safe: int | None = None,
        *,
        safe_us: int | None = None,
        min_us: int = SERVO_DEFAULT_MIN_US,
        max_us: int = SERVO_DEFAULT_MAX_US,
        max_speed: float | None = None,
        max_speed_us: int | None = None,
    ) -> Servo:
        future = self.sync.submit_servo(
            pin,
            safe,
            safe_us=safe_us,
            min_us=min_us,
            max_us=max_us,
            max_speed=max_speed,
            max_speed_us=max_speed_us,
        )
        return Servo(await _wait(future))

    async def digital_output(self, pin: int, safe: bool = False) -> DigitalOutput:
        return DigitalOutput(await _wait(self.sync.submit_digital_output(pin, safe)))

    async def ping(self, payload: bytes = b"") -> float:
        return await _wait(self.sync.submit_ping(payload))

    async def stop(self) -> None:
        await _wait(self.sync.submit_stop())

    async def heartbeat(self) -> None:
        """:meth:`protoduino.Board.heartbeat`: the loop runs on while the Ack comes back.

        With ``liveness="heartbeat"`` a control loop awaits this every cycle (or
        submits it and checks later: ``board.sync.submit_heartbeat()``).
        """
        await _wait(self.sync.submit_heartbeat())

    async def release(self, pin: int) -> None:
        await _wait(self.sync.submit_release(pin))

    async def release_all(self) -> None:
        await _wait(self.sync.submit_release_all())

    async def request(self, msg: ArduinoIn) -> Ack:
        """:meth:`protoduino.Board.request`, awaited."""
        return await _wait(self.sync.submit_request(msg))

    async def pose(self, targets: Mapping[_Output, _board.PoseValue]) -> None:
        """:meth:`protoduino.Board.pose`; the outputs may be these or the blocking ones."""
        await _wait(self.sync.submit_pose({_sync(o): v for o, v in targets.items()}))

    async def read_outputs(self) -> dict[int, OutputState]:
        return await _wait(self.sync.submit_read_outputs())

    def events(self, maxsize: int = EVENT_BUFFER) -> EventStream:
        """Every event from now on, until the board is closed: ``async for e in board.events()``."""
        if maxsize < 1:
            raise ArgumentError("maxsize must be at least 1")
        return EventStream(self, maxsize)

    def __repr__(self) -> str:
        return f"aio.{self.sync!r}"
