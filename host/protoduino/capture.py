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

import collections
import contextlib
import json
import logging
import os
import stat
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import IO, Any, get_args

from ._generated.schema_id import SCHEMA_ID
from .errors import CaptureError
from .events import Event, Stats
from .framing import cobs_encode, decode_frame
from .packets import BadFrame, ErrorReason, Packet, build_packet
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
            raise ValueError(f"capture max_bytes must be an int >= {MIN_PART}, not {max_bytes!r}")
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
            raise CaptureError(f"cannot write the capture {self.path}: {_reason(error)}") from error

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
                _reason(lost),
            )
            if self.on_lost is not None:
                self.on_lost(lost)


def _line(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, separators=(",", ":"), default=str) + "\n").encode()


def _reason(error: OSError) -> str:
    return error.strerror or str(error)


def is_capture(head: bytes) -> bool:
    """Whether a file starting with ``head`` is JSON lines, so a capture (not raw wire bytes).

    Leading NULs (the hole a copy taken while the capture was truncated starts
    with) and whitespace are passed over; whether the header is there is for
    the reader to say.
    """
    return head.lstrip(b"\0 \t\r\n").startswith(b'{"')


# -- reading -----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RawLine:
    """One line of a capture file as read, before parsing."""

    number: int  # 1-based
    data: bytes  # without its newline; only the first MAX_LINE + 1 bytes of a longer line
    length: int  # its whole length (more than MAX_LINE: too long, refused)
    nuls: int = 0  # NUL bytes dropped before it
    complete: bool = True  # ended by a newline (False: the file ended mid-line)


@dataclass(frozen=True, slots=True)
class Damage:
    """A line of a capture that was skipped, or read with something wrong before it."""

    line: int  # 0: not one line (parts of a rotated capture missed)
    reason: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.reason}" if self.line else self.reason


class LineSplitter:
    """Bytes in, :class:`RawLine` out, in bounded memory.

    Never holds more than ``limit + 1`` bytes of a line: a longer one is
    counted and skipped to its newline, whatever arrives. A run of NULs at the
    start of a line is dropped and counted (the hole that a copy of a file
    being truncated, e.g. logrotate's copytruncate, begins with).
    """

    def __init__(self, limit: int = MAX_LINE) -> None:
        self.limit = limit
        self.lines = 0
        self._part = bytearray()
        self._length = 0
        self._nuls = 0

    def feed(self, data: bytes) -> list[RawLine]:
        out: list[RawLine] = []
        start = 0
        while start < len(data):
            end = data.find(b"\n", start)
            self._add(data[start:] if end < 0 else data[start:end])
            if end < 0:
                break
            out.append(self._take(complete=True))
            start = end + 1
        return out

    def finish(self) -> RawLine | None:
        """The last line if the data ended without its newline."""
        if not self._length and not self._nuls:
            return None
        return self._take(complete=False)

    @property
    def pending(self) -> bool:
        """Part of a line waits for its newline."""
        return bool(self._length or self._nuls)

    def _add(self, piece: bytes) -> None:
        if not self._length and piece[:1] == b"\0":
            stripped = piece.lstrip(b"\0")
            self._nuls += len(piece) - len(stripped)
            piece = stripped
        self._length += len(piece)
        room = self.limit + 1 - len(self._part)
        if room > 0:
            self._part += piece[:room]

    def _take(self, *, complete: bool) -> RawLine:
        self.lines += 1
        line = RawLine(self.lines, bytes(self._part), self._length, self._nuls, complete)
        self._part.clear()
        self._length = self._nuls = 0
        return line


def read_lines(f: IO[bytes], *, chunk: int = 65536) -> Iterator[RawLine]:
    """Every line of a binary file, read ``chunk`` bytes at a time (constant memory)."""
    splitter = LineSplitter()
    while data := f.read(chunk):
        yield from splitter.feed(data)
    last = splitter.finish()
    if last is not None:
        yield last


class _LineError(Exception):
    """A line that is not a capture record; the message says why."""


def parse_line(line: str | bytes | RawLine) -> Record | None:
    """One capture line as a record; None for a blank line or a torn last line
    (a writer stopped mid-line). Raises :class:`CaptureError` for a line that is
    not a capture record, or the header of a capture version this does not read."""
    try:
        return _parse(_raw(line, 1))
    except _LineError as error:
        raise CaptureError(str(error)) from None


