"""Seeded fault scenarios on a simulated board, judged against the board's own trace.

A :class:`Scenario` opens a :class:`~protoduino.simboard.SimBoard` (either
backend) with a trace file, opens a :class:`~protoduino.Board` over
``faulty://<port>?...`` and streams commands at it from one thread per output,
with device resets (``SimBoard.reboot()``) and line cuts sprinkled in. Every
value is chosen so that its effect is recognisable in the trace: each servo
cycles through 225 pulse widths in a scrambled order (a re-execution shows as a
value reappearing out of its turn), each digital output toggles. Then the line
is healed and the link must recover by itself, and optionally the pings stop
and the failsafe must fire on time.

What the host sent is taken from the wire, not from the API: a frame monitor
records every COMMAND transmitted (the session restore's replays and every
retransmission included) and every Ack received. :func:`run` then checks:

* **no corrupted execution**: every output change in the trace is explained by
  a command transmitted for that pin with that value shortly before, or is an
  Init's, a Stop's or the failsafe's safe value (a pulse width within the
  emulated Uno's measurement tolerance, for all of them), or a reboot's 0;
* **at most once**: no message id explains two changes within one device boot
  (a reboot empties the device's dedupe window, see docs/protocol.md 7);
* **no hung call**: every call returned or raised within
  ``ack_timeout * (max_retries + 1) + handshake_timeout`` (plus a scheduling
  slack);
* **recovery**: once the faults stop, the next commands all succeed;
* **failsafe on time**: with the pings stopped, the outputs go safe between 10 s
  and 10 s + 20 ms after the device received the last Ping, both read on the
  board's own clock: the last Ping goes out in one write between two digital
  outputs' rising edges, whose trace lines bracket its arrival.

The fault streams are seeded, so a scenario injects the same damage into the
same byte positions; thread scheduling still varies from run to run, so the
figures are repeatable in distribution, not to the byte.
"""

from __future__ import annotations

import bisect
import collections
import contextlib
import json
import logging
import random
import statistics
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlencode

from protoduino.board import Board, DigitalOutput, Servo
from protoduino.commands import command
from protoduino.constants import (
    ACK_TIMEOUT,
    FAILSAFE_TIMEOUT,
    HANDSHAKE_TIMEOUT,
    MAX_MESSAGE_ID,
    MAX_RETRIES,
    WATCHDOG_TIMEOUT,
    PacketType,
)
from protoduino.errors import AckTimeoutError, CommandRejectedError, ProtocolError, ProtoduinoError
from protoduino.events import Event, EventKind
from protoduino.framing import decode_frame
from protoduino.messages import ArduinoIn, parse_in, parse_out, status_name
from protoduino.packets import Packet
from protoduino.simboard import SimBoard
from protoduino.transport import FrameRecord

from .faults import FaultyLine, line, parse_url

log = logging.getLogger(__name__)

#: Pins used, in order, for the servos and the digital outputs (never 0 and 1, the UART).
SERVO_PINS = (3, 5, 6, 9, 10, 11, 2, 4)
DIGITAL_PINS = (13, 12, 8, 7)
#: Servo limits and values: every command value is >= VALUE_BASE, every safe value below it,
#: and the values of one servo are VALUE_STEP apart (far beyond the pulse measurement's error).
SERVO_MIN_US = 500
SERVO_MAX_US = 2500
SAFE_BASE = 520
VALUE_BASE = 600
VALUE_STEP = 8
VALUE_COUNT = 225
#: Coprime with VALUE_COUNT: consecutive commands on one servo jump by ~800 us.
VALUE_STRIDE = 97

#: How far the scheduler may separate a frame's write from its record on the host (s).
SLOP = 0.25
#: Longest time between a command's last transmission and its effect in the trace (s),
#: before any configured line delay: the device reading it, a descheduled process.
LATENCY = 1.0
#: Failsafe timing tolerance: the contract's 20 ms.
FAILSAFE_TOLERANCE = 0.020
#: Widest board-clock span (s) of the two digital edges written around the last Ping
#: that still times the failsafe (the Ping's arrival is known to that much). Sent in
#: one write, the three frames run in one pass of the native board's loop, within
#: microseconds (a descheduled board adds at most 1.5 ms to its clock per reading of
#: it), and 0.8 ms apart on the emulated Uno, whose UART takes them at the line rate.
MARK_SPAN = 0.005
#: Times the last Ping is sent again when a copy of it went out outside its marks
#: (retransmitted after its marks: its Ack came late).
MARK_ATTEMPTS = 3
#: How far apart (s) the 0 lines of one reboot may be dated, beyond a servo's measuring lag.
REBOOT_SPREAD = 0.005
#: Extra time a call may take beyond its documented bound before it counts as hung (s).
HUNG_SLACK = 0.5


@dataclass(frozen=True)
class BackendTraits:
    """How a backend's trace relates to the commands."""

    #: A servo value in the trace may differ from the commanded one by this much (us).
    tolerance_us: int
    #: A measured servo change is dated up to this much after it happened (s).
    servo_lag: float
    #: The device's millisecond clock may read up to this much behind the trace's (s):
    #: the failsafe compares two readings, so it may fire that much before its time.
    millis_lag: float


BACKEND_TRAITS = {
    # Whole milliseconds of the board's clock: a Ping at 5.0009 s reads as 5000 ms.
    "native": BackendTraits(tolerance_us=0, servo_lag=0.0, millis_lag=0.001),
    # The emulated Uno measures pulses at its pins: a few us off, one 20 ms frame late.
    # Its millis() is Arduino's: Timer0 overflows every 1.024 ms and adds 1 ms each
    # time, 2 when the 24 us fractions add up to one, so a reading lags by up to the
    # fraction (< 1 ms) plus one overflow period: 2.024 ms (the soak saw failsafes up
    # to 1.9 ms early by the trace).
    "avr": BackendTraits(tolerance_us=3, servo_lag=0.06, millis_lag=0.002024),
}


def servo_value(slot: int, k: int) -> int:
    """The k-th pulse width commanded to servo number ``slot`` (unique within 225 commands)."""
    return VALUE_BASE + 2 * slot + VALUE_STEP * ((k * VALUE_STRIDE) % VALUE_COUNT)


def servo_safe(slot: int) -> int:
    return SAFE_BASE + 10 * slot


