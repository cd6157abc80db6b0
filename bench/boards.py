"""The boards parts 2, 3 and 5 measure against, and the tools to look inside them.

* :func:`started` builds and starts a simulated board (``native``: the firmware core on a pty,
  no baud rate) or the emulated Uno (``avr``: the real Uno firmware on simavr, paced to real
  time, its UART timed at 115200 baud), optionally with the runner's ``--stats`` file.
* :class:`CycleCounter` reads the emulated Uno's cycle counters (``tools/avrsim --stats``:
  SIGUSR2 appends one JSON line): total, asleep and awake cycles, UART bytes.
* :func:`on_each_board` runs one measurement on each board in turn (a Board open on it, its
  trace read by :class:`Trace`), a board that cannot run noted, not fatal.
* :class:`RawClient` talks to a board with pyserial and the project's framing only, no I/O
  thread and no request layer: the same round trip without the host library, so that the
  library's own share of a round trip can be told apart from the board's.

Every wait here is bounded; every process and port is closed by a context manager.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import random
import select
import shutil
import statistics
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any, Protocol, TypeVar

import serial
from protoduino import Board
from protoduino.closing import ClosedOnExit
from protoduino.constants import MAX_MESSAGE_ID, PROTOCOL_VERSION, ControlCode, PacketType
from protoduino.errors import ProtoduinoError
from protoduino.framing import DELIMITER, StreamDecoder, frame_packet
from protoduino.messages import ArduinoIn, parse_out
from protoduino.packets import Packet, parse_control, reset_payload
from protoduino.simboard import Backend, SimBoard
from protoduino_dev import runnerstats

log = logging.getLogger(__name__)

#: The boards, in report order: (backend, label).
BACKENDS: tuple[tuple[str, str], ...] = (
    ("native", "simulated board (native)"),
    ("avr", "emulated Uno (avr, 115200 baud)"),
)
LABELS = dict(BACKENDS)

#: Tools each backend needs; a missing one makes the backend "not run" with its name.
NEEDS: dict[str, tuple[str, ...]] = {
    "native": ("make", "gcc"),
    "avr": ("make", "gcc", "avr-gcc", "avr-size"),
}
SIMAVR_HEADER = Path("/usr/include/simavr/sim_avr.h")

#: The Uno's clock, for turning cycles into time.
UNO_HZ = 16_000_000
#: How long a --stats line may take to appear (the runner writes it within ~1 ms).
STATS_TIMEOUT = 3.0
#: Bound on every raw read.
RAW_TIMEOUT = 2.0


class BoardUnavailableError(Exception):
    """A board cannot be built or started here; the message says what is missing."""


def missing_tool(backend: str) -> str | None:
    """The first tool ``backend`` needs that is not installed, or None."""
    for tool in NEEDS[backend]:
        if shutil.which(tool) is None:
            return tool
    if backend == "avr" and not SIMAVR_HEADER.exists():
        return "libsimavr-dev"
    return None


class Trace:
    """The board's trace file, read incrementally (it only grows)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.events: list[dict[str, Any]] = []
        self._offset = 0

    def update(self) -> list[dict[str, Any]]:
        with self.path.open("rb") as f:
            f.seek(self._offset)
            data = f.read()
        end = data.rfind(b"\n") + 1
        self._offset += end
        self.events += [json.loads(line) for line in data[:end].splitlines() if line.strip()]
        return self.events


class Measured(Protocol):
    """A board's result: what went wrong, if it did not run."""

    error: str | None


R = TypeVar("R", bound=Measured)


def on_each_board(
    name: str,
    result_of: Callable[[str], R],
    measure: Callable[[R, SimBoard, Trace, Board], None],
) -> list[R]:
    """``measure`` on each board of :data:`BACKENDS`, a Board open on it and its trace read.

    A board whose tools are missing, or that fails to build, start or answer, keeps its
    result with ``error`` set (the first line of what went wrong) and the others still run.
    """
    out: list[R] = []
    for backend, _label in BACKENDS:
        result = result_of(backend)
        out.append(result)
        tool = missing_tool(backend)
        if tool is not None:
            result.error = f"`{tool}` is not installed"
            continue
        with TemporaryDirectory(prefix=f"bench-{name}-") as tmp:
            sim = SimBoard(backend, trace=Path(tmp) / "trace.jsonl")
            try:
                sim.start()
                with Board.open(sim.port, baudrate=115_200) as board:  # figures at 115200
                    measure(result, sim, Trace(Path(tmp) / "trace.jsonl"), board)
            except (ProtoduinoError, BoardUnavailableError, RuntimeError) as error:
                log.warning("%s: %s board not run: %s", name, backend, error)
                result.error = str(error).splitlines()[0]
            finally:
                sim.stop()
    return out


class _RunnerBoard(SimBoard):
    """The simavr runner with a program of the bench's own (another project's hex, the
    runner's echo), which SimBoard's backends do not run; everything else is SimBoard's."""

    def __init__(self, backend: Backend, trace: Path | None = None) -> None:
        super().__init__("avr", trace=trace)
        self._backend = backend


