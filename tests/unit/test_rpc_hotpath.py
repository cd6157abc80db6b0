"""The request layer's cheaper hot path keeps its rules: a call's completion (Done), the
memory of finished ids (late against unknown Acks), and the transport's raw POSIX I/O.

No clock is waited on: the layer is driven by hand, the threads only block until set.
"""

from __future__ import annotations

import os
import select
import threading
from collections.abc import Iterator

import protoduino
import pytest
import serial
from protoduino.constants import MAX_MESSAGE_ID, PacketType
from protoduino.errors import ProtoduinoError
from protoduino.framing import StreamDecoder, frame_packet
from protoduino.messages import ArduinoIn, ArduinoOut
from protoduino.packets import Packet
from protoduino.rpc import Done, Rpc
from protoduino.transport import Transport


def test_done_is_set_once_and_releases_every_waiter() -> None:
    done = Done()
    assert not done.is_set()
    assert done.wait(0) is False  # not set: a zero bound returns at once
    woke: list[bool] = []
    waiters = [threading.Thread(target=lambda: woke.append(done.wait())) for _ in range(3)]
    for t in waiters:
        t.start()
    done.set()
    done.set()  # a second set changes nothing (and does not raise)
    for t in waiters:
        t.join(10)
        assert not t.is_alive()
    assert woke == [True, True, True]
    assert done.is_set() and done.wait(0) and done.wait(None)


class _Link:
    """What Rpc needs of its link: every command is taken and kept."""

    down_error: ProtoduinoError | None = None
    active = True

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def send_command(self, payload: bytes) -> bool:
        self.sent.append(payload)
        return True

    def request_handshake(self) -> None:
        raise AssertionError("every id is acked at once here: no re-handshake is due")

    def reboot_inferred(self) -> None:
        pass

    def recent_frames(self) -> tuple[str, ...]:
        return ()


def _ack(message_id: int) -> ArduinoOut:
    out = ArduinoOut()
    out.ack.message_id = message_id
    return out


def _ping() -> ArduinoIn:
    msg = ArduinoIn()
    msg.ping.SetInParent()
    return msg


def test_a_finished_id_is_late_until_it_is_given_out_again() -> None:
    """Ids wrap at 127 (protocol version 5): an Ack for a finished id is late, not unknown,
    until the id goes to a new call, whose Ack it then is; an id never given out is unknown."""
    rpc = Rpc(notify=lambda event: None, ping=False, first_id=1, window=1)
    link = _Link()
    rpc.attach(link)
    calls = []
    for _ in range(MAX_MESSAGE_ID + 10):  # past the wrap: ids 1..127, then 1..10 again
        call = rpc.submit(_ping())
        rpc.link_message(_ack(call.message_id))
        assert call.done.is_set() and call.error is None
        calls.append(call)
    assert [c.message_id for c in calls[-11:]] == [127, *range(1, 11)]
    assert rpc.acks == MAX_MESSAGE_ID + 10
    rpc.link_message(_ack(calls[-1].message_id))  # the newest: late
    rpc.link_message(_ack(127))  # finished before the wrap, not given out since: late
    assert (rpc.late_acks, rpc.unknown_acks) == (2, 0)
    fresh = Rpc(notify=lambda event: None, ping=False, first_id=1, window=1)
    fresh.attach(_Link())
    fresh.link_message(_ack(5))  # never given out in this session: unknown
    assert (fresh.late_acks, fresh.unknown_acks) == (0, 1)
    pending = rpc.submit(_ping())  # id 11: its Ack completes it, whatever came before
    assert pending.message_id == 11 and not pending.done.is_set()
    rpc.link_message(_ack(11))
    assert pending.done.is_set() and pending.error is None
    assert rpc.state().open_calls == ()


def test_a_queued_call_that_fails_leaves_its_queue() -> None:
    rpc = Rpc(notify=lambda event: None, ping=False, first_id=1, window=1)
    link = _Link()
    rpc.attach(link)
    first, second = rpc.submit(_ping()), rpc.submit(_ping())
    assert len(link.sent) == 1 and rpc.state().pending == 1  # the window holds the second
    rpc.close()
    assert first.error is not None and second.error is not None
    assert rpc.state().pending == 0 and rpc.state().inflight == ()


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)
    yield master, path
    os.close(master)


