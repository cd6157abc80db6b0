"""The options of a board: one typed declaration, used by every way of opening one.

:class:`BoardOptions` names each option and its type once; ``Board(url, **options)``,
``Board.open``, ``protoduino.aio.open`` and the command line (``cli/options.py``) all take it,
so a new option is added here and type-checked everywhere. :data:`DEFAULTS` holds each
option's default (checked against the declaration by mypy, and complete by
tests/unit/test_board_options.py); :func:`resolved` merges what a caller gave over them.
"""

from __future__ import annotations

import os
import threading
from typing import Final, Literal, Protocol, TypedDict

from .constants import (
    ACK_TIMEOUT,
    FAILSAFE_TIMEOUT,
    HANDSHAKE_TIMEOUT,
    MAX_RETRIES,
    WATCHDOG_TIMEOUT,
)
from .errors import ArgumentTypeError, BoardClosedError
from .session import REBOOT_LIMIT, REBOOT_WINDOW
from .transport import FrameMonitor

#: What keeps the device's failsafe from firing: any Ping, or only the control loop's Heartbeat.
Liveness = Literal["ping", "heartbeat"]
#: What comes back after the device lost the outputs: safe values, or the last ones too.
RestorePolicy = Literal["safe", "last"]


class Closable(Protocol):
    """What :class:`OpenCancel` closes: the board being opened."""

    def close(self) -> None: ...


class OpenCancel:
    """Abandons a :meth:`Board.open` in progress from another thread.

    Pass one as ``Board.open(..., cancel=c)`` (it is an option of the board, so it lives with
    them); ``c.cancel()`` then closes the board
    being opened: the open raises :class:`BoardClosedError` (from wherever it was:
    opening the port, the handshake, reading the device's info) and, once
    ``cancel()`` returned, nothing of it runs: no I/O or event thread, no Ping, the
    port's lock released. A cancel that comes after the open returned closes the
    board it returned, so the race between the two ends the same way.
    :func:`protoduino.aio.open` uses one when its task is cancelled. ``cancel()``
    blocks while the board closes (its threads are joined: see :meth:`Board.close`).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._board: Closable | None = None
        self._cancelled = False

    @property
    def cancelled(self) -> bool:
        return self._cancelled

    def cancel(self) -> None:
        with self._lock:
            self._cancelled = True
            board = self._board
        if board is not None:
            board.close()

    def _attach(self, board: Closable) -> None:
        """Called by the board being opened, before it starts anything cancel() must stop."""
        with self._lock:
            if self._cancelled:
                raise BoardClosedError("the open was cancelled")
            self._board = board


class BoardOptions(TypedDict, total=False):
    """Every keyword of :meth:`protoduino.Board.open`; see its docstring for what each does."""

    #: The line rate, pinned; None: open at 115200 and agree on the fastest both ends offer.
    baudrate: int | None
    #: Seconds a command waits for its Ack before it is sent again.
    ack_timeout: float
    #: Seconds the device has to answer RESET.
    handshake_timeout: float
    #: Retransmissions of a command before it fails.
    max_retries: int
    #: Commands awaiting their Ack at once.
    window: int
    #: Whether the automatic Ping runs from the start.
    ping: bool
    #: Called with every frame in both directions (on the I/O thread).
    monitor: FrameMonitor | None
    #: A capture file recording every frame, the counters and the events.
    capture: str | os.PathLike[str] | None
    #: Rotate the capture before it grows past this many bytes.
    capture_max_bytes: int | None
    #: Seconds the device may stay silent while answers are due.
    watchdog_timeout: float
    #: Seconds without a sign of life before the device drives every output safe.
    failsafe_timeout: float
    liveness: Liveness
    restore: RestorePolicy
    #: A host session to resume (1..2**32-1); None: a new one.
    session: int | None
    #: This many losses of the outputs within reboot_window seconds stop restoring.
    reboot_limit: int
    reboot_window: float
    #: Lets another thread abandon the open.
    cancel: OpenCancel | None


DEFAULTS: Final[BoardOptions] = {
    "baudrate": None,
    "ack_timeout": ACK_TIMEOUT,
    "handshake_timeout": HANDSHAKE_TIMEOUT,
    "max_retries": MAX_RETRIES,
    "window": 4,
    "ping": True,
    "monitor": None,
    "capture": None,
    "capture_max_bytes": None,
    "watchdog_timeout": WATCHDOG_TIMEOUT,
    "failsafe_timeout": FAILSAFE_TIMEOUT,
    "liveness": "ping",
    "restore": "safe",
    "session": None,
    "reboot_limit": REBOOT_LIMIT,
    "reboot_window": REBOOT_WINDOW,
    "cancel": None,
}


def resolved(options: BoardOptions) -> BoardOptions:
    """``options`` over :data:`DEFAULTS`; an unknown keyword raises :class:`ArgumentTypeError`
    (as Python's own ``TypeError`` for a keyword a function lacks would, inside the tree)."""
    unknown = sorted(set(options) - set(DEFAULTS))
    if unknown:
        raise ArgumentTypeError(f"unknown board option(s): {', '.join(unknown)}")
    return {**DEFAULTS, **options}
