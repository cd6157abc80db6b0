"""Board API against the pty fake (PtyDevice): checks before sending, restore, events, threads."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino import Board, Event, EventKind
from protoduino.events import EVENT_QUEUE_LIMIT
from protoduino.messages import ArduinoOut, Status
from protoduino.testing import PtyDevice, ack
from protoduino.transport import FrameRecord


class Recorder:
    def __init__(self, board: Board) -> None:
        self.events: list[Event] = []
        self._cond = threading.Condition()
        board.on_event(self)

    def __call__(self, event: Event) -> None:
        with self._cond:
            self.events.append(event)
            self._cond.notify_all()

    def wait(self, kind: EventKind, timeout: float = 30.0, count: int = 1) -> Event:
        """The ``count``-th event of ``kind``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                found = self.of(kind)
                if len(found) >= count:
                    return found[count - 1]
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {kind} event; got {self.events}")
                self._cond.wait(left)

    def of(self, kind: EventKind) -> list[Event]:
        return [e for e in self.events if e.kind is kind]


def info_msg(count: int = 1) -> Any:
    """An informational DATA message (a DecodeError): an event no state hangs on."""
    out = ArduinoOut()
    out.decode_error.count = count
    return out


REJECTIONS: list[tuple[str, Callable[[Board], object], int]] = [
    ("pin too high", lambda b: b.servo(20), Status.STATUS_INVALID_PIN),
    ("negative pin", lambda b: b.digital_output(-1), Status.STATUS_INVALID_PIN),
    ("reserved pin 0", lambda b: b.digital_output(0), Status.STATUS_RESERVED_PIN),
    ("reserved pin 1", lambda b: b.servo(1), Status.STATUS_RESERVED_PIN),
    ("min_us too low", lambda b: b.servo(9, min_us=399), Status.STATUS_INVALID_ARGUMENT),
    ("max_us too high", lambda b: b.servo(9, max_us=2601), Status.STATUS_INVALID_ARGUMENT),
    ("min >= max", lambda b: b.servo(9, min_us=1500, max_us=1500), Status.STATUS_INVALID_ARGUMENT),
    ("safe > 180", lambda b: b.servo(9, safe=181), Status.STATUS_OUT_OF_RANGE),
    ("safe < 0", lambda b: b.servo(9, safe=-1), Status.STATUS_OUT_OF_RANGE),
    ("safe_us below", lambda b: b.servo(9, safe_us=543), Status.STATUS_OUT_OF_RANGE),
    ("safe_us above", lambda b: b.servo(9, safe_us=2401), Status.STATUS_OUT_OF_RANGE),
    ("ping too long", lambda b: b.ping(bytes(65)), Status.STATUS_DECODE_ERROR),
]


@pytest.mark.parametrize(("why", "action", "status"), REJECTIONS, ids=[r[0] for r in REJECTIONS])
def test_checked_before_sending(
    board: Board, fake: PtyDevice, why: str, action: Callable[[Board], object], status: int
) -> None:
    before = len(fake.arrivals())
    with pytest.raises(protoduino.CommandRejectedError) as info:
        action(board)
    assert info.value.status == status
    assert info.value.sent is False
    assert len(fake.arrivals()) == before  # nothing went out


def test_control_checks(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9, min_us=1000, max_us=2000)
    before = len(fake.arrivals())
    bad: list[Callable[[], None]] = [
        lambda: servo.write(181),
        lambda: servo.write(-1),
        lambda: servo.write_us(999),
    ]
    for action in bad:
        with pytest.raises(protoduino.CommandRejectedError) as info:
            action()
        assert info.value.status == Status.STATUS_OUT_OF_RANGE and not info.value.sent
    with pytest.raises(TypeError):
        servo.write("4.5")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        board.servo("9")
    with pytest.raises(TypeError):
        board.servo(10, safe=90, safe_us=1500)
    assert len(fake.arrivals()) == before
    servo.write_us(2000)
    servo.write(180)
    assert fake.values[9] == 180


def test_pin_in_use_and_free_slots(board: Board, fake: PtyDevice) -> None:
    board.digital_output(13)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.servo(13)
    assert info.value.status == Status.STATUS_PIN_IN_USE and not info.value.sent
    board.servo(9)
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.digital_output(9)
    assert info.value.status == Status.STATUS_PIN_IN_USE
    for pin in range(2, 9):  # 9 is a servo already: 8 in all
        board.servo(pin)
    board.servo(9, safe=10)  # re-init of a servo pin takes no new slot
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.servo(10)
    assert info.value.status == Status.STATUS_NO_FREE_RESOURCE and not info.value.sent


