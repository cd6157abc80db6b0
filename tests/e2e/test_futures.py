"""Non-blocking calls: ``submit`` forms return futures resolved by the Ack, with blocking errors.

The fake device holds or scripts Acks (several calls in flight from one
thread, refusals, silence, close); the simulated boards show the values at the
pins in their traces.
"""

from __future__ import annotations

import functools
import itertools
import threading
from collections.abc import Callable
from concurrent.futures import Future, wait
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino import Board
from protoduino.constants import MAX_MESSAGE_ID, PacketType
from protoduino.messages import ArduinoOut, Status, parse_out
from protoduino.packets import Packet
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice, ack
from protoduino.transport import FrameRecord, Transport
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin

#: Long enough that a held Ack never times out while a test looks at the futures.
PATIENT = 5.0


class Holder:
    """A fake-device handler that keeps the Acks of Controls until released."""

    def __init__(self, fake: PtyDevice) -> None:
        self.fake = fake
        self.held: list[Any] = []
        self.lock = threading.Lock()
        fake.handler = self

    def __call__(self, msg: Any) -> list[Any]:
        replies = self.fake.default_reply(msg)
        if msg.WhichOneof("data") in ("servo_control", "digital_control"):
            with self.lock:
                self.held.extend(replies)
            return []
        return replies

    def release(self) -> None:
        with self.lock:
            held, self.held = self.held, []
        for out in held:
            self.fake.send_data(out)


def test_several_calls_in_flight_from_one_thread(tmp_path: Path) -> None:
    with (
        PtyDevice(tmp_path) as fake,
        Board.open(fake.port, ack_timeout=PATIENT, max_retries=0, ping=False) as board,
    ):
        servo = board.servo(9)
        led = board.digital_output(13)
        holder = Holder(fake)
        before = len(fake.arrivals())
        futures = [servo.submit(10), servo.submit_us(1500), led.submit(True)]
        # Every one reached the device before any Ack came back: nothing blocked.
        assert fake.wait_for(lambda: len(fake.arrivals()) == before + 3)
        assert not any(f.done() for f in futures)
        assert all(f.running() and not f.cancel() for f in futures)  # sent is sent
        holder.release()
        done, _ = wait(futures, timeout=PATIENT)
        assert len(done) == 3
        assert [f.result() for f in futures] == [None, None, None]
        assert fake.values == {9: 1500, 13: 1}


def test_future_values(board: Board, fake: PtyDevice) -> None:
    servo = board.submit_servo(9, safe=10).result(PATIENT)
    assert isinstance(servo, protoduino.Servo) and servo.pin == 9
    led = board.submit_digital_output(13, safe=True).result(PATIENT)
    assert isinstance(led, protoduino.DigitalOutput) and led.pin == 13
    assert [r.kind for r in fake.arrivals()][-2:] == ["servo_init", "digital_init"]
    rtt = board.submit_ping(b"abc").result(PATIENT)
    assert isinstance(rtt, float) and rtt > 0
    assert board.submit_stop().result(PATIENT) is None
    assert fake.arrivals("stop")


def test_argument_errors_raise_at_once(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9, min_us=1000, max_us=2000)
    led = board.digital_output(13)
    before = len(fake.arrivals())
    refused: list[tuple[Callable[[], object], int]] = [
        (lambda: servo.submit(181), Status.STATUS_OUT_OF_RANGE),
        (lambda: servo.submit_us(999), Status.STATUS_OUT_OF_RANGE),
        (lambda: board.submit_servo(1), Status.STATUS_RESERVED_PIN),
        (lambda: board.submit_digital_output(9), Status.STATUS_PIN_IN_USE),
        (lambda: board.submit_ping(bytes(65)), Status.STATUS_DECODE_ERROR),
    ]
    for action, status in refused:
        with pytest.raises(protoduino.CommandRejectedError) as info:
            action()
        assert info.value.status == status and info.value.sent is False
    with pytest.raises(TypeError):
        servo.submit("4.5")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        led.submit("on")  # type: ignore[arg-type]
    assert len(fake.arrivals()) == before  # nothing went out


