"""Seeded, repeatable line faults for testing the link: the ``faulty://`` URL.

``faulty://<inner-url>?ber=1e-3&seed=7`` opens ``<inner-url>`` (any pyserial URL
or device path) and damages the bytes crossing it, in both directions unless
``dir=tx`` or ``dir=rx`` says otherwise. Everything is driven by
``random.Random(seed)`` (one stream per direction), so a scenario replays
byte for byte. Parameters (all optional, probabilities in 0..1):

========  ============================================================
ber       probability that any single bit is flipped
burst     probability, per byte, that an error burst starts there
burstlen  length in bits of a burst (first and last bit flipped), <= 16 by default
drop      probability that a byte is dropped
garbage   probability, per frame, that random bytes (1..garbagelen) are inserted before it
dup       probability that a whole frame (up to its 0x00) is sent twice
delay     added latency in ms, per direction (bytes arrive that much later, in order;
          the caller is never blocked)
cutat     seconds after open at which the line is cut (both directions lose everything)
cutfor    seconds the cut lasts (default 1)
seed      the seed (default 0)
dir       both | tx | rx (default both)
paused    1: open with the random faults paused until ``port.resume()`` (a clean setup)
name      a name to find the open port by, from code that did not open it: :func:`line`
========  ============================================================

From code, the port (``line(name)`` for one opened elsewhere, e.g. inside a
``Board``) can be cut (``port.cut(seconds)``), paused and resumed
(``port.pause()``, ``port.resume()``), healed for good (``port.heal()``:
faults off, cuts cancelled), and held (``port.hold("tx"|"rx"|"both")``: every
byte kept back until ``port.release()`` delivers them all, late, in order and in one
write, as a stalled ser2net or Wi-Fi link does to a TCP connection). ``port.stats``
counts what was injected. The *device reset* fault is not a line fault: the board harness
(``SimBoard.reboot()``) provides it. The line rate the caller sets reaches the inner port,
so a simulated board started with ``--line-check`` (as the soak's are) carries bytes only
while both ends run at the same rate, as a UART does: a device that resets goes back to its
opening rate, and the host hears nothing until it follows.

The inner URL may not carry a query string of its own: the last ``?`` starts
the fault parameters.
"""

from __future__ import annotations

import random
import threading
import time
import weakref
from collections import Counter
from dataclasses import dataclass, fields
from typing import Protocol
from urllib.parse import parse_qsl

SCHEME = "faulty://"


@dataclass(frozen=True)
class FaultConfig:
    ber: float = 0.0
    burst: float = 0.0
    burstlen: int = 16
    drop: float = 0.0
    garbage: float = 0.0
    garbagelen: int = 8
    dup: float = 0.0
    delay: float = 0.0  # milliseconds
    cutat: float | None = None
    cutfor: float = 1.0
    seed: int = 0
    dir: str = "both"
    paused: int = 0
    name: str = ""

    def applies_to(self, direction: str) -> bool:
        return self.dir in ("both", direction)


def parse_url(url: str) -> tuple[str, FaultConfig]:
    """Split ``faulty://INNER?params`` into the inner URL and its fault config.

    Raises ValueError with a message naming the bad parameter.
    """
    if not url.lower().startswith(SCHEME):
        raise ValueError(f"not a faulty:// URL: {url!r}")
    rest = url[len(SCHEME) :]
    inner, _, query = rest.rpartition("?") if "?" in rest else (rest, "", "")
    if not inner:
        raise ValueError("faulty:// needs an inner URL, e.g. faulty:///dev/ttyACM0?ber=1e-3")
    known = {f.name: f for f in fields(FaultConfig)}
    values: dict[str, object] = {}
    for key, raw in parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query)):
        if key not in known:
            raise ValueError(f"unknown faulty:// parameter {key!r}; known: {', '.join(known)}")
        default = known[key].default
        try:
            if key == "dir":
                if raw not in ("both", "tx", "rx"):
                    raise ValueError
                values[key] = raw
            elif key == "name":
                values[key] = raw
            elif isinstance(default, int) and not isinstance(default, bool):
                values[key] = int(raw)
            else:
                values[key] = float(raw)
        except ValueError:
            raise ValueError(f"bad value for faulty:// parameter {key}: {raw!r}") from None
    cfg = FaultConfig(**values)  # type: ignore[arg-type]
    for name in ("ber", "burst", "drop", "garbage", "dup"):
        p = getattr(cfg, name)
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"faulty:// parameter {name} must be a probability, not {p}")
    if not 1 <= cfg.burstlen <= 64 or cfg.garbagelen < 1:
        raise ValueError("faulty:// burstlen must be 1..64 and garbagelen >= 1")
    if cfg.delay < 0 or cfg.cutfor < 0:
        raise ValueError("faulty:// delay and cutfor must not be negative")
    return inner, cfg


