"""User services on the host (docs/services.md): what every generated client shares.

``protoduino gen robot.proto --out DIR`` writes ``robot_client.py``: a class per
service, derived from :class:`ServiceClient` (blocking and ``submit_`` forms) and
:class:`AsyncServiceClient` (``protoduino.aio``), with one typed method per rpc.
They go through :meth:`protoduino.Board.call_user`, so a user call has every
command's guarantees (one Ack, exactly once, the failsafe); this module adds the
user schema on top: the fingerprint check when a client is attached, the request
and reply messages, the handler's codes as the named errors the client declares,
and the reports decoded (callbacks, latest value, async iterators; newest wins).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Generic, TypeVar

from google.protobuf.message import DecodeError, Message

from ._generated import protoduino_pb2 as pb
from .aio import _Stream
from .errors import (
    ArgumentError,
    ArgumentTypeError,
    CommandRejectedError,
    ProtocolError,
    UserError,
    UserSchemaError,
    rejection,
)
from .messages import status_name
from .userreports import RawReport

if TYPE_CHECKING:
    from . import aio
    from .board import Board

log = logging.getLogger(__name__)

#: The most bytes a request, a reply or a report may take on the wire
#: (UserCall.request, Ack.user_reply, UserReport.body: protoduino.options).
MAX_USER_BYTES = 64
#: Reports one async iterator keeps for a slow consumer before dropping the oldest.
REPORT_BUFFER = 64

M = TypeVar("M", bound=Message)


@dataclass(frozen=True, slots=True)
class Report(Generic[M]):
    """One value of a user report, decoded, with when it arrived."""

    value: M
    #: ``time.monotonic()`` when it arrived.
    received: float
    #: Values the device replaced by newer ones before sending (since the previous one).
    coalesced: int

    @property
    def age(self) -> float:
        """Seconds since it arrived."""
        return time.monotonic() - self.received


def _decode(raw: RawReport, message: type[M]) -> Report[M]:
    try:
        value = message.FromString(raw.body)
    except DecodeError as error:
        raise ProtocolError(
            f"user report {raw.report} does not decode as {message.DESCRIPTOR.full_name}: {error}"
        ) from error
    return Report(value, raw.received, raw.coalesced)


class ServiceClient:
    """A generated service client's base: attach it to an open board."""

    #: The user's .proto the client was generated from (its file name).
    PROTO: ClassVar[str] = ""
    #: CRC-32 of the user schema's FileDescriptorSet (DeviceInfo.user_fingerprint).
    FINGERPRINT: ClassVar[int] = 0
    #: The handler's codes (the user's error enum) and their named errors.
    ERRORS: ClassVar[Mapping[int, type[UserError]]] = {}

    def __init__(self, board: Board) -> None:
        device = board.info.user_fingerprint
        if device != self.FINGERPRINT:
            raise UserSchemaError(self.PROTO, self.FINGERPRINT, device)
        self.board = board

    def _request(self, name: str, request: Message, expected: type[Message]) -> bytes:
        if not isinstance(request, expected):
            raise ArgumentTypeError(
                f"{name} takes a {expected.DESCRIPTOR.full_name}, not {type(request).__name__}"
            )
        body = request.SerializeToString(deterministic=True)
        if len(body) > MAX_USER_BYTES:
            raise ArgumentError(
                f"{name}: the request takes {len(body)} bytes on the wire, more than "
                f"{MAX_USER_BYTES} (UserCall.request)"
            )
        return body

    def _named(self, error: CommandRejectedError, name: str) -> CommandRejectedError:
        """The refusal of rpc ``name`` as the user should read it: the client's own error
        for the handler's code (UserError for an unknown one); the failsafe's and an
        interlock's refusals naming the rpc and what lifts them; any other unchanged."""
        if isinstance(error, UserError):
            named = self.ERRORS.get(error.code, UserError)
            label = getattr(named, "NAME", "") or str(error.code)
            return named(error.code, f"{name} refused by its handler: {label}")
        if error.status == pb.STATUS_FAILSAFE_EXPIRED:
            feed = "board.heartbeat()" if self.board.liveness == "heartbeat" else "board.ping()"
            why = (
                "the failsafe fired (no liveness message within its timeout) and holds every "
                f"output safe: {feed} re-arms it, then call {name} again"
            )
        elif error.status == pb.STATUS_INTERLOCK_ACTIVE:
            why = (
                "an interlock input tripped and holds every output safe: once the input is "
                f"back at its normal level, board.clear_interlock(), then call {name} again"
            )
        else:
            return error
        return rejection(
            error.status,
            f"{name} refused by the device: {status_name(error.status)}: {why} (an rpc that "
            "only reads is never refused: option idempotency_level = NO_SIDE_EFFECTS)",
            sent=error.sent,
        )

    @staticmethod
    def _decode(name: str, raw: bytes, reply: type[M]) -> M:
        try:
            return reply.FromString(raw)
        except DecodeError as error:
            raise ProtocolError(
                f"{name}: the reply does not decode as {reply.DESCRIPTOR.full_name}: {error}"
            ) from error

    def _call(
        self, method: int, name: str, request: Message, expected: type[Message], reply: type[M]
    ) -> M:
        """The blocking call: the board's own (no thread hop between the Ack and the caller)."""
        body = self._request(name, request, expected)
        try:
            raw = self.board.call_user(method, body)
        except CommandRejectedError as error:
            named = self._named(error, name)
            if named is error:
                raise
            raise named from error
        return self._decode(name, raw, reply)

    def _submit(
        self, method: int, name: str, request: Message, expected: type[Message], reply: type[M]
    ) -> Future[M]:
        body = self._request(name, request, expected)
        raw = self.board.submit_call_user(method, body)
        out: Future[M] = Future()
        out.set_running_or_notify_cancel()

        def done(f: Future[bytes]) -> None:
            try:
                value = self._decode(name, f.result(), reply)
            except CommandRejectedError as error:
                out.set_exception(self._named(error, name))
            except BaseException as error:  # the caller sees what the board raised
                out.set_exception(error)
            else:
                out.set_result(value)

        raw.add_done_callback(done)
        return out

    def _on_report(
        self, method: int, message: type[M], callback: Callable[[Report[M]], None]
    ) -> Callable[[], None]:
        def deliver(raw: RawReport) -> None:  # the event thread
            try:
                report = _decode(raw, message)
            except ProtocolError as error:
                log.warning("%s", error)
                return
            callback(report)

        return self.board.user_reports.on_report(method, deliver)

    def _latest(self, method: int, message: type[M]) -> Report[M] | None:
        raw = self.board.user_reports.latest(method)
        return None if raw is None else _decode(raw, message)


