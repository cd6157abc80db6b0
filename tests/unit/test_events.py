"""The event queue's bound and drop policy, and how close() stops the event thread."""

from __future__ import annotations

import threading
import time

from protoduino.events import Event, EventDispatcher, EventKind


class Gate:
    """A callback that records each event and holds the event thread on the first one."""

    def __init__(self) -> None:
        self.seen: list[Event] = []
        self.entered = threading.Event()
        self.release = threading.Event()

    def __call__(self, event: Event) -> None:
        self.seen.append(event)
        self.entered.set()
        self.release.wait(30)

    def wait_seen(self, count: int, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while len(self.seen) < count:
            assert time.monotonic() < deadline, f"only {self.seen}"
            time.sleep(0.01)


def ev(kind: EventKind, text: str) -> Event:
    return Event(kind, text)


def test_informational_events_go_first_state_changes_last() -> None:
    dispatcher = EventDispatcher("test", limit=3, close_wait=5.0)
    gate = Gate()
    dispatcher.subscribe(gate)
    try:
        dispatcher.put(ev(EventKind.DEVICE_DESYNC, "held"))
        assert gate.entered.wait(5)  # the callback holds the thread: the queue only fills
        for kind, text in [
            (EventKind.FAILSAFE, "f1"),
            (EventKind.DEVICE_DESYNC, "l1"),
            (EventKind.REBOOTED, "r1"),  # full: f1 l1 r1
            (EventKind.DEVICE_DESYNC, "l2"),  # the oldest informational one goes: f1 r1 l2
            (EventKind.RESTORED, "s1"),  # again: f1 r1 s1
            (EventKind.DECODE_ERROR, "d1"),  # none waiting: the new informational one goes
            (EventKind.ERROR, "e1"),  # nothing but state changes: the oldest goes
        ]:
            dispatcher.put(ev(kind, text))
            assert dispatcher.waiting <= 3
        assert dispatcher.dropped == {"device_desync": 2, "decode_error": 1, "failsafe": 1}
        gate.release.set()
        gate.wait_seen(4)
        assert [e.text for e in gate.seen] == ["held", "r1", "s1", "e1"]
    finally:
        gate.release.set()
        dispatcher.close()


def test_close_calls_no_callback_after_it_and_leaves_a_running_one_alone() -> None:
    dispatcher = EventDispatcher("test", close_wait=0.05)
    gate = Gate()
    dispatcher.subscribe(gate)
    for i in range(10):
        dispatcher.put(ev(EventKind.DEVICE_DESYNC, str(i)))
    assert gate.entered.wait(5)
    dispatcher.close()  # returns although the callback still runs
    thread = dispatcher.thread
    assert thread.is_alive()  # not interrupted: Python cannot stop a thread
    dispatcher.put(ev(EventKind.FAILSAFE, "late"))  # after close: ignored
    gate.release.set()
    thread.join(5)
    assert not thread.is_alive()  # it ended once the callback returned
    assert [e.text for e in gate.seen] == ["0"]  # the nine waiting events were discarded


def test_close_from_a_callback() -> None:
    dispatcher = EventDispatcher("test")
    done = threading.Event()

    def close_and_note(event: Event) -> None:
        dispatcher.close()  # must not wait for its own thread
        done.set()

    dispatcher.subscribe(close_and_note)
    dispatcher.put(ev(EventKind.DEVICE_DESYNC, "x"))
    assert done.wait(5)
    dispatcher.thread.join(5)
    assert not dispatcher.thread.is_alive()


def test_jobs_are_never_dropped_and_still_run_at_close() -> None:
    # Jobs resolve futures: one dropped would leave a caller waiting forever.
    dispatcher = EventDispatcher("test", limit=1, close_wait=0.05)
    gate = Gate()
    dispatcher.subscribe(gate)
    ran: list[int] = []
    dispatcher.put(ev(EventKind.DEVICE_DESYNC, "held"))
    assert gate.entered.wait(5)
    dispatcher.put_job(lambda: ran.append(1))
    dispatcher.put(ev(EventKind.DEVICE_DESYNC, "a"))
    dispatcher.put(ev(EventKind.DEVICE_DESYNC, "b"))  # the limit counts events only: "a" goes
    dispatcher.put_job(lambda: ran.append(2))
    assert dispatcher.dropped == {"device_desync": 1}
    dispatcher.close()  # the callback still holds the thread
    gate.release.set()
    dispatcher.thread.join(5)
    assert not dispatcher.thread.is_alive()
    assert ran == [1, 2]  # the jobs ran; the waiting event "b" was discarded
    assert [e.text for e in gate.seen] == ["held"]
    dispatcher.put_job(lambda: ran.append(3))  # after the thread ended: run at once, here
    assert ran == [1, 2, 3]


def test_a_future_resolves_where_it_is_settled_unless_it_has_done_callbacks() -> None:
    """EventThreadFuture (the submit forms'): without a done-callback, ``result()`` sees the
    value as soon as it is settled, the event thread held in a callback; with one, it is
    resolved on the event thread, its callbacks run as it resolves, in order with the
    events, never on the thread that settled it; one added once it is done runs at once."""
    from protoduino.events import EventThreadFuture

    dispatcher = EventDispatcher("test", close_wait=5.0)
    gate = Gate()
    dispatcher.subscribe(gate)
    order: list[str] = []
    threads: list[str] = []

    def settle_on_own_thread(future: EventThreadFuture[int], value: int) -> None:
        io = threading.Thread(target=future.settle, args=(lambda: value,), name="io")
        io.start()  # as the board's I/O thread settles it
        io.join(30)
        assert not io.is_alive()

    def callback(f: object) -> None:
        threads.append(threading.current_thread().name)
        order.append("callback")

    def failing(f: object) -> None:
        raise RuntimeError("a callback's failure is logged, the next one still runs")

    try:
        dispatcher.put(ev(EventKind.DEVICE_DESYNC, "first"))
        gate.entered.wait(30)  # the event thread is held in the callback
        plain: EventThreadFuture[int] = EventThreadFuture(dispatcher.put_job)
        settle_on_own_thread(plain, 42)
        assert plain.result(0) == 42  # resolved there, the event thread still held

        watched: EventThreadFuture[int] = EventThreadFuture(dispatcher.put_job)
        watched.add_done_callback(failing)
        watched.add_done_callback(callback)
        settle_on_own_thread(watched, 7)
        assert not watched.done() and order == []  # its resolution waits its turn
        dispatcher.put(ev(EventKind.DEVICE_DESYNC, "after"))
        gate.release.set()
        assert watched.result(30) == 7
        gate.wait_seen(2)
        assert order == ["callback"]
        assert threads[0].startswith("protoduino-events")
        # Added once done: called at once by the thread that adds it.
        watched.add_done_callback(callback)
        plain.add_done_callback(callback)
        assert threads[1:] == [threading.current_thread().name] * 2
        failed: EventThreadFuture[int] = EventThreadFuture(dispatcher.put_job)
        failed.settle(lambda: 1 // 0)
        assert isinstance(failed.exception(0), ZeroDivisionError)
    finally:
        gate.release.set()
        dispatcher.close()
