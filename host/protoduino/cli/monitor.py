"""``protoduino monitor PORT``: live decoded traffic, events and link counters.

It opens the board like any client (handshake, 1 Hz Ping) and prints every
frame in both directions as it crosses the wire, decoded, plus the board's
events; the counters come every ``--stats-every`` seconds and at the end.
"""

from __future__ import annotations

import argparse
import json
import queue
import time
from typing import Any

from ..board import Board
from ..errors import ProtoduinoError
from ..events import Event
from ..messages import packet_to_json
from ..packets import BadFrame
from ..transport import FrameRecord
from .options import add_port, error, load_url_handlers

HELP = "show live decoded traffic (readable lines or JSON) with the link counters"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser)
    parser.add_argument("--json", action="store_true", help="one JSON object per line")
    parser.add_argument(
        "--duration", type=float, default=0.0, metavar="S", help="stop after S seconds (0: Ctrl-C)"
    )
    parser.add_argument(
        "--stats-every",
        type=float,
        default=5.0,
        metavar="S",
        help="print the link counters every S seconds (0: only at the end)",
    )
    parser.add_argument("--no-ping", action="store_true", help="do not send the 1 Hz Ping")


def frame_json(rec: FrameRecord, t0: float) -> dict[str, Any]:
    obj: dict[str, Any] = {"t": round(rec.t - t0, 6), "dir": rec.direction}
    if isinstance(rec.item, BadFrame):
        obj.update(ok=False, error=rec.item.reason, raw=rec.item.raw.hex())
    else:
        obj.update(packet_to_json(rec.item))
    return obj


def frame_line(obj: dict[str, Any]) -> str:
    head = f"{obj['t']:10.3f} {obj['dir']}"
    if not obj.get("ok"):
        return f"{head} BAD {obj['error']} {obj['raw']}"
    msg = obj.get("message")
    body = json.dumps(msg, separators=(",", ":")) if msg is not None else obj.get("message_error")
    return f"{head} {obj['type']:<7} seq={obj['seq']:<3} {body}"


def stats_line(board: Board) -> str:
    s = board.stats
    dropped = sum(s.dropped.values())
    rtt = f"{s.rtt * 1000:.2f} ms" if s.rtt is not None else "-"
    return (
        f"[{s.state}] rx {s.rx_packets} tx {s.tx_packets} dropped {dropped} lost {s.seq_lost} "
        f"desync {s.seq_desyncs} acks {s.acks} retx {s.retransmits} timeouts {s.timeouts} "
        f"late {s.late_acks} unknown {s.unknown_acks} handshakes {s.handshakes} "
        f"reboots {s.reboots} rtt {rtt}"
    )


def run(args: argparse.Namespace) -> int:
    items: queue.Queue[FrameRecord | Event] = queue.Queue()
    t0 = time.monotonic()
    try:
        board = open_board_with_monitor(args, items.put)
    except ProtoduinoError as exc:
        return error("monitor", exc)
    board.on_event(items.put)
    deadline = t0 + args.duration if args.duration > 0 else float("inf")
    next_stats = time.monotonic() + args.stats_every if args.stats_every > 0 else float("inf")
    try:
        while (now := time.monotonic()) < deadline:
            try:
                item = items.get(timeout=max(0.0, min(deadline, next_stats, now + 0.5) - now))
            except queue.Empty:
                item = None
            if isinstance(item, FrameRecord):
                obj = frame_json(item, t0)
                print(json.dumps(obj) if args.json else frame_line(obj), flush=True)
            elif isinstance(item, Event):
                if args.json:
                    event = {"t": round(item.t - t0, 6), "event": item.kind.value}
                    print(json.dumps({**event, "text": item.text, **dict(item.details)}))
                else:
                    print(f"{item.t - t0:10.3f} EVENT   {item}", flush=True)
            if time.monotonic() >= next_stats:
                print_stats(board, args.json)
                next_stats += args.stats_every
    except KeyboardInterrupt:
        pass
    finally:
        print_stats(board, args.json)
        board.close()
    return 0


def open_board_with_monitor(args: argparse.Namespace, sink: Any) -> Board:
    load_url_handlers(args.port)
    return Board.open(
        args.port,
        baudrate=args.baud,
        ack_timeout=args.ack_timeout,
        handshake_timeout=args.handshake_timeout,
        ping=not args.no_ping,
        monitor=sink,
    )


def print_stats(board: Board, as_json: bool) -> None:
    if as_json:
        print(json.dumps({"stats": board.stats.as_dict()}, default=str), flush=True)
    else:
        print(stats_line(board), flush=True)
