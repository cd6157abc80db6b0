"""pyserial handler for ``faulty://INNER?params``: see :mod:`protoduino_dev.faults`."""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from typing import TYPE_CHECKING, Any

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

if TYPE_CHECKING:
    from _typeshed import ReadableBuffer

from ..faults import Cut, FaultConfig, FaultModel, parse_url, register

#: Longest time one read of the inner port blocks.
POLL = 0.02
#: Writes remembered with their time (:meth:`Serial.recent_writes`).
WRITE_LOG = 4096


class Serial(SerialBase):
    """A serial port whose bytes are damaged on the way, reproducibly."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._inner: serial.Serial | None = None
        self._cfg = FaultConfig()
        self._rx: FaultModel | None = None
        self._tx: FaultModel | None = None
        self._cut: Cut | None = None
        self._pending = bytearray()
        self._delayed: deque[tuple[float, bytes]] = deque()
        self._tx_delayed: deque[tuple[float, bytes]] = deque()
        self._paused = False
        # hold(): bytes kept back, in order, until release() (a stalled network).
        self._hold_tx = False
        self._hold_rx = False
        self._held_tx: list[bytes] = []
        self._held_rx = bytearray()
        self._lock = threading.Lock()
        self._tx_lock = threading.Lock()
        self.stats: Counter[str] = Counter()
        # (time.monotonic() as write() was entered, the bytes as given) for the last
        # WRITE_LOG writes: when each frame left the caller, whatever the scheduler did
        # between its write and the caller's own record of it. See recent_writes().
        self._writes: deque[tuple[float, bytes]] = deque(maxlen=WRITE_LOG)
        self._writes_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    # --- pyserial plumbing ---------------------------------------------------
    def open(self) -> None:
        if self.port is None:
            raise SerialException("port must be configured before it can be used")
        if self.is_open:
            raise SerialException("port already open")
        try:
            inner_url, cfg = parse_url(self.port)
        except ValueError as error:
            raise SerialException(str(error)) from error
        self._cfg = cfg
        self.stats = Counter()
        self._rx = FaultModel(cfg, cfg.seed * 2 + 1, self.stats) if cfg.applies_to("rx") else None
        self._tx = FaultModel(cfg, cfg.seed * 2, self.stats) if cfg.applies_to("tx") else None
        self._cut = Cut(cfg)
        self._paused = bool(cfg.paused)
        self._inner = serial.serial_for_url(
            inner_url,
            baudrate=self.baudrate,
            timeout=self._poll_interval(),
            write_timeout=self.write_timeout,
            exclusive=self.exclusive,  # the wrapped port is locked as the caller asked
        )
        self.is_open = True
        register(cfg.name, self)

    def close(self) -> None:
        self.is_open = False
        if self._inner is not None:
            self._inner.close()
            self._inner = None

    def _reconfigure_port(self) -> None:
        if self._inner is not None:
            self._inner.timeout = self._poll_interval()
            self._inner.write_timeout = self.write_timeout
            # The rate reaches the wrapped port: a board that checks rates (--line-check)
            # carries bytes only when both ends' agree, under the faults as without them.
            if self._inner.baudrate != self.baudrate:
                self._inner.baudrate = self.baudrate

    def _poll_interval(self) -> float:
        return POLL if self.timeout is None else min(self.timeout, POLL)

    def from_url(self, url: str) -> str:
        return url

    def _require(self) -> serial.Serial:
        if not self.is_open or self._inner is None:
            raise PortNotOpenError()
        return self._inner

    # --- faults ---------------------------------------------------------------
    def cut(self, seconds: float) -> None:
        """Cut the line in both directions for ``seconds``, from now."""
        if self._cut is None:
            raise PortNotOpenError()
        self._cut.cut(seconds)

    def recent_writes(self) -> list[tuple[float, bytes]]:
        """(time write() was entered, bytes) for the recent writes, oldest first.

        A copy taken under a lock: the I/O thread may be writing meanwhile.
        """
        with self._writes_lock:
            return list(self._writes)

    def pause(self) -> None:
        """Stop injecting random faults (cuts still apply; :meth:`heal` cancels them)."""
        self._paused = True

    def resume(self) -> None:
        """Inject faults again, where the seeded streams left off."""
        self._paused = False

    def heal(self) -> None:
        """Faults off for good: paused and every cut cancelled; delayed bytes still arrive."""
        self._paused = True
        if self._cut is not None:
            self._cut.cancel()

    def hold(self, direction: str = "both") -> None:
        """Keep every byte crossing the line in ``direction`` (tx, rx or both) until
        :meth:`release`: nothing is lost, everything arrives late and in order, as
        over a TCP connection whose far end (a ser2net, a Wi-Fi link) stalled."""
        if direction not in ("tx", "rx", "both"):
            raise ValueError(f"direction must be tx, rx or both, not {direction!r}")
        if direction in ("tx", "both"):
            with self._tx_lock:
                self._hold_tx = True
        if direction in ("rx", "both"):
            with self._lock:
                self._hold_rx = True

    def release(self) -> None:
        """Deliver what :meth:`hold` kept, in order, and stop holding.

        The bytes held for the device go out in one write, as a stalled link's backlog
        arrives in one burst: frames written apart while held reach the device together
        (the soak's last Ping arrives between the two digital edges written around it).
        """
        with self._tx_lock:
            self._hold_tx = False
            if self._held_tx:
                self._tx_delayed.append((time.monotonic(), b"".join(self._held_tx)))
            self.stats["held_tx_bytes"] += sum(len(c) for c in self._held_tx)
            self._held_tx.clear()
        with self._lock:
            self._hold_rx = False
            self.stats["held_rx_bytes"] += len(self._held_rx)
            if self._delayed:
                self._delayed.append((self._delayed[-1][0], bytes(self._held_rx)))
            else:
                self._pending += self._held_rx
            self._held_rx.clear()

    @property
    def in_waiting(self) -> int:
        inner = self._require()
        return len(self._pending) + int(inner.in_waiting)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, after faults; b"" once the timeout passes."""
        inner = self._require()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        while True:
            with self._lock:
                self._release_delayed()
                if self._pending:
                    out = bytes(self._pending[:size])
                    del self._pending[:size]
                    return out
            self._flush_tx()
            if deadline is not None and time.monotonic() >= deadline:
                return b""
            # The inner port polls (POLL seconds at most) so delayed bytes and
            # the caller's own timeout are honoured.
            data = inner.read(max(1, min(size, int(inner.in_waiting))))
            if data:
                self._receive(data)

    def _receive(self, data: bytes) -> None:
        assert self._cut is not None
        if self._cut.active():
            self.stats["cut_bytes"] += len(data)
            return
        if self._rx is not None and not self._paused:
            data = self._rx.apply(data)
        with self._lock:
            if self._hold_rx:
                self._held_rx += data
                return
            delay = self._cfg.delay > 0 and self._cfg.applies_to("rx") and not self._paused
            if delay:
                self.stats["delayed_bytes"] += len(data)
            if delay or self._delayed:
                # Bytes never overtake delayed ones, even once the faults pause.
                due = time.monotonic() + (self._cfg.delay / 1000 if delay else 0.0)
                if self._delayed:
                    due = max(due, self._delayed[-1][0])
                self._delayed.append((due, data))
            else:
                self._pending += data

    def _release_delayed(self) -> None:
        now = time.monotonic()
        while self._delayed and self._delayed[0][0] <= now:
            self._pending += self._delayed.popleft()[1]

    def write(self, data: ReadableBuffer, /) -> int:
        """Accept every byte at once; damaged, delayed or cut on the way (never blocks longer)."""
        inner = self._require()
        raw = bytes(data)
        with self._writes_lock:
            self._writes.append((time.monotonic(), raw))
        assert self._cut is not None
        if self._cut.active():
            self.stats["cut_bytes"] += len(raw)
            return len(raw)
        active = not self._paused
        out = self._tx.apply(raw) if self._tx is not None and active else raw
        with self._tx_lock:
            if self._hold_tx:
                self._held_tx.append(out)
                return len(raw)
            if self._tx_delayed and not (self._cfg.delay > 0 and active):
                # Released or delayed bytes go first; written under the lock so that
                # nothing overtakes them.
                while self._tx_delayed:
                    chunk = self._tx_delayed.popleft()[1]
                    if chunk:
                        inner.write(chunk)
                if out:
                    inner.write(out)
                return len(raw)
        if self._cfg.delay > 0 and self._cfg.applies_to("tx") and active:
            # Latency, not a slower line: the bytes leave later, in order, from
            # the next read or write (the caller polls reads continuously).
            self.stats["delayed_bytes"] += len(out)
            with self._tx_lock:
                self._tx_delayed.append((time.monotonic() + self._cfg.delay / 1000, out))
            self._flush_tx()
            return len(raw)
        self._flush_tx(everything=True)
        if out:
            inner.write(out)
        return len(raw)

    def _flush_tx(self, *, everything: bool = False) -> None:
        """Write the delayed bytes that are due (all of them to keep the order when asked)."""
        if not self._tx_delayed:
            return
        inner = self._require()
        now = time.monotonic()
        with self._tx_lock:
            if self._hold_tx:
                return
            while self._tx_delayed and (everything or self._tx_delayed[0][0] <= now):
                _, chunk = self._tx_delayed.popleft()
                if chunk:
                    inner.write(chunk)

    def flush(self) -> None:
        self._require().flush()

    def reset_input_buffer(self) -> None:
        inner = self._require()
        with self._lock:
            self._pending.clear()
            self._delayed.clear()
        inner.reset_input_buffer()

    def reset_output_buffer(self) -> None:
        inner = self._require()
        with self._tx_lock:
            self._tx_delayed.clear()
        inner.reset_output_buffer()

    def cancel_read(self) -> None:
        inner = self._inner
        if inner is not None and hasattr(inner, "cancel_read"):
            inner.cancel_read()
