"""The one lock order: the request layer's lock (Rpc), then the board's (rpc.py, "Lock order").

A board on protoduino.testing's device runs every path on this thread, so each acquisition
is recorded with the locks already held; a reboot drives the restore, the path where the
request layer calls the board (restore_provider) with its lock held.
"""

from __future__ import annotations

import threading
from types import TracebackType

from protoduino.testing import VirtualDevice


class Journal:
    """The tracked locks this (one) thread holds, and every acquisition with what was held."""

    def __init__(self) -> None:
        self.held: list[str] = []
        self.order: list[tuple[tuple[str, ...], str]] = []


class TrackedLock:
    """A lock that records each acquisition in a journal."""

    def __init__(self, name: str, journal: Journal) -> None:
        self.name = name
        self.journal = journal
        self._lock = threading.Lock()

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        self.journal.order.append((tuple(self.journal.held), self.name))
        got = self._lock.acquire(blocking, timeout)
        if got:
            self.journal.held.append(self.name)
        return got

    def release(self) -> None:
        self.journal.held.remove(self.name)
        self._lock.release()

    def __enter__(self) -> bool:
        return self.acquire()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


def test_the_board_lock_is_never_held_while_the_request_lock_is_taken() -> None:
    device = VirtualDevice()
    journal = Journal()
    with device.open_board(ping=False, restore="last") as board:
        board._lock = TrackedLock("board", journal)  # type: ignore[assignment]
        board._rpc._lock = TrackedLock("rpc", journal)  # type: ignore[assignment]
        servo = board.servo(9, safe=90)
        led = board.digital_output(13)
        board.pose({servo: 30, led: True})
        servo.submit(40)
        device.run(0)
        board.heartbeat()
        device.reboot()  # the restore: rpc calls the board's restore_provider
        device.run(0.5)
        assert [m.servo_init.pin for m in device.commands("servo_init")] == [9, 9]
        led.release()
        _ = board.stats
        board.release_all()
    order = journal.order
    assert (("rpc",), "board") in order, "the restore path was not driven"
    inverted = [(held, name) for held, name in order if name == "rpc" and "board" in held]
    assert inverted == []
