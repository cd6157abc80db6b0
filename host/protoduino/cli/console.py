"""``protoduino console PORT``: the live console, a local web page that shows and drives a board.

It opens the board with ``liveness="heartbeat"`` (the page's heartbeat is the only sign of
life: docs/console.md), configures the example robot with ``--example`` (the default with
``--sim``, which starts a simulated board owned by this process, as ``protoduino ros2
--sim`` does), prints the page's URL (with its access token when it listens on another
address than 127.0.0.1), with ``--foxglove`` also the board's live channels for Foxglove
(:mod:`protoduino.console.foxglovelive`), and serves until Ctrl-C or SIGTERM, which stop the
board's outputs (the device's Stop) before it closes.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
from types import FrameType

from ..errors import ProtoduinoError
from . import argtypes
from .options import add_port, add_sim, board_options, error, load_url_handlers, sim_check

HELP = "a live web page that shows the board and drives it (see docs/console.md)"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser, required=False)
    add_sim(parser, what="with the example robot; it stops with the console")
    parser.add_argument(
        "--example",
        action="store_true",
        help="configure the example robot's pins (docs/console.md; the default with --sim)",
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="the address to listen on (default 127.0.0.1: this machine only; any other "
        "needs the access token printed at start)",
    )
    parser.add_argument(
        "--http-port",
        type=argtypes.integer(0, 65535, name="port"),
        default=8037,
        metavar="N",
        help="the TCP port of the page (default 8037; 0: any free one)",
    )
    parser.add_argument(
        "--token",
        metavar="TOKEN",
        help="the access token (default: made at start when --host is not 127.0.0.1)",
    )
    parser.add_argument(
        "--failsafe-timeout",
        type=argtypes.number(0.1, 60.0, name="failsafe timeout"),
        default=2.0,
        metavar="S",
        help="seconds without the driving page's heartbeat before the device drives every "
        "output safe (default 2)",
    )
    parser.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=argtypes.integer(0, 65535, name="port"),
        metavar="N",
        help="also serve the board's live channels to Foxglove on ws://127.0.0.1:N (default "
        "8765): the MCAP export's channels, read-only (pip install 'protoduino[foxglove]')",
    )
    parser.add_argument(
        "--window",
        type=argtypes.number(1.0, 600.0, name="window"),
        default=30.0,
        metavar="S",
        help="seconds of input history the plots show (default 30)",
    )


def check(args: argparse.Namespace) -> str | None:
    return sim_check(args)


def run(args: argparse.Namespace) -> int:
    if args.sim is None:
        return _serve(args, example=args.example)
    from ..simboard import SimBoard

    try:
        with SimBoard(args.sim, trace=args.trace) as sim:
            args.port = sim.start()
            print(f"protoduino console: simulated board ({args.sim}) on {args.port}", flush=True)
            return _serve(args, example=True)
    except ProtoduinoError as exc:
        return error("console", exc)


def _serve(args: argparse.Namespace, *, example: bool) -> int:
    from .. import Board
    from ..console import EXAMPLE_ROBOT, ConsoleServer, LiveBoard

    done = threading.Event()

    def stop(signum: int, frame: FrameType | None) -> None:
        done.set()

    try:
        load_url_handlers(args.port)
        options = board_options(args)
        options["liveness"] = "heartbeat"  # the driving page's heartbeat: docs/console.md
        options["failsafe_timeout"] = args.failsafe_timeout
        with Board.open(args.port, **options) as board:
            live = LiveBoard(board, window=args.window)
            if example:
                live.configure_all(EXAMPLE_ROBOT)
            server = ConsoleServer(live, host=args.host, port=args.http_port, token=args.token)
            signal.signal(signal.SIGTERM, stop)
            signal.signal(signal.SIGINT, stop)
            with server, contextlib.ExitStack() as stack:
                print(f"protoduino console: open {server.url}", flush=True)
                if args.foxglove is not None:
                    from ..console.foxglovelive import FoxgloveLive

                    live_channels = stack.enter_context(FoxgloveLive(board, port=args.foxglove))
                    print(f"protoduino console: Foxglove on {live_channels.url}", flush=True)
                done.wait()
            board.stop()
    except ProtoduinoError as exc:
        return error("console", exc)
    except OSError as exc:  # the HTTP port is taken
        return error("console", exc)
    except ImportError as exc:  # --foxglove without the foxglove extra
        return error("console", f"{exc}: pip install 'protoduino[foxglove]'")
    print("protoduino console: stopped", file=sys.stderr)
    return 0