def _packets(master: int, decoder: StreamDecoder) -> list[object]:
    """The next packets the transport wrote (a bound only against a hang: 10 s)."""
    while True:
        ready, _, _ = select.select([master], [], [], 10)
        assert ready, "the transport wrote nothing"
        got: list[object] = [i for i in decoder.feed(os.read(master, 100)) if isinstance(i, Packet)]
        if got:
            return got


class _Listener:
    def __init__(self) -> None:
        self.items: list[object] = []
        self.got = threading.Event()

    def transport_opened(self, reopened: bool) -> None:
        pass

    def transport_lost(self, error: Exception) -> None:
        pass

    def transport_received(self, items: list[object]) -> None:
        self.items.extend(items)
        self.got.set()

    def transport_tick(self, now: float) -> float:
        return now + 1.0


def test_a_pty_is_read_and_written_by_its_descriptor(pty: tuple[int, str]) -> None:
    master, path = pty
    transport = Transport(path)
    listener = _Listener()
    transport.start(listener)  # type: ignore[arg-type]
    try:
        assert transport._raw and transport._fd is not None  # pyserial's own POSIX class
        assert type(transport._port) is serial.Serial
        transport.send(PacketType.COMMAND, b"\x08\x01")
        decoder = StreamDecoder()
        assert _packets(master, decoder) == [Packet(PacketType.COMMAND, 0, b"\x08\x01")]
        os.write(master, frame_packet(PacketType.DATA, 7, b"\x01\x02"))
        assert listener.got.wait(10)
        assert listener.items == [Packet(PacketType.DATA, 7, b"\x01\x02")]
    finally:
        transport.close()


def test_a_pose_records_the_control_a_write_of_the_same_level_records() -> None:
    from protoduino.testing import VirtualDevice

    board = VirtualDevice().open_board(ping=False)
    led, other = board.digital_output(13), board.digital_output(12)
    levels: tuple[bool | int, ...] = (True, False, 1, 0, True)
    for level in levels:
        board.pose({led: level, other: not level})
        posed = (board._outputs[13].last, board._outputs[12].last)
        led.write(level)  # type: ignore[arg-type]  # 1 and 0 are levels too
        other.write(not level)
        assert posed == (board._outputs[13].last, board._outputs[12].last)
        assert led.value is bool(level) and other.value is (not level)
    with pytest.raises(protoduino.CommandRejectedError):
        board.pose({led: 2})  # still refused on the host, as a write of 2 is
    board.close()


class _Echo(_Listener):
    """Answers each packet it receives, from the I/O thread (as an Ack lets the next call
    of a window go): no wake-up is written for it, the thread's next pass sends it."""

    def __init__(self, transport: Transport) -> None:
        super().__init__()
        self.transport = transport

    def transport_received(self, items: list[object]) -> None:
        for item in items:
            if isinstance(item, Packet):
                self.transport.send(PacketType.COMMAND, item.payload)
        super().transport_received(items)


def test_a_packet_queued_on_the_io_thread_is_written_without_a_wake_up(
    pty: tuple[int, str],
) -> None:
    master, path = pty
    transport = Transport(path)
    transport.start(_Echo(transport))  # type: ignore[arg-type]
    try:
        decoder = StreamDecoder()
        for n in range(3):
            os.write(master, frame_packet(PacketType.DATA, n, bytes([n + 1])))
            assert _packets(master, decoder) == [Packet(PacketType.COMMAND, n, bytes([n + 1]))]
    finally:
        transport.close()


class _PortWrites:
    """``os.write`` as the transport calls it, counting the writes to one descriptor; each
    of them takes at most ``room.pop(0)`` bytes while ``room`` lists any (a full driver)."""

    def __init__(self, fd: int, room: list[int] | None = None) -> None:
        self.fd = fd
        self.room = room or []
        self.calls: list[int] = []  # the length of each write asked for
        self._write = os.write

    def __call__(self, fd: int, data: bytes) -> int:
        if fd != self.fd:
            return self._write(fd, data)
        self.calls.append(len(data))
        if self.room:
            return self._write(fd, bytes(data)[: self.room.pop(0)])
        return self._write(fd, data)