class ReportStream(_Stream[Report[M]]):
    """An async iterator of one user report's values (newest wins: a consumer that
    falls behind loses the oldest, counted in :attr:`dropped`)."""

    def __init__(self, board: aio.Board, method: int, message: type[M], maxsize: int) -> None:
        super().__init__(board, maxsize)
        self._message = message
        #: The value known when the iterator started (None: none yet).
        current, self._remove = board.sync.user_reports.add_sink(method, self._from_thread)
        self.current = None if current is None else _decode(current, message)
        board._streams.add(self)
        if board.closed:
            self.close()

    def _from_thread(self, raw: RawReport) -> None:  # the I/O thread, under the table's lock
        try:
            report = _decode(raw, self._message)
        except ProtocolError as error:
            log.warning("%s", error)
            return
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody listens any more
            self._loop.call_soon_threadsafe(self._put, report)

    def _detach(self) -> None:
        self._remove()


C = TypeVar("C", bound=ServiceClient)


class AsyncServiceClient(Generic[C]):
    """A generated service client for ``protoduino.aio``: the blocking client's
    ``submit_`` forms, awaited (no second request layer)."""

    #: The blocking client class this one awaits.
    SYNC: ClassVar[type[ServiceClient]] = ServiceClient

    def __init__(self, board: aio.Board) -> None:
        self.board = board
        self.sync: C = self.SYNC(board.sync)  # type: ignore[assignment]

    @staticmethod
    async def _wait(future: Future[M]) -> M:
        return await asyncio.wrap_future(future)

    def _stream(self, method: int, message: type[M], maxsize: int) -> ReportStream[M]:
        return ReportStream(self.board, method, message, maxsize)
