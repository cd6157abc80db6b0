"""Request layer against the pty fake (PtyDevice): ids, retransmission, timeouts, window."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino import Board
from protoduino.constants import PING_INTERVAL, PacketType
from protoduino.framing import StreamDecoder, frame_size
from protoduino.messages import ArduinoIn, Status
from protoduino.packets import Packet, parse_control
from protoduino.testing import PtyDevice, VirtualDevice, ack

ACK_TIMEOUT = 0.1


def packets_in(raw: bytes | bytearray) -> list[Packet]:
    return [p for p in StreamDecoder().feed(bytes(raw)) if isinstance(p, Packet)]


@pytest.fixture
def board(fake: PtyDevice) -> Iterator[Board]:
    with Board.open(fake.port, ack_timeout=ACK_TIMEOUT, ping=False) as b:
        yield b


def ping_msg(payload: bytes = b"") -> Any:
    msg = ArduinoIn()
    msg.ping.payload = payload
    return msg


def test_message_ids_increment(board: Board, fake: PtyDevice) -> None:
    # The wrap past 127 (to 1, never 0): tests/unit/test_layers.py, on a chosen first id.
    first = board.rpc_state().next_id
    for _ in range(3):
        board.ping()
    ids = [r.msg.message_id for r in fake.arrivals("ping")]
    assert ids == [first, first % 127 + 1, (first % 127 + 1) % 127 + 1]


def test_message_ids_start_at_1_each_session(tmp_path: Path) -> None:
    # A new host session starts at 1, and its RESET says so (NEXT_ID): the device clears its
    # window for a new session, so the previous session's ids cannot pass for repeats.
    for i in range(2):
        directory = tmp_path / str(i)
        directory.mkdir()
        with PtyDevice(directory) as f, Board.open(f.port, ping=False):
            pass
        assert f.arrivals("get_info")[0].msg.message_id == 1
    resets = [
        parse_control(p.payload)
        for p in packets_in(f.raw_rx)
        if p.type is PacketType.CONTROL and p.payload[0] == 0
    ]
    assert resets and all(r.next_id == 1 for r in resets)


def test_dropped_ack_is_retransmitted_with_the_same_id(board: Board, fake: PtyDevice) -> None:
    dropped: list[int] = []

    def drop_first(msg: Any) -> list[Any]:
        if not dropped:
            dropped.append(msg.message_id)
            return []
        return fake.default_reply(msg)

    fake.handler = drop_first
    board.ping(b"x")
    pings = fake.arrivals("ping")
    assert len(pings) == 2
    assert pings[0].msg.message_id == pings[1].msg.message_id == dropped[0]
    assert pings[0].seq != pings[1].seq  # a new packet, a new SEQ
    assert board.stats.retransmits == 1


def test_no_ack_times_out_after_every_retry(board: Board, fake: PtyDevice) -> None:
    fake.handler = lambda msg: []
    with pytest.raises(protoduino.AckTimeoutError) as info:
        board.ping()
    assert isinstance(info.value, TimeoutError)
    assert isinstance(info.value, protoduino.ProtoduinoError)
    pings = fake.arrivals("ping")
    assert len(pings) == 1 + protoduino.constants.MAX_RETRIES
    assert len({p.msg.message_id for p in pings}) == 1
    # When it fails (exactly call_timeout after the first transmission) is judged on an
    # injected clock: tests/unit/test_rpc_clock.py and tests/unit/test_layers.py.
    assert info.value.recent_frames  # ring buffer of recent frames attached
    assert any("COMMAND" in line for line in info.value.recent_frames)
    assert board.stats.timeouts == 1


def test_duplicate_ack_is_counted_late_and_dropped(board: Board, fake: PtyDevice) -> None:
    fake.handler = lambda msg: fake.default_reply(msg) * 2
    board.ping(b"a")
    board.ping(b"b")
    assert fake.wait_for(lambda: board.stats.late_acks == 2)
    assert board.stats.acks == 4  # get_info, configure_failsafe, two pings


def test_late_ack_never_completes_the_wrong_call(board: Board, fake: PtyDevice) -> None:
    first: list[Any] = []

    def handler(msg: Any) -> list[Any]:
        if not first or msg.message_id == first[0].message_id:
            first.append(msg)  # never answered in time, nor its retransmissions
            return []
        if msg.ping.payload == b"second":
            # the first call's Ack arrives now, late, before the second's own
            late = ack(first[0].message_id)
            late.ack.ping_echo = first[0].ping.payload
            fake.send_data(late)
        return fake.default_reply(msg)

    fake.handler = handler
    with pytest.raises(protoduino.AckTimeoutError):
        board.ping(b"first")
    assert board.ping(b"second") >= 0  # an echo mismatch would raise ProtocolError
    assert board.stats.late_acks >= 1


def test_unknown_ack_is_counted_and_dropped(board: Board, fake: PtyDevice) -> None:
    fake.send_data(ack((board.rpc_state().next_id + 50) % 127 + 1))  # not given yet
    assert fake.wait_for(lambda: board.stats.unknown_acks == 1)
    board.ping()


def test_rejection_carries_the_status(board: Board, fake: PtyDevice) -> None:
    fake.handler = lambda msg: [ack(msg.message_id, Status.STATUS_OUT_OF_RANGE)]
    with pytest.raises(protoduino.CommandRejectedError) as info:
        board.ping()
    assert info.value.status == Status.STATUS_OUT_OF_RANGE
    assert info.value.sent
    assert "STATUS_OUT_OF_RANGE" in str(info.value)
    assert board.stats.rejected == 1


def test_window_lets_several_calls_fly(fake: PtyDevice) -> None:
    held: list[Any] = []

    def answer_after_four(msg: Any) -> list[Any]:
        if msg.WhichOneof("data") != "ping":
            return fake.default_reply(msg)
        held.append(msg)
        if len({m.message_id for m in held}) < 4:
            return []  # no Ack until four distinct calls are in flight
        return [r for m in held for r in fake.default_reply(m)]

    with Board.open(fake.port, window=4, ping=False, ack_timeout=0.5) as board:
        fake.handler = answer_after_four
        futures = [board.submit_ping(bytes([i])) for i in range(4)]
        for future in futures:
            future.result(timeout=30)  # bounds a failure only
        assert len({p.msg.message_id for p in fake.arrivals("ping")}) == 4
        assert board.stats.retransmits == 0


def test_window_bounds_calls_in_flight(fake: PtyDevice) -> None:
    with Board.open(fake.port, window=2, ping=False, ack_timeout=ACK_TIMEOUT) as board:
        fake.handler = lambda msg: []
        futures = [board.submit_ping(bytes([i])) for i in range(4)]
        assert fake.wait_for(lambda: len(fake.arrivals("ping")) >= 4)  # with retransmissions
        first = fake.arrivals("ping")[:4]
        assert len({p.msg.message_id for p in first}) == 2
        assert {p.msg.ping.payload for p in first} == {b"\x00", b"\x01"}  # the first two calls
        board.close()
        for future in futures:
            with pytest.raises(protoduino.ProtoduinoError):
                future.result(timeout=30)


def test_bytes_in_flight_stay_within_the_devices_receive_buffer(fake: PtyDevice) -> None:
    """Flow control by bytes: at window 16, only as many frames fly as fit DeviceInfo.rx_buffer."""
    payload = bytes(10)
    longest = ping_msg(payload)
    longest.message_id = 127  # every id is one varint byte (protocol version 5)
    size = frame_size(len(longest.SerializeToString()))
    fake.rx_buffer = 3 * size + 1  # room for three frames, not four
    held: list[Any] = []

    def hold(msg: Any) -> list[Any]:
        if msg.WhichOneof("data") != "ping":
            return fake.default_reply(msg)
        held.append(msg)
        return []

    with Board.open(fake.port, window=16, ping=False, ack_timeout=0.5) as board:
        assert board.info.rx_buffer == fake.rx_buffer
        fake.handler = hold
        futures = [board.submit_ping(payload) for _ in range(8)]
        # Submitting sends at once what may go: three frames fit, five wait their turn.
        state = board.rpc_state()
        assert len(state.inflight) == 3 and state.pending == 5
        assert fake.wait_for(lambda: len(held) >= 3)
        assert len({m.message_id for m in held}) == 3
        # Each answer frees room for one more.
        fake.handler = fake.default_reply
        for msg in list(held):
            for reply in fake.default_reply(msg):
                fake.send_data(reply)
        for future in futures:
            future.result(timeout=10)
        assert board.stats.retransmits == 0


def _pings_sent(device: VirtualDevice) -> int:
    """The Pings the board sent (the device keeps them out of ``executed``)."""
    return len(device.arrivals("ping"))


def test_automatic_ping_and_pause() -> None:
    """The board's automatic Ping, paused and resumed, judged on the device's manual clock: a
    pause of several intervals sends none (no wall-clock sleep decides it). The layer's exact
    schedule is tests/unit/test_layers.py's."""
    device = VirtualDevice()
    with device.open_board(ping=True) as board:
        device.run(2.5 * PING_INTERVAL)
        assert _pings_sent(device) >= 2
        board.pinging = False
        device.run(PING_INTERVAL)  # a Ping already sent or queued is answered meanwhile
        assert not board.rpc_state().inflight and board.rpc_state().urgent == 0
        count = _pings_sent(device)
        device.run(5 * PING_INTERVAL)
        assert _pings_sent(device) == count
        board.pinging = True
        device.run(1.5 * PING_INTERVAL)
        assert _pings_sent(device) > count
        assert board.stats.pings >= 3
        assert board.stats.rtt is not None