def _only_its_own(program: Path | None) -> None:
    """A backend that runs one fixed program refuses another build."""
    if program is not None:
        raise ValueError(f"this bench board runs its own program, not {program}")


def _hex_backend(hex_file: Path, stats: Path, profile: Path | None = None) -> Backend:
    """The runner with a program of another project, loaded from Intel hex, and --stats
    (and --profile)."""
    from protoduino.simboard import runner_command
    from protoduino_dev import build as builds

    extra = ["--stats", str(stats)]
    if profile is not None:
        extra += ["--profile", str(profile)]

    def command(
        trace: Path | None, link: Path | None, control: Path | None, program: Path | None
    ) -> list[str]:
        _only_its_own(program)
        cmd = runner_command(trace=trace, link=link, control=control, hex_files=[hex_file])
        return [*cmd, *extra]

    return Backend(build=builds.build_runner, command=command)


def _echo_backend() -> Backend:
    """The runner with its own test program, which echoes every UART byte at once."""
    from protoduino.simboard import runner_command
    from protoduino_dev import build as builds

    def build() -> Path:
        builds.build_test_program()
        return builds.build_runner()

    def command(
        trace: Path | None, link: Path | None, control: Path | None, program: Path | None
    ) -> list[str]:
        _only_its_own(program)
        return runner_command(builds.TEST_PROGRAM, trace=trace, link=link, control=control)

    return Backend(build=build, command=command)


@contextlib.contextmanager
def started(
    backend: str,
    *,
    stats: Path | None = None,
    profile: Path | None = None,
    trace: Path | None = None,
    board: str = "uno",
) -> Iterator[SimBoard]:
    """A started board of ``backend`` (the emulated ``board``: "uno" or "mega"), stopped on
    exit. ``stats`` and ``profile`` (avr only) are the runner's --stats and --profile files,
    ``trace`` its trace file.

    Raises :class:`BoardUnavailableError` when a tool is missing or the build fails.
    """
    tool = missing_tool(backend)
    if tool is not None:
        raise BoardUnavailableError(f"`{tool}` is not installed")
    if (stats is not None or profile is not None) and backend != "avr":
        raise ValueError("cycle statistics exist only on the emulated Uno (avr)")
    if profile is not None and stats is None:
        raise ValueError("a profile is written with the statistics: give stats= too")
    options: list[str] = []
    if stats is not None:
        options += ["--stats", str(stats)]
    if profile is not None:
        options += ["--profile", str(profile)]
    yield from _run(SimBoard(backend, board=board, trace=trace, options=options))


@contextlib.contextmanager
def started_hex(
    hex_file: Path, *, stats: Path, trace: Path | None = None, profile: Path | None = None
) -> Iterator[SimBoard]:
    """The emulated Uno running another project's firmware from ``hex_file``, unmodified
    (the bench's race runs StandardFirmata so), with the runner's --stats file (and its
    --profile file)."""
    tool = missing_tool("avr")
    if tool is not None:
        raise BoardUnavailableError(f"`{tool}` is not installed")
    yield from _run(_RunnerBoard(_hex_backend(hex_file, stats, profile), trace))


@contextlib.contextmanager
def started_echo() -> Iterator[SimBoard]:
    """The emulated Uno running the runner's test program (a byte echo), not the firmware:
    what the runner and the pty cost a round trip with no work on the MCU."""
    tool = missing_tool("avr")
    if tool is not None:
        raise BoardUnavailableError(f"`{tool}` is not installed")
    yield from _run(_RunnerBoard(_echo_backend()))


def _run(sim: SimBoard) -> Iterator[SimBoard]:
    try:
        sim.start()
    except ProtoduinoError as error:  # BuildError, TransportError
        sim.stop()
        raise BoardUnavailableError(str(error).splitlines()[0]) from error
    try:
        yield sim
    finally:
        sim.stop()


@dataclass(frozen=True, slots=True)
class CycleStats:
    """One line of the runner's --stats file, and the host's clock when it was read."""

    t: float  # emulated seconds
    cycles: int
    awake: int
    uart_rx: int
    uart_tx: int
    wall: float  # time.perf_counter() when the line appeared
    #: First bytes the UART sent after a host burst's last byte, and their cycles since that
    #: byte was ready in UDR0: the firmware's answer time (tools/avrsim/README.md).
    answers: int = 0
    answer_cycles: int = 0

    def __sub__(self, other: CycleStats) -> CycleStats:
        return CycleStats(
            self.t - other.t,
            self.cycles - other.cycles,
            self.awake - other.awake,
            self.uart_rx - other.uart_rx,
            self.uart_tx - other.uart_tx,
            self.wall - other.wall,
            self.answers - other.answers,
            self.answer_cycles - other.answer_cycles,
        )

    @property
    def awake_share(self) -> float:
        return self.awake / self.cycles if self.cycles else 0.0

    @property
    def pace(self) -> float:
        """Emulated time over wall time (of a difference): 1.0 when the emulator keeps up."""
        return self.t / self.wall if self.wall > 0 else 0.0


