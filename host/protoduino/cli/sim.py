"""``protoduino sim``: run a simulated board, in the foreground or detached.

A board started here was started on purpose: it has no owner and runs until it
is stopped (:mod:`protoduino.simboard` states the one lifetime rule).

In the foreground the board's program replaces this process (exec), so its
first stdout line, the port to connect to, is the first line the user sees, and
Ctrl-C, SIGTERM or the terminal closing (SIGHUP, unless ``nohup`` ignores it)
reach it directly for a clean exit. Build output goes to stderr, never stdout.

``--detach`` starts it in a session of its own, prints its port, writes its pid
to ``--pid-file`` and returns: the board survives the shell and the terminal,
and ``protoduino sim --stop PIDFILE`` (or ``kill PID``) stops it. Its stdin,
stdout and stderr are not the caller's (``--log FILE`` keeps its stderr), so
``PORT=$(protoduino sim --detach)`` or a pipe does not wait for it.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from ..errors import ProtoduinoError
from ..simboard import AVR_BOARDS, BACKENDS, STOP_TIMEOUT, build, command, read_port
from .options import error

HELP = "run a simulated board; prints the port to connect to first"

#: The programs a pid file may name (``--stop`` signals nothing else).
PROGRAMS = ("pd_sim", "avrsim")
STARTUP_TIMEOUT = 30.0


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--backend",
        choices=sorted(BACKENDS),
        default="native",
        help="native: the firmware core on this machine (default); avr: the emulated Uno",
    )
    parser.add_argument(
        "--board",
        choices=sorted(AVR_BOARDS),
        default="uno",
        help="the board's pins: uno (default) or mega (the Mega 2560: with --backend avr its "
        "emulated ATmega2560, natively the simulated board with the Mega's pins)",
    )
    parser.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="write one JSON line per output change: {t, pin, mode, value}",
    )
    parser.add_argument(
        "--link", type=Path, metavar="PATH", help="also make PATH a symlink to the board's port"
    )
    parser.add_argument(
        "--control",
        type=Path,
        metavar="PATH",
        help='a Unix socket driving the inputs, one JSON object per line: {"pin": 2, "level": 0}, '
        '{"pin": 14, "analog": 512}, {"pin": 3, "pulses": 100, "hz": 2000}',
    )
    parser.add_argument(
        "--firmware",
        type=Path,
        metavar="FILE",
        help="run another build: a user service's (docs/services.md), its pd_sim (native) "
        "or protoduino.elf (avr)",
    )
    parser.add_argument(
        "--detach",
        action="store_true",
        help="run the board in the background: print its port and return; it runs until "
        "stopped (--stop PIDFILE, or kill)",
    )
    parser.add_argument(
        "--pid-file", type=Path, metavar="FILE", help="with --detach: write the board's pid here"
    )
    parser.add_argument(
        "--log", type=Path, metavar="FILE", help="with --detach: append the board's stderr here"
    )
    parser.add_argument(
        "--stop",
        type=Path,
        metavar="PIDFILE",
        help="stop the detached board whose pid PIDFILE holds, wait for it to exit, remove PIDFILE",
    )


def check(args: argparse.Namespace) -> str | None:
    if (args.pid_file is not None or args.log is not None) and not args.detach:
        return "--pid-file and --log go with --detach"
    if args.stop is not None and (
        args.detach or args.trace or args.link or args.control or args.backend != "native"
    ):
        return "--stop PIDFILE takes no other option"
    return None


def run(args: argparse.Namespace) -> int:
    if args.stop is not None:
        return stop(args.stop)
    try:
        build(args.backend, args.board)
        cmd = command(
            args.backend,
            trace=args.trace,
            link=args.link,
            control=args.control,
            firmware=args.firmware,
            board=args.board,
        )
    except ProtoduinoError as exc:
        return error("sim", exc)
    if args.detach:
        return detach(cmd, args)
    try:
        os.execv(cmd[0], cmd)
    except OSError as exc:
        return error("sim", f"cannot run {cmd[0]}: {exc.strerror}")
    return 0  # pragma: no cover - execv does not return


def detach(cmd: list[str], args: argparse.Namespace) -> int:
    """Start the board in its own session, print its port, write its pid file, return."""
    try:
        log = open(args.log, "ab") if args.log is not None else None  # noqa: SIM115
    except OSError as exc:
        return error("sim", f"cannot write the log {args.log}: {exc.strerror}")
    try:
        proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=log if log is not None else subprocess.DEVNULL,
            start_new_session=True,  # no terminal, no SIGHUP from it, not the shell's job
        )
    except OSError as exc:
        return error("sim", f"cannot run {cmd[0]}: {exc.strerror}")
    finally:
        if log is not None:
            log.close()
    try:
        port = read_port(proc, time.monotonic() + STARTUP_TIMEOUT, "the board")
    except ProtoduinoError as exc:
        _end(proc.pid)
        return error("sim", exc)
    if args.pid_file is not None:
        try:
            _write_pid(args.pid_file, proc.pid)
        except OSError as exc:
            _end(proc.pid)
            return error("sim", f"cannot write the pid file {args.pid_file}: {exc.strerror}")
    assert proc.stdout is not None
    proc.stdout.close()  # the board writes nothing more there
    print(port, flush=True)
    how = f"protoduino sim --stop {args.pid_file}" if args.pid_file else f"kill {proc.pid}"
    print(f"protoduino sim: board pid {proc.pid} runs until stopped ({how})", file=sys.stderr)
    # Not waited for: this process returns and the board goes on (init adopts it).
    proc.returncode = 0  # tells Popen's finaliser not to warn about a child still running
    return 0


def _write_pid(path: Path, pid: int) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(f"{pid}\n")
    tmp.replace(path)  # a reader never sees half a pid


def stop(pid_file: Path) -> int:
    """SIGTERM the board a pid file names, wait until it is gone, remove the file."""
    try:
        pid = int(pid_file.read_text().strip())
    except OSError as exc:
        return error("sim", f"cannot read the pid file {pid_file}: {exc.strerror}")
    except ValueError:
        return error("sim", f"{pid_file} holds no pid")
    if not _is_board(pid):
        pid_file.unlink(missing_ok=True)
        return error("sim", f"no simulated board runs with pid {pid} (stale {pid_file} removed)")
    _end(pid)
    if not _gone(pid):
        return error("sim", f"the board (pid {pid}) did not exit, even after SIGKILL")
    pid_file.unlink(missing_ok=True)
    print(f"protoduino sim: board pid {pid} stopped", file=sys.stderr)
    return 0


def _end(pid: int) -> None:
    """SIGTERM, wait up to STOP_TIMEOUT, then SIGKILL (and wait again)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + STOP_TIMEOUT
        while not _gone(pid) and time.monotonic() < deadline:
            _reap(pid)
            time.sleep(0.02)
        if _gone(pid):
            return


def _reap(pid: int) -> None:
    """Collect it if it is this process's child (a --detach that failed half-way)."""
    with contextlib.suppress(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)


def _state(pid: int) -> str | None:
    """The process's state letter from /proc, None if there is no such process."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[0]


def _gone(pid: int) -> bool:
    """Exited: no such process, or a zombie its parent has not collected yet."""
    return _state(pid) in (None, "Z", "X")


def _is_board(pid: int) -> bool:
    """Whether ``pid`` runs one of the board programs (not a pid reused by another one)."""
    if _gone(pid):
        return False
    try:
        argv0 = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0", 1)[0]
    except OSError:
        return False
    return os.path.basename(argv0.decode(errors="replace")) in PROGRAMS