@dataclass(frozen=True)
class Scenario:
    """One seeded run; see the module docstring. ``faults`` is a faulty:// query string."""

    name: str
    commands: int = 200
    seed: int = 1
    faults: str = ""
    resets: int = 0
    cuts: int = 0
    cut_seconds: float = 1.0
    servos: int = 4
    digitals: int = 2
    window: int = 4
    #: Threads calling at once (more than ``window`` keeps the window full).
    workers: int = 8
    ack_timeout: float = ACK_TIMEOUT
    max_retries: int = MAX_RETRIES
    handshake_timeout: float = HANDSHAKE_TIMEOUT
    recovery_commands: int = 20
    failsafe: bool = False
    backend: str = "native"
    #: What the fault kind is, in words, for the report.
    description: str = ""

    def __post_init__(self) -> None:
        if not 1 <= self.servos <= len(SERVO_PINS) or not 0 <= self.digitals <= len(DIGITAL_PINS):
            raise ValueError(
                f"servos must be 1..{len(SERVO_PINS)}, digitals 0..{len(DIGITAL_PINS)}"
            )
        if self.workers < 1:
            raise ValueError("workers >= 1")
        if self.commands < 1 or self.resets < 0 or self.cuts < 0 or self.recovery_commands < 1:
            raise ValueError("commands and recovery_commands >= 1, resets and cuts >= 0")
        if self.failsafe and (self.digitals < 2 or self.window < 3):
            # The last Ping is dated by two digital edges sent with it (LastPing).
            raise ValueError("the failsafe check needs digitals >= 2 and window >= 3")
        keys = {k for k, _ in parse_qsl(self.faults)}
        if keys & {"seed", "name", "paused"}:
            raise ValueError("seed, name and paused are set by the scenario, not in faults")
        parse_url(f"faulty://x?{self.faults}")  # raises ValueError on a bad parameter

    @property
    def call_bound(self) -> float:
        """The longest any call may take (docs/api.md): every attempt, plus a handshake."""
        return self.ack_timeout * (self.max_retries + 1) + self.handshake_timeout

    def as_dict(self) -> dict[str, Any]:
        """The scenario's part of :meth:`SoakResult.as_dict` (what reproducing it needs)."""
        return SoakResult(self).as_dict()

    def url(self, port: str, name: str) -> str:
        params = [*parse_qsl(self.faults), ("seed", str(self.seed)), ("paused", "1")]
        params.append(("name", name))
        return f"faulty://{port}?{urlencode(params)}"

    def command_line(self) -> str:
        """The ``protoduino soak`` command that runs this scenario again (alone)."""
        return command_line(
            backend=self.backend,
            commands=self.commands,
            seed=self.seed,
            faults=self.faults,
            resets=self.resets,
            cuts=self.cuts,
            cut_seconds=self.cut_seconds,
            failsafe=self.failsafe,
        )


def command_line(
    *,
    backend: str,
    commands: int,
    seed: int,
    faults: str,
    resets: int,
    cuts: int,
    cut_seconds: float,
    failsafe: bool,
) -> str:
    """``protoduino soak`` options that run one scenario with these parameters, alone."""
    parts = ["protoduino soak", f"--backend {backend}", f"--commands {commands}", f"--seed {seed}"]
    parts.append(f"--faults '{faults}'")
    parts.append(f"--resets {resets}")
    if cuts:
        parts.append(f"--cuts {cuts} --cut-seconds {cut_seconds:g}")
    parts.append("--failsafe" if failsafe else "--no-failsafe")
    parts.append("--kinds none")
    return " ".join(parts)


