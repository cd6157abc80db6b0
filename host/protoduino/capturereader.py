"""Reading capture files: bytes to records, in bounded memory, damage reported not fatal.

The format is :mod:`protoduino.capture`'s. A capture is read line by line
(:class:`LineSplitter` never holds more than :data:`MAX_LINE` bytes of one), so
``protoduino decode`` streams whatever the file's size. What is not a record
(binary garbage, not JSON, nested too deep, too long, a run of NULs before a
line, a missing header) is a :class:`Damage`: handed to the caller's
``on_damage`` and skipped, never an exception from deep inside ``json``.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import IO, Any, get_args

from .capture import (
    MAGIC,
    MAX_LINE,
    VERSION,
    CapturedEvent,
    CapturedFrame,
    CapturedStats,
    CaptureEnd,
    CaptureHeader,
    Record,
)
from .errors import ArgumentError, ArgumentTypeError, CaptureError
from .framing import decode_frame
from .packets import BadFrame, ErrorReason


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
            raise ArgumentError(f"unknown drop reason {error!r}")
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
        raise ArgumentTypeError(f"a JSON {type(value).__name__} where an object belongs")
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
        report(on_damage, Damage(number, reason))

    first = True
    for number, item in enumerate(lines, 1):
        line = _raw(item, number)
        record = read_record(line, on_damage)
        if record is None:
            continue
        if first and not isinstance(record, CaptureHeader):
            damage(line.number, "no header line: not a protoduino capture, or its start is missing")
        first = False
        yield record


def report(on_damage: Callable[[Damage], None] | None, damage: Damage) -> None:
    """Hand ``damage`` to ``on_damage``, or raise it as :class:`CaptureError` without one."""
    if on_damage is None:
        raise CaptureError(str(damage))
    on_damage(damage)


def read_record(line: RawLine, on_damage: Callable[[Damage], None] | None) -> Record | None:
    """One line's record, or None (blank, torn, or damaged: reported to ``on_damage``, or
    raised as :class:`CaptureError` without it; see :func:`read_capture`)."""
    if line.nuls:
        reason = (
            f"{line.nuls} NUL bytes before it (the start of this capture was lost: "
            "copied while it was being truncated?)"
        )
        report(on_damage, Damage(line.number, reason))
    try:
        return _parse(line)
    except _LineError as error:
        report(on_damage, Damage(line.number, str(error)))
        return None
