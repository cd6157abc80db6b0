"""``protoduino info PORT``: what the device says about itself, and the link counters."""

from __future__ import annotations

import argparse
import dataclasses
import json

from ..board import Board
from .options import add_port, with_board

HELP = "show the device's firmware, board, pins and protocol, and the link counters"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _counter(value: object) -> str:
    if isinstance(value, dict):  # drops by reason
        return ", ".join(f"{k} {v}" for k, v in sorted(value.items())) or "0"
    if value is None:
        return "-"
    return f"{value:.6f}" if isinstance(value, float) else str(value)


def run(args: argparse.Namespace) -> int:
    def body(board: Board) -> int:
        rtt = board.ping()
        info = dataclasses.asdict(board.info)
        info["schema_id"] = f"0x{board.info.schema_id:08X}"
        info["user_fingerprint"] = f"0x{board.info.user_fingerprint:08X}"  # 0: no user service
        info["reserved_pins"] = list(board.info.reserved_pins)
        info["features"] = sorted(board.info.features)  # the pin modes built in
        for mask in ("pwm_pins", "analog_pins", "counter_pins"):
            info[mask] = list(getattr(board.info, mask))
        # The pin table as the device states it: a byte per pin, what each timer is held for.
        info["pins"] = list(board.info.pins)
        info["timers"] = [board.info.timer_use(t) for t in range(len(board.info.timers))]
        if args.json:
            print(
                json.dumps(
                    {"port": args.port, "info": info, "rtt": rtt, "stats": board.stats.as_dict()},
                    default=str,
                )
            )
            return 0
        print(f"port              {args.port}")
        for key, value in info.items():
            print(f"{key:<17} {value}")
        print(f"rtt               {rtt * 1000:.3f} ms")
        print("link counters")
        for key, value in board.stats.as_dict().items():
            if key in ("last_ping", "rtt"):  # a time.monotonic() reading; rtt is above
                continue
            print(f"{key:<17} {_counter(value)}")
        return 0

    return with_board("info", args, body, ping=False)
