"""Options shared by the commands that talk to a board, and their error handling."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
import urllib.parse
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

from .. import plugins
from ..arguments import Pin
from ..board import Board, conflict
from ..boardoptions import BoardOptions
from ..capture import MIN_PART
from ..commands import PIN_MODES, PinMode
from ..constants import ACK_TIMEOUT, HANDSHAKE_TIMEOUT
from ..errors import (
    ArgumentError,
    ArgumentTypeError,
    CommandRejectedError,
    ProtoduinoError,
    TransportError,
    rejection,
)
from ..messages import Status
from ..transport import FrameMonitor
from . import argtypes

#: Refusals by the device that mean a value on the command line is wrong for it (a pin it
#: does not have or keeps for itself, found out only from its info): exit status 2.
BAD_VALUE = frozenset({Status.STATUS_INVALID_PIN, Status.STATUS_RESERVED_PIN})


def add_port(parser: argparse.ArgumentParser, *, required: bool = True) -> None:
    """PORT plus the link options every board command takes."""
    parser.add_argument(
        "port",
        metavar="PORT",
        nargs=None if required else "?",
        help="serial port or pyserial URL (/dev/ttyACM0, rfc2217://pi:7000, socket://...)",
    )
    parser.add_argument(
        "--baud",
        type=argtypes.baud,
        default=None,
        help="pin the line rate (default: open at 115200 and agree on the fastest the "
        "device offers)",
    )
    parser.add_argument(
        "--ack-timeout",
        type=argtypes.positive_seconds,
        default=ACK_TIMEOUT,
        metavar="S",
        help="seconds to wait for each Ack before a retry (default: %(default)s)",
    )
    parser.add_argument(
        "--handshake-timeout",
        type=argtypes.positive_seconds,
        default=HANDSHAKE_TIMEOUT,
        metavar="S",
        help="seconds to wait for the device to answer (default: %(default)s)",
    )
    parser.add_argument(
        "--new-session",
        action="store_true",
        help="start afresh: the device first releases every output (ReleaseAll); what "
        "this command configures stays in the port's session, for the next command",
    )
    add_capture(parser)


def add_sim(parser: argparse.ArgumentParser, *, what: str) -> None:
    """``--sim [native|avr]`` instead of PORT, and ``--trace`` with it: a simulated board
    this command starts and owns; ``what`` says what the command does with it."""
    from ..simboard import BACKENDS

    parser.add_argument(
        "--sim",
        nargs="?",
        const="native",
        choices=sorted(BACKENDS),
        help="instead of PORT: start a simulated board, native (the default) or avr (the "
        f"emulated Uno), {what}",
    )
    parser.add_argument(
        "--trace", type=Path, metavar="FILE", help="with --sim: the board's pin trace"
    )


def sim_check(args: argparse.Namespace, *sim_only: str) -> str | None:
    """A PORT or ``--sim``, one of them; ``--trace`` and each option named in ``sim_only``
    (by its attribute) only with ``--sim``."""
    if (args.port is None) == (args.sim is None):
        return "give a PORT or --sim (a simulated board), one of them"
    if args.sim is None:
        for name in ("trace", *sim_only):
            if getattr(args, name) is not None:
                return f"--{name} is the simulated board's: it needs --sim"
    return None


def add_capture(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--capture",
        type=Path,
        metavar="FILE",
        help="record every frame both ways with its time, the counters and the events "
        "(protoduino decode reads it; monitor --follow shows it live)",
    )
    parser.add_argument(
        "--capture-max",
        type=argtypes.number(MIN_PART / 1e6, name="megabytes"),
        metavar="MB",
        help="with --capture: before FILE grows past MB megabytes it is renamed FILE.1 "
        "(replacing an older one) and a new FILE goes on (default: no limit; a capture "
        "grows about 160 bytes per command, 300 MB an hour at the Uno link's full rate)",
    )


def capture_max_bytes(args: argparse.Namespace) -> int | None:
    """--capture-max in bytes, or None."""
    mb = getattr(args, "capture_max", None)
    return None if mb is None else round(mb * 1e6)


def capture_check(args: argparse.Namespace) -> str | None:
    """--capture-max goes with --capture."""
    if getattr(args, "capture_max", None) is not None and getattr(args, "capture", None) is None:
        return "--capture-max goes with --capture FILE"
    return None


def capture_verdict(command: str, board: Board, rc: int) -> int:
    """``rc``, or 1 with a message if the session's capture stopped (a full disk).

    The command itself ran to its end (a robot keeps going); its exit status
    says the record of it is incomplete.
    """
    stats = board.stats
    if stats.capture_error is None:
        return rc
    error(
        command,
        f"the capture stopped: {stats.capture_error}; {stats.capture_lost} records "
        f"({stats.capture_lost_bytes} bytes) were not written",
    )
    return rc or 1


def cli_session(port: str) -> int:
    """The host session every command on ``port`` shares (1..2**32-1, from the device's name).

    One-shot commands build on each other: the device keeps what the previous
    command configured, and an Init that repeats it changes nothing at the pin.
    The id comes from :func:`device_identity`, so the same device under another
    name (a ``/dev/serial/by-id`` link) is the same session, not a new one that
    would release every output.
    """
    return zlib.crc32(f"protoduino-cli {device_identity(port)}".encode()) or 1


def device_identity(port: str) -> str:
    """What names the device behind ``port``, whichever name it was given.

    A local port (no URL scheme) is its resolved real path: ``/dev/ttyACM0`` and a
    ``/dev/serial/by-id/...`` or ``/dev/arduino`` link to it are one device. A URL
    (``rfc2217://pi:7000``, ``socket://...``) names a port on another machine, whose
    links this host cannot resolve: it is the URL with its scheme and host in lower
    case (both are case-insensitive) and without its ``?options`` (``ign_set_control``,
    ``logging=...`` change how the port is driven, not which device it is). The host
    name is not resolved (a DNS look-up per command, and an answer that can change):
    ``rfc2217://pi:7000`` and ``rfc2217://192.168.1.5:7000`` are two sessions.
    """
    if "://" not in port:
        return os.path.realpath(port)
    parts = urllib.parse.urlsplit(port)
    return f"{parts.scheme.lower()}://{parts.netloc.lower()}{parts.path}"


def session_of(args: argparse.Namespace) -> int:
    """The session of every command on the port, ``--new-session`` included.

    The rule (README, "The command line"): no command takes the device over from the
    command line's own session. ``--new-session`` does not start another session (the
    next plain command, even a read-only ``info``, would then take the device over and
    release what it configured): it releases every output within the port's session
    (:func:`start_afresh`), so the next command resumes what it left.
    """
    return cli_session(args.port)


def start_afresh(board: Board, args: argparse.Namespace) -> None:
    """With ``--new-session``: release every output first (closing the board if that fails)."""
    if not getattr(args, "new_session", False):
        return
    try:
        board.release_all()
    except BaseException:
        board.close()
        raise


def load_url_handlers(port: str) -> None:
    """Make PORT's URL scheme known when an installed distribution declares it (``faulty://``).

    The seeded line faults are development tooling (protoduino-dev), which declares the scheme
    by entry point (:mod:`protoduino.plugins`); the runtime never imports it by name, and an
    application that imports protoduino gets no extra URL scheme.
    """
    scheme, sep, _ = port.partition("://")
    if not sep:
        return
    entry = plugins.find(plugins.SERIAL_URLS, scheme)
    if entry is not None:
        entry.load()  # importing it registers the scheme with pyserial
    elif scheme == "faulty":
        raise TransportError(
            "faulty:// URLs come with the development tools (protoduino-dev): in a source "
            "checkout run ./tools/dev.sh setup"
        )


def board_options(
    args: argparse.Namespace, *, ping: bool = True, monitor: FrameMonitor | None = None
) -> BoardOptions:
    """The board options a command's arguments give (the one place the CLI spells them)."""
    return {
        "baudrate": args.baud,
        "ack_timeout": args.ack_timeout,
        "handshake_timeout": args.handshake_timeout,
        "ping": ping,
        "monitor": monitor,
        "capture": args.capture,
        "capture_max_bytes": capture_max_bytes(args),
        "session": session_of(args),
    }


def open_board(
    args: argparse.Namespace, *, ping: bool = True, monitor: FrameMonitor | None = None
) -> Board:
    """The board of a command: the port's session, the link options, ``--new-session``."""
    load_url_handlers(args.port)
    board = Board.open(args.port, **board_options(args, ping=ping, monitor=monitor))
    start_afresh(board, args)
    return board


def exit_status(problem: object) -> int:
    """The exit status of a command that ends on ``problem`` (README, "Exit statuses"): 2 for
    a value refused before anything was sent (by the host, with the status the device would
    give, ``sent=False``; an ``ArgumentError``) and for a pin the device does not have or
    keeps for itself, known only from its info; 1 for anything else that went wrong."""
    if isinstance(problem, ArgumentError | ArgumentTypeError):
        return 2
    if isinstance(problem, CommandRejectedError):
        return 2 if not problem.sent or problem.status in BAD_VALUE else 1
    return 1


def error(command: str, problem: object) -> int:
    """Say what went wrong in one line on stderr; its exit status (:func:`exit_status`)."""
    print(f"protoduino {command}: {problem}", file=sys.stderr)
    return exit_status(problem)


def with_board(
    command: str, args: argparse.Namespace, body: Callable[[Board], int], *, ping: bool = True
) -> int:
    """Open the board, run ``body``, close it; a ProtoduinoError becomes its line and exit
    status (:func:`error`), and a capture that stopped makes it 1 (:func:`capture_verdict`)."""
    try:
        board = open_board(args, ping=ping)
    except ProtoduinoError as exc:
        return error(command, exc)
    try:
        with board:
            rc = body(board)
    except ProtoduinoError as exc:
        rc = error(command, exc)
    return capture_verdict(command, board, rc)


#: The device's refusals that the outputs it drives can explain.
IN_USE = frozenset({Status.STATUS_PIN_IN_USE, Status.STATUS_TIMER_IN_USE})
_MODES = {mode.name: mode for mode in PIN_MODES}


@contextlib.contextmanager
def configuring(board: Board, pin: Pin, mode: PinMode) -> Iterator[None]:
    """Configure ``pin`` as ``mode`` inside; a device's refusal of a pin or timer in use is
    then said as the API says its own (:func:`protoduino.board.conflict`), from what the
    device drives (``read_outputs``). A command resumes the port's session, whose outputs an
    earlier command configured: its board never saw them, so the device refuses, not the
    host, with a bare status. What no output explains (an input the session keeps) keeps it.
    """
    try:
        yield
    except CommandRejectedError as exc:
        if not exc.sent or exc.status not in IN_USE:
            raise
        try:
            held = {p: _MODES[out.mode] for p, out in board.read_outputs().items()}
        except ProtoduinoError:
            raise exc from None
        why = conflict(board.info, board.pin_number(pin), mode, held)
        if why is None or why.status != exc.status:
            raise
        raise rejection(exc.status, str(why)) from exc


def add_hold(parser: argparse.ArgumentParser, safe: str) -> None:
    """``--hold S``: the output commands' way to keep the link alive before the failsafe
    (which then does ``safe``, e.g. "sets the safe level")."""
    parser.add_argument(
        "--hold",
        type=argtypes.seconds,
        default=0.0,
        metavar="S",
        help="keep the link alive S seconds; once the host stops pinging, the device's "
        f"failsafe {safe} after 10 s",
    )


def hold(board: Board, seconds: float) -> None:
    """Keep the link (and its pings) alive for ``seconds``, so the failsafe stays away."""
    if seconds > 0:
        time.sleep(seconds)
