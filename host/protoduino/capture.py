"""Capture files: every frame of a session in both directions, with timestamps.

A capture is JSON Lines, written as the session runs and flushed line by line,
so that another process can follow it live (``protoduino monitor --follow``)
without touching the port, and ``protoduino decode`` can read it afterwards:

* the first line is the header: ``{"capture": "protoduino", "version": 1,
  "url": ..., "schema_id": ..., "started": UNIX_TIME}``;
* a frame: ``{"t": UNIX_TIME, "dir": "tx"|"rx", "frame": HEX}``, the frame
  as it crossed the wire (COBS-encoded, without its 0x00 delimiter), plus
  ``"error": REASON`` for a frame the receiver dropped;
* the link counters, at most once per ``stats_every`` seconds while frames
  flow and once at the end: ``{"t": ..., "stats": {...}}`` (:class:`Stats`);
* a board event (reboot, failsafe, ...): ``{"t": ..., "event": KIND,
  "text": ..., "details": {...}}``;
* the last line, when the session closes: ``{"t": ..., "end": true}``.

Text rather than a binary format: a capture is small (a frame is tens of
bytes), survives a crash mid-line (the reader skips a torn last line), and
``grep``/``jq`` read it as they are. ``protoduino decode --mcap`` turns it into
MCAP for Foxglove (:mod:`protoduino.mcapexport`).
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import IO, Any, get_args

from ._generated.schema_id import SCHEMA_ID
from .errors import ArgumentError, CaptureError
from .events import Event, Stats
from .framing import cobs_encode, decode_frame
from .packets import BadFrame, ErrorReason, Packet, build_packet
from .transport import FrameRecord

MAGIC = "protoduino"
VERSION = 1
#: Default seconds between two stats lines while frames flow.
STATS_EVERY = 1.0


@dataclass(frozen=True, slots=True)
class CaptureHeader:
    url: str
    schema_id: int
    started: float  # UNIX time


@dataclass(frozen=True, slots=True)
class CapturedFrame:
    t: float  # UNIX time
    direction: str  # "tx" or "rx"
    item: Packet | BadFrame


@dataclass(frozen=True, slots=True)
class CapturedStats:
    t: float
    stats: dict[str, Any]


@dataclass(frozen=True, slots=True)
class CapturedEvent:
    t: float
    kind: str
    text: str
    details: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class CaptureEnd:
    t: float


Record = CaptureHeader | CapturedFrame | CapturedStats | CapturedEvent | CaptureEnd


def encoded_frame(item: Packet | BadFrame) -> bytes:
    """The frame as on the wire, without its delimiter (a packet encodes one way only)."""
    if isinstance(item, BadFrame):
        return item.raw
    return cobs_encode(build_packet(item.type, item.seq, item.payload))


class CaptureWriter:
    """Appends a session's frames, counters and events to a capture file.

    :meth:`frame` is a transport frame monitor: it runs on the I/O thread, so
    it only formats one short line and writes it (the file is line-buffered;
    a reader following the file sees each frame as it happens). ``stats`` is
    asked for the link counters at most every ``stats_every`` seconds.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        url: str,
        *,
        stats: Callable[[], Stats] | None = None,
        stats_every: float = STATS_EVERY,
        schema_id: int = SCHEMA_ID,
    ) -> None:
        self.path = os.fspath(path)
        self._stats = stats
        self._stats_every = stats_every
        self._lock = threading.Lock()
        # time.monotonic() (the frames' clock) to UNIX time, fixed once per capture.
        self._offset = time.time() - time.monotonic()
        self._next_stats = 0.0
        try:
            self._file: IO[str] | None = open(  # noqa: SIM115 - closed in close()
                self.path, "w", encoding="utf-8", buffering=1
            )
        except OSError as error:
            raise CaptureError(f"cannot write the capture {self.path}: {error.strerror}") from error
        header = {
            "capture": MAGIC,
            "version": VERSION,
            "url": url,
            "schema_id": schema_id,
            "started": round(time.time(), 6),
        }
        self._write(header)

    def set_stats(self, stats: Callable[[], Stats]) -> None:
        self._stats = stats

    def frame(self, rec: FrameRecord) -> None:
        obj: dict[str, Any] = {
            "t": round(rec.t + self._offset, 6),
            "dir": rec.direction,
            "frame": encoded_frame(rec.item).hex(),
        }
        if isinstance(rec.item, BadFrame):
            obj["error"] = rec.item.reason
        self._write(obj)
        if rec.t >= self._next_stats:
            self._next_stats = rec.t + self._stats_every
            self.write_stats()

    def event(self, event: Event) -> None:
        self._write(
            {
                "t": round(event.t + self._offset, 6),
                "event": event.kind.value,
                "text": event.text,
                "details": dict(event.details),
            }
        )

    def write_stats(self) -> None:
        if self._stats is not None:
            stats = self._stats().as_dict()
            stats.pop("last_ping", None)  # a time.monotonic() reading of this process
            self._write({"t": round(time.time(), 6), "stats": stats})

    def close(self) -> None:
        """The final counters and the end mark; idempotent."""
        if self._file is None:
            return
        self.write_stats()
        self._write({"t": round(time.time(), 6), "end": True})
        with self._lock:
            file, self._file = self._file, None
        if file is not None:
            file.close()

    def _write(self, obj: dict[str, Any]) -> None:
        line = json.dumps(obj, separators=(",", ":"), default=str) + "\n"
        with self._lock:
            if self._file is None:
                return
            try:
                self._file.write(line)
            except OSError:  # disk full: the session goes on, the capture stops
                self._file = None


