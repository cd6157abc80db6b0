"""Reading captures that are damaged, huge, not captures at all, or not written yet (issue 20,
item 9): ``decode`` and ``monitor --follow`` report what is wrong, skip it and go on, never
crash, never hang, and ``decode`` reads in constant memory."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import tracemalloc
from pathlib import Path

import pytest
from protoduino.capture import MAX_LINE, CaptureEnd, CaptureHeader
from protoduino.capturefollow import follow
from protoduino.cli.main import main

HEADER = '{"capture":"protoduino","version":1,"url":"u","schema_id":1,"started":1.0}\n'
EVENT = '{"t":2.0,"event":"log","text":"after","details":{}}\n'
END = '{"t":3.0,"end":true}\n'

#: Bounds a failing (hanging) command only; a passing one ends in about a second.
HANG = 60.0


def _decode(
    capsys: pytest.CaptureFixture[str], path: Path
) -> tuple[int, list[dict[str, object]], str]:
    rc = main(["decode", str(path)])
    out, err = capsys.readouterr()
    return rc, [json.loads(line) for line in out.splitlines()], err


def _monitor(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "protoduino.cli.main", "monitor", *argv],
        capture_output=True,
        text=True,
        timeout=HANG,
        check=False,
        stdin=subprocess.DEVNULL,
    )


def test_decode_refuses_a_text_file_that_is_no_capture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plain = tmp_path / "plain.txt"
    plain.write_text("just some notes\nabout the robot\n")
    rc, objs, err = _decode(capsys, plain)
    assert rc == 1 and objs == []
    assert "is not a capture and holds no protoduino frame" in err
    empty = tmp_path / "empty.jsonl"
    empty.touch()
    rc, objs, err = _decode(capsys, empty)
    assert rc == 1 and objs == [] and f"{empty} is empty" in err


def test_decode_reports_a_copy_truncated_capture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """logrotate's copytruncate: the copy starts with a hole of NULs where the start was."""
    cap = tmp_path / "copy.jsonl"
    cap.write_bytes(b"\0" * 200_000 + EVENT.encode() + END.encode())
    rc, objs, err = _decode(capsys, cap)
    assert rc == 1
    assert "starts with 200000 NUL bytes" in err
    assert "no header line" in err
    assert [o.get("text") for o in objs] == ["after", None]  # what follows is still read


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("[" * 200_000, f"200000 bytes long (a record is at most {MAX_LINE})"),
        ("[" * 60_000, "JSON nested too deep"),
        ('{"t": 1, "stats": [1, 2]}', "not a capture record"),
        ('{"t": 1, "event": "log", "details": "x"}', "not a capture record"),
        ("not json at all", "not JSON"),
    ],
    ids=["too-long", "too-deep", "stats-not-object", "details-not-object", "not-json"],
)
def test_decode_skips_a_line_that_is_no_record_and_goes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], line: str, reason: str
) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_text(HEADER + line + "\n" + EVENT + END)
    rc, objs, err = _decode(capsys, cap)
    assert rc == 1
    assert f"line 2: {reason}" in err
    assert "internal error" not in err
    assert objs[0]["version"] == 1  # the header keeps its version
    assert [o.get("text") for o in objs[1:]] == ["after", None]