def _raw(line: str | bytes | RawLine, number: int) -> RawLine:
    if isinstance(line, RawLine):
        return line
    data = line.encode("utf-8", errors="surrogateescape") if isinstance(line, str) else line
    complete = data.endswith(b"\n")
    data = data.rstrip(b"\n")
    stripped = data.lstrip(b"\0")
    nuls = len(data) - len(stripped)
    return RawLine(number, stripped[: MAX_LINE + 1], len(stripped), nuls, complete)


def _parse(line: RawLine) -> Record | None:
    if line.length > MAX_LINE:
        raise _LineError(f"{line.length} bytes long (a record is at most {MAX_LINE}): skipped")
    data = line.data.strip()
    if not data:
        return None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise _LineError(f"not UTF-8 text (byte {error.start}): skipped") from None
    try:
        obj = json.loads(text)
    except RecursionError:
        raise _LineError("JSON nested too deep: skipped") from None
    except ValueError as error:
        if not line.complete:
            return None  # torn: the writer stopped mid-line
        raise _LineError(f"not JSON ({error}): skipped") from None
    if not isinstance(obj, dict):
        raise _LineError(f"a JSON {type(obj).__name__}, not a record: skipped")
    try:
        return _record(obj)
    except CaptureError:
        raise
    except (KeyError, ValueError, TypeError, AttributeError, RecursionError) as error:
        raise _LineError(
            f"not a capture record ({type(error).__name__}: {error}): skipped"
        ) from None


def _record(obj: dict[str, Any]) -> Record | None:
    if obj.get("capture") == MAGIC:
        if obj.get("version") != VERSION:
            raise CaptureError(f"capture version {obj.get('version')} (this reads {VERSION})")
        return CaptureHeader(
            str(obj.get("url", "")),
            int(obj["schema_id"]),
            float(obj["started"]),
            version=VERSION,
            part=int(obj.get("part", 1)),
        )
    t = float(obj.get("t", 0.0))
    if "frame" in obj:
        raw = bytes.fromhex(obj["frame"])
        error = obj.get("error")
        if error is None:
            item = decode_frame(raw)
        elif error in get_args(ErrorReason):
            item = BadFrame(error, raw)
        else:
            raise ValueError(f"unknown drop reason {error!r}")
        return CapturedFrame(t, str(obj["dir"]), item)
    if "stats" in obj:
        return CapturedStats(t, _mapping(obj["stats"]))
    if "event" in obj:
        details = _mapping(obj.get("details", {}))
        return CapturedEvent(t, str(obj["event"]), str(obj.get("text", "")), details)
    if obj.get("end"):
        return CaptureEnd(t, rotated=bool(obj.get("rotated", False)))
    return None


def _mapping(value: object) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise TypeError(f"a JSON {type(value).__name__} where an object belongs")
    return value


def read_capture(
    lines: Iterable[str | bytes | RawLine],
    *,
    on_damage: Callable[[Damage], None] | None = None,
) -> Iterator[Record]:
    """Every record of a capture, streamed.

    A line that is not a record (binary garbage, not JSON, nested too deep,
    longer than :data:`MAX_LINE`), a run of NULs before a line, and a first
    record that is no header (the start of the capture is missing) are damage:
    reported to ``on_damage`` and skipped (the NULs alone: the line after them
    is read), or, without ``on_damage``, raised as :class:`CaptureError`. A
    capture of a version this does not read always raises. A torn last line
    (the writer stopped mid-line) is not damage: it is left out.
    """

    def damage(number: int, reason: str) -> None:
        _damage(on_damage, Damage(number, reason))

    first = True
    for number, item in enumerate(lines, 1):
        line = _raw(item, number)
        record = _read_one(line, on_damage)
        if record is None:
            continue
        if first and not isinstance(record, CaptureHeader):
            damage(line.number, "no header line: not a protoduino capture, or its start is missing")
        first = False
        yield record


def _damage(on_damage: Callable[[Damage], None] | None, damage: Damage) -> None:
    if on_damage is None:
        raise CaptureError(str(damage))
    on_damage(damage)


