"""What ``protoduino read`` and ``protoduino watch`` share: naming inputs and configuring them.

An input on the command line is ``PIN`` (a digital input), ``PIN:analog`` or
``PIN:counter``; ``--analog`` / ``--counter`` change what a bare ``PIN`` is.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

from ..arguments import Pin
from ..board import Board
from ..commands import ANALOG_INPUT, COUNTER, DIGITAL_INPUT, PinMode
from ..inputs import Input, Reading
from ..messages import InputKind
from . import argtypes
from .options import configuring

KINDS: tuple[InputKind, ...] = ("digital", "analog", "counter")


@dataclass(frozen=True, slots=True)
class Spec:
    pin: Pin  # a number or a name ("A0"), as the board's methods take it
    kind: InputKind | None  # None: the command's default


def spec(text: str) -> Spec:
    """argparse type of one input: ``PIN`` or ``PIN:KIND``."""
    pin_text, _, kind = text.partition(":")
    pin = argtypes.pin(pin_text)
    if kind and kind not in KINDS:
        raise argparse.ArgumentTypeError(f"{kind!r} is not an input kind (want {', '.join(KINDS)})")
    return Spec(pin, kind or None)


def add_input_options(parser: argparse.ArgumentParser) -> None:
    kind = parser.add_mutually_exclusive_group()
    kind.add_argument(
        "--analog",
        action="store_true",
        help="PIN is an analog input (A0, or its number: 14 on the Uno)",
    )
    kind.add_argument("--counter", action="store_true", help="PIN counts pulses")
    parser.add_argument("--pull-up", action="store_true", help="turn on the pin's pull-up")
    parser.add_argument(
        "--debounce",
        type=argtypes.integer(0, 255, name="ms"),
        default=0,
        metavar="MS",
        help="digital inputs: a level must hold MS ms to count (default: 0)",
    )
    parser.add_argument(
        "--edge",
        choices=("rising", "falling", "both"),
        default="rising",
        help="counters: which edges count (default: rising)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per line")


def default_kind(args: argparse.Namespace) -> InputKind:
    if args.analog:
        return "analog"
    return "counter" if args.counter else "digital"


#: Each kind's pin mode.
MODES: dict[InputKind, PinMode] = {
    "digital": DIGITAL_INPUT,
    "analog": ANALOG_INPUT,
    "counter": COUNTER,
}


def configure(board: Board, pin: Pin, kind: InputKind, args: argparse.Namespace) -> Input:
    with configuring(board, pin, MODES[kind]):
        if kind == "analog":
            return board.analog_input(pin)
        if kind == "counter":
            return board.counter(pin, edge=args.edge, pull_up=args.pull_up)
        return board.digital_input(pin, pull_up=args.pull_up, debounce_ms=args.debounce)


def show(kind: InputKind, reading: Reading, *, as_json: bool) -> str:
    """One input's value as a line: readable, or a JSON object."""
    value: int | bool = bool(reading.value) if kind == "digital" else reading.value
    if as_json:
        return json.dumps(
            {
                "pin": reading.pin,
                "kind": kind,
                "value": value,
                "age": round(reading.age, 6),
                "time_ms": reading.time_ms,
            }
        )
    shown = int(value) if kind == "digital" else value
    return f"pin {reading.pin} {kind}: {shown} ({reading.age * 1000:.1f} ms old)"