def test_decode_skips_binary_garbage(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_bytes(HEADER.encode() + b"\xff\xfe\x80garbage\x00\x01\n" + EVENT.encode())
    rc, objs, err = _decode(capsys, cap)
    assert rc == 1
    assert "line 2: not UTF-8 text" in err
    assert [o.get("text") for o in objs[1:]] == ["after"]


def test_decode_keeps_the_header_version_and_a_torn_last_line_is_no_damage(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_text(HEADER + EVENT + '{"t":2.5,"event":"lo')  # the writer died mid-line
    rc, objs, err = _decode(capsys, cap)
    assert rc == 0, err
    assert objs[0] == {"capture": "u", "version": 1, "schema_id": "0x00000001", "started": 1.0}
    assert len(objs) == 2


class _Sink:
    """stdout that counts lines and keeps nothing."""

    def __init__(self) -> None:
        self.lines = 0

    def write(self, text: str) -> int:
        self.lines += text.count("\n")
        return len(text)

    def flush(self) -> None:
        pass


def test_decode_streams_in_constant_memory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A 24 MB capture decodes with a peak of Python allocations far below its size: read and
    written record by record (the old decode read it whole, then decoded it whole)."""
    cap = tmp_path / "big.jsonl"
    records = 160_000
    line = '{"t":%d.5,"event":"log","text":"%s","details":{"level":"info"}}\n'
    with cap.open("w") as f:
        f.write(HEADER)
        for i in range(records):
            f.write(line % (i, "x" * 100))
    size = cap.stat().st_size
    assert size > 20_000_000
    sink = _Sink()
    monkeypatch.setattr(sys, "stdout", sink)
    tracemalloc.start()
    try:
        rc = main(["decode", str(cap)])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert rc == 0
    assert sink.lines == records + 1  # every record came out
    assert peak < 4_000_000, f"decode's peak {peak} B for a {size} B capture"


def test_monitor_follow_skips_binary_garbage_and_exits_1(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_bytes(HEADER.encode() + b"\xff\xfe garbage\n" + EVENT.encode() + END.encode())
    done = _monitor("--follow", str(cap), "--from-start")
    assert done.returncode == 1, done.stderr
    assert "line 2: not UTF-8 text" in done.stderr
    assert "internal error" not in done.stderr
    assert "EVENT   log: after" in done.stdout
    assert done.stdout.splitlines()[-1].endswith("END     the session closed")


def test_monitor_follow_refuses_a_line_nested_too_deep(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_text(HEADER + "[" * 200_000 + "\n" + "[" * 60_000 + "\n" + EVENT + END)
    done = _monitor("--follow", str(cap), "--from-start")
    assert done.returncode == 1, done.stderr
    assert "line 2: 200000 bytes long" in done.stderr
    assert "line 3: JSON nested too deep" in done.stderr
    assert "EVENT   log: after" in done.stdout


def test_monitor_follow_of_a_fifo_ends_at_its_duration(tmp_path: Path) -> None:
    """No writer ever opens the FIFO: the old monitor blocked in open() forever."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    done = _monitor("--follow", str(fifo), "--duration", "1")
    assert done.returncode == 1
    assert "no capture came within --duration" in done.stderr


def test_monitor_follow_of_a_capture_that_already_ended_says_so(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_text(HEADER + EVENT + END)
    done = _monitor("--follow", str(cap))
    assert done.returncode == 0, done.stderr
    assert "its session had already closed" in done.stderr
    assert "EVENT" not in done.stdout  # the old traffic is not shown without --from-start


def test_monitor_follow_waits_for_a_capture_that_does_not_exist_yet(tmp_path: Path) -> None:
    cap = tmp_path / "later.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "protoduino.cli.main", "monitor", "--follow", str(cap)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    watchdog = threading.Timer(HANG, proc.kill)  # bounds a failing test only
    watchdog.start()
    try:
        assert proc.stderr is not None and proc.stdout is not None
        assert "does not exist yet: waiting for it" in proc.stderr.readline()
        assert proc.poll() is None  # still waiting: it did not exit at once
        cap.write_text(HEADER)
        assert proc.stdout.readline().startswith(f"following {cap}")
        with cap.open("a") as f:
            f.write(EVENT + END)
        out = proc.stdout.read()
        assert proc.wait() == 0
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
    assert "EVENT   log: after" in out
    assert out.splitlines()[-1].endswith("END     the session closed")


def test_follow_goes_on_across_a_rotation(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    cap.write_text(HEADER)
    records = follow(cap, poll=0.01)
    assert isinstance(next(records), CaptureHeader)
    with cap.open("a") as f:
        f.write('{"t":2.0,"end":true,"rotated":true}\n')
    cap.rename(tmp_path / "c.jsonl.1")
    cap.write_text(HEADER.replace('"started":1.0', '"started":2.0,"part":2') + END)
    rotated = next(records)
    assert isinstance(rotated, CaptureEnd) and rotated.rotated
    header = next(records)
    assert isinstance(header, CaptureHeader) and header.part == 2
    end = next(records)
    assert isinstance(end, CaptureEnd) and not end.rotated
    assert list(records) == []