class FaultyLine(Protocol):
    """What an open ``faulty://`` port offers to code that drives a scenario."""

    stats: Counter[str]

    def recent_writes(self) -> list[tuple[float, bytes]]: ...

    def cut(self, seconds: float) -> None: ...

    def pause(self) -> None: ...

    def resume(self) -> None: ...

    def heal(self) -> None: ...

    def hold(self, direction: str = "both") -> None: ...

    def release(self) -> None: ...


_lines: weakref.WeakValueDictionary[str, FaultyLine] = weakref.WeakValueDictionary()
_lines_lock = threading.Lock()


def register(name: str, port: FaultyLine) -> None:
    """Make ``port`` findable by :func:`line` (the latest port opened under a name wins)."""
    if name:
        with _lines_lock:
            _lines[name] = port


def line(name: str) -> FaultyLine | None:
    """The open ``faulty://`` port whose URL said ``name=NAME``, if it is still alive."""
    with _lines_lock:
        return _lines.get(name)


class FaultModel:
    """Damages one direction of a byte stream; pure apart from its RNG and counters.

    Frame-aware faults (garbage, dup) look at 0x00 delimiters, so the model keeps
    the bytes of the frame in progress until its delimiter passes.
    """

    def __init__(self, cfg: FaultConfig, seed: int, stats: Counter[str]) -> None:
        self.cfg = cfg
        self.rng = random.Random(seed)
        self.stats = stats
        self._frame = bytearray()
        self._bits_to_next_error = self._draw_gap()

    def _draw_gap(self) -> float:
        """Bits until the next random bit error (geometric, via the exponential)."""
        if self.cfg.ber <= 0.0:
            return float("inf")
        return self.rng.expovariate(self.cfg.ber)

    def apply(self, data: bytes) -> bytes:
        if not data:
            return b""
        buf = bytearray(data)
        self._flip_random_bits(buf)
        out = bytearray()
        cfg, rng = self.cfg, self.rng
        for byte in self._bursts(buf):
            if cfg.drop and rng.random() < cfg.drop:
                self.stats["dropped_bytes"] += 1
                continue
            if not self._frame and cfg.garbage and rng.random() < cfg.garbage:
                junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, cfg.garbagelen)))
                out += junk
                self.stats["garbage_bytes"] += len(junk)
            self._frame.append(byte)
            out.append(byte)
            if byte == 0:
                if cfg.dup and len(self._frame) > 1 and rng.random() < cfg.dup:
                    out += self._frame
                    self.stats["duplicated_frames"] += 1
                self._frame.clear()
        return bytes(out)

    def _flip_random_bits(self, buf: bytearray) -> None:
        nbits = len(buf) * 8
        pos = self._bits_to_next_error
        while pos < nbits:
            bit = int(pos)
            buf[bit // 8] ^= 0x80 >> (bit % 8)
            self.stats["flipped_bits"] += 1
            pos += 1 + self._draw_gap()
        self._bits_to_next_error = pos - nbits

    def _bursts(self, buf: bytearray) -> bytearray:
        cfg, rng = self.cfg, self.rng
        if not cfg.burst:
            return buf
        i = 0
        while i < len(buf):
            if rng.random() < cfg.burst:
                length = max(1, cfg.burstlen)
                pattern = 1 | (1 << (length - 1)) | rng.getrandbits(length)
                start = i * 8 + rng.randrange(8)
                for k in range(length):
                    bit = start + k
                    if pattern >> k & 1 and bit // 8 < len(buf):
                        buf[bit // 8] ^= 0x80 >> (bit % 8)
                self.stats["bursts"] += 1
                i += (length + 7) // 8
            i += 1
        return buf


class Cut:
    """When the line is cut: a schedule from the URL plus cuts ordered from code."""

    def __init__(self, cfg: FaultConfig) -> None:
        self._opened = time.monotonic()
        self._windows: list[tuple[float, float]] = []
        if cfg.cutat is not None:
            start = self._opened + cfg.cutat
            self._windows.append((start, start + cfg.cutfor))

    def cut(self, seconds: float) -> None:
        now = time.monotonic()
        self._windows.append((now, now + seconds))

    def cancel(self) -> None:
        self._windows.clear()

    def active(self) -> bool:
        now = time.monotonic()
        return any(a <= now < b for a, b in self._windows)
