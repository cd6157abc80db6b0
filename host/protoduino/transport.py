"""Transport: one pyserial port and the one I/O thread that owns it.

The thread opens the port, reads in bulk and feeds the incremental
:class:`~protoduino.framing.StreamDecoder`, writes the queued packets
(CONTROL ahead of COMMAND; on a plain POSIX port every packet queued in one
write, issue 35), and calls its listener's ``transport_tick`` at
least every ``TICK`` seconds so that the layers above can run their timers
(handshake backoff, watchdog, retransmission, ping) on the same thread,
without locks around the port and without threads of their own. The tick
returns when the timers next need to run, and the thread never sleeps past
that: a retransmission or a call's failure happens on time, not up to a TICK
late (four late retries made a 1.0 s bound 1.066 s).

Any pyserial URL works (``/dev/ttyACM0``, ``socket://``, ``rfc2217://``,
``spy://``, ``loop://``). When the port has a file descriptor (serial ports,
sockets) the thread sleeps in ``select`` on it and on a wake-up pipe, so a
queued write leaves at once; otherwise it polls with short timeout reads. A
plain POSIX port (pyserial's own class: a tty or a pty) is then read and
written by its descriptor, as pyserial does, less the second ``select`` its
read and write each make (host CPU per command, issue 23).

If the port disappears (USB unplugged, the simulated board's pseudo-terminal
gone), or fails in any way (a read, a write, a change of rate that a stalled
``rfc2217://`` server never acknowledges), the thread closes it, tells the
listener, and keeps trying to reopen it with a bounded backoff until the
transport is closed. The thread never ends silently: any other exception (a
bug) is logged and handed to the listener (``transport_failed``), which fails
the board with an ERROR event, before the thread ends.

The transmit SEQ counter lives here because docs/protocol.md section 6 ties it to
the write itself: it advances only after the whole frame was written, and a
frame that failed to write keeps its SEQ.

One exception to "the I/O thread writes": a COMMAND sent from another thread
(a caller's own submit, its window free) onto a plain POSIX port, when nothing
is queued, is written by that thread at once, which saves the wake-up and a
pass of the I/O thread per command (issue 23). One lock (``_wlock``) is held
around taking a packet, giving it its SEQ and writing it, by whichever thread
writes, and around opening, closing and re-rating the port: frames leave
whole, in the order they were sent, their SEQs in order on the wire. The
write is the same (:meth:`_write_items`): a timeout drops the packet and its
SEQ goes to the next; any other failure is handed to the I/O thread, which
loses the port as if its own write had failed. Reading, the timers, the frame monitors and
losing the port stay the I/O thread's: a frame written by a caller is shown to
the monitors by the I/O thread, before anything it reads after it (the record
is queued under the lock that the write holds, and the I/O thread takes that
lock to collect the records before it shows what it read). Such a write wakes no
thread: the I/O thread learns of the call's retransmission timer at its next tick,
TICK at the latest, so with an Ack timeout under TICK (20 ms; 250 ms by default) a
first retransmission may go out up to TICK late.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import logging
import os
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import serial

from .constants import PacketType
from .errors import PortInUseError, TransportError
from .framing import DELIMITER, StreamDecoder, frame_packet
from .packets import BadFrame, Packet

log = logging.getLogger(__name__)


def _stk500v2_message(body: bytes, seq: int = 1) -> bytes:
    """One message of the stk500v2 protocol (Atmel's AVR068): start, SEQ, size, token,
    body, and the XOR of every byte before the checksum."""
    head = bytes([0x1B, seq, len(body) >> 8, len(body) & 0xFF, 0x0E])
    checksum = 0
    for byte in head + body:
        checksum ^= byte
    return head + body + bytes([checksum])


#: stk500v2's CMD_LEAVE_PROGMODE_ISP (0x11, with the two delays avrdude sends): a Mega 2560's
#: bootloader, just reset by the open, starts the application at once when it reads this.
#: Otherwise it stays while bytes arrive: a RESET at least once a second kept it there for
#: good (its wait for a first byte is about 0.7 s, measured on the emulated Mega running
#: Debian's hex). A RESET goes after it while nothing at all has been heard since the open (a
#: waiting bootloader says nothing); a protoduino device takes it for two bad frames (it
#: holds a 0x00), dropped and counted; Optiboot lets go at any stray byte anyway.
BOOTLOADER_LEAVE = _stk500v2_message(bytes([0x11, 0x01, 0x01]))

#: Longest the I/O thread sleeps between timer ticks (seconds).
TICK = 0.02
#: Bytes asked for per read; reads return whatever is there, up to this.
READ_CHUNK = 4096
#: A write that cannot complete within this is abandoned (port stuck).
WRITE_TIMEOUT = 1.0
#: Reopen backoff after the port was lost: first and largest delay (seconds).
REOPEN_FIRST = 0.05
REOPEN_MAX = 1.0
#: Frames kept for diagnostics (attached to timeout errors).
RECENT_FRAMES = 32
#: URL schemes whose pyserial handler has no write timeout, and whose port settings
#: (timeouts included) are negotiated with a remote server at each change.
NO_WRITE_TIMEOUT = REMOTE_URLS = ("rfc2217://",)
#: First bytes received after each open, kept to say what a wrong device sent.
RX_HEAD = 64


def open_port(url: str, *, baudrate: int = 115200) -> Any:
    """Open ``url`` as every protoduino user of a port does: holding its lock.

    pyserial takes ``flock(LOCK_EX | LOCK_NB)`` on a serial port or pty (``exclusive=True``)
    before it configures anything: a second opener fails with :class:`PortInUseError`, and
    the first one's line is untouched (two hosts would re-handshake each other in turn).
    Any other failure is a :class:`TransportError`. The port reads without waiting
    (``timeout=0``); a write gives up after WRITE_TIMEOUT.
    """
    # pyserial 3.5's rfc2217:// refuses any write timeout (NotImplementedError); its
    # socket's own 5 s timeout bounds a write there instead.
    no_write_timeout = url.lower().startswith(NO_WRITE_TIMEOUT)
    try:
        return serial.serial_for_url(
            url,
            baudrate=baudrate,
            timeout=0,
            write_timeout=None if no_write_timeout else WRITE_TIMEOUT,
            exclusive=True,
        )
    except Exception as error:  # any URL handler's failure, in the ProtoduinoError tree
        if getattr(error, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
            # pyserial's "Could not exclusively lock port": the lock is held
            raise PortInUseError(
                f"cannot open {url}: port in use by another program (another "
                "protoduino Board or `protoduino monitor`, in this or another process); "
                "close it first"
            ) from error
        hint = ""
        if no_write_timeout and "option 'control'" in str(error):
            hint = (
                " (a server in front of a pseudo-terminal or of a port without modem "
                "lines never acknowledges modem control: add ?ign_set_control to the URL)"
            )
        raise TransportError(f"cannot open {url}: {error}{hint}") from error


def check_port_free(url: str, *, baudrate: int = 115200) -> None:
    """Raise :class:`PortInUseError` if a running board (or monitor) holds ``url``.

    For a tool that opens the port by other means (avrdude, which takes no lock):
    the lock is taken as every board takes it, then let go at once. Opening a
    real Uno's port resets it (DTR), as the tool is about to do anyway.
    """
    open_port(url, baudrate=baudrate).close()


#: pyserial's POSIX serial port (a tty or a pty): its read and write are os.read and os.write
#: with a select around them, which the I/O thread, already in its own select, does itself.
_PosixSerial: type | None
try:
    from serial.serialposix import Serial as _PosixSerial
except ImportError:  # pragma: no cover - not a POSIX system
    _PosixSerial = None
#: Errors pyserial retries rather than raises (the descriptor is non-blocking).
_RETRY_ERRNOS = (errno.EAGAIN, errno.EALREADY, errno.EWOULDBLOCK, errno.EINPROGRESS, errno.EINTR)


def _read_fd(fd: int) -> bytes:
    """One read of what a plain serial port holds, after select said it is readable.

    As pyserial's read with ``timeout=0`` does, less its second select: the errors it
    retries read as nothing, the others and an empty read (a vanished device) raise
    SerialException.
    """
    try:
        data = os.read(fd, READ_CHUNK)
    except OSError as error:
        if error.errno in _RETRY_ERRNOS:
            return b""
        raise serial.SerialException(f"read failed: {error}") from error
    if not data:
        raise serial.SerialException(
            "device reports readiness to read but returned no data "
            "(device disconnected or multiple access on port?)"
        )
    return data


class TransportListener(Protocol):
    """What the link implements; every method runs on the I/O thread."""

    def transport_opened(self, reopened: bool) -> None: ...

    def transport_lost(self, error: Exception) -> None: ...

    def transport_failed(self, error: Exception) -> None:
        """The I/O thread failed other than by its port (a bug) and is ending: report it."""
        ...

    def transport_received(self, items: list[Packet | BadFrame]) -> None: ...

    def transport_tick(self, now: float) -> float:
        """Run the timers; return when they next need to run (the thread wakes by then)."""
        ...


@dataclass(frozen=True, slots=True)
class FrameRecord:
    """One frame seen by the transport, for the recent-frames ring buffer and monitors."""

    t: float  # time.monotonic()
    direction: str  # "tx" or "rx"
    item: Packet | BadFrame

    def describe(self) -> str:
        """A short human-readable line (the payload as hex)."""
        if isinstance(self.item, BadFrame):
            return f"{self.t:.3f} {self.direction} BAD({self.item.reason}) {self.item.raw.hex()}"
        p = self.item
        return f"{self.t:.3f} {self.direction} {p.type.name} seq={p.seq} {p.payload.hex()}"


#: A monitor sees every frame in both directions, on the I/O thread, as the frame
#: passes: it must be quick, and it cannot make a blocking board call (that raises
#: ReentrantCallError: it would wait for an Ack that only this thread can read).
FrameMonitor = Callable[[FrameRecord], None]


@dataclass(slots=True)
class _Outgoing:
    ptype: PacketType
    payload: bytes
    reset_seq: bool  # RESET/RESET_ACK: sent with SEQ 0, the counter is 1 afterwards


class Transport:
    """A pyserial port driven by one I/O thread; see the module docstring."""

    def __init__(self, url: str, *, baudrate: int = 115200, name: str | None = None) -> None:
        self.url = url
        self.baudrate = baudrate
        self.name = name or url
        self._port: Any = None
        #: The port's file descriptor (None: it has none, or no port is open), and whether
        #: it is a plain POSIX serial port or pty (pyserial's own class, not a subclass),
        #: which the I/O thread then reads and writes with os.read / os.write itself.
        self._fd: int | None = None
        self._raw = False
        self._listener: TransportListener | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._qlock = threading.Lock()
        #: Held around taking a packet, giving it its SEQ and writing it, and around
        #: opening, closing and re-rating the port (module docstring: a caller's own write).
        self._wlock = threading.Lock()
        #: A caller's write that failed other than by a timeout, or a re-rate that failed:
        #: the I/O thread loses the port at its next pass.
        self._port_failure: Exception | None = None
        #: Records of frames written (by any thread, under ``_wlock``), in that order,
        #: that the I/O thread has still to show to the monitors.
        self._unshown: collections.deque[FrameRecord] = collections.deque()
        self._control: collections.deque[_Outgoing] = collections.deque()
        self._data: collections.deque[_Outgoing] = collections.deque()
        self._wake_r, self._wake_w = os.pipe()
        # Held while the wake-up pipe is written or closed: a write to a closed
        # descriptor's number would go to whatever file reused it.
        self._wake_lock = threading.Lock()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._decoder = StreamDecoder()
        self._tx_seq = 0
        self._monitors: list[FrameMonitor] = []
        self._recent: collections.deque[FrameRecord] = collections.deque(maxlen=RECENT_FRAMES)
        self.connected = False
        #: When the listener's timers next need a tick (time.monotonic()): the
        #: thread never sleeps past it, so a timeout fires on time, not up to TICK late.
        self._next_tick = 0.0
        #: Whether the last read was woken by the wake-up pipe (something was queued).
        self._woken = False
        self.last_error: Exception | None = None
        # Counters (read without a lock: single ints written by the I/O thread).
        self.rx_bytes = 0
        self.tx_bytes = 0
        self.tx_packets = 0
        #: Packets written by the thread that sent them, not the I/O thread (a counter).
        self.direct_writes = 0
        self.write_errors = 0
        self.opens = 0
        #: Bytes received since the port was last opened, and the first RX_HEAD of them.
        self.rx_since_open = 0
        self.rx_head = b""

    # --- life cycle ---------------------------------------------------------

    def start(self, listener: TransportListener) -> None:
        """Open the port (raising :class:`TransportError` if it cannot) and start the thread."""
        if self._thread is not None:
            raise RuntimeError("transport already started")
        self._listener = listener
        self._open()  # the first failure is the caller's: a wrong path must not retry forever
        self._thread = threading.Thread(
            target=self._run, name=f"protoduino-io[{self.name}]", daemon=True
        )
        self._thread.start()

    def close(self, timeout: float = 2.0) -> None:
        """Stop the thread and close the port; idempotent."""
        self._stop.set()
        self._wake()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
            if thread.is_alive():  # pragma: no cover - a wedged driver
                log.error("%s: I/O thread did not stop within %.1f s", self.name, timeout)
        if thread is None or not thread.is_alive():
            self._close_port()
            self._close_wake_pipe()

    @property
    def closed(self) -> bool:
        return self._stop.is_set()

    def on_io_thread(self) -> bool:
        """Is the caller this transport's I/O thread (a monitor, or a listener callback)?"""
        return self._thread is threading.current_thread()

    # --- sending ------------------------------------------------------------

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None:
        """Queue one packet; CONTROL packets go ahead of anything queued.

        A COMMAND from a thread other than the I/O thread, onto a plain POSIX port with
        nothing queued, is written here and now (module docstring).
        """
        item = _Outgoing(ptype, payload, reset_seq)
        io = self._thread is threading.current_thread()
        if self._raw and not io and ptype is PacketType.COMMAND and self._thread is not None:
            with self._wlock:
                # Under the lock: the port may have closed, or something been queued,
                # since; a queued packet goes first, so this one queues behind it.
                if self._raw and not self._control and not self._data and not self.closed:
                    self._direct_write(item)
                    return
        with self._qlock:
            (self._control if ptype is PacketType.CONTROL else self._data).append(item)
        if not io:
            # The I/O thread itself (the link's timers, an Ack that lets the next call of
            # the window go, a monitor) needs no wake-up: every pass of its loop writes
            # what is queued before it sleeps, and a wake-up would cost a pass of its own.
            self._wake()

    def clear_queue(self) -> None:
        """Drop every queued packet (the link was reset; they are stale)."""
        with self._qlock:
            self._control.clear()
            self._data.clear()

    def add_monitor(self, monitor: FrameMonitor) -> None:
        with self._wlock:  # a frame being written is shown to it, or not, whole
            self._monitors.append(monitor)

    def remove_monitor(self, monitor: FrameMonitor) -> None:
        with contextlib.suppress(ValueError):
            self._monitors.remove(monitor)

    def recent_frames(self) -> tuple[str, ...]:
        """The last frames in both directions, oldest first, as readable lines."""
        return tuple(r.describe() for r in list(self._recent))

    def set_baudrate(self, rate: int) -> None:
        """The line's rate from now on (docs/protocol.md 5, *Line rate*); on the I/O thread.

        It applies to the bytes written after it: the link changes it only between
        frames, once what it waited for has arrived. A port reopened later opens at it.
        A port that refuses the change (a stalled rfc2217:// server does not acknowledge
        it; a USB adapter unplugged meanwhile) is lost, as a failed write is: the I/O
        thread closes it at its next pass and reopens it at ``rate``, and the link
        handshakes again there (issue 32: the exception once ended the I/O thread).
        """
        with self._wlock:  # never in the middle of a caller's frame
            self.baudrate = rate
            if self._port is not None:
                try:
                    self._port.baudrate = rate
                except (serial.SerialException, OSError) as error:
                    log.warning("%s: setting %d baud failed: %s", self.name, rate, error)
                    self._port_failure = error

    @property
    def tx_seq(self) -> int:
        return self._tx_seq

    @property
    def decoder_counts(self) -> dict[str, int]:
        return dict(self._decoder.counts)

    # --- the I/O thread -----------------------------------------------------

    def _wake(self) -> None:
        with self._wake_lock:
            if self._wake_w >= 0:
                with contextlib.suppress(OSError):  # pipe full: the thread is awake anyway
                    os.write(self._wake_w, b"x")

    def _close_wake_pipe(self) -> None:
        with self._wake_lock:
            fds = (self._wake_r, self._wake_w)
            self._wake_r = self._wake_w = -1
        for fd in fds:
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)

    def _open(self) -> None:
        port = open_port(self.url, baudrate=self.baudrate)
        try:
            with self._wlock:
                self._port = port
                self._fd = self._fileno()
                self._raw = self._fd is not None and type(self._port) is _PosixSerial
                # docs/protocol.md 2: a lone 0x00 flushes the receiver's half-filled buffer.
                self._write_raw(DELIMITER)
        except Exception as error:  # any URL handler's failure, in the ProtoduinoError tree
            self._close_port()
            raise TransportError(f"cannot open {self.url}: {error}") from error
        self._decoder.reset()
        self.rx_since_open = 0
        self.rx_head = b""
        self.connected = True
        self.opens += 1

    def _close_port(self) -> None:
        with self._wlock:  # no caller is writing to the descriptor as it closes
            port, self._port = self._port, None
            self._fd, self._raw = None, False
            self.connected = False
            self._port_failure = None  # the port it was about is gone
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()

    def _fileno(self) -> int | None:
        try:
            fd = self._port.fileno()
        except Exception:  # loop://, rfc2217:// and others have none
            return None
        return fd if isinstance(fd, int) and fd >= 0 else None

    def _run(self) -> None:
        listener = self._listener
        assert listener is not None
        reopen_delay = REOPEN_FIRST
        next_reopen = 0.0
        try:
            listener.transport_opened(False)
            while not self._stop.is_set():
                now = time.monotonic()
                if self._port is None:
                    if now >= next_reopen:
                        try:
                            self._open()
                        except TransportError as error:
                            log.debug("%s: reopen failed: %s", self.name, error)
                            next_reopen = now + reopen_delay
                            reopen_delay = min(reopen_delay * 2, REOPEN_MAX)
                        else:
                            log.warning("%s: port reopened", self.name)
                            reopen_delay = REOPEN_FIRST
                            listener.transport_opened(True)
                            continue
                    listener.transport_tick(now)
                    self._stop.wait(min(TICK * 5, max(0.0, next_reopen - time.monotonic())))
                    continue
                try:
                    self._pass(listener)
                except (serial.SerialException, OSError) as error:
                    # The port's failure wherever it surfaced: a read, a write (the I/O
                    # thread's or a caller's), or a re-rate the link asked for in a timer
                    # (a stalled rfc2217:// server refuses it: issue 32).
                    self._lost(error)
                    next_reopen = time.monotonic() + REOPEN_FIRST
                    reopen_delay = REOPEN_FIRST * 2
        except Exception as error:  # a bug above: reported, never a silent death
            log.exception("%s: I/O thread failed", self.name)
            self.last_error = TransportError(f"{self.name}: I/O thread failed: {error!r}")
            try:
                listener.transport_failed(self.last_error)
            except Exception:
                log.exception("%s: reporting the I/O thread's failure failed", self.name)
        finally:
            self._close_port()
            if self._stop.is_set():
                # Closed from this thread (a frame monitor, a listener): close()
                # could not wait for the thread to end, so the thread cleans up.
                self._close_wake_pipe()

    def _pass(self, listener: TransportListener) -> None:
        """One pass of the I/O thread with the port open: write, read, hand over, tick.

        A failure of the port raises (SerialException, OSError): the caller loses it.
        """
        if self._port_failure is not None:  # a caller's write or a re-rate failed
            raise self._port_failure
        self._flush_writes()
        data = self._read()
        # A packet queued while select slept (its wake-up ended the sleep) leaves now,
        # not after the timer tick below: that tick is on no request's critical path.
        # The monitors see every frame written so far (a caller's too) before what was
        # just read.
        self._flush_writes()
        items = None
        if data:
            self.rx_bytes += len(data)
            if len(self.rx_head) < RX_HEAD:
                self.rx_head += data[: RX_HEAD - len(self.rx_head)]
            self.rx_since_open += len(data)
            items = self._decoder.feed(data)
            if items:
                # Dated and kept as read, shown to the monitors once the layers above
                # have them: a monitor (a capture writing its line) is not on an Ack's
                # way to its caller. What the listener has written in answer is shown
                # after them (the next pass), as it went out after.
                records = [self._record("rx", item) for item in items]
                listener.transport_received(items)
                for rec in records:
                    self._show(rec)
        now = time.monotonic()
        # Bytes of a frame not complete yet (a slow line delivers an Ack in pieces)
        # change nothing the timers depend on: their tick waits for the frame, a
        # wake-up, a timeout or its due time, whichever comes first.
        if items or not data or self._woken or now >= self._next_tick:
            self._next_tick = listener.transport_tick(now)

    def _lost(self, error: Exception) -> None:
        log.warning("%s: port lost: %s", self.name, error)
        self.last_error = TransportError(f"port {self.url} lost ({error}); reopening")
        # The link goes down first, then the port reads as closed: a caller who sees
        # `connected` False and submits a command must find the link down too (its call
        # then waits for the next session). In the other order a command submitted in
        # between was handed to a closed port's queue, counted as sent, and failed as
        # possibly run once the next handshake found the outputs lost.
        assert self._listener is not None
        self._listener.transport_lost(self.last_error)
        self._close_port()
        self.clear_queue()

    def _sleep_limit(self) -> float:
        """How long a read may wait: TICK at most, and not past the next timer."""
        return min(TICK, max(0.0, self._next_tick - time.monotonic()))

    def _read(self) -> bytes:
        fd = self._fd
        if fd is None:
            if not self.url.lower().startswith(REMOTE_URLS):
                self._port.timeout = min(TICK / 2, self._sleep_limit())
                return bytes(self._port.read(READ_CHUNK))
            if self._port.timeout != TICK / 2:
                # Set once: pyserial reconfigures the port at every assignment, and on
                # rfc2217:// that is a round trip of subnegotiations to the server (it made
                # every read take 160 ms); the network's latency dwarfs the finer timer here.
                self._port.timeout = TICK / 2
            # rfc2217's read(n) waits out its whole timeout unless n bytes came: ask for
            # what is queued, or for one byte, returned the moment it arrives.
            return bytes(self._port.read(self._port.in_waiting or 1))
        try:
            ready, _, _ = select.select([fd, self._wake_r], [], [], self._sleep_limit())
        except ValueError as error:  # fd closed under us
            raise OSError(str(error)) from error
        self._woken = self._wake_r in ready
        if self._woken:
            with contextlib.suppress(OSError):
                os.read(self._wake_r, 4096)
        if fd in ready:
            if self._raw:
                return _read_fd(fd)
            # timeout=0: one os.read of whatever is there, never byte by byte;
            # a vanished device raises SerialException here.
            return bytes(self._port.read(READ_CHUNK))
        return b""

    def _take(self) -> list[_Outgoing]:
        """The packets to write next, out of their queues (CONTROL first): every one queued
        on a plain POSIX port (they leave in one write: :meth:`_write_items`), else one.

        Taken before they are written: a write that times out drops the packet it cut,
        and any other failure loses the port, whose queues are then cleared (:meth:`_lost`).
        """
        with self._qlock:
            if self._raw:
                items = [*self._control, *self._data]
                self._control.clear()
                self._data.clear()
                return items
            if self._control:
                return [self._control.popleft()]
            if self._data:
                return [self._data.popleft()]
            return []

    def _put_back(self, items: list[_Outgoing]) -> None:
        """Return packets taken and not written to the front of their queues, in order."""
        with self._qlock:
            for item in reversed(items):
                (self._control if item.ptype is PacketType.CONTROL else self._data).appendleft(item)

    def _flush_writes(self) -> None:
        # The deques are looked at without the lock first (their length is atomic): most
        # passes of the loop have nothing to write.
        while self._control or self._data:
            with self._wlock:  # taken and written as one: a caller's write goes after it
                items = self._take()
                if not items or not self._write_items(items):
                    break  # a write timed out: what is left goes at the next pass
        self._show_written()

    def _show_written(self) -> None:
        """Show the monitors the frames written since last time, in the order written
        (the I/O thread; the monitors run with no lock held: they may send, or go)."""
        if not self._monitors:
            self._unshown.clear()  # nobody to show them to
            return
        with self._wlock:  # a caller between its write and its record: it finishes first
            records = list(self._unshown)
            self._unshown.clear()
        for rec in records:
            self._show(rec)

    def _direct_write(self, item: _Outgoing) -> None:
        """Write a caller's COMMAND on its own thread (``_wlock`` held; module docstring)."""
        try:
            self._write_items([item])  # the I/O thread shows it to the monitors
        except (serial.SerialException, OSError) as error:
            # Lost with the port, as the I/O thread's own failed write would be: it
            # loses the port (the link goes down there, on its thread), woken for it.
            self._port_failure = error
            self._wake()
            return
        self.direct_writes += 1

    def _write_items(self, items: list[_Outgoing]) -> bool:
        """Give each of ``items`` its SEQ and write them as one (``_wlock`` held), keeping
        their records in the order written; False if the write timed out.

        Packets queued together leave in one write (issue 35: each write is a system call
        that also wakes the reader; flat out at window 4 on the simulated board the I/O
        thread made about one write per pass, 1,422 for 3,000 commands, not one per
        command; the host CPU per command moved less than the runs' spread). On a plain
        POSIX port,
        ``os.write`` says how many bytes the driver took: the frames it took whole are
        written; the one it cut is finished through pyserial, which waits for room and
        gives up after WRITE_TIMEOUT; the rest go back to the front of their queues, for
        the next write. Any other port takes one packet at a time (:meth:`_take`).

        A write that times out drops the packet it cut (the layers above retransmit) and
        that packet's SEQ goes to the next one, as docs/protocol.md 6 asks; any other
        failure raises.
        """
        seq = self._tx_seq
        seqs: list[int] = []
        frames: list[bytes] = []
        for item in items:
            sent = 0 if item.reset_seq else seq
            frame = frame_packet(item.ptype, sent, item.payload)
            # A RESET flushes the device's receiver first, and takes a silent board out of
            # a bootloader that waits for bytes (BOOTLOADER_LEAVE).
            if item.reset_seq:
                leave = BOOTLOADER_LEAVE if self.rx_since_open == 0 else b""
                frame = leave + DELIMITER + frame
            frames.append(frame)
            seqs.append(sent)
            seq = 1 if item.reset_seq else (sent + 1) & 0xFF
        taken = self._write_some(frames[0] if len(frames) == 1 else b"".join(frames))
        whole = end = 0  # frames the driver took whole, and their bytes
        for frame in frames:
            if end + len(frame) > taken:
                break
            end += len(frame)
            whole += 1
        timed_out = False
        if whole < len(frames):
            try:
                self._port.write(frames[whole][taken - end :])
            except serial.SerialTimeoutException:
                self.write_errors += 1
                log.warning("%s: write timed out; packet dropped", self.name)
                timed_out = True
            else:
                taken = end = end + len(frames[whole])
                whole += 1
            self._put_back(items[whole + timed_out :])
        self.tx_bytes += taken
        for item, sent in zip(items[:whole], seqs, strict=False):
            self._tx_seq = 1 if item.reset_seq else (sent + 1) & 0xFF
            self.tx_packets += 1
            rec = FrameRecord(time.monotonic(), "tx", Packet(item.ptype, sent, item.payload))
            self._recent.append(rec)
            if self._monitors:
                self._unshown.append(rec)
        return not timed_out

    def _write_some(self, data: bytes) -> int:
        """One ``os.write`` of ``data`` to a plain POSIX port: the bytes the driver took (0
        when it has no room); on any other port nothing is written (0): pyserial writes all."""
        fd = self._fd
        if not self._raw or fd is None:
            return 0
        try:
            return os.write(fd, data)
        except OSError as error:
            if error.errno not in _RETRY_ERRNOS:
                raise serial.SerialException(f"write failed: {error}") from error
            return 0

    def _write_raw(self, data: bytes) -> None:
        # What pyserial's write does first, without its select for room afterwards (one
        # syscall, not two): the rest, if the driver took only part, goes through pyserial,
        # which waits for room and gives up after WRITE_TIMEOUT.
        taken = self._write_some(data)
        if taken < len(data):
            self._port.write(data[taken:])
        self.tx_bytes += len(data)

    def _record(self, direction: str, item: Packet | BadFrame) -> FrameRecord:
        rec = FrameRecord(time.monotonic(), direction, item)
        self._recent.append(rec)
        return rec

    def _show(self, rec: FrameRecord) -> None:
        """Hand ``rec`` to the monitors (the I/O thread, no lock held)."""
        if not self._monitors:
            return
        for monitor in list(self._monitors):
            try:
                monitor(rec)
            except Exception:
                log.exception("%s: frame monitor failed", self.name)