def _read_one(line: RawLine, on_damage: Callable[[Damage], None] | None) -> Record | None:
    """One line's record, its damage reported (see :func:`read_capture`)."""
    if line.nuls:
        reason = (
            f"{line.nuls} NUL bytes before it (the start of this capture was lost: "
            "copied while it was being truncated?)"
        )
        _damage(on_damage, Damage(line.number, reason))
    try:
        return _parse(line)
    except _LineError as error:
        _damage(on_damage, Damage(line.number, str(error)))
        return None


def follow(
    path: str | os.PathLike[str],
    *,
    from_start: bool = False,
    poll: float = 0.05,
    stop: Callable[[], bool] = lambda: False,
    on_damage: Callable[[Damage], None] | None = None,
    on_wait: Callable[[str], None] | None = None,
) -> Iterator[Record]:
    """Records as another process appends them, until its end mark or ``stop()``.

    Like ``tail -F``: a capture that does not exist yet is waited for
    (``on_wait`` is told once); the header comes first; then, unless
    ``from_start``, only what is written from now on. A capture that had
    already ended (its last line is the end mark) yields its header and that
    end mark, and nothing else. A capture that shrinks was started again by a
    new session (the writer truncates it), and one that rotated (an end mark
    with ``rotated``, see :class:`CaptureWriter`) goes on at PATH: reading
    starts over at the new header, which is yielded like the first.

    The file is opened non-blocking and read in polls of ``poll`` seconds, so
    ``stop()`` is honoured whatever it is: a regular file, or a FIFO with no
    writer yet. A line is parsed once whole; damaged lines go to ``on_damage``
    (or raise :class:`CaptureError` without it), as :func:`read_capture` says.
    Never opens the port, only the file.
    """
    name = os.fspath(path)
    tail = _Tail(name, poll, stop, on_wait)
    if not tail.open():
        return
    with tail:
        header: CaptureHeader | None = None
        for line in tail.lines():
            record = _read_one(line, on_damage)
            if record is None:
                continue
            if not isinstance(record, CaptureHeader):
                if header is None:
                    raise CaptureError(f"{name} is not a protoduino capture (no header line)")
            else:
                header = record
                ended = None
                if tail.started_over:
                    tail.started_over = False
                elif not from_start:
                    # Before the header is handed out: nothing older follows it.
                    ended = tail.skip_to_end()
                yield record
                if ended is not None:
                    yield ended
                    return
                continue
            yield record
            if isinstance(record, CaptureEnd):
                if not record.rotated:
                    return
                missed = tail.next_part(header.part + 1 if header is not None else 1)
                if missed:
                    _damage(
                        on_damage,
                        Damage(
                            0,
                            f"{missed} part(s) of the capture were rotated away before they "
                            "could be read (a capture_max_bytes too small for this rate?)",
                        ),
                    )


def _part_of(name: str) -> int | None:
    """The part number in the header of capture file ``name``; None if it has none yet."""
    try:
        with open(name, "rb") as f:
            first = f.readline(MAX_LINE + 1)
    except OSError:
        return None
    if not first.endswith(b"\n"):
        return None
    try:
        record = _parse(RawLine(1, first[:-1], len(first) - 1))
    except (_LineError, CaptureError):
        return None
    return record.part if isinstance(record, CaptureHeader) else None


