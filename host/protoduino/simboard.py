"""Build, start and stop a simulated board: a real firmware core behind a pty.

Backends:

* ``native``: the firmware's portable core compiled for this machine with a
  POSIX HAL (``make -C firmware sim`` -> ``build/sim/pd_sim``). Needs only gcc.
* ``avr``: the firmware's Uno build (``make -C firmware avr``) on an emulated
  ATmega328P at 16 MHz (simavr, ``tools/avrsim`` -> ``build/avrsim/avrsim``),
  paced to real time; its trace is measured at the emulated pins. Needs
  avr-gcc and libsimavr-dev. Reboot = reset of the emulated MCU.

Each backend is one entry in :data:`BACKENDS`: how to build it and the command
that runs it. Every backend's program takes ``--trace FILE`` and ``--link
PATH``, prints the port to open as its first line on stdout, reboots on
SIGUSR1 (or its own equivalent, see :meth:`SimBoard.reboot`) and exits cleanly
on SIGTERM.

Typical use, in tests and in ``protoduino demo``::

    with SimBoard(trace=tmp / "trace.jsonl") as sim:
        port = sim.start()
        ...                       # talk to `port` with pyserial or Board.open
        changes = sim.trace()     # [{"t": ..., "pin": 9, "mode": "servo", "value": 1500}, ...]
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import select
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from .errors import BuildError, TransportError

logger = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
FIRMWARE_DIR = ROOT / "firmware"
BUILD = ROOT / "build"
#: make's cache is per file; this lock keeps two processes from building at once.
BUILD_LOCK = BUILD / ".build.lock"
MAKE_TIMEOUT = 300.0
STOP_TIMEOUT = 5.0
_TAIL_CHARS = 4000


@dataclass(frozen=True)
class Backend:
    """How to build one kind of simulated board and run it."""

    #: Builds everything the board needs and returns the program to run.
    build: Callable[[], Path]
    #: The full command line for the built program, given --trace and --link.
    command: Callable[[Path | None, Path | None], list[str]]


@contextlib.contextmanager
def _build_lock() -> Iterator[None]:
    BUILD.mkdir(parents=True, exist_ok=True)
    with BUILD_LOCK.open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def make(directory: Path, *targets: str) -> None:
    """Run make quietly; raise :class:`BuildError` with the tail of its output on failure."""
    if not (directory / "Makefile").is_file():
        raise BuildError(
            f"{directory / 'Makefile'} not found: the simulated board is built from a "
            "source checkout (git clone, then ./tools/dev.sh setup)"
        )
    cmd = ["make", "-s", "-C", str(directory), *targets]
    with _build_lock():
        try:
            result = subprocess.run(
                cmd, capture_output=True, text=True, check=False, timeout=MAKE_TIMEOUT
            )
        except FileNotFoundError as error:
            raise BuildError("`make` is not installed (run ./tools/dev.sh setup)") from error
        except subprocess.TimeoutExpired as error:
            raise BuildError(f"`{' '.join(cmd)}` did not finish in {MAKE_TIMEOUT:.0f} s") from error
    if result.returncode != 0:
        output = (result.stdout + result.stderr).strip()[-_TAIL_CHARS:]
        raise BuildError(f"`{' '.join(cmd)}` failed (exit {result.returncode}):\n{output}")
    logger.debug("%s: ok", " ".join(cmd))


def _build_native() -> Path:
    make(FIRMWARE_DIR, "sim")
    return BUILD / "sim" / "pd_sim"


def _native_command(trace: Path | None, link: Path | None) -> list[str]:
    cmd = [str(BUILD / "sim" / "pd_sim")]
    if trace is not None:
        cmd += ["--trace", str(trace)]
    if link is not None:
        cmd += ["--link", str(link)]
    return cmd


def _build_avr() -> Path:
    # The emulated Uno: the simavr runner (tools/avrsim) and the real firmware ELF.
    from . import emulator

    emulator.build_firmware()
    return emulator.build_runner()


def _avr_command(trace: Path | None, link: Path | None) -> list[str]:
    from . import emulator

    return emulator.runner_command(emulator.FIRMWARE_ELF, trace=trace, link=link)


#: Backend name -> how to build and run it.
BACKENDS: dict[str, Backend] = {
    "native": Backend(build=_build_native, command=_native_command),
    "avr": Backend(build=_build_avr, command=_avr_command),
}


def _backend(name: str) -> Backend:
    try:
        return BACKENDS[name]
    except KeyError:
        raise ValueError(
            f"unknown simulated board backend {name!r}; choose from {', '.join(BACKENDS)}"
        ) from None


def build(backend: str = "native") -> Path:
    """Build the board's program if needed (make caches it) and return its path."""
    return _backend(backend).build()


