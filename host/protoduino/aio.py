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

Inputs: ``await board.digital_input(2)`` (and ``analog_input``, ``counter``) returns
once the first value is known; ``read()`` is the latest value at once (no round
trip, no await); ``async for reading in button.changes()`` sees each change from
then on, and ``await button.wait_for(False)`` waits for a condition. Both are fed
from the I/O thread straight into the loop (``call_soon_threadsafe``), never through
the event thread, so a slow ``on_event`` callback does not delay them. An iterator
keeps at most ``maxsize`` readings for a consumer that falls behind and drops the
oldest (counted in :attr:`InputChanges.dropped`): freshness over completeness, as
on the device.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from types import TracebackType
from typing import TYPE_CHECKING, Any, Generic, Self, SupportsFloat, TypeVar

from . import board as _board
from . import inputs as _inputs
from .arguments import Pin, RealNumber
from .board import Edge, Interlock, OutputState
from .boardoptions import BoardOptions
from .constants import SERVO_DEFAULT_MAX_US, SERVO_DEFAULT_MIN_US
from .errors import ArgumentError, BoardClosedError, InputTimeoutError
from .events import Event, Stats
from .inputs import SINK_BUFFER, Reading
from .messages import ArduinoIn
from .rpc import Ack

if TYPE_CHECKING:
    from typing_extensions import Unpack

T = TypeVar("T")
InputT = TypeVar("InputT", bound="_Input")

#: Events one iterator keeps for a slow consumer before dropping the oldest.
EVENT_BUFFER = 256


async def _wait(future: Future[T]) -> T:
    return await asyncio.wrap_future(future)


async def open(url: str, **options: Unpack[BoardOptions]) -> Board:
    """Open ``url`` like :meth:`protoduino.Board.open` (same keywords); the loop runs on.

    Cancelling it (``asyncio.wait_for(aio.open(url), 0.5)`` timing out, ``task.cancel()``)
    at any point leaves nothing running: the open runs on a worker thread, which a
    cancellation cannot stop, so it is abandoned there (:class:`protoduino.board.OpenCancel`)
    and the cancellation completes once the board's threads are gone and the port is free.
    A board the open had just returned is closed likewise.
    """
    cancel = _board.OpenCancel()
    options = {**options, "cancel": cancel}
    opening = asyncio.ensure_future(asyncio.to_thread(_board.Board.open, url, **options))
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


class PwmOutput:
    """An awaitable PWM output; get one from :meth:`Board.pwm_output`."""

    def __init__(self, sync: _board.PwmOutput) -> None:
        self.sync = sync
        self.pin = sync.pin
        self.safe = sync.safe

    @property
    def value(self) -> int | None:
        return self.sync.value

    async def write(self, duty: RealNumber) -> None:
        await _wait(self.sync.submit(duty))

    def __repr__(self) -> str:
        return f"aio.{self.sync!r}"


_Output = Servo | DigitalOutput | PwmOutput | _board.Servo | _board.DigitalOutput | _board.PwmOutput


def _sync(output: _Output) -> _board.PoseOutput:
    return output.sync if isinstance(output, Servo | DigitalOutput | PwmOutput) else output


ItemT = TypeVar("ItemT")


class _Stream(Generic[ItemT]):
    """An async iterator fed from another thread: a bounded buffer on the loop (the
    oldest item dropped and counted when the consumer falls behind), ended by
    :meth:`close` after the items already buffered. Subclasses subscribe in their
    ``__init__`` and say how to unsubscribe in :meth:`_detach`."""

    def __init__(self, board: Board, maxsize: int) -> None:
        if maxsize < 1:
            raise ArgumentError("maxsize must be at least 1")
        self._loop = asyncio.get_running_loop()
        self._buffer: collections.deque[ItemT | None] = collections.deque()
        self._maxsize = maxsize
        self._ready = asyncio.Event()
        self._board = board
        #: Items dropped because this iterator's consumer fell behind.
        self.dropped = 0

    def _detach(self) -> None:
        raise NotImplementedError

    def _put(self, item: ItemT | None) -> None:  # the loop's thread
        if item is not None and len(self._buffer) >= self._maxsize:
            self._buffer.popleft()
            self.dropped += 1
        self._buffer.append(item)
        self._ready.set()

    def close(self) -> None:
        """End the iteration (after the items already buffered)."""
        self._detach()
        self._board._streams.discard(self)
        self._put(None)

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> ItemT:
        while not self._buffer:
            self._ready.clear()
            await self._ready.wait()
        item = self._buffer.popleft()
        if item is None:
            self._buffer.append(None)  # stays ended
            raise StopAsyncIteration
        return item


