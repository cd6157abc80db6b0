"""``protoduino ping PORT``: round-trip time statistics over the acknowledged link.

Like ping(8), Ctrl-C ends the run early and still prints the summary of the
pings sent so far (the one interrupted is not counted). The exit status is the
same either way: 0 when every ping counted was answered, 1 when one was lost
(ping(8) exits 0 once any reply came; a lost Ping here is worth a non-zero
status, as a script checks a link with it).
"""

from __future__ import annotations

import argparse
import statistics
import time

from ..board import MAX_PING_PAYLOAD, Board
from ..errors import AckTimeoutError
from . import argtypes
from .options import add_port, with_board

HELP = "send Pings and print round-trip time statistics"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument(
        "-c", "--count", type=argtypes.positive_count, default=10, help="pings (default: 10)"
    )
    parser.add_argument(
        "-i",
        "--interval",
        type=argtypes.seconds,
        default=0.2,
        metavar="S",
        help="seconds between pings",
    )
    parser.add_argument(
        "-s",
        "--size",
        type=argtypes.integer(0, MAX_PING_PAYLOAD, name="size"),
        default=0,
        help=f"payload bytes echoed back (0..{MAX_PING_PAYLOAD}, default 0)",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="print the summary only")


def run(args: argparse.Namespace) -> int:
    payload = bytes(i & 0xFF for i in range(args.size))

    def body(board: Board) -> int:
        rtts: list[float] = []
        lost = 0
        interrupted = False
        try:
            for n in range(args.count):
                if n:
                    time.sleep(args.interval)
                try:
                    rtt = board.ping(payload)
                except AckTimeoutError as error:
                    lost += 1
                    if not args.quiet:
                        print(f"ping {n + 1}: timeout ({error})")
                    continue
                rtts.append(rtt)
                if not args.quiet:
                    print(f"ping {n + 1}: {len(payload)} bytes, rtt {rtt * 1000:.3f} ms")
        except KeyboardInterrupt:
            interrupted = True
        sent = len(rtts) + lost
        note = " (interrupted)" if interrupted else ""
        print(f"--- {args.port}: {sent} sent, {len(rtts)} answered, {lost} lost{note}")
        if rtts:
            dev = statistics.pstdev(rtts) if len(rtts) > 1 else 0.0
            print(
                f"rtt min/avg/max/stddev = {min(rtts) * 1000:.3f}/"
                f"{statistics.fmean(rtts) * 1000:.3f}/{max(rtts) * 1000:.3f}/"
                f"{dev * 1000:.3f} ms"
            )
        stats = board.stats
        print(f"retransmits {stats.retransmits}, timeouts {stats.timeouts}", flush=True)
        return 0 if not lost else 1

    return with_board("ping", args, body)