def command(
    backend: str = "native", *, trace: Path | None = None, link: Path | None = None
) -> list[str]:
    """The command line that runs an already built board."""
    return _backend(backend).command(trace, link)


class SimBoard:
    """One simulated board process; a context manager whose exit stops it."""

    def __init__(
        self, backend: str = "native", *, trace: Path | None = None, link: Path | None = None
    ) -> None:
        self._backend = _backend(backend)
        self.backend = backend
        self.trace_path = trace
        self.link = link
        self._proc: subprocess.Popen[bytes] | None = None
        self._port: str | None = None

    # -- lifecycle -----------------------------------------------------------

    def start(self, timeout: float = 30.0) -> str:
        """Build if needed, start the board, and return the port to open."""
        if self._proc is not None:
            raise RuntimeError("this SimBoard was already started")
        deadline = time.monotonic() + timeout
        self._backend.build()
        cmd = self._backend.command(self.trace_path, self.link)
        logger.debug("starting %s", " ".join(cmd))
        # stderr is inherited: the board writes there only when something is wrong.
        self._proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)
        try:
            self._port = self._read_port(deadline)
        except BaseException:
            self.stop()
            raise
        logger.info("%s board pid %d on %s", self.backend, self._proc.pid, self._port)
        return self._port

    def _read_port(self, deadline: float) -> str:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        fd = proc.stdout.fileno()
        line = b""
        while not line.endswith(b"\n"):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TransportError(f"the {self.backend} board printed no port in time")
            ready, _, _ = select.select([fd], [], [], min(remaining, 0.1))
            if not ready:
                continue
            chunk = os.read(fd, 256)
            if not chunk:
                code = proc.wait(timeout=STOP_TIMEOUT)
                raise TransportError(
                    f"the {self.backend} board exited (code {code}) before printing its port"
                )
            line += chunk
        return line.split(b"\n", 1)[0].decode().strip()

    @property
    def port(self) -> str:
        if self._port is None:
            raise RuntimeError("the board is not started")
        return self._port

    @property
    def pid(self) -> int:
        if self._proc is None:
            raise RuntimeError("the board is not started")
        return self._proc.pid

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def reboot(self) -> None:
        """Simulated power cycle: outputs released, link IDLE, EVENT BOOT; same port."""
        self._signal(signal.SIGUSR1)

    def kill(self) -> None:
        """Kill the board without letting it clean up: its pty disappears."""
        if self._proc is None:
            return
        if self._proc.poll() is None:
            self._proc.kill()
        self._reap(self._proc)

    def stop(self) -> None:
        """SIGTERM and wait (SIGKILL if it does not exit in time). Idempotent."""
        proc = self._proc
        if proc is None:
            return
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                logger.warning("%s board pid %d ignored SIGTERM; killing", self.backend, proc.pid)
                proc.kill()
        self._reap(proc)

    def _reap(self, proc: subprocess.Popen[bytes]) -> None:
        proc.wait()
        stdout: IO[bytes] | None = proc.stdout
        if stdout is not None:
            stdout.close()

    def _signal(self, sig: signal.Signals) -> None:
        if self._proc is None or self._proc.poll() is not None:
            raise RuntimeError("the board is not running")
        self._proc.send_signal(sig)

    def __enter__(self) -> SimBoard:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    # -- trace ---------------------------------------------------------------

    def trace(self) -> list[dict[str, Any]]:
        """Every output change written so far (a line still being written is left out)."""
        if self.trace_path is None:
            raise RuntimeError("this SimBoard was created without trace=")
        try:
            text = self.trace_path.read_text()
        except FileNotFoundError:
            return []
        changes: list[dict[str, Any]] = []
        for line in text.splitlines(keepends=True):
            if not line.endswith("\n"):
                break
            changes.append(json.loads(line))
        return changes