def fault_scenarios(commands: int, seed: int = 1, backend: str = "native") -> dict[str, Scenario]:
    """One scenario per fault kind, ``commands`` commands each, keyed by the kind."""
    resets = max(1, min(5, commands // 100))
    cuts = max(1, min(5, commands // 100))
    kinds = [
        Scenario("ber", faults="ber=1e-3", description="random bit flips, bit error rate 1e-3"),
        Scenario(
            "burst",
            faults="burst=2e-3&burstlen=16",
            description="error bursts of 16 bits (first and last flipped), 2e-3 per byte",
        ),
        Scenario("drop", faults="drop=2e-3", description="dropped bytes, 2e-3 per byte"),
        Scenario(
            "garbage",
            faults="garbage=0.05&garbagelen=8",
            description="1..8 random bytes before 5 % of the frames",
        ),
        Scenario("dup", faults="dup=0.02", description="2 % of the frames sent twice"),
        Scenario(
            "delay",
            faults="delay=150",
            description="150 ms latency each way: every Ack comes after a retransmission",
        ),
        Scenario(
            "cut",
            cuts=cuts,
            cut_seconds=1.0,
            description=f"line cut for 1 s, {cuts} times, then restored",
        ),
        Scenario("reset", resets=resets, description=f"device reset {resets} times"),
    ]
    return {s.name: replace(s, commands=commands, seed=seed, backend=backend) for s in kinds}


# --- what happened ------------------------------------------------------------------------


@dataclass
class CallRecord:
    """One API call made by the scenario."""

    pin: int
    kind: str  # "servo" or "digital"
    value: int
    start: float
    end: float = 0.0
    outcome: str = "pending"  # ok, rejected, timeout, error
    detail: str = ""
    phase: str = "faults"  # faults, recovery, failsafe, setup

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass
class _Sent:
    """One message id as seen on the wire."""

    #: A key of its own: the session's count of ids given before it, plus one (ids wrap
    #: every 127 since protocol version 5; this does not). ``wire_id`` is the id itself.
    message_id: int
    kind: str
    pin: int | None
    value: int | None
    txs: list[float] = field(default_factory=list)
    ack: float | None = None
    status: int | None = None
    wire_id: int = 0


@dataclass(frozen=True)
class _Cause:
    """Something that may legitimately change ``pin`` to ``value`` between lo and hi (host time)."""

    pin: int
    value: int
    lo: float
    hi: float
    what: str  # "command", "init", "stop"
    message_id: int


@dataclass(frozen=True)
class LastPing:
    """The last Ping before the silence, as :meth:`_Runner.last_ping` sent it.

    The host's clock cannot say when the device received it closely enough: the
    board's clock may run slower than the host's (a busy machine holds the native
    board back, whose clock then counts at most 1.5 ms per pass of its loop; the
    emulated Uno counts emulated cycles), so a host-to-board offset measured only
    10 ms before the Ping was seen off by 2.8 ms, the failsafe looking early by
    that. So the Ping is written in one write with the rising edges of the digital
    outputs ``marks``, the low mark's frame before it, the high mark's after: the
    device runs the frames in the order they came, so the trace dates the Ping's
    arrival on the board's own clock between the two edges (:func:`_marked_ping`
    checks the order on the line's record of writes).
    """

    #: Host times just before the three were submitted and just after all returned.
    before: float
    after: float
    #: The pins of the low and the high mark.
    marks: tuple[int, int]


@dataclass
class SoakResult:
    """The figures of one scenario run, and every invariant violation found."""

    scenario: Scenario
    duration: float = 0.0
    sent: int = 0
    ok: int = 0
    executed: int = 0
    executed_after_timeout: int = 0
    rejected: dict[str, int] = field(default_factory=dict)
    timed_out: int = 0
    errors: dict[str, int] = field(default_factory=dict)
    duplicates: int = 0
    corrupted: int = 0
    reexecuted_after_reboot: int = 0
    hung: int = 0
    max_call: float = 0.0
    call_bound: float = 0.0
    recovery: list[float] = field(default_factory=list)
    recovered: bool = False
    recovery_failures: int = 0
    failsafe_checked: bool = False
    failsafe_delay: tuple[float, float] | None = None
    failsafe_ok: bool | None = None
    failsafe_lines: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    link: dict[str, Any] = field(default_factory=dict)
    trace_lines: int = 0
    violations: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.violations

    @property
    def recovery_median(self) -> float | None:
        return statistics.median(self.recovery) if self.recovery else None

    @property
    def recovery_max(self) -> float | None:
        return max(self.recovery) if self.recovery else None

    def as_dict(self) -> dict[str, Any]:
        s = self.scenario
        return {
            "scenario": s.name,
            "backend": s.backend,
            "seed": s.seed,
            "faults": s.faults,
            "resets": s.resets,
            "cuts": s.cuts,
            "command_line": s.command_line(),
            "commands": s.commands,
            "cut_seconds": s.cut_seconds,
            "failsafe": s.failsafe,
            "recovery_commands": s.recovery_commands,
            "description": s.description,
            "servos": s.servos,
            "digitals": s.digitals,
            "workers": s.workers,
            "window": s.window,
            "ack_timeout": s.ack_timeout,
            "max_retries": s.max_retries,
            "passed": self.passed,
            "duration_s": round(self.duration, 3),
            "sent": self.sent,
            "ok": self.ok,
            "executed": self.executed,
            "executed_after_timeout": self.executed_after_timeout,
            "rejected": dict(self.rejected),
            "timed_out": self.timed_out,
            "errors": dict(self.errors),
            "duplicates": self.duplicates,
            "corrupted": self.corrupted,
            "reexecuted_after_reboot": self.reexecuted_after_reboot,
            "hung": self.hung,
            "max_call_s": round(self.max_call, 4),
            "call_bound_s": self.call_bound,
            "recovery_s": [round(r, 4) for r in self.recovery],
            "recovery_median_s": self.recovery_median,
            "recovery_max_s": self.recovery_max,
            "recovered": self.recovered,
            "recovery_failures": self.recovery_failures,
            "failsafe_checked": self.failsafe_checked,
            "failsafe_ok": self.failsafe_ok,
            "failsafe_delay_s": self.failsafe_delay,
            "faults_injected": dict(self.faults),
            "link": dict(self.link),
            "trace_lines": self.trace_lines,
            "violations": list(self.violations),
        }


# --- recording the wire --------------------------------------------------------------------


class Wire:
    """Frame monitor: every COMMAND transmitted and every Ack received, by message id."""

    def __init__(self, hide: Callable[[FrameRecord], bool] | None = None) -> None:
        #: Frames left out of the record (run()'s ``hide``).
        self._hide = hide
        #: message id -> when write() was entered for each of its frames (recent ones only).
        self.writes: dict[int, list[float]] = {}
        self.sent: dict[int, _Sent] = {}
        self.order: list[int] = []  # ids in order of first transmission
        self.ping_txs: list[float] = []
        self.bad: Counter[str] = Counter()
        #: Unwrapping the ids as the device tells them apart (protocol.md section 7, *Message
        #: ids*): an id 1..63 ahead of the newest new one is new, any other one a repeat.
        self._key_of: dict[int, int] = {}
        self._newest = 0
        self._keys = 0

    def sent_of(self, mid: int) -> _Sent:
        """The call that last went out under the id ``mid``."""
        return self.sent[self._key_of[mid]]

    def key(self, mid: int) -> int:
        """The key of the id ``mid`` just transmitted (a new one if it is a new id)."""
        key = self._key_of.get(mid)
        if key is None or (self._newest and 1 <= (mid - self._newest) % MAX_MESSAGE_ID <= 63):
            self._keys += 1
            key = self._key_of[mid] = self._keys
            self._newest = mid
        return key

    def __call__(self, record: FrameRecord) -> None:
        item = record.item
        if not isinstance(item, Packet) or (self._hide is not None and self._hide(record)):
            return
        try:
            if record.direction == "tx" and item.type is PacketType.COMMAND:
                self.command(record.t, item.payload)
            elif record.direction == "rx" and item.type is PacketType.DATA:
                out = parse_out(item.payload)  # the short Ack as the Ack it stands for
                if out.WhichOneof("data") == "ack":
                    sent = self.sent.get(self._key_of.get(out.ack.message_id, 0))
                    if sent is not None and sent.ack is None:
                        sent.ack, sent.status = record.t, int(out.ack.status)
        except Exception as error:  # a monitor must never take the I/O thread down
            self.bad[type(error).__name__] += 1

    def command(self, t: float, payload: bytes) -> None:
        """Record one COMMAND written at ``t`` (the monitor's path; a made-up run's too)."""
        msg = ArduinoIn()
        msg.ParseFromString(payload)
        mid = self.key(msg.message_id)
        sent = self.sent.get(mid)
        if sent is None:
            kind = msg.WhichOneof("data") or "empty"
            pin: int | None = None
            value: int | None = None
            if kind == "servo_control":
                ctl = msg.servo_control
                pin = ctl.pin
                value = ctl.us if ctl.WhichOneof("value") == "us" else _deg_to_us(ctl.degrees)
            elif kind == "digital_control":
                pin, value = msg.digital_control.pin, int(msg.digital_control.level)
            elif kind == "servo_init":
                init = msg.servo_init
                pin = init.pin
                lo, hi = init.min_us or 544, init.max_us or 2400
                value = (
                    init.safe_us
                    if init.WhichOneof("safe") == "safe_us"
                    else _deg_to_us(init.safe_degrees, lo, hi)
                )
            elif kind == "digital_init":
                pin, value = msg.digital_init.pin, int(msg.digital_init.safe_level)
            sent = _Sent(mid, kind, pin, value, wire_id=msg.message_id)
            self.sent[mid] = sent
            self.order.append(mid)
        sent.txs.append(t)
        if sent.kind == "ping":
            self.ping_txs.append(t)


def _written_commands(writes: Iterable[tuple[float, bytes]]) -> Iterator[tuple[float, ArduinoIn]]:
    """Each COMMAND frame handed to the line, with the time of its write."""
    for t, raw in writes:
        for chunk in raw.split(b"\x00"):
            item = decode_frame(chunk) if chunk else None
            if isinstance(item, Packet) and item.type is PacketType.COMMAND:
                with contextlib.suppress(ProtocolError):
                    yield t, parse_in(item.payload)


def _write_times(writes: Iterable[tuple[float, bytes]]) -> dict[int, list[float]]:
    """Message id -> the times its COMMAND frames were handed to the line."""
    out: dict[int, list[float]] = {}
    for t, msg in _written_commands(writes):
        out.setdefault(msg.message_id, []).append(t)
    return out


def _all_written(
    writes: Iterable[tuple[float, bytes]], since: float, marks: tuple[int, int]
) -> bool:
    """Were a Ping and both marks' rising edges (``marks``: their pins) written since ``since``?"""
    seen: set[int | None] = set()  # the marks' pins, None for the Ping
    for _t, msg in _written_commands((t, raw) for t, raw in writes if t >= since):
        if msg.WhichOneof("data") == "ping":
            seen.add(None)
        elif msg.WhichOneof("data") == "digital_control" and msg.digital_control.level:
            seen.add(msg.digital_control.pin)
    return seen >= {None, *marks}


def _writes_of(wire: Wire, sent: _Sent) -> list[float]:
    """When ``sent``'s frames were handed to the line: its id's writes while it was open
    (ids wrap, so the same id's writes for other calls are left out)."""
    end = sent.ack if sent.ack is not None else float("inf")
    return [t for t in wire.writes.get(sent.wire_id, []) if sent.txs[0] - 0.05 <= t <= end]


def _deg_to_us(degrees: int, lo: int = SERVO_MIN_US, hi: int = SERVO_MAX_US) -> int:
    return lo + degrees * (hi - lo) // 180


# --- running ---------------------------------------------------------------------------------


class _Outputs:
    """The scenario's outputs and the per-output command counters."""

    def __init__(self, board: Board, scenario: Scenario) -> None:
        self.servos: list[Servo] = []
        self.digitals: list[DigitalOutput] = []
        for slot in range(scenario.servos):
            self.servos.append(
                board.servo(
                    SERVO_PINS[slot],
                    safe_us=servo_safe(slot),
                    min_us=SERVO_MIN_US,
                    max_us=SERVO_MAX_US,
                )
            )
        for slot in range(scenario.digitals):
            self.digitals.append(board.digital_output(DIGITAL_PINS[slot], safe=False))
        self.counters = [0] * (len(self.servos) + len(self.digitals))
        self._lock = threading.Lock()

    @property
    def count(self) -> int:
        return len(self.counters)

    def next_command(self, out: int) -> tuple[str, int, int, Callable[[], None]]:
        """(kind, pin, value, call) for output number ``out``'s next command."""
        with self._lock:
            k = self.counters[out]
            self.counters[out] += 1
        if out < len(self.servos):
            servo = self.servos[out]
            us = servo_value(out, k)
            return "servo", servo.pin, us, lambda: servo.write_us(us)
        dig = self.digitals[out - len(self.servos)]
        level = k % 2 == 0  # 1, 0, 1, ...
        return "digital", dig.pin, int(level), lambda: dig.write(level)


class _Runner:
    def __init__(self, scenario: Scenario, sim: SimBoard, board: Board, name: str) -> None:
        self.s = scenario
        self.sim = sim
        self.board = board
        self.name = name
        self.calls: list[CallRecord] = []
        self.reboots: list[float] = []
        self.cuts: list[tuple[float, float]] = []
        self.heal_at = 0.0
        self.events: list[Event] = []
        self._lock = threading.Lock()
        self._next = 0
        rng = random.Random(scenario.seed)
        n = scenario.commands
        span = range(n // 10, max(n // 10 + 1, n * 9 // 10))
        self.disruptions: dict[int, str] = {}
        for kind, count in (("reset", scenario.resets), ("cut", scenario.cuts)):
            free = [i for i in span if i not in self.disruptions]
            for i in rng.sample(free, min(count, len(free))):
                self.disruptions[i] = kind
        board.on_event(self.events.append)

    def line(self) -> FaultyLine:
        port = line(self.name)
        if port is None:
            raise ProtoduinoError(f"the faulty line {self.name} is not open")
        return port

    def call(
        self,
        kind: str,
        pin: int,
        value: int,
        fn: Callable[[], None],
        phase: str,
        *,
        start: float | None = None,
    ) -> bool:
        """Make one call (``fn``) and record it; ``start``: when it was submitted, if earlier."""
        rec = CallRecord(
            pin, kind, value, time.monotonic() if start is None else start, phase=phase
        )
        try:
            fn()
            rec.outcome = "ok"
        except CommandRejectedError as error:
            rec.outcome, rec.detail = "rejected", status_name(error.status)
        except AckTimeoutError:
            rec.outcome = "timeout"
        except ProtoduinoError as error:
            rec.outcome, rec.detail = "error", type(error).__name__
        except Exception as error:  # a bug: recorded, and the run goes on
            log.exception("unexpected error from %s write", kind)
            rec.outcome, rec.detail = "error", f"unexpected {type(error).__name__}"
        rec.end = time.monotonic()
        with self._lock:
            self.calls.append(rec)
        return rec.outcome == "ok"

    def disrupt(self, what: str) -> None:
        if what == "reset":
            with self._lock:
                self.reboots.append(time.monotonic())
            self.sim.reboot()
        else:
            start = time.monotonic()
            self.line().cut(self.s.cut_seconds)
            with self._lock:
                self.cuts.append((start, start + self.s.cut_seconds))

    def worker(self, outputs: _Outputs, progress: Callable[[int], None] | None) -> None:
        """Take the next command index; command i goes to output i mod the output count.

        Several workers write to one output at once, so an output changes while
        an older command to it still awaits its Ack: were that command run
        again, its value would come back in the trace, out of its turn.
        """
        while True:
            with self._lock:
                index = self._next
                if index >= self.s.commands:
                    return
                self._next += 1
            what = self.disruptions.get(index)
            if what is not None:
                self.disrupt(what)
            kind, pin, value, fn = outputs.next_command(index % outputs.count)
            self.call(kind, pin, value, fn, "faults")
            if progress is not None and index % 1000 == 999:
                progress(index + 1)

    def stream(self, outputs: _Outputs, progress: Callable[[int], None] | None) -> None:
        threads = [
            threading.Thread(
                target=self.worker, args=(outputs, progress), name=f"soak-{i}", daemon=True
            )
            for i in range(self.s.workers)
        ]
        for t in threads:
            t.start()
        # Each call is bounded, so the stream is; the join bound only guards against a bug.
        limit = self.s.commands * self.s.call_bound + 60.0
        deadline = time.monotonic() + limit
        for t in threads:
            t.join(max(0.0, deadline - time.monotonic()))
        if any(t.is_alive() for t in threads):
            raise ProtoduinoError("soak workers did not finish: a call hung")

    def recover(self, outputs: _Outputs) -> int:
        """Heal the line, then recovery_commands commands, round robin; how many failed."""
        self.heal_at = time.monotonic()
        self.line().heal()
        failed = 0
        for i in range(self.s.recovery_commands):
            kind, pin, value, fn = outputs.next_command(i % outputs.count)
            if not self.call(kind, pin, value, fn, "recovery"):
                failed += 1
        return failed

    def last_ping(self, outputs: _Outputs, wire: Wire) -> LastPing:
        """Stop the automatic Ping, drive every output off its safe value, Ping once more,
        between two marks (:class:`LastPing`).

        A copy of the Ping that went out after its high mark (its Ack came so late that
        it was sent again) would feed the failsafe after the marks: then it is all
        done again, up to MARK_ATTEMPTS times; the judge finds out if none succeeded.
        """
        self.board.pinging = False
        rpc = self.board._rpc
        deadline = time.monotonic() + self.s.call_bound
        while rpc._ping_call is not None and time.monotonic() < deadline:
            time.sleep(0.01)  # an automatic Ping still under way
        for out in range(outputs.count):
            kind, pin, value, fn = outputs.next_command(out)
            if kind == "digital" and value == 0:  # end on 1: the failsafe then shows as a 0
                self.call(kind, pin, value, fn, "failsafe")
                kind, pin, value, fn = outputs.next_command(out)
            self.call(kind, pin, value, fn, "failsafe")
        lo, hi = outputs.digitals[:2]  # Scenario: two at least with the failsafe check
        for _ in range(MARK_ATTEMPTS):
            last = self._send_marked_ping(lo, hi)
            wire.writes = _write_times(self.line().recent_writes())
            if not isinstance(_marked_ping(wire, last), str):
                break
        return last

    def _send_marked_ping(self, lo: DigitalOutput, hi: DigitalOutput) -> LastPing:
        """Both marks low, then ``lo`` high, a Ping and ``hi`` high in one write."""
        for mark in (lo, hi):
            self.call("digital", mark.pin, 0, mark.off, "failsafe")
        line = self.line()
        before = time.monotonic()
        line.hold("tx")  # until all three frames are written: then they go out as one
        try:
            calls = (lo.submit(True), self.board.submit_ping(), hi.submit(True))
            deadline = before + self.s.ack_timeout
            while time.monotonic() < deadline and not _all_written(
                line.recent_writes(), before, (lo.pin, hi.pin)
            ):
                time.sleep(0.001)
        finally:
            line.release()
        wait = self.s.call_bound + HUNG_SLACK
        self.call("digital", lo.pin, 1, lambda: calls[0].result(wait), "failsafe", start=before)
        calls[1].result(wait)  # raises, as the blocking ping() would
        self.call("digital", hi.pin, 1, lambda: calls[2].result(wait), "failsafe", start=before)
        return LastPing(before, time.monotonic(), (lo.pin, hi.pin))


def run(
    scenario: Scenario,
    workdir: Path,
    *,
    progress: Callable[[int], None] | None = None,
    hide: Callable[[FrameRecord], bool] | None = None,
) -> SoakResult:
    """Run ``scenario`` on a fresh simulated board; trace and log files go to ``workdir``.

    ``hide`` leaves the frames it returns True for out of the wire record, to test the
    judge itself: an effect whose command was hidden must count as corrupted.
    """
    workdir.mkdir(parents=True, exist_ok=True)
    trace = workdir / f"{scenario.name}-{scenario.backend}-{scenario.seed}.trace.jsonl"
    trace.unlink(missing_ok=True)
    name = f"soak-{scenario.name}-{id(scenario):x}-{time.monotonic_ns()}"
    wire = Wire(hide)
    result = SoakResult(scenario, call_bound=scenario.call_bound)
    t0 = time.monotonic()
    # --line-check: the board's line carries bytes only at matching rates, as a UART does
    # (a reset device is back at the opening rate while the host runs at the agreed one).
    with SimBoard(scenario.backend, trace=trace, options=("--line-check",)) as sim:
        port = sim.start()
        with Board.open(
            scenario.url(port, name),
            ack_timeout=scenario.ack_timeout,
            max_retries=scenario.max_retries,
            handshake_timeout=scenario.handshake_timeout,
            window=scenario.window,
            monitor=wire,
            # The resets are the scenario's own fault: not a reboot loop to stop at.
            reboot_limit=scenario.resets + 1,
        ) as board:
            runner = _Runner(scenario, sim, board, name)
            outputs = _Outputs(board, scenario)
            _setup_values(runner, outputs)
            runner.line().resume()
            runner.stream(outputs, progress)
            failed = runner.recover(outputs)
            result.recovered = failed == 0
            result.recovery_failures = failed
            last_ping = runner.last_ping(outputs, wire) if scenario.failsafe else None
            if last_ping is not None:
                _wait_for_failsafe(sim, outputs, last_ping.after)
            result.faults = dict(runner.line().stats)
            wire.writes = _write_times(runner.line().recent_writes())
            result.link = _link_figures(board, runner)
        result.faults["device_resets"] = len(runner.reboots)
        result.faults["line_cuts"] = len(runner.cuts)
        sim.stop()
        lines = sim.trace()
    result.duration = time.monotonic() - t0
    if wire.bad:
        result.violations.append(f"frames the monitor could not parse: {dict(wire.bad)}")
    judge(result, runner, wire, lines, last_ping)
    _dump(trace.with_suffix("").with_suffix(".wire.jsonl"), runner, wire)
    return result


def _dump(path: Path, runner: _Runner, wire: Wire) -> None:
    """What the host did, beside the trace, to look into a violation afterwards."""
    with path.open("w") as out:
        for r in runner.reboots:
            out.write(json.dumps({"reboot": r}) + "\n")
        for a, b in runner.cuts:
            out.write(json.dumps({"cut": [a, b]}) + "\n")
        out.write(json.dumps({"heal": runner.heal_at}) + "\n")
        for c in runner.calls:
            out.write(json.dumps({"call": asdict(c)}) + "\n")
        for mid in wire.order:
            out.write(json.dumps({"sent": asdict(wire.sent[mid])}) + "\n")


def _setup_values(runner: _Runner, outputs: _Outputs) -> None:
    """On the clean line, one command per output: their trace lines fix the clock offset."""
    for out in range(outputs.count):
        kind, pin, value, fn = outputs.next_command(out)
        if not runner.call(kind, pin, value, fn, "setup"):
            raise ProtoduinoError(f"setup command failed on a clean line: {runner.calls[-1]}")


def _wait_for_failsafe(sim: SimBoard, outputs: _Outputs, since: float) -> None:
    """Wait (bounded) until every output shows its safe value again after the pings stopped."""
    deadline = since + FAILSAFE_TIMEOUT + 3.0
    safe = {s.pin: servo_safe(i) for i, s in enumerate(outputs.servos)}
    safe.update({d.pin: 0 for d in outputs.digitals})
    while time.monotonic() < deadline:
        time.sleep(0.1)
        last: dict[int, int] = {}
        for entry in sim.trace():
            last[int(entry["pin"])] = int(entry["value"])
        tol = BACKEND_TRAITS[sim.backend].tolerance_us
        if all(abs(last.get(pin, -100) - v) <= tol for pin, v in safe.items()):
            return


def _link_figures(board: Board, runner: _Runner) -> dict[str, Any]:
    st = board.stats
    kinds = Counter(e.kind.value for e in runner.events)
    return {
        "retransmits": st.retransmits,
        "late_acks": st.late_acks,
        "unknown_acks": st.unknown_acks,
        "bad_frames": dict(st.dropped),
        "rehandshakes": max(0, st.handshakes - 1),
        "reboots_seen": st.reboots,
        "seq_lost": st.seq_lost,
        "seq_desyncs": st.seq_desyncs,
        "watchdog_resets": st.watchdog_resets,
        "device_desyncs": st.device_desyncs,
        "device_rx_overflows": st.device_rx_overflows,
        "timeouts": st.timeouts,
        "pings": st.pings,
        "ping_failures": st.ping_failures,
        "restores": kinds.get(EventKind.RESTORED.value, 0),
        "failsafe_events": sum(
            1 for e in runner.events if e.kind is EventKind.FAILSAFE and e.details.get("active")
        ),
        "decode_errors": kinds.get(EventKind.DECODE_ERROR.value, 0),
        "guard_holds": board._rpc.guard_holds,
    }


# --- judging ---------------------------------------------------------------------------------


def judge(
    result: SoakResult,
    runner: _Runner,
    wire: Wire,
    lines: list[dict[str, Any]],
    last_ping: LastPing | None,
) -> None:
    """Fill ``result`` from a run: the calls ``runner`` made, the frames ``wire`` saw and
    the trace ``lines`` (run() calls it; the judge's own tests feed it made-up runs)."""
    s = runner.s
    traits = BACKEND_TRAITS.get(s.backend, BACKEND_TRAITS["avr"])
    result.trace_lines = len(lines)
    calls = list(runner.calls)
    stream = [c for c in calls if c.phase in ("faults", "recovery")]
    result.sent = len(stream)
    result.ok = sum(c.outcome == "ok" for c in stream)
    result.timed_out = sum(c.outcome == "timeout" for c in stream)
    result.rejected = dict(Counter(c.detail for c in stream if c.outcome == "rejected"))
    result.errors = dict(Counter(c.detail for c in stream if c.outcome == "error"))
    for c in calls:
        if c.outcome != "ok" and c.phase in ("setup", "failsafe"):
            result.violations.append(f"{c.phase} command failed on a clean line: {c}")

    # No hung call.
    result.max_call = max((c.duration for c in calls), default=0.0)
    hung = [c for c in calls if c.duration > s.call_bound + HUNG_SLACK]
    result.hung = len(hung)
    for c in hung[:5]:
        result.violations.append(
            f"hung call: {c.kind} pin {c.pin} = {c.value} took {c.duration:.3f} s "
            f"(bound {s.call_bound:g} s): {c.outcome} {c.detail}"
        )

    # The trace's clock against the host's.
    lines = sorted(lines, key=lambda e: float(e["t"]))  # a measured pulse is written late
    clock = _clock_map(calls, wire, lines, traits)
    if clock is None:
        result.violations.append("could not relate the trace's clock to the host's")
        return
    tx_delay = _tx_delay(s)

    # What may legitimately change each output, and when.
    causes = _causes(wire, tx_delay)
    boundaries = _boundaries(runner.reboots, lines, clock, traits)
    failsafe = _Failsafe(wire)

    used: dict[int, int] = {}  # message id -> the boot it executed in
    matched_ids: set[int] = set()
    # Per (pin, value), causes in order of their window's start, for bisection: a digital
    # level has thousands of them in a long run.
    by_value: dict[tuple[int, int], list[_Cause]] = {}
    for cause in sorted(causes, key=lambda c: c.lo):
        by_value.setdefault((cause.pin, cause.value), []).append(cause)
    starts = {key: [c.lo for c in group] for key, group in by_value.items()}
    span = max((c.hi - c.lo for c in causes), default=0.0)
    failsafe_lines: list[float] = []
    previous: dict[int, int] = {}
    for entry in lines:
        pin, value, t = int(entry["pin"]), int(entry["value"]), float(entry["t"])
        servo = entry["mode"] == "servo"
        lag = traits.servo_lag if servo else 0.0
        tol = traits.tolerance_us if servo else 0
        last, previous[pin] = previous.get(pin), value
        if tol and last is not None and abs(value - last) <= tol:
            continue  # a measured pulse's jitter: the same output value measured again
        h = clock.host(t)  # host time of the line
        # A change just before a reset belongs to the old boot.
        boot = sum(1 for b in boundaries if t >= b)
        if value == 0 and any(-REBOOT_SPREAD <= t - b <= lag + REBOOT_SPREAD for b in boundaries):
            continue  # a reboot releases every output
        candidates = []
        for v in range(value - tol, value + tol + 1):
            group = by_value.get((pin, v), [])
            los = starts.get((pin, v), [])
            first = bisect.bisect_left(los, h - lag - span)
            last = bisect.bisect_right(los, h + SLOP)
            candidates += [c for c in group[first:last] if c.lo - SLOP <= h <= c.hi + lag]
        fresh = [c for c in candidates if used.get(c.message_id, -1) != boot]
        # Never-used causes first (a cause used in an earlier boot may run again after a
        # reboot, but only if nothing else explains the line), then the one whose window
        # closes first: lines come in time order, so this earliest-deadline choice
        # explains as many lines as can be explained.
        fresh.sort(key=lambda c: (c.message_id in used, c.hi))
        if fresh:
            chosen = fresh[0]
            if chosen.message_id in used:
                result.reexecuted_after_reboot += 1
            used[chosen.message_id] = boot
            matched_ids.add(chosen.message_id)
            continue
        if failsafe.possible(pin, value, h, tol):
            failsafe_lines.append(h)
            continue
        if candidates:
            result.duplicates += 1
            if result.duplicates <= 5:
                ids = sorted({c.message_id for c in candidates})
                result.violations.append(
                    f"duplicate execution: pin {pin} = {value} at trace t={t:.4f} again "
                    f"(message ids {ids} already executed in this boot)"
                )
        else:
            result.corrupted += 1
            if result.corrupted <= 5:
                result.violations.append(
                    f"unexplained output change (corrupted command?): pin {pin} = {value} "
                    f"at trace t={t:.4f} (host {h:.4f}); no command sent with that value then"
                )
    result.failsafe_lines = len(failsafe_lines)

    # Executed: the stream's calls whose message id explains a trace line.
    ids_by_value: dict[tuple[int, int], list[_Sent]] = {}
    for sent in wire.sent.values():
        if command(sent.kind).is_control and sent.pin is not None:
            assert sent.value is not None
            ids_by_value.setdefault((sent.pin, sent.value), []).append(sent)
    firsts = {key: [x.txs[0] for x in sents] for key, sents in ids_by_value.items()}
    for c in stream:
        sents = ids_by_value.get((c.pin, c.value), [])
        los = firsts.get((c.pin, c.value), [])
        window = sents[
            bisect.bisect_left(los, c.start - SLOP) : bisect.bisect_right(los, c.end + SLOP)
        ]
        ids = [x.message_id for x in window]
        seen = any(i in matched_ids for i in ids)
        if seen:
            result.executed += 1
            if c.outcome == "timeout":
                result.executed_after_timeout += 1
        elif c.outcome == "ok" and c.kind == "servo" and traits.servo_lag == 0.0:
            # Exact traces only: an acknowledged pulse width must show (each is new).
            result.violations.append(
                f"acknowledged but never executed: pin {c.pin} = {c.value} "
                f"({c.start:.3f}..{c.end:.3f})"
            )
        if c.outcome in ("ok", "timeout", "rejected") and not ids:
            result.violations.append(f"call never reached the wire: {c}")

    # Recovery times: from each disruption's end to the next successful call.
    ok_ends = sorted(c.end for c in stream if c.outcome == "ok")
    marks = [*runner.reboots, *(b for _, b in runner.cuts), runner.heal_at]
    for mark in sorted(marks):
        after = next((e for e in ok_ends if e > mark), None)
        if after is None:
            result.violations.append(f"no successful call after the disruption at {mark:.3f}")
        else:
            result.recovery.append(after - mark)
    bound = s.call_bound + WATCHDOG_TIMEOUT
    if not result.recovered:
        result.violations.append(
            f"the link did not recover: {result.recovery_failures} of "
            f"{s.recovery_commands} commands failed on the healed line"
        )
    slow = [r for r in result.recovery if r > bound]
    if slow:
        result.violations.append(f"recovery slower than {bound:g} s: {max(slow):.3f} s")

    if last_ping is not None:
        _judge_failsafe(result, wire=wire, lines=lines, last_ping=last_ping, traits=traits)


def _tx_delay(s: Scenario) -> float:
    params = dict(parse_qsl(s.faults))
    if params.get("dir", "both") in ("both", "tx"):
        return float(params.get("delay", 0.0)) / 1000
    return 0.0


def _causes(wire: Wire, tx_delay: float) -> list[_Cause]:
    """Every output change the transmitted commands may cause, with its time window."""
    causes: list[_Cause] = []
    configured: dict[int, int] = {}  # pin -> safe value of its latest Init sent
    for mid in wire.order:
        sent = wire.sent[mid]
        lo, hi = sent.txs[0], sent.txs[-1] + LATENCY + tx_delay
        declared = command(sent.kind)
        if declared.is_control or declared.is_init:
            assert sent.pin is not None and sent.value is not None
            what = "command" if declared.is_control else "init"
            causes.append(_Cause(sent.pin, sent.value, lo, hi, what, mid))
            if what == "init":
                configured[sent.pin] = sent.value
        elif sent.kind == "stop":
            for pin, safe in configured.items():
                causes.append(_Cause(pin, safe, lo, hi, "stop", mid))
    return causes


def _boundaries(
    reboots: list[float], lines: list[dict[str, Any]], clock: _ClockMap, traits: BackendTraits
) -> list[float]:
    """Trace times at which the device rebooted, from the 0 lines each reset leaves.

    A reboot releases every output: each servo that was driven shows 0, which
    no command can ask for (a measured pulse: up to ``servo_lag`` after the
    reset). The first such line after the reset was ordered dates it; a
    digital output's 0 (dated exactly) within that lag dates it more closely.
    Without a servo's 0, the host's own clock does.
    """
    servo_zeros = sorted(
        float(e["t"]) for e in lines if e["mode"] == "servo" and int(e["value"]) == 0
    )
    digital_zeros = sorted(
        float(e["t"]) for e in lines if e["mode"] == "digital" and int(e["value"]) == 0
    )
    out: list[float] = []
    for r in sorted(reboots):
        # The reset follows the signal within a few ms; resets may come 0.1 s apart.
        start = clock.trace(r) - 0.05
        if out:
            start = max(start, out[-1] + traits.servo_lag + REBOOT_SPREAD)
        first = next((z for z in servo_zeros if z >= start), None)
        if first is None or first > start + 2.0:
            out.append(clock.trace(r))
            continue
        lo = first - traits.servo_lag - REBOOT_SPREAD
        exact = [z for z in digital_zeros if lo <= z <= first + REBOOT_SPREAD]
        out.append(min(exact) if exact and traits.servo_lag else first - traits.servo_lag)
    return out


class _Failsafe:
    """Could the device's failsafe have driven ``pin`` to ``value`` at host time ``h``?

    Only to the safe value of the pin's latest Init (within ``tol``: a measured pulse
    width, like a commanded one), and only if no Ping the
    device certainly received (acknowledged) went out less than
    FAILSAFE_TIMEOUT before.
    """

    def __init__(self, wire: Wire) -> None:
        self._inits: dict[int, list[tuple[float, int]]] = {}
        pings: list[tuple[float, float]] = []
        for sent in wire.sent.values():  # in order of first transmission
            if command(sent.kind).is_init and sent.pin is not None:
                assert sent.value is not None
                self._inits.setdefault(sent.pin, []).append((sent.txs[0], sent.value))
            elif sent.kind == "ping" and sent.ack is not None and sent.status == 0:
                pings.append((sent.txs[0], sent.ack))
        self._ping_tx = [tx for tx, _ in pings]
        self._ping_ack = [ack for _, ack in pings]

    def possible(self, pin: int, value: int, h: float, tol: int = 0) -> bool:
        inits = self._inits.get(pin, [])
        i = bisect.bisect_right([t for t, _ in inits], h)
        if i == 0 or abs(inits[i - 1][1] - value) > tol:
            return False
        first = bisect.bisect_right(self._ping_tx, h - FAILSAFE_TIMEOUT + SLOP)
        return not any(ack <= h for ack in self._ping_ack[first:])


class _ClockMap:
    """Host time of a trace time, and back.

    The trace's clock may drift against the host's: the emulated Uno counts
    emulated cycles and falls behind real time when the machine is busy. So
    the offset is estimated locally, as the median over the nearest anchors:
    trace lines whose command is known (a unique pulse width, sent once,
    acknowledged quickly), each bounding the offset by its command's
    transmission and Ack.
    """

    #: Anchors on each side of a time that the local estimate uses.
    NEIGHBOURS = 15

    def __init__(self, anchors: list[tuple[float, float]]) -> None:
        anchors = sorted(anchors)
        self._t = [a for a, _ in anchors]
        self._o = [b for _, b in anchors]
        self._median = statistics.median(self._o)

    def offset(self, t: float) -> float:
        i = bisect.bisect(self._t, t)
        window = self._o[max(0, i - self.NEIGHBOURS) : i + self.NEIGHBOURS]
        return statistics.median(window)

    def host(self, t: float) -> float:
        return t + self.offset(t)

    def trace(self, h: float) -> float:
        return h - self.offset(h - self._median)


def _setup_offset(
    calls: list[CallRecord], wire: Wire, lines: list[dict[str, Any]], traits: BackendTraits
) -> float | None:
    """A first offset from the setup commands (one unique value per output, clean line).

    Digital edges are dated exactly on every backend, so they are preferred;
    a measured servo pulse may come up to ``servo_lag`` late.
    """
    exact: list[tuple[float, float]] = []
    measured: list[tuple[float, float]] = []
    for c in calls:
        if c.phase != "setup" or c.outcome != "ok":
            continue
        sent = next(
            (
                x
                for x in wire.sent.values()
                if x.pin == c.pin
                and x.value == c.value
                and x.kind.endswith("control")
                and c.start - SLOP <= x.txs[0] <= c.end
            ),
            None,
        )
        if sent is None or sent.ack is None:
            continue
        servo = c.kind == "servo"
        tol = traits.tolerance_us if servo else 0
        lag = traits.servo_lag if servo else 0.0
        for e in lines:
            if int(e["pin"]) == c.pin and abs(int(e["value"]) - c.value) <= tol:
                t = float(e["t"])
                (measured if lag else exact).append((sent.txs[0] - t, sent.ack + lag - t))
                break
    intervals = exact or measured
    if not intervals:
        return None
    return statistics.median((a + b) / 2 for a, b in intervals)


def _clock_map(
    calls: list[CallRecord], wire: Wire, lines: list[dict[str, Any]], traits: BackendTraits
) -> _ClockMap | None:
    """Anchor every servo line whose command is unambiguous, walking forward in time."""
    first = _setup_offset(calls, wire, lines, traits)
    if first is None:
        return None
    by_value: dict[tuple[int, int], list[_Sent]] = {}
    for x in wire.sent.values():
        if (
            x.kind == "servo_control"
            and x.pin is not None
            and x.value is not None
            and len(x.txs) == 1
            and x.ack is not None
            and x.ack - x.txs[0] < 0.1
        ):
            by_value.setdefault((x.pin, x.value), []).append(x)
    anchors: list[tuple[float, float]] = []
    recent: collections.deque[float] = collections.deque([first], maxlen=_ClockMap.NEIGHBOURS)
    for e in lines:
        if e["mode"] != "servo":
            continue
        t, pin, value = float(e["t"]), int(e["pin"]), int(e["value"])
        guess = t + statistics.median(recent)
        found = [
            x
            for v in range(value - traits.tolerance_us, value + traits.tolerance_us + 1)
            for x in by_value.get((pin, v), ())
        ]
        if not found:
            continue
        best = min(found, key=lambda x: abs(x.txs[0] - guess))
        assert best.ack is not None
        lo, hi = best.txs[0] - t, best.ack + traits.servo_lag - t
        if abs(t + (lo + hi) / 2 - guess) > 1.0:
            continue  # far from where the clock was: a value of another cycle, not an anchor
        anchors.append((t, (lo + hi) / 2))
        recent.append((lo + hi) / 2)
    return _ClockMap(anchors or [(0.0, first)])


def _marked_ping(wire: Wire, last: LastPing) -> tuple[_Sent, _Sent, _Sent] | str:
    """The low mark, the last Ping and the high mark as the wire saw them, or why the
    marks do not bracket the Ping's arrival.

    They do if the line carried the low mark's first frame before every copy of the
    Ping, and every copy before the high mark's first frame: one thread writes, so
    the order of the line's record of writes is the order of the bytes (a repeated
    mark is not run again, a repeated Ping is). Only the order counts here; how far
    apart the edges are is the trace's to say.
    """
    sents = list(wire.sent.values())  # one step: the I/O thread may add to it

    def last_sent(kind: str, pin: int | None) -> _Sent | None:
        return next(
            (
                x
                for x in reversed(sents)
                if x.kind == kind
                and (pin is None or (x.pin, x.value) == (pin, 1))
                and last.before <= x.txs[0] <= last.after
            ),
            None,
        )

    lo, ping, hi = (
        last_sent("digital_control", last.marks[0]),
        last_sent("ping", None),
        last_sent("digital_control", last.marks[1]),
    )
    if lo is None or ping is None or hi is None:
        return "the last Ping or a mark is missing from the wire"
    lo_w, ping_w, hi_w = (_writes_of(wire, x) for x in (lo, ping, hi))
    if not lo_w or not ping_w or not hi_w:
        return "the last Ping or a mark is missing from the line's record of writes"
    if not min(lo_w) < min(ping_w) <= max(ping_w) < min(hi_w):
        return f"the last Ping went out {len(ping_w)} times, not all between its marks"
    return lo, ping, hi


def _judge_failsafe(
    result: SoakResult,
    *,
    wire: Wire,
    lines: list[dict[str, Any]],
    last_ping: LastPing,
    traits: BackendTraits,
) -> None:
    """The first safe value after the last Ping, against that Ping's arrival, both on the
    board's clock: the arrival lies between the marks' rising edges (:class:`LastPing`).
    Nothing here reads the host's clock but to pick the Ping among the frames sent."""
    result.failsafe_checked = True
    marked = _marked_ping(wire, last_ping)
    if isinstance(marked, str):
        result.violations.append(f"failsafe check: {marked}")
        result.failsafe_ok = False
        return
    _, ping, _ = marked
    answered = ping.ack if ping.ack is not None else last_ping.after
    later = [s for s in wire.sent.values() if s.kind == "ping" and s.txs[-1] > answered]
    if later:
        result.violations.append(f"failsafe check: {len(later)} Pings after the last one")
    # Each mark's edge is its pin's last rise: the marks were the last commands, and the
    # failsafe only lowers them (a mark that did not run is a failed call, reported).
    lo_t, hi_t = (
        max(
            (float(e["t"]) for e in lines if int(e["pin"]) == pin and int(e["value"]) == 1),
            default=None,
        )
        for pin in last_ping.marks
    )
    if lo_t is None or hi_t is None or not 0 <= hi_t - lo_t <= MARK_SPAN:
        result.violations.append(
            f"failsafe check: the last Ping's marks are not in the trace {MARK_SPAN * 1000:g} "
            f"ms apart at most, in order (low at {lo_t}, high at {hi_t})"
        )
        result.failsafe_ok = False
        return
    digital_pins = {
        s.pin for s in wire.sent.values() if s.kind == "digital_init" and s.pin is not None
    }
    servo_safe_by_pin = {
        s.pin: s.value
        for s in wire.sent.values()
        if s.kind == "servo_init" and s.pin is not None and s.value is not None
    }
    safe_lines = [
        e
        for e in lines
        if float(e["t"]) > lo_t
        and (
            (int(e["pin"]) in digital_pins and int(e["value"]) == 0)
            or (
                int(e["pin"]) in servo_safe_by_pin
                and abs(int(e["value"]) - servo_safe_by_pin[int(e["pin"])]) <= traits.tolerance_us
            )
        )
    ]
    if not safe_lines:
        result.violations.append("failsafe never fired after the pings stopped")
        result.failsafe_ok = False
        return
    # When the outputs went safe: a digital edge is dated exactly, a measured servo
    # pulse up to servo_lag late (the marks are digital, so there is a digital one).
    digital = [float(e["t"]) for e in safe_lines if e["mode"] == "digital"]
    fired_hi = min(digital) if digital else min(float(e["t"]) for e in safe_lines)
    fired_lo = fired_hi if digital else fired_hi - traits.servo_lag
    low, high = fired_lo - hi_t, fired_hi - lo_t
    result.failsafe_delay = (round(low, 4), round(high, 4))
    # Due 10 s after the last Ping received, not before, at most 20 ms late: the measured
    # interval must meet [10 s, 10.02 s], give or take the lag of the device's millisecond
    # clock, whose readings the failsafe compares.
    early = FAILSAFE_TIMEOUT - traits.millis_lag
    ok = high >= early and low <= FAILSAFE_TIMEOUT + FAILSAFE_TOLERANCE
    result.failsafe_ok = ok and not later
    if not ok:
        result.violations.append(
            f"failsafe fired {low:.4f}..{high:.4f} s after the last Ping "
            f"(expected {FAILSAFE_TIMEOUT:g} s + {FAILSAFE_TOLERANCE * 1000:g} ms)"
        )
