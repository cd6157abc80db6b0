"""``protoduino monitor PORT``: live decoded traffic, events and link counters.

It opens the board like any client (handshake, 1 Hz Ping) and prints every
frame in both directions as it crosses the wire, decoded, plus the board's
events; the counters come every ``--stats-every`` seconds and at the end.

``monitor --follow CAPTURE`` watches a session that another process owns
instead (one started with ``--capture CAPTURE`` or ``Board.open(capture=)``):
it reads the capture as it grows, never the port, and shows the same lines,
with that session's own counters as it records them (about once a second).
It follows like ``tail -F``: a capture that does not exist yet is waited for,
one that a new session restarts or that rotates (``--capture-max``) is read on
from its new header; it ends at the session's end mark, at ``--duration`` or
Ctrl-C (a FIFO with no writer too). A capture whose session had already closed
is said so, and the command exits 0 at once. A damaged line (binary garbage,
not JSON, too long or nested too deep) is reported on stderr and skipped; the
command then exits 1 at the end.
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import time
from pathlib import Path
from typing import Any

from ..board import Board
from ..capture import (
    CapturedEvent,
    CapturedFrame,
    CapturedStats,
    CaptureEnd,
    CaptureHeader,
)
from ..capturefollow import follow
from ..capturereader import Damage
from ..errors import ProtoduinoError
from ..events import Event
from ..messages import packet_to_json
from ..packets import BadFrame
from ..transport import FrameRecord
from . import argtypes
from .decode import record_json
from .options import (
    add_port,
    capture_verdict,
    error,
    open_board,
)

#: Damaged capture lines reported one by one; the rest are counted.
DAMAGE_SHOWN = 10

HELP = "show live decoded traffic (readable lines or JSON) with the link counters"


def register(parser: argparse.ArgumentParser) -> None:
    add_port(parser, required=False)
    parser.add_argument(
        "--follow",
        type=Path,
        metavar="CAPTURE",
        help="show the live traffic of the session writing CAPTURE; the port is not touched",
    )
    parser.add_argument(
        "--from-start",
        action="store_true",
        help="with --follow: the whole capture first, not only what comes next",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per line")
    parser.add_argument(
        "--duration",
        type=argtypes.seconds,
        default=0.0,
        metavar="S",
        help="stop after S seconds (0: Ctrl-C)",
    )
    parser.add_argument(
        "--stats-every",
        type=argtypes.seconds,
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


def stats_line(s: dict[str, Any]) -> str:
    """The counters (``Stats.as_dict()``, or a capture's stats line) in one line."""
    dropped = sum(s.get("dropped", {}).values())
    rtt = f"{s['rtt'] * 1000:.2f} ms" if s.get("rtt") is not None else "-"
    return (
        f"[{s.get('state')}] rx {s.get('rx_packets')} tx {s.get('tx_packets')} dropped "
        f"{dropped} lost {s.get('seq_lost')} desync {s.get('seq_desyncs')} acks {s.get('acks')} "
        f"retx {s.get('retransmits')} timeouts {s.get('timeouts')} late {s.get('late_acks')} "
        f"unknown {s.get('unknown_acks')} handshakes {s.get('handshakes')} "
        f"reboots {s.get('reboots')} rtt {rtt}"
    )


def check(args: argparse.Namespace) -> str | None:
    if (args.port is None) == (args.follow is None):
        return "give either PORT or --follow CAPTURE"
    if args.from_start and args.follow is None:
        return "--from-start goes with --follow"
    if args.follow is not None and args.capture is not None:
        return "--capture records a session this command opens; --follow opens none"
    return None


def run(args: argparse.Namespace) -> int:
    if args.follow is not None:
        return follow_capture(args)
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
    return capture_verdict("monitor", board, 0)


def open_board_with_monitor(args: argparse.Namespace, sink: Any) -> Board:
    return open_board(args, ping=not args.no_ping, monitor=sink)


def print_stats(board: Board, as_json: bool) -> None:
    if as_json:
        print(json.dumps({"stats": board.stats.as_dict()}, default=str), flush=True)
    else:
        print(stats_line(board.stats.as_dict()), flush=True)


def follow_capture(args: argparse.Namespace) -> int:
    """Print a capture's records as its writer appends them, until it ends or --duration.

    Waits for a capture that does not exist yet (like ``tail -F``); says so and
    exits 0 at once for one that had already ended; reports each damaged line
    on stderr, skips it and goes on, and then exits 1 at the end.
    """
    deadline = time.monotonic() + args.duration if args.duration > 0 else float("inf")
    t0 = 0.0
    damaged = 0
    since_header = 0
    headers = 0

    def on_damage(damage: Damage) -> None:
        nonlocal damaged
        damaged += 1
        if damaged <= DAMAGE_SHOWN:  # a file of garbage must not flood the terminal
            print(f"protoduino monitor: {args.follow}: {damage}", file=sys.stderr, flush=True)

    def on_wait(text: str) -> None:
        print(f"protoduino monitor: {text} (Ctrl-C or --duration ends the wait)", file=sys.stderr)

    try:
        for record in follow(
            args.follow,
            from_start=args.from_start,
            stop=lambda: time.monotonic() >= deadline,
            on_damage=on_damage,
            on_wait=on_wait,
        ):
            if isinstance(record, CaptureHeader):
                if record.part == 1 or not headers:  # a later part goes on on the same clock
                    t0 = record.started
                since_header = 0
                headers += 1
                if not args.json:
                    part = f" (part {record.part})" if record.part > 1 else ""
                    print(f"following {args.follow}: the session on {record.url}{part}", flush=True)
                continue
            if isinstance(record, CaptureEnd) and record.rotated:
                if not args.json:
                    print(
                        f"{record.t - t0:10.3f} ROTATED the capture goes on in a new part "
                        f"(this one is now {args.follow}.1)",
                        flush=True,
                    )
                continue
            if isinstance(record, CaptureEnd):
                if not since_header and headers == 1 and not args.from_start:
                    when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(record.t))
                    print(
                        f"protoduino monitor: {args.follow}: its session had already closed at "
                        f"{when}: nothing more will come (--from-start shows it all)",
                        file=sys.stderr,
                    )
                elif not args.json:
                    print(f"{record.t - t0:10.3f} END     the session closed", flush=True)
                break
            since_header += 1
            if args.json:
                obj = record_json(record)
                obj["t"] = round(obj["t"] - t0, 6)
                print(json.dumps(obj, default=str), flush=True)
            elif isinstance(record, CapturedFrame):
                rec = FrameRecord(record.t, record.direction, record.item)
                print(frame_line(frame_json(rec, t0)), flush=True)
            elif isinstance(record, CapturedStats):
                print(stats_line(record.stats), flush=True)
            elif isinstance(record, CapturedEvent):
                print(f"{record.t - t0:10.3f} EVENT   {record.kind}: {record.text}", flush=True)
    except KeyboardInterrupt:
        pass
    except ProtoduinoError as exc:
        return error("monitor", exc)
    if damaged:
        hidden = f" ({damaged - DAMAGE_SHOWN} not shown)" if damaged > DAMAGE_SHOWN else ""
        return error("monitor", f"{args.follow}: {damaged} damaged line(s) skipped{hidden}")
    if not headers:
        return error("monitor", f"{args.follow}: no capture came within --duration")
    return 0