def test_close_fails_waiting_calls(board: Board, fake: PtyDevice) -> None:
    fake.handler = lambda msg: []
    errors: list[BaseException] = []

    def call() -> None:
        try:
            board.ping()
        except protoduino.ProtoduinoError as error:
            errors.append(error)

    worker = threading.Thread(target=call)
    worker.start()
    assert fake.wait_for(lambda: len(fake.arrivals("ping")) >= 1)
    board.close()
    worker.join(5)
    assert not worker.is_alive()
    assert len(errors) == 1
    assert isinstance(errors[0], protoduino.BoardClosedError | protoduino.AckTimeoutError)


def test_calls_fail_in_time_while_the_port_is_gone(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False, handshake_timeout=0.5) as board:
        fake.unplug()
        with pytest.raises(protoduino.TransportError) as info:
            board.ping()  # when it fails is judged on an injected clock: tests/unit/test_layers.py
        assert "lost" in str(info.value)
        assert board.stats.state == "disconnected"


def test_calls_wait_for_a_reconnect(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False, handshake_timeout=3.0) as board:
        fake.unplug()
        assert fake.wait_for(lambda: not board.stats.connected)
        threading.Timer(0.3, fake.replug).start()
        assert board.ping(b"back") >= 0
        assert board.stats.reconnects == 1
        assert board.stats.state == "active"


