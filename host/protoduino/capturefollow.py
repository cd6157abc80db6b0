"""Following a capture another process is writing, like ``tail -F``.

``protoduino monitor --follow`` reads a session's capture as it grows, never
its port: the capture may not exist yet, may be a FIFO, may be started again
by a new session (truncated) or rotated by its writer (``capture_max_bytes``),
or may belong to a session that already closed. :func:`follow` handles each
and honours its ``stop()`` whatever the file does, because it never blocks:
the file is opened non-blocking and polled.
"""

from __future__ import annotations

import collections
import os
import stat
import time
from collections.abc import Callable, Iterator

from .capture import MAX_LINE, CaptureEnd, CaptureHeader, Record, reason_of
from .capturereader import Damage, LineSplitter, RawLine, read_record, report
from .closing import ClosedOnExit
from .errors import CaptureError


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
            record = read_record(line, on_damage)
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
                    report(
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
        record = read_record(RawLine(1, first[:-1], len(first) - 1), _ignore)
    except CaptureError:  # a version this does not read
        return None
    return record.part if isinstance(record, CaptureHeader) else None


def _ignore(damage: Damage) -> None:
    """Damage in a line looked at only to decide where to read: not reported twice."""


class _Tail(ClosedOnExit):
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
                    f"cannot read the capture {self.path}: {reason_of(error)}"
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
            raise CaptureError(f"cannot read the capture {name}: {reason_of(error)}") from error
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

    def skip_to_end(self) -> CaptureEnd | None:
        """Go to the end of a regular file (live traffic only); its end mark if it had ended."""
        if not self.regular or self.fd is None:
            return None
        self.ready.clear()
        size = os.fstat(self.fd).st_size
        last = self._last_line(size)
        if last is not None:
            try:
                record = read_record(last, _ignore)
            except CaptureError:
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
