"""`protoduino decode` on the shared vectors and on protobuf payloads."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from protoduino._generated import protoduino_pb2 as pb
from protoduino.cli.main import main
from protoduino.constants import PacketType
from protoduino.framing import frame_packet
from wirevectors import INVALID_FRAME_REASONS, load

V = load()


def _decode(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[dict[str, object]]]:
    rc = main(["decode", *argv])
    out = capsys.readouterr().out
    return rc, [json.loads(line) for line in out.splitlines()]


def test_decode_hex_prints_every_vector_packet_and_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wires = [p["wire"] for p in V["packets"]] + [f["wire"] for f in V["invalid_frames"]]
    capture = tmp_path / "capture.hex"
    capture.write_text("\n".join(wires) + "\n")
    rc, objs = _decode(capsys, "--hex", str(capture))
    assert rc == 0
    assert len(objs) == len(wires)
    for p, obj in zip(V["packets"], objs, strict=False):
        assert obj["ok"] is True
        assert obj["type"] == PacketType(p["type"]).name
        assert obj["seq"] == p["seq"]
        assert obj["payload"] == p["payload"]
    for f, obj in zip(V["invalid_frames"], objs[len(V["packets"]) :], strict=True):
        assert obj == {
            "ok": False,
            "error": INVALID_FRAME_REASONS[f["name"]],
            "raw": f["wire"][:-2],
        }
    assert objs[0]["message"] == {"code": "RESET", "version": 1}
    assert objs[1]["message"] == {"code": "RESET_ACK", "version": 1, "schema_id": "0x1A2B3C00"}
    by_name = {p["name"]: obj for p, obj in zip(V["packets"], objs, strict=False)}
    assert by_name["EVENT BOOT"]["message"] == {"code": "EVENT", "event": "BOOT"}


def test_decode_raw_from_stdin_renders_protobuf(tmp_path: Path) -> None:
    cmd = pb.ArduinoIn(message_id=7, servo_control=pb.ServoControl(pin=9, degrees=45))
    ack = pb.ArduinoOut(ack=pb.Ack(message_id=7, status=pb.STATUS_OUT_OF_RANGE))
    data = frame_packet(PacketType.COMMAND, 1, cmd.SerializeToString()) + frame_packet(
        PacketType.DATA, 1, ack.SerializeToString()
    )
    proc = subprocess.run(
        [sys.executable, "-m", "protoduino.cli.main", "decode"],
        input=data,
        capture_output=True,
        check=True,
    )
    objs = [json.loads(line) for line in proc.stdout.splitlines()]
    assert objs[0]["message"] == {"message_id": 7, "servo_control": {"pin": 9, "degrees": 45}}
    assert objs[1]["message"] == {"ack": {"message_id": 7, "status": "STATUS_OUT_OF_RANGE"}}


def test_decode_reports_a_payload_that_is_not_protobuf(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    capture = tmp_path / "bad.bin"
    capture.write_bytes(frame_packet(PacketType.DATA, 3, b"\xff\xff\xff"))
    rc, objs = _decode(capsys, str(capture))
    assert rc == 0
    assert objs[0]["ok"] is True and objs[0]["message"] is None
    assert "does not decode" in str(objs[0]["message_error"])


def test_decode_unreadable_file_exits_2(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rc = main(["decode", str(tmp_path / "missing.bin")])
    assert rc == 2
    assert "cannot read" in capsys.readouterr().err


def test_decode_bad_hex_exits_2(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    capture = tmp_path / "x.hex"
    capture.write_text("zz not hex")
    assert main(["decode", "--hex", str(capture)]) == 2
    assert "not hex" in capsys.readouterr().err


def test_decode_into_a_reader_that_closes_early_ends_quietly(tmp_path: Path) -> None:
    """``protoduino decode robot.jsonl | head``: the broken pipe is on stdout, not the input,
    so it ends as a Unix tool does (no "cannot read", no traceback), not with status 2."""
    cmd = pb.ArduinoIn(message_id=7, servo_control=pb.ServoControl(pin=9, degrees=45))
    frame = frame_packet(PacketType.COMMAND, 1, cmd.SerializeToString())
    capture = tmp_path / "robot.bin"
    capture.write_bytes(frame * 20000)  # far more output than a pipe buffers
    proc = subprocess.Popen(
        [sys.executable, "-m", "protoduino.cli.main", "decode", str(capture)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()  # the reader takes one line, as `head -1` does
    proc.stdout.close()
    err = proc.stderr.read().decode()
    rc = proc.wait(timeout=60)
    assert json.loads(first)["ok"] is True
    assert err == "" and rc == 0, (rc, err)