def is_capture(head: bytes) -> bool:
    """Whether a file starting with ``head`` is a capture (not raw wire bytes)."""
    return head.lstrip().startswith(b'{"capture"')


def parse_line(line: str) -> Record | None:
    """One capture line as a record; None for a blank or torn line (a crash mid-write)."""
    line = line.strip()
    if not line:
        return None
    try:
        obj = json.loads(line)
    except ValueError:
        return None
    if not isinstance(obj, dict):
        return None
    return _record(obj)


def _record(obj: dict[str, Any]) -> Record | None:
    if obj.get("capture") == MAGIC:
        if obj.get("version") != VERSION:
            raise CaptureError(f"capture version {obj.get('version')} (this reads {VERSION})")
        return CaptureHeader(str(obj.get("url", "")), int(obj["schema_id"]), float(obj["started"]))
    t = float(obj.get("t", 0.0))
    if "frame" in obj:
        raw = bytes.fromhex(obj["frame"])
        error = obj.get("error")
        if error is None:
            item = decode_frame(raw)
        elif error in get_args(ErrorReason):
            item = BadFrame(error, raw)
        else:
            raise ArgumentError(f"unknown drop reason {error!r}")
        return CapturedFrame(t, str(obj["dir"]), item)
    if "stats" in obj:
        return CapturedStats(t, dict(obj["stats"]))
    if "event" in obj:
        return CapturedEvent(t, str(obj["event"]), str(obj.get("text", "")), obj.get("details", {}))
    if obj.get("end"):
        return CaptureEnd(t)
    return None


def read_capture(lines: Iterable[str]) -> Iterator[Record]:
    """Every record of a capture; raises :class:`CaptureError` if it is not one."""
    first = True
    for number, line in enumerate(lines, 1):
        try:
            record = parse_line(line)
        except (KeyError, ValueError, TypeError) as error:
            raise CaptureError(f"line {number} is not a capture record: {error}") from error
        if record is None:
            continue
        if first and not isinstance(record, CaptureHeader):
            raise CaptureError("not a protoduino capture (no header line)")
        first = False
        yield record


def follow(
    path: str | os.PathLike[str],
    *,
    from_start: bool = False,
    poll: float = 0.05,
    stop: Callable[[], bool] = lambda: False,
) -> Iterator[Record]:
    """Records as another process appends them, until its end mark or ``stop()``.

    Reads the header first; then, unless ``from_start``, skips what is already
    there (live traffic only). Only whole lines are parsed: a line still being
    written waits for its newline. A capture that shrinks was started again by
    a new session (the writer truncates it): reading starts over at its new
    header, which is yielded like the first. Never opens the port, only the file.
    """
    try:
        f = open(path, encoding="utf-8")  # noqa: SIM115 - closed below
    except OSError as error:
        raise CaptureError(
            f"cannot read the capture {os.fspath(path)}: {error.strerror}"
        ) from error
    with f:
        header = None
        pending = ""
        while header is None:
            pending += f.readline()
            if pending.endswith("\n"):
                header = parse_line(pending)
                if not isinstance(header, CaptureHeader):
                    raise CaptureError(f"{os.fspath(path)} is not a protoduino capture")
                pending = ""
            elif stop():
                return
            else:
                time.sleep(poll)
        if not from_start:
            f.seek(0, os.SEEK_END)  # before the header is handed out: nothing older follows it
        yield header
        while not stop():
            chunk = f.readline()
            if not chunk:
                if os.fstat(f.fileno()).st_size < f.tell():  # a new session's capture
                    f.seek(0)
                    pending = ""
                    continue
                time.sleep(poll)
                continue
            pending += chunk
            if not pending.endswith("\n"):
                continue
            line, pending = pending, ""
            try:
                record = parse_line(line)
            except (KeyError, ValueError, TypeError):
                continue
            if record is None:
                continue
            yield record
            if isinstance(record, CaptureEnd):
                return