def test_device_refusal_in_the_future(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    fake.handler = lambda msg: [ack(msg.message_id, Status.STATUS_OUT_OF_RANGE)]
    error = servo.submit(10).exception(PATIENT)
    assert isinstance(error, protoduino.CommandRejectedError)
    assert error.status == Status.STATUS_OUT_OF_RANGE and error.sent is True
    # The blocking call raises the same kind of error.
    with pytest.raises(protoduino.CommandRejectedError) as info:
        servo.write(10)
    assert info.value.status == Status.STATUS_OUT_OF_RANGE


def test_silence_times_out(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    fake.handler = lambda msg: []
    future = servo.submit(10)
    error = future.exception(PATIENT)
    assert isinstance(error, protoduino.AckTimeoutError) and isinstance(error, TimeoutError)
    assert len(fake.arrivals("servo_control")) == 4  # the first try and three retries


def test_wrong_ping_echo(board: Board, fake: PtyDevice) -> None:
    def bad_echo(msg: Any) -> list[Any]:
        out = ArduinoOut()
        out.ack.message_id = msg.message_id
        out.ack.ping_echo = b"other"
        return [out]

    fake.handler = bad_echo
    assert isinstance(board.submit_ping(b"mine").exception(PATIENT), protoduino.ProtocolError)


def test_close_fails_outstanding_futures(tmp_path: Path) -> None:
    with PtyDevice(tmp_path) as fake:
        board = Board.open(fake.port, ack_timeout=PATIENT, max_retries=0, ping=False)
        servo = board.servo(9)
        Holder(fake)
        future = servo.submit(10)
        assert fake.wait_for(lambda: bool(fake.arrivals("servo_control")))
        board.close()
        assert isinstance(future.exception(PATIENT), protoduino.BoardClosedError)
        with pytest.raises(protoduino.BoardClosedError):
            servo.submit(20)


def test_done_callback_may_command_the_board(board: Board, fake: PtyDevice) -> None:
    """Futures resolve on the event thread, not the I/O thread: a blocking call works there."""
    servo = board.servo(9)
    seen: list[str] = []
    finished = threading.Event()

    def then(future: Future[None]) -> None:
        seen.append(threading.current_thread().name)
        servo.write(30)  # blocking, from the callback
        finished.set()

    servo.submit(20).add_done_callback(then)
    assert finished.wait(PATIENT)
    assert seen[0].startswith("protoduino-events")
    assert fake.values[9] == 30


def record(order: list[int], value: int, future: Future[None]) -> None:
    order.append(value)


def test_futures_in_ack_order_with_blocking_calls(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    order: list[int] = []
    futures = []
    for degrees in range(0, 181, 20):
        future = servo.submit(degrees)
        future.add_done_callback(functools.partial(record, order, degrees))
        futures.append(future)
    servo.write(7)  # a blocking call among futures still returns once acked
    wait(futures, timeout=PATIENT)
    assert order == list(range(0, 181, 20))
    assert fake.values[9] == 7


def ends_near(want: int, values: list[int]) -> bool:
    return bool(values) and abs(values[-1] - want) <= PULSE_TOLERANCE_US


def test_futures_reach_the_pins(sim_board: SimBoard) -> None:
    with Board.open(sim_board.port) as board:
        servos = [board.servo(pin) for pin in (3, 5, 6, 9)]
        led = board.digital_output(13)
        futures: list[Future[None]] = []
        for step in range(5):
            futures += [s.submit(step * 20 + i) for i, s in enumerate(servos)]
            futures.append(led.submit(step % 2 == 0))
        done, _ = wait(futures, timeout=30)
        assert len(done) == len(futures)
        assert all(f.exception() is None for f in futures)
        for i, servo in enumerate(servos):
            want = 544 + (80 + i) * (2400 - 544) // 180
            wait_for_pin(sim_board, servo.pin, functools.partial(ends_near, want))
        wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])
        assert board.stats.timeouts == 0 and board.stats.rejected == 0


def test_callers_own_writes_keep_seq_and_ids_in_order(tmp_path: Path) -> None:
    """A caller writes its own COMMAND when nothing is queued (transport.py's docstring),
    the I/O thread the ones an Ack lets go: with both at once, from four threads, every
    SEQ on the wire follows the one before and the message ids go out in the order given.
    A frame monitor sees every frame on the I/O thread, each command before its Ack."""
    with (
        PtyDevice(tmp_path) as fake,
        Board.open(fake.port, ack_timeout=PATIENT, max_retries=0, ping=False) as board,
    ):
        led = board.digital_output(13)
        transport = board._transport  # the real port's transport: counters of who wrote
        assert isinstance(transport, Transport)
        seen: list[tuple[str, str, int]] = []  # thread, direction, message id

        def monitor(rec: FrameRecord) -> None:
            item = rec.item
            assert isinstance(item, Packet)
            if item.type is PacketType.COMMAND:
                seen.append((threading.current_thread().name, rec.direction, item.payload[1]))
            elif item.type is PacketType.DATA:
                out = parse_out(item.payload)
                if out.WhichOneof("data") == "ack":
                    seen.append((threading.current_thread().name, "ack", out.ack.message_id))

        board.add_frame_monitor(monitor)
        direct, written = transport.direct_writes, transport.tx_packets
        go = threading.Event()
        held: list[Any] = []

        def hold_four(msg: Any) -> list[Any]:
            """The first four Acks wait, the device's thread with them, until ``go``; then
            it sends them itself (one thread sends, in SEQ order)."""
            if len(held) < 4 and msg.WhichOneof("data") == "digital_control":
                held.extend(fake.default_reply(msg))
                if len(held) < 4:
                    return []
                go.wait(PATIENT)
                fake.handler = fake.default_reply
                return held
            return fake.default_reply(msg)

        fake.handler = hold_four
        first = [led.submit(i % 2 == 0) for i in range(8)]  # window 4: four wait
        assert fake.wait_for(lambda: len(fake.arrivals("digital_control")) == 4)
        assert transport.direct_writes - direct == 4  # the window's four: the caller wrote
        go.set()  # their Acks let the four that wait go, from the I/O thread
        done, _ = wait(first, timeout=PATIENT)
        assert len(done) == 8
        for f in first:
            f.result()
        by_io = (transport.tx_packets - written) - (transport.direct_writes - direct)
        assert by_io == 4

        def hammer() -> None:
            futures = [led.submit(i % 2 == 0) for i in range(40)]
            for i in range(5):
                led.write(i % 2 == 0)
            wait(futures, timeout=PATIENT * 4)

        threads = [threading.Thread(target=hammer) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(PATIENT * 4)
        assert not any(t.is_alive() for t in threads)
        received = fake.arrivals()
        seqs = [r.seq for r in received]
        assert all((b - a) & 0xFF == 1 for a, b in itertools.pairwise(seqs)), str(seqs)
        ids = [r.msg.message_id for r in received]
        assert all(b == a % MAX_MESSAGE_ID + 1 for a, b in itertools.pairwise(ids)), str(ids)
        assert len(fake.arrivals("digital_control")) == 8 + 4 * 45
        assert board._link.seq_desyncs == 0 and board._link.handshakes == 1
        assert {name for name, _, _ in seen} == {transport._thread.name}  # type: ignore[union-attr]
        sent = [mid for _, direction, mid in seen if direction == "tx"]
        assert sent == ids[-len(sent) :]  # every command after the monitor came, in order
        assert len(sent) == 8 + 4 * 45
        open_ids: set[int] = set()
        for _, direction, mid in seen:
            if direction == "tx":
                open_ids.add(mid)
            else:
                assert mid in open_ids, f"the Ack of {mid} shown before its command"
                open_ids.discard(mid)


def test_a_monitor_sees_an_ack_after_its_call_has_it(tmp_path: Path) -> None:
    """A frame read is shown to the monitors once the layers above have it (transport.py):
    when a monitor sees an Ack, the future it answers is already resolved, so a slow
    monitor (a capture writing its line) is never on the way from the Ack to its caller."""
    with (
        PtyDevice(tmp_path) as fake,
        Board.open(fake.port, ack_timeout=PATIENT, max_retries=0, ping=False) as board,
    ):
        led = board.digital_output(13)
        holder = Holder(fake)  # each Ack waits until its future is known here
        current: list[Future[None]] = []
        resolved_when_shown: list[bool] = []

        def monitor(rec: FrameRecord) -> None:
            item = rec.item
            if (
                rec.direction == "rx"
                and isinstance(item, Packet)
                and item.type is PacketType.DATA
                and parse_out(item.payload).WhichOneof("data") == "ack"
            ):
                resolved_when_shown.append(current[-1].done())

        board.add_frame_monitor(monitor)
        for i in range(20):
            current.append(led.submit(i % 2 == 0))
            assert fake.wait_for(lambda: bool(holder.held))
            holder.release()
            current[-1].result(PATIENT)
        assert resolved_when_shown == [True] * 20