def test_outputs_reach_the_device(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9, safe=90)
    servo.write(45)
    led = board.digital_output(13, safe=False)
    led.write(True)
    assert fake.values == {9: 45, 13: 1}
    led.off()
    assert fake.values[13] == 0
    init = fake.arrivals("servo_init")[0].msg.servo_init
    assert (init.pin, init.min_us, init.max_us, init.safe_degrees) == (9, 544, 2400, 90)
    assert fake.arrivals("digital_init")[0].msg.digital_init.safe_level is False
    board.stop()
    assert fake.arrivals("stop")


def test_device_rejection_is_sent_true(board: Board, fake: PtyDevice) -> None:
    fake.handler = lambda msg: [ack(msg.message_id, Status.STATUS_PIN_IN_USE)]
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.servo(9)
    assert info.value.status == Status.STATUS_PIN_IN_USE and info.value.sent


def _configure_a_session(board: Board) -> tuple[protoduino.Servo, protoduino.DigitalOutput]:
    servo = board.servo(9, safe=90)
    servo.write(45)
    led = board.digital_output(13)
    led.write(True)
    board.servo(10, safe_us=1500)  # an output never commanded: its Init alone is replayed
    return servo, led


def test_restore_after_reboot_brings_outputs_up_safe(board: Board, fake: PtyDevice) -> None:
    """The default policy: every output re-initialised (at its safe value), no stale values."""
    rec = Recorder(board)
    servo, _ = _configure_a_session(board)
    mark = len(fake.arrivals())
    fake.reboot()
    restored = rec.wait(EventKind.RESTORED)
    assert restored.details == {"replayed": 4, "failed": [], "values": False}
    rec.wait(EventKind.REBOOTED)
    replay = [r.kind for r in fake.arrivals()[mark:] if r.kind != "ping"]
    assert replay[:4] == ["configure_failsafe", "servo_init", "digital_init", "servo_init"]
    assert fake.pins == {9: "servo", 13: "digital", 10: "servo"}
    assert fake.values == {}  # nothing moved back to a pose of the previous boot
    servo.write(50)  # and the session goes on
    assert fake.values[9] == 50


def test_restore_last_values_when_opted_in(fake: PtyDevice) -> None:
    with Board.open(fake.port, restore="last") as board:
        rec = Recorder(board)
        _configure_a_session(board)
        mark = len(fake.arrivals())
        fake.reboot()
        restored = rec.wait(EventKind.RESTORED)
        assert restored.details == {"replayed": 6, "failed": [], "values": True}
        replay = [r.kind for r in fake.arrivals()[mark:] if r.kind != "ping"]
        assert replay[:6] == ["configure_failsafe", "servo_init", "digital_init", "servo_init",
                              "servo_control", "digital_control"]  # fmt: skip
        assert fake.values == {9: 45, 13: 1}


def test_a_call_in_flight_at_a_reboot_fails_and_is_not_replayed(fake: PtyDevice) -> None:
    """Defect 3: the command whose execution reset the board is never sent again."""
    # ack_timeout 0.5: room for the reboot before retries run out.
    with Board.open(fake.port, ack_timeout=0.5, ping=False) as board:
        _call_in_flight_at_a_reboot(board, fake)


def _call_in_flight_at_a_reboot(board: Board, fake: PtyDevice) -> None:
    rec = Recorder(board)
    servo = board.servo(9)
    swallowed: list[int] = []

    def reboot_on_write(msg: Any) -> list[Any]:
        if msg.WhichOneof("data") == "servo_control" and not swallowed:
            swallowed.append(msg.message_id)
            threading.Thread(target=fake.reboot).start()  # the device dies mid-command
            return []
        return fake.default_reply(msg)

    fake.handler = reboot_on_write
    with pytest.raises(protoduino.DeviceRebootedError, match="rebooted"):
        servo.write(120)
    rec.wait(EventKind.RESTORED)
    assert [r.kind for r in fake.arrivals()].count("servo_control") == 1  # never replayed
    assert 9 not in fake.values and fake.pins == {9: "servo"}  # back, at its safe value
    servo.write(60)  # the application decides what comes next
    assert fake.values[9] == 60


