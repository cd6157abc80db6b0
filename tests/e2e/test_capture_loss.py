"""A capture that cannot be written, and one that must stay small (issue 20, item 8).

A robot keeps running when its capture's disk fills up: the board goes on, the loss is one
CAPTURE_LOST event and counters in ``board.stats``, and a command that captured exits 1 at
its end. A full disk is a small tmpfs mounted for the test (CI runs as root); ``/dev/full``
fails the header, so there the open is refused. ``capture_max_bytes`` rotates the file.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from protoduino import Board, CaptureError
from protoduino.capture import CapturedFrame, CaptureEnd, CaptureHeader
from protoduino.capturefollow import follow
from protoduino.capturereader import Damage, read_capture
from protoduino.cli.main import main
from protoduino.events import Event, EventKind
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice

#: tmpfs takes whole pages: this leaves the capture one 4 KiB page after the filler.
DISK = 64 * 1024
FILLER = DISK - 4096
#: Bounds a wait that fails only.
DEADLINE = 30.0


@pytest.fixture
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A 64 KiB tmpfs with 4 KiB free: a capture on it fills it after a few dozen frames."""
    if os.geteuid() != 0 or shutil.which("mount") is None or shutil.which("umount") is None:
        pytest.skip("mounting a tmpfs needs root and mount(8) (CI has both)")
    disk = tmp_path / "disk"
    disk.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={DISK}", "tmpfs", str(disk)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"mount -t tmpfs was refused here: {done.stderr.strip()}")
    try:
        (disk / "filler").write_bytes(b"x" * FILLER)
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)


def _wait(condition: Callable[[], bool]) -> bool:
    deadline = time.monotonic() + DEADLINE
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


def test_a_full_disk_stops_the_capture_not_the_board(fake: PtyDevice, full_disk: Path) -> None:
    cap = full_disk / "robot.jsonl"
    events: list[Event] = []
    lock = threading.Lock()

    def lost() -> list[Event]:
        with lock:
            return [e for e in events if e.kind is EventKind.CAPTURE_LOST]

    def collect(event: Event) -> None:
        with lock:
            events.append(event)

    with Board.open(fake.port, capture=cap) as board:
        board.on_event(collect)
        for _ in range(2000):  # a bound; the page fills after a few dozen frames
            board.ping()
            if board.stats.capture_error is not None:
                break
        stats = board.stats
        assert stats.capture_error == os.strerror(errno.ENOSPC)
        assert stats.capture_lost >= 1 and stats.capture_lost_bytes > 0
        for _ in range(20):
            board.ping()  # the board goes on
        assert board.stats.capture_lost > stats.capture_lost  # and what it misses is counted
        assert _wait(lambda: bool(lost()))
        assert board.stats.state == "active"
    reported = lost()
    assert len(reported) == 1, reported  # once, however many records were lost after it
    assert reported[0].details["errno"] == errno.ENOSPC
    assert reported[0].details["path"] == str(cap)
    # What was written before the disk filled reads back whole (the last line may be torn,
    # which is no damage); nothing came after the failed write.
    damage: list[Damage] = []
    records = list(
        read_capture(cap.read_bytes().splitlines(keepends=True), on_damage=damage.append)
    )
    assert damage == []
    assert isinstance(records[0], CaptureHeader)
    assert not any(isinstance(r, CaptureEnd) for r in records)