def _queued(path: str, payloads: list[bytes]) -> Transport:
    """A transport on the pty at ``path``, its port open, ``payloads`` queued as COMMANDs (no
    I/O thread: the test flushes them as the thread's pass does)."""
    transport = Transport(path)
    transport._open()
    for payload in payloads:
        transport.send(PacketType.COMMAND, payload)
    return transport


def _read_all(master: int, decoder: StreamDecoder) -> list[object]:
    """Every frame the transport wrote so far (it wrote before this is called)."""
    got: list[object] = []
    while select.select([master], [], [], 0)[0]:
        got += decoder.feed(os.read(master, 4096))
    return got


def test_packets_queued_together_leave_in_one_write(
    pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 35: the I/O thread writes every packet queued (a window's next calls, sent as
    a batch of Acks came in) in one write to a plain POSIX port, their SEQs in order."""
    master, path = pty
    payloads = [b"\x08\x01", b"\x08\x02\x10\x01", b"\x08\x03"]
    transport = _queued(path, payloads)
    try:
        assert transport._fd is not None
        writes = _PortWrites(transport._fd)
        monkeypatch.setattr(os, "write", writes)
        transport._flush_writes()
        monkeypatch.undo()
        assert len(writes.calls) == 1
        got = _read_all(master, StreamDecoder())
        assert got == [Packet(PacketType.COMMAND, n, p) for n, p in enumerate(payloads)]
        assert (transport.tx_packets, transport.tx_seq) == (3, 3)
        assert [r.item for r in transport._recent] == got  # recorded in the order written
    finally:
        transport._close_port()


def test_a_write_the_driver_cuts_finishes_its_frame_and_sends_the_rest_after(
    pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A driver with room for part of the batch: the frame it cut is finished (pyserial waits
    for room), the frames after it go in the next write; nothing is lost or reordered."""
    master, path = pty
    payloads = [b"\x08\x01\x10\x01", b"\x08\x02\x10\x01", b"\x08\x03\x10\x01"]
    transport = _queued(path, payloads)
    try:
        assert transport._fd is not None
        first = len(frame_packet(PacketType.COMMAND, 0, payloads[0]))
        writes = _PortWrites(transport._fd, room=[first + 2])  # the second frame is cut
        monkeypatch.setattr(os, "write", writes)
        transport._flush_writes()
        monkeypatch.undo()
        assert writes.calls[0] == 3 * first  # the three asked for in one write
        got = _read_all(master, StreamDecoder())
        assert got == [Packet(PacketType.COMMAND, n, p) for n, p in enumerate(payloads)]
        assert (transport.tx_packets, transport.tx_seq, transport.write_errors) == (3, 3, 0)
    finally:
        transport._close_port()


def test_a_write_that_times_out_drops_the_packet_it_cut_and_its_seq_goes_to_the_next(
    pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """docs/protocol.md 6: a frame that failed to write keeps its SEQ for the next one; the
    packets queued behind it stay queued (the next pass writes them)."""
    master, path = pty
    payloads = [b"\x08\x01", b"\x08\x02", b"\x08\x03"]
    transport = _queued(path, payloads)
    try:
        assert transport._fd is not None
        monkeypatch.setattr(os, "write", _PortWrites(transport._fd, room=[0]))  # no room

        def stuck(data: bytes) -> int:
            raise serial.SerialTimeoutException("Write timeout")

        monkeypatch.setattr(transport._port, "write", stuck)
        transport._flush_writes()
        monkeypatch.undo()
        assert (transport.tx_packets, transport.tx_seq, transport.write_errors) == (0, 0, 1)
        assert [item.payload for item in transport._data] == payloads[1:]
        transport._flush_writes()
        got = _read_all(master, StreamDecoder())
        assert got == [Packet(PacketType.COMMAND, n, p) for n, p in enumerate(payloads[1:])]
    finally:
        transport._close_port()
