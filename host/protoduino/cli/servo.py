"""``protoduino servo PORT PIN ANGLE``: configure a servo and move it."""

from __future__ import annotations

import argparse

from ..board import Board
from .options import add_port, error, hold, with_board

HELP = "move a servo to ANGLE degrees (or microseconds with --us)"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("pin", type=int, metavar="PIN")
    parser.add_argument("angle", type=int, metavar="ANGLE", help="0..180 degrees, or us with --us")
    parser.add_argument("--us", action="store_true", help="ANGLE is a pulse width in microseconds")
    parser.add_argument("--safe", type=int, default=90, help="safe position in degrees (90)")
    parser.add_argument("--min-us", type=int, default=544, help="pulse for 0 degrees (544)")
    parser.add_argument("--max-us", type=int, default=2400, help="pulse for 180 degrees (2400)")
    parser.add_argument(
        "--hold",
        type=float,
        default=0.0,
        metavar="S",
        help="keep the link alive S seconds; once the host stops pinging, the device's "
        "failsafe returns the servo to --safe after 10 s",
    )


def run(args: argparse.Namespace) -> int:
    # Checked before the Init, which would move the servo to its safe position first.
    low, high = (args.min_us, args.max_us) if args.us else (0, 180)
    if not low <= args.angle <= high:
        unit = "us" if args.us else "degrees"
        return error("servo", f"{args.angle} {unit} is outside {low}..{high}; nothing sent")

    def body(board: Board) -> int:
        servo = board.servo(args.pin, safe=args.safe, min_us=args.min_us, max_us=args.max_us)
        if args.us:
            servo.write_us(args.angle)
            print(f"servo {args.pin}: {args.angle} us")
        else:
            servo.write(args.angle)
            print(f"servo {args.pin}: {args.angle} degrees")
        hold(board, args.hold)
        return 0

    return with_board("servo", args, body)