class InputChanges(_Stream[Reading]):
    """An async iterator of one input's changes (see the module docstring)."""

    def __init__(self, board: Board, sync: _inputs.Input, maxsize: int) -> None:
        super().__init__(board, maxsize)
        table = board.sync.inputs
        #: The value known when the iterator started (None: none yet).
        self.current, self._remove = table.add_sink(sync.kind, sync.pin, self._from_thread)
        board._streams.add(self)
        if board.closed:
            self.close()

    def _from_thread(self, reading: Reading) -> None:  # the I/O thread, under the table's lock
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody listens any more
            self._loop.call_soon_threadsafe(self._put, reading)

    def _detach(self) -> None:
        self._remove()


class _Input:
    """What the awaitable inputs share; ``.sync`` is the blocking input object."""

    def __init__(self, board: Board, sync: _inputs.Input) -> None:
        self._board = board
        self._input = sync
        self.pin = sync.pin

    def reading(self) -> Reading | None:
        """The latest reading at once (no round trip), or None before the first."""
        return self._input.reading()

    @property
    def age(self) -> float | None:
        return self._input.age

    def on_change(self, callback: Callable[[Reading], None]) -> Callable[[], None]:
        """A callback on the board's event thread (see the blocking input's on_change)."""
        return self._input.on_change(callback)

    def changes(self, maxsize: int = SINK_BUFFER) -> InputChanges:
        """Every change from now on, until the board is closed: ``async for r in x.changes()``."""
        return InputChanges(self._board, self._input, maxsize)

    async def _wait(self, test: Callable[[Reading], bool], timeout: float | None) -> Reading:
        limit = self._input.timeout if timeout is None else timeout
        async with self.changes() as changes:
            current = changes.current
            if current is not None and test(current):
                return current
            try:
                async with asyncio.timeout(limit):
                    async for reading in changes:
                        if test(reading):
                            return reading
            except TimeoutError:
                raise InputTimeoutError(
                    f"{self._input.kind} input {self.pin}: no matching value within {limit:g} s"
                ) from None
        raise BoardClosedError("the board was closed while waiting for an input")

    async def release(self) -> None:
        """Release the pin (free for any mode); the loop runs on meanwhile."""
        await asyncio.to_thread(self._input.release)

    def __repr__(self) -> str:
        return f"aio.{self._input!r}"


class DigitalInput(_Input):
    """An awaitable digital input; get one from :meth:`Board.digital_input`."""

    def __init__(self, board: Board, sync: _board.DigitalInput) -> None:
        super().__init__(board, sync)
        self.sync = sync
        self.interlock = sync.interlock

    def read(self) -> bool | None:
        return self.sync.read()

    async def wait_for(self, level: _inputs.LevelCondition, timeout: float | None = None) -> bool:
        """Wait until the level is ``level`` (or ``level(value)`` holds), without blocking."""
        test = _inputs._level_test(level)
        return bool((await self._wait(lambda r: test(bool(r.value)), timeout)).value)


class _ValueInput(_Input):
    """An input whose value is a count (an analog input's, a counter's)."""

    def read(self) -> int | None:
        reading = self.reading()
        return None if reading is None else reading.value

    async def wait_for(
        self, condition: _inputs.ValueCondition, timeout: float | None = None
    ) -> int:
        return (await self._wait(lambda r: condition(r.value), timeout)).value


class AnalogInput(_ValueInput):
    """An awaitable analog input; get one from :meth:`Board.analog_input`."""

    def __init__(self, board: Board, sync: _board.AnalogInput) -> None:
        super().__init__(board, sync)
        self.sync = sync