def test_a_command_whose_capture_stopped_exits_1(
    fake: PtyDevice, full_disk: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cap = full_disk / "ping.jsonl"
    rc = main(["ping", fake.port, "-c", "200", "-i", "0", "-q", "--capture", str(cap)])
    out, err = capsys.readouterr()
    assert "200 sent, 200 answered, 0 lost" in out  # the command itself did its work
    assert rc == 1
    assert "protoduino ping: the capture stopped: No space left on device" in err
    assert "records (" in err and "bytes) were not written" in err


def test_a_capture_whose_header_cannot_be_written_opens_nothing(fake: PtyDevice) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("/dev/full is missing")
    with pytest.raises(CaptureError, match="cannot write the capture /dev/full: No space left"):
        Board.open(fake.port, capture="/dev/full")
    assert fake.resets == 0


def test_capture_max_bytes_rotates_to_a_second_part(fake: PtyDevice, tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    old = tmp_path / "c.jsonl.1"
    with Board.open(fake.port, capture=cap, capture_max_bytes=4096) as board:
        for _ in range(300):
            board.ping()
    assert cap.stat().st_size <= 4096 and old.stat().st_size <= 4096
    newer = list(read_capture(cap.read_bytes().splitlines(keepends=True)))
    older = list(read_capture(old.read_bytes().splitlines(keepends=True)))
    first, last = older[0], newer[0]
    assert isinstance(first, CaptureHeader) and isinstance(last, CaptureHeader)
    assert last.part == first.part + 1 >= 3  # 300 pings fill more than two 4 KiB parts
    end = older[-1]
    assert isinstance(end, CaptureEnd) and end.rotated
    final = newer[-1]
    assert isinstance(final, CaptureEnd) and not final.rotated
    with pytest.raises(ValueError, match="max_bytes must be an int >= 4096"):
        Board.open(fake.port, capture=tmp_path / "x.jsonl", capture_max_bytes=100)
    with pytest.raises(ValueError, match="give capture= too"):
        Board.open(fake.port, capture_max_bytes=100_000)


def test_capture_max_goes_with_capture(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["ping", "/dev/null", "--capture-max", "1"])
    assert exit_.value.code == 2
    assert "--capture-max goes with --capture FILE" in capsys.readouterr().err


def test_a_capture_grows_about_160_bytes_per_command(tmp_path: Path) -> None:
    """docs/api.md's growth figures rest on this: a servo command and its Ack take about
    140 bytes of capture (138 with protocol version 5's one-byte ids and short Ack; the
    counters line, once a second, comes on top)."""
    cap = tmp_path / "c.jsonl"
    with SimBoard("native") as sim, Board.open(sim.start(), capture=cap, ping=False) as board:
        servo = board.servo(9)
        before = cap.stat().st_size
        for n in range(500):
            servo.write_us(1000 + n)
    # Read once the board closed: the capture's lines are written by the I/O thread after the
    # layers above have their frames (docs/architecture.md), so the last Acks' lines may still
    # be on their way when the last call returns.
    frames = [line for line in cap.read_bytes().splitlines(keepends=True)[1:] if b'"frame"' in line]
    size = cap.stat().st_size - before
    per_command = sum(len(line) for line in frames[-1000:]) / 500
    assert 125 <= per_command <= 155, per_command
    assert size >= 500 * per_command  # the counters lines add to it, nothing else is left out


def test_follow_reads_every_frame_across_live_rotations(fake: PtyDevice, tmp_path: Path) -> None:
    """A follower started before the capture exists waits for it, then goes from part to
    part as the writer rotates, and misses no frame of the session silently: a part that was
    rotated away before it could be read (two rotations within one poll) is reported."""
    cap = tmp_path / "live.jsonl"
    seen: list[object] = []
    damage: list[Damage] = []
    stop = threading.Event()

    def read() -> None:
        for record in follow(
            cap, from_start=True, poll=0.005, stop=stop.is_set, on_damage=damage.append
        ):
            seen.append(record)

    follower = threading.Thread(target=read)
    follower.start()
    try:
        with Board.open(fake.port, capture=cap, capture_max_bytes=16384) as board:
            # The handshake fits in part 1: the follower is on it before the pings fill it.
            assert _wait(lambda: bool(seen)), "the follower never found the capture"
            for _ in range(600):
                board.ping()
        sent = board.stats  # after the close: every frame is in the capture
        follower.join(DEADLINE)  # ends at the last part's end mark; the bound is for a failure
        assert not follower.is_alive(), "the follower did not see the end of the session"
    finally:
        stop.set()
        follower.join()
    parts = [r.part for r in seen if isinstance(r, CaptureHeader)]
    missed = sum(int(d.reason.split()[0]) for d in damage)
    assert all("rotated away before they could be read" in d.reason for d in damage)
    assert parts == sorted(parts) and parts[0] == 1 and len(parts) + missed == parts[-1] >= 3
    ends = [r for r in seen if isinstance(r, CaptureEnd)]
    assert [e.rotated for e in ends] == [True] * (len(parts) - 1) + [False]
    if not missed:  # the usual case: every frame the host sent, none twice
        sent_frames = [r for r in seen if isinstance(r, CapturedFrame) and r.direction == "tx"]
        assert len(sent_frames) == sent.tx_packets


def test_follow_reports_parts_rotated_away_unread(tmp_path: Path) -> None:
    cap = tmp_path / "c.jsonl"
    header = '{"capture":"protoduino","version":1,"url":"u","schema_id":1,"started":1.0%s}\n'
    cap.write_text(header % "")
    damage: list[Damage] = []
    records = follow(cap, poll=0.01, on_damage=damage.append)
    assert isinstance(next(records), CaptureHeader)
    # Before the follower looks again, the writer rotated three times: parts 2 and 3 are gone.
    with cap.open("a") as f:
        f.write('{"t":2.0,"end":true,"rotated":true}\n')
    cap.rename(tmp_path / "part1")  # renamed, later replaced: the follower's file lives on
    rotated = '{"t":3,"end":true,"rotated":true}\n'
    (tmp_path / "c.jsonl.1").write_text(header % ',"part":4' + rotated)
    (tmp_path / "part5").write_text(header % ',"part":5' + '{"t":4.0,"end":true}\n')
    (tmp_path / "part5").rename(cap)
    assert next(records) == CaptureEnd(2.0, rotated=True)
    part4 = next(records)
    assert isinstance(part4, CaptureHeader) and part4.part == 4
    assert [str(d) for d in damage] == [
        "2 part(s) of the capture were rotated away before they could be read "
        "(a capture_max_bytes too small for this rate?)"
    ]
    assert next(records) == CaptureEnd(3.0, rotated=True)
    part5 = next(records)
    assert isinstance(part5, CaptureHeader) and part5.part == 5
    assert next(records) == CaptureEnd(4.0)
    assert list(records) == []
