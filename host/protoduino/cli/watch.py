"""``protoduino watch PORT PIN...``: configure inputs and print their values live.

Each change prints a line with the value and its age (seconds since the report
that carried it reached the host); ``--every S`` also prints every input every S
seconds, so a quiet input still shows how fresh its value is. Ends after
``--duration`` seconds, after ``--count`` changes, with exit status 0, or at Ctrl-C
(130, as every command).
"""

from __future__ import annotations

import argparse
import collections
import threading
import time
from collections.abc import Callable

from ..board import Board
from ..inputs import Reading
from ..messages import InputKind
from . import argtypes
from .inputs import add_input_options, configure, default_kind, show, spec
from .options import add_port, with_board

HELP = "watch inputs live: their values and ages (PIN, PIN:analog, PIN:counter)"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument(
        "inputs", type=spec, nargs="+", metavar="PIN", help="PIN, PIN:analog or PIN:counter"
    )
    add_input_options(parser)
    parser.add_argument(
        "--every",
        type=argtypes.seconds,
        default=0.0,
        metavar="S",
        help="also print every input every S seconds (default: only changes)",
    )
    parser.add_argument(
        "--duration",
        type=argtypes.seconds,
        default=0.0,
        metavar="S",
        help="stop after S seconds (default: at Ctrl-C)",
    )
    parser.add_argument(
        "--count",
        type=argtypes.positive_count,
        metavar="N",
        help="stop after N changes (the values at the start do not count)",
    )


def check(args: argparse.Namespace) -> str | None:
    pins = [s.pin for s in args.inputs]
    if len(set(pins)) != len(pins):
        return "each pin at most once"
    return None


#: Values waiting to be printed, at most; beyond that the oldest is dropped (a
#: terminal or pipe slower than the inputs sees fresh values, not a growing backlog).
BACKLOG = 1024


class _Printer:
    """The values to print, in the order they came: filled on the I/O thread, bounded."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._items: collections.deque[tuple[InputKind, Reading]] = collections.deque()
        self.dropped = 0

    def sink(self, kind: InputKind) -> Callable[[Reading], None]:
        def put(reading: Reading) -> None:  # the I/O thread: quick, never blocks
            with self._cond:
                if len(self._items) >= BACKLOG:
                    self._items.popleft()
                    self.dropped += 1
                self._items.append((kind, reading))
                self._cond.notify()

        return put

    def get(self, timeout: float) -> tuple[InputKind, Reading] | None:
        with self._cond:
            if not self._items:
                self._cond.wait(timeout)
            return self._items.popleft() if self._items else None


def run(args: argparse.Namespace) -> int:
    def body(board: Board) -> int:
        printer = _Printer()
        watched = []
        for item in args.inputs:
            kind: InputKind = item.kind or default_kind(args)
            # Listening before the Init: its first value, and every change after it,
            # reach the printer in the order they came.
            board.inputs.add_sink(kind, board.pin_number(item.pin), printer.sink(kind))
            watched.append((kind, configure(board, item.pin, kind, args)))
        started: set[int] = set()
        changes = 0
        end = time.monotonic() + args.duration if args.duration else None
        tick = time.monotonic() + args.every if args.every else None
        while True:  # Ctrl-C: KeyboardInterrupt, exit status 130 (main)
            now = time.monotonic()
            due = min(t for t in (end, tick, now + 1.0) if t is not None)
            got = printer.get(max(0.0, due - now))
            if got is not None:
                kind, reading = got
                print(show(kind, reading, as_json=args.json), flush=True)
                if reading.pin in started:
                    changes += 1
                started.add(reading.pin)
                if args.count is not None and changes >= args.count:
                    return 0
            now = time.monotonic()
            if tick is not None and now >= tick:
                tick = now + args.every
                for kind, source in watched:
                    latest = source.reading()
                    if latest is not None:
                        print(show(kind, latest, as_json=args.json), flush=True)
            if end is not None and now >= end:
                return 0

    return with_board("watch", args, body)