class _Tail:
    """The file ``follow`` reads: opened non-blocking, polled, reopened as ``tail -F`` does."""

    def __init__(
        self,
        path: str,
        poll: float,
        stop: Callable[[], bool],
        on_wait: Callable[[str], None] | None,
    ) -> None:
        self.path = path
        self.poll = poll
        self.stop = stop
        self.on_wait = on_wait
        self.fd: int | None = None
        #: The file open now: PATH, or PATH.1 for a part that rotated before it was read.
        self.name = path
        self.regular = False
        self.pos = 0
        self.splitter = LineSplitter()
        #: Lines read and not yet handed out.
        self.ready: collections.deque[RawLine] = collections.deque()
        #: Reading began again at the start of a file: its header is a new session's.
        self.started_over = False
        self._skip_partial = False

    def open(self) -> bool:
        """Open PATH, waiting for it to exist; False if ``stop()`` came first."""
        told = False
        while True:
            try:
                fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
            except FileNotFoundError:
                if not told and self.on_wait is not None:
                    self.on_wait(f"{self.path} does not exist yet: waiting for it")
                told = True
                if self.stop():
                    return False
                time.sleep(self.poll)
                continue
            except OSError as error:
                raise CaptureError(
                    f"cannot read the capture {self.path}: {_reason(error)}"
                ) from error
            break
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            os.close(fd)
            raise CaptureError(f"{self.path} is a directory, not a capture")
        self.fd = fd
        self.name = self.path
        self.regular = stat.S_ISREG(st.st_mode)
        self.pos = 0
        self.splitter = LineSplitter()
        self.ready.clear()
        return True

    def next_part(self, part: int) -> int:
        """After a rotation mark: open ``part``, wherever it is now; how many were missed.

        The writer renames the full part to PATH.1 and starts the next at PATH,
        so the next part is at PATH, or already at PATH.1 if the writer rotated
        again since (it is then complete and read to its own rotation mark), or
        gone if it rotated twice: then the oldest part still there is read, and
        the parts in between are missed. Until the writer has written the new
        part's header it is waited for quietly.
        """
        self.close()
        while not self.stop():
            found = [(p, name) for name in (self.path + ".1", self.path) if (p := _part_of(name))]
            for p, name in found:
                if p >= part and self._open_name(name):
                    self.started_over = True
                    return p - part
            time.sleep(self.poll)
        return 0

    def _open_name(self, name: str) -> bool:
        try:
            fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        except FileNotFoundError:
            return False  # renamed between the look and the open: look again
        except OSError as error:
            raise CaptureError(f"cannot read the capture {name}: {_reason(error)}") from error
        self.fd = fd
        self.name = name
        self.regular = True
        self.pos = 0
        self.splitter = LineSplitter()
        self.ready.clear()
        self._skip_partial = False
        return True

    def close(self) -> None:
        fd, self.fd = self.fd, None
        if fd is not None:
            os.close(fd)

    def __enter__(self) -> _Tail:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def skip_to_end(self) -> CaptureEnd | None:
        """Go to the end of a regular file (live traffic only); its end mark if it had ended."""
        if not self.regular or self.fd is None:
            return None
        self.ready.clear()
        size = os.fstat(self.fd).st_size
        last = self._last_line(size)
        if last is not None:
            try:
                record = _parse(last)
            except (_LineError, CaptureError):
                record = None
            if isinstance(record, CaptureEnd) and not record.rotated:
                return record
        os.lseek(self.fd, size, os.SEEK_SET)
        self.pos = size
        self.splitter = LineSplitter()
        # Landed in a line still being written: its rest is not a whole line.
        self._skip_partial = last is None or not last.complete
        return None

    def _last_line(self, size: int) -> RawLine | None:
        assert self.fd is not None
        start = max(0, size - MAX_LINE)
        data = os.pread(self.fd, size - start, start)
        complete = data.endswith(b"\n")
        body = data[:-1] if complete else data
        cut = body.rfind(b"\n")
        if cut < 0 and start > 0:
            return None
        body = body[cut + 1 :]
        return RawLine(0, body, len(body), 0, complete)

    def lines(self) -> Iterator[RawLine]:
        while not self.stop():
            if self.ready:
                yield self.ready.popleft()
                continue
            if self.fd is None:
                return
            try:
                data = os.read(self.fd, 65536)
            except BlockingIOError:  # a FIFO with a writer and nothing written
                data = b""
            if data:
                self.pos += len(data)
                for line in self.splitter.feed(data):
                    if self._skip_partial:
                        self._skip_partial = False
                        continue
                    self.ready.append(line)
                continue
            if self.regular and self.name == self.path and self._restarted():
                continue
            time.sleep(self.poll)

    def _restarted(self) -> bool:
        """A new session truncated the file, or another file replaced it: start over."""
        assert self.fd is not None
        if os.fstat(self.fd).st_size < self.pos:
            os.lseek(self.fd, 0, os.SEEK_SET)
        else:
            try:
                replaced = os.stat(self.path).st_ino != os.fstat(self.fd).st_ino
            except FileNotFoundError:
                return False
            if not replaced:
                return False
            self.close()
            if not self.open():
                return False
        self.pos = 0
        self.splitter = LineSplitter()
        self.ready.clear()
        self._skip_partial = False
        self.started_over = True
        return True
