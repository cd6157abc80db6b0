"""The faulty:// line: seeded, repeatable, and the codec survives it."""

from __future__ import annotations

import gc
import time
from collections import Counter
from typing import cast

import pytest
import serial
from protoduino.constants import PacketType
from protoduino.framing import StreamDecoder, frame_packet
from protoduino.packets import Packet
from protoduino_dev import faults  # importing protoduino_dev registers faulty://
from protoduino_dev.faults import FaultConfig, FaultModel, parse_url
from protoduino_dev.urlhandler.protocol_faulty import Serial as FaultySerial


def _traffic(n: int = 400) -> tuple[list[Packet], bytes]:
    packets = [Packet(PacketType.DATA, i % 256, bytes([i % 251]) * (i % 40)) for i in range(n)]
    return packets, b"".join(frame_packet(p.type, p.seq, p.payload) for p in packets)


def test_parse_url() -> None:
    inner, cfg = parse_url("faulty://socket://localhost:7777?ber=1e-3&seed=7&dir=tx")
    assert inner == "socket://localhost:7777"
    assert cfg == FaultConfig(ber=1e-3, seed=7, dir="tx")
    assert parse_url("faulty:///dev/ttyACM0")[0] == "/dev/ttyACM0"


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("faulty://loop://?bogus=1", "unknown faulty:// parameter 'bogus'"),
        ("faulty://loop://?ber=2", "must be a probability"),
        ("faulty://loop://?ber=x", "bad value for faulty:// parameter ber"),
        ("faulty://loop://?dir=up", "bad value for faulty:// parameter dir"),
        ("faulty://?ber=0.1", "needs an inner URL"),
    ],
)
def test_bad_urls_are_refused_clearly(url: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_url(url)


def test_same_seed_same_damage_different_seed_different_damage() -> None:
    _, data = _traffic()
    cfg = FaultConfig(ber=1e-3, burst=1e-3, drop=1e-3, garbage=0.01, dup=0.01)

    def run(seed: int) -> bytes:
        model = FaultModel(cfg, seed, Counter())
        return b"".join(model.apply(data[i : i + 37]) for i in range(0, len(data), 37))

    assert run(7) == run(7)
    assert run(7) != run(8)


def test_bit_error_rate_is_as_configured() -> None:
    stats: Counter[str] = Counter()
    model = FaultModel(FaultConfig(ber=1e-3), 1, stats)
    model.apply(bytes(200_000))  # 1.6 M bits -> 1600 flips expected, sd 40
    assert 1400 < stats["flipped_bits"] < 1800


def test_no_damaged_packet_ever_passes_the_codec() -> None:
    packets, data = _traffic(2000)
    stats: Counter[str] = Counter()
    cfg = FaultConfig(ber=2e-3, burst=2e-3, drop=1e-3, garbage=0.02, dup=0.02)
    damaged = FaultModel(cfg, 11, stats).apply(data)
    got = [x for x in StreamDecoder().feed(damaged) if isinstance(x, Packet)]
    sent = set(packets)
    assert stats["flipped_bits"] > 100 and stats["duplicated_frames"] > 10
    assert all(p in sent for p in got)  # nothing corrupted got through
    assert len(set(got)) > len(packets) // 4  # and the line still carries traffic


def test_faulty_url_over_loop_duplicates_and_cuts() -> None:
    port = cast(FaultySerial, serial.serial_for_url("faulty://loop://?dup=1&dir=tx", timeout=0.2))
    try:
        frame = frame_packet(PacketType.COMMAND, 1, b"\x08\x01")
        port.write(frame)
        assert port.read(100) == frame + frame
        port.cut(2.0)
        port.write(frame)
        assert port.read(100) == b""  # cut: lost
        lost = 1
        # The cut ends by itself; each write until then is lost whole (the deadline only
        # bounds a failure: the verdict is what got through, not when).
        deadline = time.monotonic() + 20.0
        while True:
            port.write(frame)
            got = port.read(100)
            if got:
                break
            lost += 1
            assert time.monotonic() < deadline, "the cut never ended"
        assert got == frame + frame
        assert port.stats["duplicated_frames"] == 2
        assert port.stats["cut_bytes"] == lost * len(frame)
    finally:
        port.close()


def test_delay_holds_bytes_back() -> None:
    port = serial.serial_for_url("faulty://loop://?delay=150&dir=rx", timeout=1.0)
    try:
        t0 = time.monotonic()
        port.write(b"abc\x00")
        assert port.read(10) == b"abc\x00"
        assert time.monotonic() - t0 >= 0.15
        assert cast(FaultySerial, port).stats["delayed_bytes"] == 4
    finally:
        port.close()


def test_named_line_pause_resume_heal() -> None:
    url = "faulty://loop://?drop=1&dir=tx&paused=1&name=test-line-1"
    port = serial.serial_for_url(url, timeout=0.2)
    try:
        found: object = faults.line("test-line-1")
        assert found is port  # found by name, from code that did not open it
        line = cast(FaultySerial, found)
        frame = frame_packet(PacketType.COMMAND, 1, b"\x08\x01")
        port.write(frame)
        assert port.read(100) == frame  # paused: the line is clean
        line.resume()
        port.write(frame)
        assert port.read(100) == b""  # drop=1: every byte lost
        line.cut(30.0)
        line.heal()  # faults off for good, the cut cancelled
        port.write(frame)
        assert port.read(100) == frame
        assert line.stats["dropped_bytes"] == len(frame)
        assert [raw for _, raw in line.recent_writes()] == [frame] * 3  # every write, as given
    finally:
        port.close()
    del port, line, found
    gc.collect()
    assert faults.line("test-line-1") is None  # the registry does not keep ports alive


def test_held_bytes_go_out_in_one_write(monkeypatch: pytest.MonkeyPatch) -> None:
    """What hold() kept reaches the far end in order and in one write: frames written
    apart arrive together (the soak times the failsafe from a Ping sent so, between two
    digital edges)."""
    port = serial.serial_for_url("faulty://loop://", timeout=0.05)
    try:
        line = cast(FaultySerial, port)
        inner = line._inner
        assert inner is not None
        written: list[bytes] = []
        real = inner.write

        def write(data: bytes) -> int | None:
            written.append(bytes(data))
            return real(data)

        monkeypatch.setattr(inner, "write", write)
        line.hold("tx")
        for part in (b"lo\x00", b"ping\x00", b"hi\x00"):
            port.write(part)
        assert port.read(100) == b"" and written == []
        line.release()
        assert port.read(100) == b"lo\x00ping\x00hi\x00"
        assert written == [b"lo\x00ping\x00hi\x00"]
        assert line.stats["held_tx_bytes"] == len(written[0])
    finally:
        port.close()


def test_tx_delay_is_latency_not_a_blocked_writer() -> None:
    port = serial.serial_for_url("faulty://loop://?delay=1000&dir=tx", timeout=0.05)
    try:
        t0 = time.monotonic()
        port.write(b"abc\x00")
        port.write(b"def\x00")
        # Both writes returned and nothing has arrived: the writer did not wait for the delay
        # (a writer that did would have found its bytes delivered).
        assert port.read(100) == b""
        got = b""
        while len(got) < 8 and time.monotonic() - t0 < 10.0:
            got += port.read(100)
        arrived = time.monotonic() - t0
        assert got == b"abc\x00def\x00"  # in order
        assert arrived >= 1.0  # never early
    finally:
        port.close()
