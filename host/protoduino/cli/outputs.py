"""``protoduino outputs PORT``: what the device drives now (ReadOutputs), changing nothing."""

from __future__ import annotations

import argparse
import dataclasses
import json

from ..board import Board
from .options import add_port, with_board

HELP = "show every output the device drives now (pin, mode, value, target), changing nothing"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    def body(board: Board) -> int:
        # The port's session is resumed (README, "The command line"): the readback shows
        # what the last command left, and releases nothing.
        outputs = board.read_outputs()
        if args.json:
            rows = [dataclasses.asdict(state) for state in outputs.values()]
            print(json.dumps({"port": args.port, "outputs": rows}))
            return 0
        if not outputs:
            print(f"{args.port}: no output configured")
            return 0
        print(f"{'pin':>3}  {'mode':<7}  {'value':>7}  {'target':>7}")
        for state in outputs.values():
            unit = " us" if state.mode == "servo" else ""
            value, target = f"{state.value}{unit}", f"{state.target}{unit}"
            print(f"{state.pin:>3}  {state.mode:<7}  {value:>7}  {target:>7}")
        return 0

    return with_board("outputs", args, body, ping=False)
