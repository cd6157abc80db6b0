"""Capture files: what a session records, decode reads, MCAP export and monitor --follow."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import pytest
from protoduino import Board, CaptureError
from protoduino.capture import (
    CapturedEvent,
    CapturedFrame,
    CapturedStats,
    CaptureEnd,
    CaptureHeader,
)
from protoduino.capturefollow import follow
from protoduino.capturereader import read_capture
from protoduino.cli.main import main
from protoduino.constants import PacketType
from protoduino.messages import parse_in, parse_out
from protoduino.packets import Packet
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice
from simfixtures import wait_for_pin


def _commands(records: Sequence[object]) -> list[str]:
    """The kinds of the ArduinoIn messages the host sent, in order."""
    out = []
    for r in records:
        if (
            isinstance(r, CapturedFrame)
            and r.direction == "tx"
            and isinstance(r.item, Packet)
            and r.item.type is PacketType.COMMAND
        ):
            out.append(str(parse_in(r.item.payload).WhichOneof("data")))
    return out


def test_a_session_is_captured_both_ways_and_decoded(
    sim_board: SimBoard, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cap = tmp_path / "session.jsonl"
    with Board.open(sim_board.port, capture=cap) as board:
        servo = board.servo(9, safe=90)
        servo.write(45)
        board.digital_output(13).write(True)
        board.ping(b"hi")
        acks = board.stats.acks
    wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])

    records = list(read_capture(cap.read_text().splitlines()))
    header = records[0]
    assert isinstance(header, CaptureHeader) and header.url == sim_board.port
    assert isinstance(records[-1], CaptureEnd)
    frames = [r for r in records if isinstance(r, CapturedFrame)]
    assert {f.direction for f in frames} == {"tx", "rx"}
    times = [f.t for f in frames]
    assert times == sorted(times) and header.started <= times[0]
    # The handshake is in it, then every command in the order sent, each acked.
    first = frames[0].item
    assert isinstance(first, Packet) and first.type is PacketType.CONTROL
    sent = [c for c in _commands(records) if c != "ping"]  # the 1 Hz Ping may come anywhere
    assert sent == [
        "get_info",
        "configure_failsafe",
        "servo_init",
        "servo_control",
        "digital_init",
        "digital_control",
    ]
    device = [
        parse_out(f.item.payload)
        for f in frames
        if isinstance(f.item, Packet) and f.item.type is PacketType.DATA
    ]
    assert sum(1 for m in device if m.WhichOneof("data") == "ack") == acks
    # The counters: one line while it ran, the last at the close with everything counted.
    stats = [r for r in records if isinstance(r, CapturedStats)]
    assert stats and stats[-1].stats["acks"] == acks and stats[-1].stats["state"] == "closed"

    assert main(["decode", str(cap)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    decoded = [o for o in lines if "dir" in o]
    assert len(decoded) == len(frames)
    assert all(o["ok"] for o in decoded)
    assert {"pin": 9, "degrees": 45} in [o["message"].get("servo_control") for o in decoded]
    assert any("stats" in o for o in lines) and lines[-1]["end"] is True


def test_mcap_export_reads_back_with_the_schemas(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("mcap_protobuf", reason="mcap-protobuf-support is not installed")
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    cap, out = tmp_path / "s.jsonl", tmp_path / "s.mcap"
    with PtyDevice(tmp_path) as fake:
        with Board.open(fake.port, capture=cap) as board:
            servo = board.servo(9, safe=90)
            for angle in (10, 20, 30):
                servo.write(angle)
            board.digital_output(13).write(True)
        assert main(["decode", str(cap), "--mcap", str(out)]) == 0
    assert "wrote" in capsys.readouterr().err

    with out.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.name: s.encoding for s in summary.schemas.values()}
        assert schemas["protoduino.ArduinoIn"] == "protobuf"
        assert schemas["protoduino.ArduinoOut"] == "protobuf"
        topics = {c.topic: c.message_encoding for c in summary.channels.values()}
        assert topics["/protoduino/commands"] == "protobuf"
        assert topics["/protoduino/stats"] == "json"
        degrees: list[int] = []
        levels: list[bool] = []
        acks = 0
        for _schema, channel, message, decoded in reader.iter_decoded_messages(
            topics=["/protoduino/commands", "/protoduino/device"]
        ):
            assert message.log_time > 0
            if channel.topic == "/protoduino/commands":
                if decoded.HasField("servo_control"):
                    degrees.append(decoded.servo_control.degrees)
                if decoded.HasField("digital_control"):
                    levels.append(decoded.digital_control.level)
            elif decoded.HasField("ack"):
                acks += 1
        assert degrees == [10, 20, 30] and levels == [True]
        assert acks >= 6  # get_info, the two inits, four controls (and pings)
    with out.open("rb") as f:
        stats = [
            json.loads(m.data)
            for _s, c, m in make_reader(f).iter_messages(topics=["/protoduino/stats"])
        ]
    assert stats and stats[-1]["acks"] >= 6


def test_decode_refuses_what_is_not_a_capture_for_mcap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw.bin"
    raw.write_bytes(b"\x01\x02\x00")
    assert main(["decode", str(raw), "--mcap", str(tmp_path / "x.mcap")]) == 1
    assert "not a capture" in capsys.readouterr().err
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"capture": "protoduino", "version": 99, "schema_id": 1, "started": 0}\n')
    assert main(["decode", str(bad)]) == 1
    assert "capture version 99" in capsys.readouterr().err


def test_a_capture_that_cannot_be_written_opens_nothing(fake: PtyDevice, tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match="cannot write the capture"):
        Board.open(fake.port, capture=tmp_path / "no-such-dir" / "c.jsonl")
    assert fake.resets == 0


def test_follow_starts_at_the_end_and_stops_at_the_end_mark(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    header = '{"capture":"protoduino","version":1,"url":"u","schema_id":1,"started":1.0}\n'
    cap.write_text(header + '{"t":2.0,"event":"log","text":"old","details":{}}\n')
    records = follow(cap)
    assert isinstance(next(records), CaptureHeader)
    with cap.open("a") as f:
        f.write('{"t":3.0,"event":"log","text":"new","details":{}}\n{"t":4.0,"end":true}\n')
    rest = list(records)
    assert [r.text for r in rest if isinstance(r, CapturedEvent)] == ["new"]
    assert isinstance(rest[-1], CaptureEnd)


def test_follow_starts_over_when_a_new_session_restarts_the_capture(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    first = '{"capture":"protoduino","version":1,"url":"old","schema_id":1,"started":1.0}\n'
    cap.write_text(first + '{"t":2.0,"event":"log","text":"a long line of the old session"}\n')
    records = follow(cap, from_start=True)
    assert isinstance(next(records), CaptureHeader)
    assert isinstance(next(records), CapturedEvent)
    # What a new CaptureWriter on the same path does: truncate, then write its header.
    cap.write_text('{"capture":"protoduino","version":1,"url":"new","schema_id":1,"started":5}\n')
    with cap.open("a") as f:
        f.write('{"t":6.0,"end":true}\n')
    header = next(records)
    assert isinstance(header, CaptureHeader) and header.url == "new"
    assert isinstance(next(records), CaptureEnd)


def test_monitor_follows_a_session_another_process_owns(fake: PtyDevice, tmp_path: Path) -> None:
    """The session is this process's; the monitor is another one and reads only the file."""
    cap = tmp_path / "live.jsonl"
    with Board.open(fake.port, capture=cap) as board:
        monitor = subprocess.Popen(
            [sys.executable, "-m", "protoduino.cli.main", "monitor", "--follow", str(cap)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            assert monitor.stdout is not None
            first = monitor.stdout.readline()  # printed once it sits at the end of the file
            assert first.startswith(f"following {cap}")
            board.servo(9).write(33)
            board.ping()
        finally:
            watchdog = threading.Timer(30.0, monitor.kill)  # bounds a failing test only
            watchdog.start()
    try:
        out, err = monitor.communicate()
    finally:
        watchdog.cancel()
    assert monitor.returncode == 0, err
    lines = out.splitlines()
    assert any('"servo_control":{"pin":9,"degrees":33}' in line for line in lines), out
    assert not any("RESET_ACK" in line for line in lines)  # the handshake was before it
    assert any(line.startswith("[closed] rx ") for line in lines)  # the session's counters
    assert lines[-1].endswith("END     the session closed")
    # The monitor never opened the port: every RESET the device saw is in the session's capture.
    resets = [
        r
        for r in read_capture(cap.read_text().splitlines())
        if isinstance(r, CapturedFrame)
        and r.direction == "tx"
        and isinstance(r.item, Packet)
        and r.item.type is PacketType.CONTROL
    ]
    assert fake.resets == len(resets) >= 1
