"""Start and stop a simulated board: a real firmware core behind a pty.

Backends:

* ``native``: the firmware's portable core compiled for this machine with a
  POSIX HAL (the program ``pd_sim``), with the Uno's pins or, ``board="mega"``, the
  Mega 2560's (the Mega build's own table: ``pd_sim --board mega``).
* ``avr``: the firmware's Uno build on an emulated ATmega328P at 16 MHz (simavr,
  the runner ``avrsim``), paced to real time; its trace is measured at the
  emulated pins. Reboot = reset of the emulated MCU. ``board="mega"``: the
  firmware's Mega 2560 build on an emulated ATmega2560 instead (:data:`AVR_BOARDS`).

Where the programs come from (a wheel's bundled copies, or built from the
sources in a checkout) is :mod:`protoduino.programs`' business.

Each backend is one entry in :data:`BACKENDS`: how to build it and the command
that runs it. Every backend's program takes ``--trace FILE``, ``--link PATH``,
``--control PATH`` and ``--owner-fd FD``, prints the port to open as its first
line on stdout, reboots on SIGUSR1 (or its own equivalent, see
:meth:`SimBoard.reboot`) and exits cleanly on SIGTERM, SIGINT and SIGHUP
(unless SIGHUP was ignored, as ``nohup`` does).

A board's lifetime is one rule. A board a program starts for itself (a
:class:`SimBoard`: ``protoduino demo``, a test, a user's script) is OWNED: it
gets the read end of a pipe as ``--owner-fd 0`` (its stdin) whose write end
only the owner holds, and exits when that reads end-of-file, i.e. when the
owner is gone however it died (SIGKILL included); it runs in its own process
group, so a Ctrl-C meant for the owner reaches the owner, which then closes
its Board before it stops the board. A board a user starts on purpose
(``protoduino sim``, in the foreground or ``--detach``) has no owner and runs
until it is stopped (Ctrl-C, SIGTERM, ``protoduino sim --stop PIDFILE``).

The board's inputs are driven through its control socket
(:mod:`protoduino.simcontrol`): :meth:`SimBoard.set_level`,
:meth:`SimBoard.set_analog` and :meth:`SimBoard.pulses`. On the emulated Uno
they reach the real AVR's pins, external interrupts and ADC, so
the firmware's own input code (digital inputs, interlocks, analog inputs,
counters) is what a test exercises; tests/e2e/test_pins_sim.py does so through
the Board API on both boards.

The trace records every output change, PWM duties included
(``{"pin": 3, "mode": "pwm", "value": 128}``): the native board writes what it
is told, the emulated Uno what it measures at the pin (servo pulse widths, and
PWM duties from the timers' compare outputs).

Typical use, in tests and in ``protoduino demo``::

    with SimBoard(trace=tmp / "trace.jsonl") as sim:
        port = sim.start()
        ...                       # talk to `port` with pyserial or Board.open
        changes = sim.trace()     # [{"t": ..., "pin": 9, "mode": "servo", "value": 1500}, ...]
        sim.set_level(2, 0)       # a button on pin 2 pressed (to ground)
"""

from __future__ import annotations

import functools
import json
import logging
import os
import platform
import select
import shutil
import signal
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import programs
from .closing import ClosedOnExit
from .errors import ArgumentError, BuildError, TransportError
from .flashing import MCU
from .simcontrol import SimControl

logger = logging.getLogger(__name__)

STOP_TIMEOUT = 5.0


@dataclass(frozen=True)
class Backend:
    """How to build one kind of simulated board and run it."""

    #: Builds everything the board needs and returns the program to run.
    build: Callable[[], Path]
    #: The full command line for the built program, given --trace, --link, --control and
    #: another build of the board's program (a user service's; None: the backend's own).
    command: Callable[[Path | None, Path | None, Path | None, Path | None], list[str]]


def _build_native() -> Path:
    return check_loadable(programs.locate(programs.NATIVE_SIM), "the simulated board")