class Counter(_ValueInput):
    """An awaitable pulse counter; get one from :meth:`Board.counter`."""

    def __init__(self, board: Board, sync: _board.Counter) -> None:
        super().__init__(board, sync)
        self.sync = sync


class EventStream(_Stream[Event]):
    """An async iterator of a board's events (see the module docstring)."""

    def __init__(self, board: Board, maxsize: int) -> None:
        super().__init__(board, maxsize)
        self._unsubscribe = board.sync.on_event(self._from_thread)
        board._streams.add(self)

    def _from_thread(self, event: Event) -> None:  # the board's event thread
        try:
            self._loop.call_soon_threadsafe(self._put, event)
        except RuntimeError:  # the loop is closed: nobody is listening any more
            self._unsubscribe()

    def _detach(self) -> None:
        self._unsubscribe()


class Board:
    """An awaitable board; get one with :func:`open`. ``.sync`` is the blocking Board."""

    def __init__(self, sync: _board.Board) -> None:
        self.sync = sync
        self._streams: set[_Stream[Any]] = set()

    @classmethod
    async def open(cls, url: str, **options: Unpack[BoardOptions]) -> Board:
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
        pin: Pin,
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

    async def digital_output(self, pin: Pin, safe: bool = False) -> DigitalOutput:
        return DigitalOutput(await _wait(self.sync.submit_digital_output(pin, safe)))

    async def pwm_output(self, pin: Pin, safe: RealNumber = 0) -> PwmOutput:
        return PwmOutput(await _wait(self.sync.submit_pwm_output(pin, safe)))

    async def digital_input(
        self,
        pin: Pin,
        *,
        pull_up: bool = False,
        debounce_ms: int = 0,
        interlock: Interlock | None = None,
    ) -> DigitalInput:
        """:meth:`protoduino.Board.digital_input`: returns once its first level is known."""
        future = self.sync.submit_digital_input(
            pin, pull_up=pull_up, debounce_ms=debounce_ms, interlock=interlock
        )
        return await self._first(DigitalInput(self, await _wait(future)))

    async def analog_input(
        self, pin: Pin, *, rate_hz: float = 100.0, threshold: int = 0, heartbeat: float = 1.0
    ) -> AnalogInput:
        """:meth:`protoduino.Board.analog_input`: returns once its first value is known."""
        future = self.sync.submit_analog_input(
            pin, rate_hz=rate_hz, threshold=threshold, heartbeat=heartbeat
        )
        return await self._first(AnalogInput(self, await _wait(future)))

    async def counter(
        self, pin: Pin, *, edge: Edge = "rising", pull_up: bool = False, rate_hz: float = 50.0
    ) -> Counter:
        """:meth:`protoduino.Board.counter`: returns once its first count is known."""
        future = self.sync.submit_counter(pin, edge=edge, pull_up=pull_up, rate_hz=rate_hz)
        return await self._first(Counter(self, await _wait(future)))

    async def _first(self, made: InputT) -> InputT:
        """Wait (up to the board's round_time) for an input's first value, reported after its Ack;
        a report lost on the line leaves read() None until the next one, as in the blocking
        form."""
        with contextlib.suppress(InputTimeoutError, BoardClosedError):
            await made._wait(lambda _reading: True, self.sync.round_time)
        return made

    async def clear_interlock(self) -> None:
        await _wait(self.sync.submit_clear_interlock())

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

    async def release(self, pin: Pin) -> None:
        await _wait(self.sync.submit_release(pin))

    async def release_all(self) -> None:
        await _wait(self.sync.submit_release_all())

    async def request(self, msg: ArduinoIn) -> Ack:
        """:meth:`protoduino.Board.request`, awaited."""
        return await _wait(self.sync.submit_request(msg))

    async def call_user(self, method: int, request: bytes) -> bytes:
        """:meth:`protoduino.Board.call_user` (a user service's method), awaited."""
        return await _wait(self.sync.submit_call_user(method, request))

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
