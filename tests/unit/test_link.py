"""Link layer against the pty fake (PtyDevice): handshake, checks, SEQ, watchdog, events."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import protoduino
import pytest
from protoduino import Board, EventKind
from protoduino.constants import EventCode, PacketType
from protoduino.framing import cobs_encode, frame_packet
from protoduino.packets import build_packet, event_payload
from protoduino.testing import PtyDevice, ack


def events_of(board: Board) -> tuple[list[protoduino.Event], threading.Event]:
    seen: list[protoduino.Event] = []
    flag = threading.Event()

    def callback(event: protoduino.Event) -> None:
        seen.append(event)
        flag.set()

    board.on_event(callback)
    return seen, flag


def test_handshake_and_info(fake: PtyDevice) -> None:
    with Board.open(fake.port) as board:
        assert board.info.board == "virtual"
        assert board.info.num_pins == 20
        assert board.info.reserved_pins == (0, 1)
        assert board.stats.handshakes == 1
        assert board.stats.state == "active"
    assert fake.resets >= 1
    assert fake.arrivals("get_info")


def test_version_mismatch_names_both_versions(tmp_path: Path) -> None:
    newer = protoduino.PROTOCOL_VERSION + 1
    with PtyDevice(tmp_path, version=newer), pytest.raises(protoduino.VersionMismatchError) as info:
        Board.open(str(tmp_path / "fake-tty"))
    assert info.value.host_version == protoduino.PROTOCOL_VERSION
    assert info.value.device_version == newer
    assert f"host speaks {protoduino.PROTOCOL_VERSION}, device speaks {newer}" in str(info.value)
    assert isinstance(info.value, protoduino.LinkError)


@pytest.mark.parametrize("older", [6, 7])
def test_firmware_of_32_pin_masks_is_refused_clearly(tmp_path: Path, older: int) -> None:
    """A version 7 device's pin sets are 32-bit masks (fixed32, uint32) where version 8's are
    bytes of any width, and a version 6 device states its pins in masks the host no longer
    reads (DeviceInfo.pins came with version 7): the handshake refuses both, naming both
    versions."""
    assert protoduino.PROTOCOL_VERSION == 8
    with PtyDevice(tmp_path, version=older), pytest.raises(protoduino.VersionMismatchError) as info:
        Board.open(str(tmp_path / "fake-tty"))
    assert (info.value.host_version, info.value.device_version) == (8, older)
    assert f"host speaks 8, device speaks {older}" in str(info.value)


def test_version_1_firmware_gets_the_clear_version_error(tmp_path: Path) -> None:
    """A version 1 device answers our RESET with its 6-byte RESET_ACK: the host names both."""
    with PtyDevice(tmp_path, version=1), pytest.raises(protoduino.VersionMismatchError) as info:
        Board.open(str(tmp_path / "fake-tty"))
    assert (info.value.host_version, info.value.device_version) == (protoduino.PROTOCOL_VERSION, 1)
    assert f"host speaks {protoduino.PROTOCOL_VERSION}, device speaks 1" in str(info.value)


def test_schema_mismatch_names_both_fingerprints(tmp_path: Path) -> None:
    with (
        PtyDevice(tmp_path, schema_id=0x12345678) as fake,
        pytest.raises(protoduino.SchemaMismatchError) as info,
    ):
        Board.open(fake.port)
    text = str(info.value)
    assert "0x12345678" in text
    assert f"0x{protoduino.SCHEMA_ID:08X}" in text
    assert "flash" in text


def test_silent_device_fails_handshake_in_time_after_retries(tmp_path: Path) -> None:
    with PtyDevice(tmp_path, answer_reset=False) as fake:
        # When it fails (exactly at handshake_timeout) is judged on an injected clock:
        # tests/unit/test_layers.py.
        with pytest.raises(protoduino.HandshakeError) as info:
            Board.open(fake.port, handshake_timeout=0.6)
        assert fake.resets >= 3  # RESET resent with backoff: t=0, 0.1, 0.3, ...
    assert "did not answer RESET" in str(info.value)
    assert "may still be in a bootloader" in str(info.value)  # nothing heard at all


def test_missing_port_is_a_transport_error(tmp_path: Path) -> None:
    with pytest.raises(protoduino.TransportError) as info:
        Board.open(str(tmp_path / "nothing-here"))
    assert "nothing-here" in str(info.value)


def test_garbage_and_partial_frames_are_dropped_and_counted(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False) as board:

        def noisy(msg: Any) -> list[Any]:
            fake.send_raw(b"\x13\x37garbage\x00")  # not COBS-valid or a bad packet
            good = frame_packet(PacketType.DATA, 5, b"\x08\x01")
            fake.send_raw(good[: len(good) // 2])  # a partial frame, cut short ...
            fake.send_raw(b"\x00")  # ... and ended by the delimiter
            bad_crc = bytearray(build_packet(PacketType.DATA, 9, b"\x01"))
            bad_crc[-1] ^= 0xFF
            fake.send_raw(cobs_encode(bytes(bad_crc)) + b"\x00")
            return fake.default_reply(msg)

        fake.handler = noisy
        assert board.ping(b"ok") >= 0
        dropped = board.stats.dropped
        assert sum(dropped.values()) >= 3
        assert dropped.get("crc", 0) >= 1
        # the link carries on
        fake.handler = fake.default_reply
        board.ping(b"again")


def test_seq_gap_counts_lost_packets(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False) as board:

        def skipping(msg: Any) -> list[Any]:
            fake.skip_seq(3)  # three packets "lost" on the way
            return fake.default_reply(msg)

        fake.handler = skipping
        board.ping()
        assert board.stats.seq_lost == 3
        assert board.stats.seq_desyncs == 0


def test_seq_desync_rehandshakes(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False) as board:
        resets = fake.resets
        mid = board.rpc_state().next_id  # the next call's id
        fake.handler = lambda msg: []
        out = ack(mid)
        results: list[float] = []
        worker = threading.Thread(target=lambda: results.append(board.ping()))
        worker.start()
        assert fake.wait_for(lambda: len(fake.arrivals("ping")) >= 1)
        fake.send_data(out, seq=(fake.tx_seq + 100) & 0xFF)  # a jump backward/forward
        assert fake.wait_for(lambda: fake.resets > resets)
        fake.handler = fake.default_reply
        worker.join(10)
        assert board.stats.seq_desyncs == 1
        assert len(results) == 1  # the call in flight was resent on the new link and answered
        board.ping()


def test_watchdog_rehandshakes_when_device_goes_silent(fake: PtyDevice) -> None:
    # 1.5 s: longer than the 1 s between pings, which the device answers until it goes silent.
    with Board.open(fake.port, watchdog_timeout=1.5) as board:
        seen, _ = events_of(board)
        resets = fake.resets
        fake.handler = lambda msg: []
        assert fake.wait_for(lambda: fake.resets > resets, timeout=5)
        fake.handler = fake.default_reply
        assert board.stats.watchdog_resets >= 1
        board.ping()
        # Events reach callbacks on the board's event thread: wait for it, not for a time.
        assert fake.wait_for(
            lambda: any(
                e.kind is EventKind.DISCONNECTED and e.details["reason"] == "watchdog"
                for e in list(seen)
            )
        )


def test_device_events_reach_callbacks(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False) as board:
        seen, _ = events_of(board)
        fake.send_control(event_payload(EventCode.DESYNC))
        fake.send_control(event_payload(EventCode.RX_OVERFLOW))
        fake.send_control(event_payload(0x7E))  # unknown: logged, ignored
        fake.send_raw(frame_packet(PacketType.COMMAND, fake.next_seq(), b"\x08\x01"))
        board.ping()
        assert fake.wait_for(lambda: len(seen) >= 2)  # delivered on the event thread
        kinds = [e.kind for e in seen]
        assert EventKind.DEVICE_DESYNC in kinds
        assert EventKind.RX_OVERFLOW in kinds
        stats = board.stats
        assert stats.device_desyncs == 1
        assert stats.device_rx_overflows == 1
        assert stats.dropped.get("direction") == 1


def test_not_active_means_handshake_again_and_the_boot_id_tells(fake: PtyDevice) -> None:
    with Board.open(fake.port, ping=False) as board:
        seen, _ = events_of(board)
        # A NOT_ACTIVE from a device that did not reboot (same boot id, session resumed):
        # a handshake, nothing lost, no restore.
        fake.send_control(event_payload(EventCode.NOT_ACTIVE))
        assert fake.wait_for(lambda: board.stats.handshakes == 2)
        board.ping()
        assert board.stats.reboots == 0 and board.stats.sessions_lost == 0
        # A real reboot: a new boot id.
        fake.reboot()
        assert fake.wait_for(lambda: board.stats.reboots == 1)
        board.ping()
        assert board.stats.handshakes == 3
        assert fake.wait_for(lambda: EventKind.REBOOTED in [e.kind for e in list(seen)])
        assert [e.kind for e in list(seen)].count(EventKind.REBOOTED) == 1


def test_board_close_stops_threads_and_is_idempotent(fake: PtyDevice) -> None:
    before = {t.name for t in threading.enumerate()}
    board = Board.open(fake.port)
    names = {t.name for t in threading.enumerate()} - before
    assert any(n.startswith("protoduino-io") for n in names)
    assert any(n.startswith("protoduino-events") for n in names)
    board.close()
    board.close()
    assert board.closed
    with pytest.raises(protoduino.BoardClosedError):
        board.ping()