#: The shared libraries the boards' programs link beyond the C library, with the Debian
#: package (also Ubuntu's and Raspberry Pi OS's) that installs each. A released wheel carries
#: them (tools/build_wheels.sh); a wheel built without auditwheel or a checkout's build does not.
LIBRARY_PACKAGES = {
    "libjansson.so.4": "libjansson4",
    "libsimavr.so.2": "libsimavr2",
    "libsimavrparts.so.1": "libsimavrparts1",
    "libelf.so.1": "libelf1",
    "libz.so.1": "zlib1g",
}

#: Programs whose libraries all resolved: (path, modification time).
_loadable: set[tuple[str, int]] = set()


def missing_libraries(program: Path) -> list[str]:
    """The shared libraries that ``program`` needs and the dynamic loader cannot find.

    The loader answers itself (glibc's ``LD_TRACE_LOADED_OBJECTS``, what ``ldd`` uses), so the
    program's own RUNPATH (a wheel's bundled copies) counts, and the program does not run.
    Elsewhere than glibc the variable would run the program instead: nothing is checked.
    """
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return []
    env = {**os.environ, "LD_TRACE_LOADED_OBJECTS": "1"}
    try:
        result = subprocess.run(
            [str(program)], env=env, capture_output=True, text=True, timeout=60, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return []  # starting it will report what is wrong, with its own words
    return [
        line.split("=>", 1)[0].strip()
        for line in result.stdout.splitlines()
        if line.rstrip().endswith("not found") and "=>" in line
    ]


def check_loadable(program: Path, what: str) -> Path:
    """``program``, or :class:`BuildError` naming each library it lacks and its package.

    Checked before any board starts, so that a missing library is not reported as the
    loader's bare exit code 127.
    """
    try:
        key = (str(program), program.stat().st_mtime_ns)
    except OSError:
        return program  # starting it reports that it is missing
    if key in _loadable:
        return program
    missing = missing_libraries(program)
    if not missing:
        _loadable.add(key)
        return program
    known = [LIBRARY_PACKAGES[name] for name in missing if name in LIBRARY_PACKAGES]
    unknown = [name for name in missing if name not in LIBRARY_PACKAGES]
    how = []
    if known:
        how.append(f"sudo apt install {' '.join(known)} (Debian, Ubuntu, Raspberry Pi OS)")
    if unknown:
        how.append(f"install the package that has {', '.join(unknown)}")
    raise BuildError(
        f"{what} cannot start: its program {program} needs the shared "
        f"{'library' if len(missing) == 1 else 'libraries'} {', '.join(missing)}, "
        f"not installed here: {'; '.join(how)}"
    )


def _native_command(
    trace: Path | None,
    link: Path | None,
    control: Path | None,
    program: Path | None = None,
    *,
    board: str = "uno",
) -> list[str]:
    cmd = [str(program if program is not None else programs.locate(programs.NATIVE_SIM))]
    if board != "uno":
        cmd += ["--board", board]
    if trace is not None:
        cmd += ["--trace", str(trace)]
    if link is not None:
        cmd += ["--link", str(link)]
    if control is not None:
        cmd += ["--control", str(control)]
    return cmd


#: The boards the ``avr`` backend emulates: board -> (its firmware's program, its MCU). The
#: runner takes each board's pins from the MCU (tools/avrsim/avrsim.c), the host its pin
#: table from the firmware's DeviceInfo: a board is one line here. The native board serves
#: the same boards' pins (``pd_sim --board``, from the firmware's own tables).
AVR_BOARDS: dict[str, tuple[str, str]] = {
    "uno": (programs.FIRMWARE_ELF, MCU),
    "mega": (programs.MEGA_FIRMWARE_ELF, "atmega2560"),
}


def _avr_backend(board: str) -> Backend:
    """The emulated ``board``: the simavr runner and the real firmware ELF built for it."""
    elf, mcu = AVR_BOARDS[board]

    def build_avr() -> Path:
        programs.locate(elf)
        return check_loadable(
            programs.locate(programs.RUNNER), f"the emulated {board} (backend avr)"
        )

    def avr_command(
        trace: Path | None, link: Path | None, control: Path | None, program: Path | None = None
    ) -> list[str]:
        firmware = program if program is not None else programs.locate(elf)
        return runner_command(firmware, trace=trace, link=link, control=control, mcu=mcu)

    return Backend(build=build_avr, command=avr_command)


def runner_command(
    firmware: Path | None = None,
    *,
    runner: Path | None = None,
    trace: Path | None = None,
    link: Path | None = None,
    control: Path | None = None,
    hex_files: Sequence[Path] = (),
    boot_address: int | None = None,
    auto_reset: bool = False,
    mcu: str = MCU,
) -> list[str]:
    """The runner's command line (same options as the native board, plus flashing ones).

    ``boot_address`` starts the MCU there (BOOTRST) with the external-reset
    flag set, as after pressing reset; ``auto_reset`` resets it when a client
    opens the port while no other holds it open, as a real board's DTR line
    does. ``runner`` defaults to the located (in a checkout: freshly built)
    ``avrsim``; ``mcu`` is the emulated MCU (the Uno's by default; :data:`AVR_BOARDS`).
    """
    if runner is None:
        runner = programs.locate(programs.RUNNER)
    cmd = [str(runner), "--mcu", mcu, "--freq", "16000000"]
    if trace is not None:
        cmd += ["--trace", str(trace)]
    if link is not None:
        cmd += ["--link", str(link)]
    if control is not None:
        cmd += ["--control", str(control)]
    for hex_file in hex_files:
        cmd += ["--hex", str(hex_file)]
    if boot_address is not None:
        cmd += ["--boot", f"0x{boot_address:X}"]
    if auto_reset:
        cmd.append("--auto-reset")
    if firmware is not None:
        cmd.append(str(firmware))
    return cmd


#: Backend name -> how to build and run it.
BACKENDS: dict[str, Backend] = {
    "native": Backend(build=_build_native, command=_native_command),
    "avr": _avr_backend("uno"),
}


def _command(
    backend: Backend,
    name: str,
    *,
    trace: Path | None,
    link: Path | None,
    control: Path | None,
    firmware: Path | None,
) -> list[str]:
    """``backend``'s command line, its program checked for its shared libraries."""
    cmd = backend.command(trace, link, control, firmware)
    check_loadable(Path(cmd[0]), f"the {name} board")
    return cmd


def _backend(name: str, board: str = "uno") -> Backend:
    try:
        backend = BACKENDS[name]
    except KeyError:
        raise ArgumentError(
            f"unknown simulated board backend {name!r}; choose from {', '.join(BACKENDS)}"
        ) from None
    if board == "uno":
        return backend
    if board in AVR_BOARDS and name == "native":
        return Backend(build=_build_native, command=functools.partial(_native_command, board=board))
    if board in AVR_BOARDS and name == "avr":
        return _avr_backend(board)
    raise ArgumentError(
        f"unknown board {board!r} for backend {name!r}: the native and avr backends serve "
        f"{', '.join(AVR_BOARDS)}"
    )


def build(backend: str = "native", board: str = "uno") -> Path:
    """The board's program (in a checkout: built first, make caches it)."""
    return _backend(backend, board).build()


def command(
    backend: str = "native",
    *,
    trace: Path | None = None,
    link: Path | None = None,
    control: Path | None = None,
    firmware: Path | None = None,
    board: str = "uno",
) -> list[str]:
    """The command line that runs an already built board (``firmware``: another build
    of its program, as :class:`SimBoard` takes it; ``board``: as SimBoard's);
    :class:`BuildError` if its program lacks a shared library (:func:`check_loadable`)."""
    return _command(
        _backend(backend, board),
        backend,
        trace=trace,
        link=link,
        control=control,
        firmware=firmware,
    )


#: The option that makes a board owned: its stdin is the owner's pipe.
OWNER_FD = ["--owner-fd", "0"]


def owned(cmd: list[str]) -> list[str]:
    """``cmd`` (a board's command line) as an owned board: run it with ``stdin=PIPE`` and
    keep that pipe open for as long as the board may live (see the module docstring)."""
    return [cmd[0], *OWNER_FD, *cmd[1:]]


def read_port(proc: subprocess.Popen[bytes], deadline: float, what: str) -> str:
    """The first stdout line of a starting board: the port it made."""
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    line = b""
    while not line.endswith(b"\n"):
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TransportError(f"{what} printed no port in time")
        ready, _, _ = select.select([fd], [], [], min(remaining, 0.1))
        if not ready:
            continue
        chunk = os.read(fd, 256)
        if not chunk:
            code = proc.wait(timeout=STOP_TIMEOUT)
            raise TransportError(f"{what} exited (code {code}) before printing its port")
        line += chunk
    return line.split(b"\n", 1)[0].decode().strip()


class SimBoard(ClosedOnExit):
    """One simulated board process, owned by this one; a context manager whose exit stops it.

    ``control`` is where its input-control socket listens; by default a
    fresh temporary directory holds it (a Unix socket path must stay under
    108 bytes, which test directories often exceed).

    The native board's trace (:meth:`trace`) writes every output change it is told, at once.
    The emulated Uno's (``backend="avr"``) is measured at the emulated pins, in the mode the
    firmware configured there (the runner reads it from the MCU: a pin its PWM driver runs,
    one a channel of its servo driver drives, else a digital output), so the two boards write the
    same lines for the same writes, within a logic analyser's limits; every line is dated to
    the change on the board's clock, but some are written later, and a change shorter than
    these does not show at all:

    * Digital outputs: every level change shows at once (a pin toggled every millisecond
      shows every edge).
    * PWM: a duty of 0 or 255 (a steady level: the timer is disconnected from the pin)
      shows at once; any other duty shows once two periods in a row agree (about 2 ms at
      the Uno's 976 Hz).
    * Servos: a width shows once the next pulse has it too (a single pulse off the width is
      taken for interrupt latency), and a change smaller than 0.75 us does not show unless
      two pulses in a row round to another whole microsecond (so a width first read from a
      pulse that latency stretched is corrected by the next ones). A detached servo shows
      value 0 at once, dated to the end of its last pulse; an attached one whose pulses
      stop shows value 0 once 50 ms passed without one.
    * A program that does not record its servos and PWM pins as protoduino's firmware does
      (a hex flashed through the bootloader, StandardFirmata) is judged by its waveform: an
      output whose timer runs in a PWM mode is PWM, and shows a duty of 0 or 255 once it has
      had no edge for 5 ms (a duty of 0 held for less does not show); a high of at most 3 ms
      is a pulse, a longer one a digital 1; pulses at most 50 ms apart are a servo; a pin
      that becomes an output low shows 0 once 50 ms passed without a pulse (a servo's first
      frame may still come); a lone pulse shows as 1 then 0 once 50 ms passed without
      another.
    """

    def __init__(
        self,
        backend: str = "native",
        *,
        trace: str | os.PathLike[str] | None = None,
        link: str | os.PathLike[str] | None = None,
        control: str | os.PathLike[str] | None = None,
        firmware: str | os.PathLike[str] | None = None,
        options: Sequence[str] = (),
        board: str = "uno",
    ) -> None:
        #: The board it is: "uno", or another of :data:`AVR_BOARDS` ("mega": with backend
        #: "avr" the emulated Mega 2560 running the firmware's Mega build, with "native" the
        #: simulated board with the Mega's pins).
        self.board = board
        self._backend = _backend(backend, board)
        #: Another build of the board's program (a user service's, docs/services.md): the
        #: simulated board's binary (native), or the firmware's ELF (avr). None: the default.
        self.firmware = None if firmware is None else Path(firmware)
        #: More options of the board program, for tests: both backends take the line's
        #: (--line-check, --line-max BAUD, --line-max-out BAUD: firmware/simcontrol/pd_linerate.h),
        #: the emulated Uno its runner's too (--stats FILE ...: tools/avrsim/avrsim.c).
        self.options = tuple(options)
        self.backend = backend
        # A str names a file as well as a Path does (trace() reads it as a Path).
        self.trace_path = None if trace is None else Path(trace)
        self.link = None if link is None else Path(link)
        self._control_path = None if control is None else Path(control)
        self._control_dir: Path | None = None
        self._control: SimControl | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._port: str | None = None

    # -- lifecycle -----------------------------------------------------------

    def start(self, timeout: float = 30.0) -> str:
        """Build if needed, start the board, and return the port to open."""
        if self._proc is not None:
            raise RuntimeError("this SimBoard was already started")
        deadline = time.monotonic() + timeout
        self._backend.build()
        if self._control_path is None:
            self._control_dir = Path(tempfile.mkdtemp(prefix="protoduino-"))
            self._control_path = self._control_dir / "control"
        self._control = SimControl(self._control_path)
        # This board's backend: a subclass may bring its own.
        cmd = _command(
            self._backend,
            self.backend,
            trace=self.trace_path,
            link=self.link,
            control=self._control_path,
            firmware=self.firmware,
        )
        cmd = owned(cmd)
        cmd += self.options
        logger.debug("starting %s", " ".join(cmd))
        # stderr is inherited: the board writes there only when something is wrong.
        # stdin is the owner's pipe (module docstring); its own process group keeps a
        # terminal's Ctrl-C for this process, which stops the board after its Board closed.
        self._proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, process_group=0
        )
        try:
            self._port = self._read_port(deadline)
        except BaseException:
            self.stop()
            raise
        logger.info("%s board pid %d on %s", self.backend, self._proc.pid, self._port)
        return self._port

    def _read_port(self, deadline: float) -> str:
        assert self._proc is not None
        return read_port(self._proc, deadline, f"the {self.backend} board")

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
    def control_path(self) -> Path:
        """The board's input-control socket (see :mod:`protoduino.simcontrol`)."""
        if self._control_path is None:
            raise RuntimeError("the board is not started")
        return self._control_path

    # -- inputs --------------------------------------------------------------

    @property
    def control(self) -> SimControl:
        """The client of the board's control socket (:meth:`SimControl.send` takes any command)."""
        if self._control is None or not self.running:
            raise RuntimeError("the board is not running")
        return self._control

    def set_level(self, pin: int, level: bool | int) -> float:
        """Drive digital input ``pin`` (ends a pulse train on it); returns the board time."""
        return self.control.level(pin, level)

    def set_analog(self, pin: int, counts: int) -> float:
        """Set analog input ``pin`` (14..19 = A0..A5) to ``counts`` (0..1023)."""
        return self.control.analog(pin, counts)

    def pulses(self, pin: int, count: int, hz: int) -> float:
        """Send ``count`` pulses at ``hz`` on ``pin``, on the board's own clock.

        Each pulse leaves the pin's current level for half a period and comes
        back. Returns when the train has started (its board time); it lasts
        ``count / hz`` seconds.
        """
        return self.control.pulses(pin, count, hz)

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def reboot(self) -> None:
        """Simulated power cycle: outputs released, link IDLE, a user service's statics as at
        power-up, EVENT BOOT; same port."""
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
        for stream in (proc.stdin, proc.stdout):
            if stream is not None:
                stream.close()
        if self._control is not None:
            self._control.close()
        if self._control_dir is not None:
            shutil.rmtree(self._control_dir, ignore_errors=True)
            self._control_dir = None

    def _signal(self, sig: signal.Signals) -> None:
        if self._proc is None or self._proc.poll() is not None:
            raise RuntimeError("the board is not running")
        self._proc.send_signal(sig)

    def close(self) -> None:
        """:meth:`stop`, under the name ``with`` calls (closing.ClosedOnExit)."""
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