def test_a_board_failed_for_good_fails_calls_at_once(fake: PtyDevice) -> None:
    # A reboot into firmware of another protocol version: the link cannot come back, so
    # a call in flight fails with the version error as soon as it is known, and so does
    # every later call, instead of waiting out a deadline (here 600 s, to tell them apart).
    with Board.open(fake.port, ping=False, ack_timeout=1.0, handshake_timeout=600.0) as board:
        failed = threading.Event()
        board.on_event(lambda e: failed.set() if e.kind is protoduino.EventKind.ERROR else None)
        fake.version = protoduino.constants.PROTOCOL_VERSION + 1
        fake.handler = lambda msg: []  # the ping is swallowed: the device reboots instead
        errors: list[BaseException] = []

        def call() -> None:
            try:
                board.ping()
            except protoduino.ProtoduinoError as error:
                errors.append(error)

        worker = threading.Thread(target=call)
        worker.start()
        assert fake.wait_for(lambda: len(fake.arrivals("ping")) >= 1)
        fake.reboot()
        assert failed.wait(10)
        worker.join(10)  # bounds a failing test only: the call's deadline is 600 s away
        assert not worker.is_alive()
        assert len(errors) == 1 and isinstance(errors[0], protoduino.VersionMismatchError)
        commands = board.stats.commands
        with pytest.raises(protoduino.VersionMismatchError):
            board.servo(9)
        assert board.stats.commands == commands  # refused before it was queued
        assert board.stats.state == "failed"