def test_a_reboot_loop_stops_restoring(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False, reboot_limit=3, reboot_window=60.0) as board:
        rec = Recorder(board)
        servo = board.servo(9)
        for n in (1, 2):
            fake.reboot()
            rec.wait(EventKind.RESTORED, count=n)
            board.ping()
        inits = len(fake.arrivals("servo_init"))
        fake.reboot()
        error = rec.wait(EventKind.ERROR)
        assert "reboot loop" in error.text
        with pytest.raises(protoduino.RebootLoopError):
            servo.write(10)
        with pytest.raises(protoduino.RebootLoopError):
            board.ping()
        assert len(fake.arrivals("servo_init")) == inits  # no third restore
        assert len(rec.of(EventKind.RESTORED)) == 2


def test_stop_and_failsafe_forget_values(fake: PtyDevice) -> None:
    # Even with restore="last", a value the device overrode with the safe one
    # (Stop, a failsafe) is not driven again after a reboot.
    with Board.open(fake.port, ack_timeout=0.1, ping=False, restore="last") as board:
        rec = Recorder(board)
        servo = board.servo(9)
        servo.write(30)
        board.stop()
        assert rec.wait(EventKind.FAILSAFE).details == {"active": True, "cause": "stop", "epoch": 1}
        assert 9 not in fake.values  # the stop drove it safe
        fake.reboot()
        rec.wait(EventKind.RESTORED)
        assert 9 not in fake.values  # the restore keeps it so
        servo.write(60)
        assert fake.values[9] == 60
        fake.expire_failsafe()  # a new boot's epoch 0 runs out
        event = rec.wait(EventKind.FAILSAFE, count=2)
        assert event.details == {"active": True, "cause": "ping_timeout", "epoch": 1}
        assert 9 not in fake.values
        mark = len(fake.arrivals())
        fake.reboot()
        restored = rec.wait(EventKind.RESTORED, count=2)
        assert restored.details["replayed"] == 2  # no value left to replay
        replay = [r.kind for r in fake.arrivals()[mark:] if r.kind != "ping"]
        assert replay[:2] == ["configure_failsafe", "servo_init"]
        assert 9 not in fake.values


def test_decode_error_events(board: Board, fake: PtyDevice) -> None:
    rec = Recorder(board)
    out = ArduinoOut()
    out.decode_error.count = 3
    fake.send_data(out)
    assert rec.wait(EventKind.DECODE_ERROR).details == {"count": 3}


def test_callback_errors_do_not_stop_events(board: Board, fake: PtyDevice) -> None:
    def broken(event: Event) -> None:
        raise RuntimeError("user bug")

    board.on_event(broken)
    rec = Recorder(board)
    fake.send_data(info_msg())
    rec.wait(EventKind.DECODE_ERROR)


def test_unsubscribe(board: Board, fake: PtyDevice) -> None:
    seen: list[Event] = []
    unsubscribe = board.on_event(seen.append)
    unsubscribe()
    rec = Recorder(board)
    fake.send_data(info_msg())
    rec.wait(EventKind.DECODE_ERROR)
    assert seen == []


def test_concurrent_callers(board: Board, fake: PtyDevice) -> None:
    servos = [board.servo(pin) for pin in range(2, 10)]
    errors: list[BaseException] = []

    def worker(servo: protoduino.Servo) -> None:
        try:
            for degrees in range(0, 181, 6):
                servo.write(degrees)
            servo.write(servo.pin)
        except BaseException as error:
            errors.append(error)

    threads = [threading.Thread(target=worker, args=(s,)) for s in servos]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert errors == []
    assert fake.values == {pin: pin for pin in range(2, 10)}
    assert board.stats.timeouts == 0


