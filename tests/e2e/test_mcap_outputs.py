"""The readback in MCAP as numbers Foxglove can plot (issue 20, item 14).

On the wire a readback's servo widths are packed bytes (5 per servo); the exporter publishes
each readback decoded on /protoduino/outputs: per servo its pin, the width it drives now and
the width it moves to, per digital output its level, all JSON numbers.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from protoduino import Board
from protoduino.cli.main import main
from protoduino.simboard import SimBoard


def test_the_readback_is_published_as_numbers(
    sim_board: SimBoard, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("mcap", reason="mcap is not installed")
    from mcap.reader import make_reader

    cap, out = tmp_path / "s.jsonl", tmp_path / "s.mcap"
    with Board.open(sim_board.port, capture=cap) as board:
        # A slow servo: right after the write it is still on its way (now != target).
        servo = board.servo(9, safe_us=1000, max_speed_us=500)
        servo.write_us(2000)
        board.digital_output(13).on()
        moving = board.read_outputs()
    assert main(["decode", str(cap), "--mcap", str(out)]) == 0
    capsys.readouterr()
    with out.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic: c.message_encoding for c in summary.channels.values()}
        assert topics["/protoduino/outputs"] == "json"
        published = [
            json.loads(m.data) for _s, _c, m in reader.iter_messages(topics=["/protoduino/outputs"])
        ]
    assert len(published) == 1
    readback = published[0]
    (servo_row,) = readback["servos"]
    assert servo_row == {"pin": 9, "us": moving[9].value, "target_us": 2000}
    assert 1000 <= servo_row["us"] < 2000  # moving: the two widths differ, both plottable
    assert readback["digital"] == [{"pin": 13, "level": 1}]
    assert all(type(v) is int for row in readback["servos"] for v in row.values())