class CycleCounter:
    """Snapshots of an emulated Uno's cycle counters (its runner started with --stats)."""

    def __init__(self, sim: SimBoard, path: Path) -> None:
        self.sim = sim
        self.path = path

    def snapshot(self) -> CycleStats:
        row = runnerstats.snapshot(self.sim.pid, self.path, STATS_TIMEOUT)
        return CycleStats(
            float(row["t"]),
            int(row["cycles"]),
            int(row["awake_cycles"]),
            int(row["uart_rx_bytes"]),
            int(row["uart_tx_bytes"]),
            time.perf_counter(),
            int(row["answers"]),
            int(row["answer_cycles"]),
        )


@dataclass(frozen=True, slots=True)
class Percentiles:
    """Summary of latency samples, in seconds."""

    n: int
    p50: float
    p90: float
    p99: float
    low: float
    high: float

    @classmethod
    def of(cls, samples: Sequence[float]) -> Percentiles:
        if not samples:
            raise ValueError("no samples")
        s = sorted(samples)

        def pct(q: float) -> float:
            # Nearest rank: with a few hundred samples p99 is one of the slowest few.
            return s[min(len(s) - 1, max(0, round(q * len(s)) - 1))]

        return cls(len(s), statistics.median(s), pct(0.90), pct(0.99), s[0], s[-1])


class RawClient(ClosedOnExit):
    """A board driven directly: pyserial, ``framing`` and hand-kept SEQ and message ids.

    No thread: :meth:`call` writes one COMMAND and reads until its Ack arrives, in the caller's
    thread. It is what a round trip costs without the host library; it does no retransmission
    and is only for a quiet, healthy link.
    """

    def __init__(self, port: str) -> None:
        self._serial = serial.Serial(port, 115200, timeout=0)
        self._fd: int = self._serial.fileno()
        self._decoder = StreamDecoder()
        self._seq = 1
        self._next_id = 1  # as a Board's session: 1..127, wrapping (protocol version 5)
        try:
            self._handshake()
        except BaseException:
            self._serial.close()
            raise

    def close(self) -> None:
        self._serial.close()

    def _read_until(self, want: Callable[[Packet], bool]) -> Packet:
        deadline = time.perf_counter() + RAW_TIMEOUT
        while (remaining := deadline - time.perf_counter()) > 0:
            ready, _, _ = select.select([self._fd], [], [], remaining)
            if not ready:
                continue
            for item in self._decoder.feed(os.read(self._fd, 4096)):
                if isinstance(item, Packet) and want(item):
                    return item
        raise TimeoutError("the board did not answer in time")

    def _handshake(self) -> None:
        frame = frame_packet(PacketType.CONTROL, 0, reset_payload(PROTOCOL_VERSION))
        self._serial.write(DELIMITER + frame)

        def is_reset_ack(p: Packet) -> bool:
            return (
                p.type is PacketType.CONTROL
                and parse_control(p.payload).code is ControlCode.RESET_ACK
            )

        self._read_until(is_reset_ack)

    def call(self, msg: ArduinoIn) -> float:
        """Send ``msg`` with the next id; return the seconds until its Ack was decoded."""
        mid = self._next_id
        self._next_id = mid % MAX_MESSAGE_ID + 1
        msg.message_id = mid
        frame = frame_packet(PacketType.COMMAND, self._seq, msg.SerializeToString())
        self._seq = (self._seq + 1) & 0xFF

        def is_ack(p: Packet) -> bool:
            if p.type is not PacketType.DATA:
                return False
            out = parse_out(p.payload)  # the short Ack too
            return out.WhichOneof("data") == "ack" and out.ack.message_id == mid

        start = time.perf_counter()
        self._serial.write(frame)
        self._read_until(is_ack)
        return time.perf_counter() - start


def echo_round_trips(
    port: str,
    n: int,
    *,
    warmup: int = 5,
    gap: float = 0.0,
    rng: random.Random | None = None,
) -> list[float]:
    """Seconds from writing one byte to reading its echo, ``n`` times (after ``warmup``),
    each after a random pause of up to ``gap`` seconds."""
    rng = rng or random.Random(0)
    out: list[float] = []
    with serial.Serial(port, 115200, timeout=0) as link:
        fd: int = link.fileno()
        for i in range(warmup + n):
            if gap > 0:
                time.sleep(rng.uniform(0.0, gap))
            start = time.perf_counter()
            link.write(b"x")
            got = b""
            deadline = start + RAW_TIMEOUT
            while not got:
                remaining = deadline - time.perf_counter()
                if remaining <= 0:
                    raise TimeoutError("the echo did not come back in time")
                ready, _, _ = select.select([fd], [], [], remaining)
                if ready:
                    got = os.read(fd, 64)
            if i >= warmup:
                out.append(time.perf_counter() - start)
    return out