def test_several_boards_at_once(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with (
        PtyDevice(tmp_path / "a") as fa,
        PtyDevice(tmp_path / "b") as fb,
        Board.open(fa.port) as a,
        Board.open(fb.port) as b,
    ):
        a.servo(9).write(10)
        b.servo(9).write(20)
        assert (fa.values[9], fb.values[9]) == (10, 20)


def test_close_from_an_event_callback(fake: PtyDevice) -> None:
    board = Board.open(fake.port, ping=False)
    closed = threading.Event()

    def close_on_log(event: Event) -> None:
        board.close()
        closed.set()

    board.on_event(close_on_log)
    fake.send_data(info_msg())
    assert closed.wait(5)
    assert board.closed


def test_an_event_flood_behind_a_slow_callback_stays_bounded(board: Board, fake: PtyDevice) -> None:
    # A device flooding informational events while a callback is slow: the queue holds at
    # most EVENT_QUEUE_LIMIT events, the oldest informational ones go first and are counted,
    # and a failsafe arriving behind the flood is delivered all the same.
    held = threading.Event()
    release = threading.Event()
    seen: list[Event] = []

    def slow(event: Event) -> None:
        seen.append(event)
        held.set()
        release.wait(30)

    board.on_event(slow)
    fake.send_data(info_msg(0))
    assert held.wait(5)  # the callback holds the event thread from here on
    flood = EVENT_QUEUE_LIMIT * 3
    fake.send_burst([info_msg(1000 + i) for i in range(flood)])
    failsafe = ArduinoOut()
    failsafe.failsafe.active = True
    failsafe.failsafe.cause = 1  # type: ignore[assignment]
    fake.send_data(failsafe)
    dropped = flood + 1 - EVENT_QUEUE_LIMIT  # what the queue cannot hold, failsafe included
    try:
        assert fake.wait_for(lambda: board.stats.events_dropped == {"decode_error": dropped}, 10)
        assert board.events.waiting == EVENT_QUEUE_LIMIT
    finally:
        release.set()
    assert fake.wait_for(lambda: bool(seen) and seen[-1].kind is EventKind.FAILSAFE, 10)
    counts = [e.details["count"] for e in seen if e.kind is EventKind.DECODE_ERROR]
    assert counts == [0] + [1000 + i for i in range(dropped, flood)]  # the newest


def test_close_returns_and_calls_nothing_more(fake: PtyDevice) -> None:
    board = Board.open(fake.port, ping=False)
    held = threading.Event()
    release = threading.Event()
    seen: list[Event] = []

    def slow(event: Event) -> None:
        seen.append(event)
        held.set()
        release.wait(30)

    board.on_event(slow)
    for i in range(10):
        fake.send_data(info_msg(i))
    assert held.wait(5)
    assert fake.wait_for(lambda: board.events.waiting == 9)
    try:
        board.close()  # returns although the callback still runs (after CLOSE_WAIT)
        thread = board.events.thread
        assert thread.is_alive()  # a running callback is not interrupted
    finally:
        release.set()
    thread.join(5)
    assert not thread.is_alive()
    assert [e.details["count"] for e in seen] == [0]  # nothing was called after close()


def test_a_frame_monitor_cannot_call_into_the_board(board: Board, fake: PtyDevice) -> None:
    # A monitor runs on the I/O thread: a call from it would wait for an answer that only
    # that thread can deliver (the link stalled for 8 s). It is refused at once instead.
    errors: list[BaseException] = []
    armed = threading.Event()

    def meddling(record: FrameRecord) -> None:
        if armed.is_set() and record.direction == "rx":
            armed.clear()
            try:
                board.ping(b"from the monitor")
            except protoduino.ProtoduinoError as error:
                errors.append(error)

    board.add_frame_monitor(meddling)
    armed.set()
    board.ping(b"main")  # its Ack is the frame the monitor sees
    assert len(errors) == 1 and isinstance(errors[0], protoduino.ReentrantCallError), errors
    assert "I/O thread" in str(errors[0])
    assert [p.msg.ping.payload for p in fake.arrivals("ping")] == [b"main"]
    assert board.stats.timeouts == 0 and board.stats.retransmits == 0
    board.close()  # closing from a monitor is fine too: nothing waits


def _open_fds() -> set[int]:
    return {int(name) for name in os.listdir("/proc/self/fd")}


def test_closing_from_a_frame_monitor_leaves_no_descriptor_open(fake: PtyDevice) -> None:
    # close() from the I/O thread cannot wait for that thread to end; the thread
    # closes the port and its wake-up pipe itself on the way out.
    before = _open_fds()
    earlier = set(threading.enumerate())  # a pty's name may be an earlier test's, too
    board = Board.open(fake.port, ack_timeout=0.1, ping=False)
    name = f"protoduino-io[{fake.port}]"
    (io_thread,) = [t for t in set(threading.enumerate()) - earlier if t.name == name]
    closed = threading.Event()

    def closer(record: FrameRecord) -> None:
        if record.direction == "rx" and not closed.is_set():
            board.close()
            closed.set()

    board.add_frame_monitor(closer)
    with contextlib.suppress(protoduino.ProtoduinoError):
        board.ping(b"last")  # its Ack is the frame the monitor closes on
    assert closed.wait(10.0)  # bounds a failing wait only
    io_thread.join(10.0)  # bounds a failing wait only
    assert not io_thread.is_alive()
    left = {fd: os.readlink(f"/proc/self/fd/{fd}") for fd in _open_fds() - before}
    assert left == {}
