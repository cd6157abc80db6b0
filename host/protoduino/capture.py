"""Capture files: every frame of a session in both directions, with timestamps.

This module is the format, its records and the writer; reading is
:mod:`protoduino.capturereader`, following a live one :mod:`protoduino.capturefollow`.

A capture is JSON Lines, each line written with one ``write(2)`` as it
happens, so that another process can follow it live (``protoduino monitor
--follow``) without touching the port, and ``protoduino decode`` can read it
afterwards:

* the first line is the header: ``{"capture": "protoduino", "version": 1,
  "url": ..., "schema_id": ..., "started": UNIX_TIME}``, plus ``"part": N``
  from the second part of a rotated capture on;
* a frame: ``{"t": UNIX_TIME, "dir": "tx"|"rx", "frame": HEX}``, the frame
  as it crossed the wire (COBS-encoded, without its 0x00 delimiter), plus
  ``"error": REASON`` for a frame the receiver dropped;
* the link counters, at most once per ``stats_every`` seconds while frames
  flow and once at the end: ``{"t": ..., "stats": {...}}`` (:class:`Stats`);
* a board event (reboot, failsafe, ...): ``{"t": ..., "event": KIND,
  "text": ..., "details": {...}}``;
* the last line, when the session closes: ``{"t": ..., "end": true}``; or,
  when the part reached ``max_bytes``, ``{"t": ..., "end": true, "rotated":
  true}`` and the session goes on in the next part (:class:`CaptureWriter`).

Text rather than a binary format: a capture is small (a frame is tens of
bytes), survives a crash mid-line (the reader skips a torn last line), and
``grep``/``jq`` read it as they are. ``protoduino decode --mcap`` turns it into
MCAP for Foxglove (:mod:`protoduino.mcapexport`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ._generated.schema_id import SCHEMA_ID
from .errors import ArgumentError, CaptureError
from .events import Event, Stats
from .framing import cobs_encode
from .packets import BadFrame, Packet, build_packet
from .transport import FrameRecord

log = logging.getLogger(__name__)

MAGIC = "protoduino"
VERSION = 1
#: A longer line is refused unread (a record is at most a few kilobytes): reading stays
#: in bounded memory whatever the file holds.
MAX_LINE = 65536
#: The smallest ``max_bytes`` a capture may have (a header and a few records).
MIN_PART = 4096
#: Default seconds between two stats lines while frames flow.
STATS_EVERY = 1.0


@dataclass(frozen=True, slots=True)
class CaptureHeader:
    url: str
    schema_id: int
    started: float  # UNIX time
    version: int = VERSION
    part: int = 1  # 2, 3, ... after rotations (max_bytes)


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
    #: The part ended because it reached max_bytes; the session goes on in the next part.
    rotated: bool = False


Record = CaptureHeader | CapturedFrame | CapturedStats | CapturedEvent | CaptureEnd


def encoded_frame(item: Packet | BadFrame) -> bytes:
    """The frame as on the wire, without its delimiter (a packet encodes one way only)."""
    if isinstance(item, BadFrame):
        return item.raw
    return cobs_encode(build_packet(item.type, item.seq, item.payload))


class CaptureWriter:
    """Appends a session's frames, counters and events to a capture file.

    :meth:`frame` is a transport frame monitor: it runs on the I/O thread, so
    it only formats one short line and writes it with one ``write(2)`` (no
    buffer in between: a reader following the file sees each frame as it
    happens). ``stats`` is asked for the link counters at most every
    ``stats_every`` seconds.

    A capture that cannot be created, or whose header cannot be written,
    raises :class:`CaptureError` here, before anything else is opened. A write
    that fails later (a full disk) must not stop a robot: the capture stops,
    the session goes on, ``on_lost`` is called once with the ``OSError``, and
    every record from the failed one on is counted in :attr:`lost_records` and
    :attr:`lost_bytes`.

    ``max_bytes`` bounds the file: before the line that would take it past
    ``max_bytes``, the part ends with a rotation mark (an end line with
    ``"rotated": true``), is renamed ``PATH.1`` (replacing an older one) and a
    new part starts at PATH with its own header (``"part": N``). So at most
    twice ``max_bytes`` stay on disk, the newest records always among them.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        url: str,
        *,
        stats: Callable[[], Stats] | None = None,
        stats_every: float = STATS_EVERY,
        schema_id: int = SCHEMA_ID,
        max_bytes: int | None = None,
        on_lost: Callable[[OSError], None] | None = None,
    ) -> None:
        if max_bytes is not None and (
            isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < MIN_PART
        ):
            raise ArgumentError(
                f"capture max_bytes must be an int >= {MIN_PART}, not {max_bytes!r}"
            )
        self.path = os.fspath(path)
        self.url = url
        self.max_bytes = max_bytes
        self.on_lost = on_lost
        self._schema_id = schema_id
        self._stats = stats
        self._stats_every = stats_every
        self._lock = threading.Lock()
        # time.monotonic() (the frames' clock) to UNIX time, fixed once per capture.
        self._offset = time.time() - time.monotonic()
        self._next_stats = 0.0
        self._fd: int | None = None
        self._size = 0  # bytes in the current part
        self._closed = False
        #: The current part: 1, then one more at each rotation.
        self.part = 1
        #: Why the capture stopped (None while it records).
        self.error: OSError | None = None
        #: Records (lines) not written since it stopped, and their bytes.
        self.lost_records = 0
        self.lost_bytes = 0
        try:
            self._start_part()
        except OSError as error:
            self._close_fd()
            raise CaptureError(
                f"cannot write the capture {self.path}: {reason_of(error)}"
            ) from error

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
        if self._closed:
            return
        self.write_stats()
        self._write({"t": round(time.time(), 6), "end": True})
        with self._lock:
            self._closed = True
            self._close_fd()

    # -- writing -------------------------------------------------------------

    def _start_part(self) -> None:
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o666)
        self._size = 0
        header: dict[str, Any] = {
            "capture": MAGIC,
            "version": VERSION,
            "url": self.url,
            "schema_id": self._schema_id,
            "started": round(time.time(), 6),
        }
        if self.part > 1:
            header["part"] = self.part
        self._put(_line(header))

    def _put(self, data: bytes) -> None:
        """All of ``data`` (a nearly full disk takes part of it, then fails)."""
        assert self._fd is not None
        view = memoryview(data)
        while view:
            view = view[os.write(self._fd, view) :]
        self._size += len(data)

    def _rotate(self) -> None:
        mark = _line({"t": round(time.time(), 6), "end": True, "rotated": True})
        self._put(mark)
        self._close_fd()
        os.replace(self.path, self.path + ".1")
        self.part += 1
        self._start_part()

    def _close_fd(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)

    def _write(self, obj: dict[str, Any]) -> None:
        line = _line(obj)
        lost: OSError | None = None
        with self._lock:
            if self._closed:
                return
            if self._fd is None:
                self.lost_records += 1
                self.lost_bytes += len(line)
                return
            try:
                # The rotation mark (about 50 bytes) fits in the part too.
                if self.max_bytes is not None and self._size + len(line) + 64 > self.max_bytes:
                    self._rotate()
                self._put(line)
            except OSError as error:
                lost = self.error = error
                self.lost_records += 1
                self.lost_bytes += len(line)
                with contextlib.suppress(OSError):
                    self._close_fd()
        if lost is not None:
            log.warning(
                "the capture %s stopped: %s; the session goes on without it",
                self.path,
                reason_of(lost),
            )
            if self.on_lost is not None:
                self.on_lost(lost)


def _line(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, separators=(",", ":"), default=str) + "\n").encode()


def reason_of(error: OSError) -> str:
    """An OSError as the OS says it (``No space left on device``)."""
    return error.strerror or str(error)
