"""``protoduino decode``: a capture, or raw wire bytes, as one JSON object per frame.

A capture (``--capture FILE`` of any board command, ``Board.open(capture=)``)
is recognised by its header line; each frame then carries its time and
direction, and the link counters and events come along. Anything else is read
as the bytes of one direction of the line (raw, or hex text with ``--hex``).
``--mcap OUT`` writes an MCAP file for Foxglove instead of JSON.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path
from typing import Any

from ..capture import (
    CapturedEvent,
    CapturedFrame,
    CapturedStats,
    CaptureEnd,
    CaptureHeader,
    Record,
    is_capture,
    read_capture,
)
from ..errors import ProtoduinoError
from ..framing import StreamDecoder
from ..messages import packet_to_json
from ..packets import BadFrame, Packet
from .options import error

HELP = "decode a capture (or raw wire bytes, or hex text with --hex) into JSON lines or MCAP"

CHUNK = 65536


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", default="-", help="capture file, or - for stdin")
    parser.add_argument(
        "--hex", action="store_true", help="raw input is hex text (whitespace ignored)"
    )
    parser.add_argument(
        "--mcap",
        type=Path,
        metavar="OUT",
        help="write the capture as MCAP with the protobuf schemas (Foxglove) instead of JSON",
    )


def item_json(item: Packet | BadFrame) -> dict[str, Any]:
    if isinstance(item, Packet):
        return packet_to_json(item)
    return {"ok": False, "error": item.reason, "raw": item.raw.hex()}


def record_json(record: Record) -> dict[str, Any]:
    """One capture record as ``decode`` prints it (times are UNIX seconds)."""
    if isinstance(record, CapturedFrame):
        return {"t": record.t, "dir": record.direction, **item_json(record.item)}
    if isinstance(record, CapturedStats):
        return {"t": record.t, "stats": record.stats}
    if isinstance(record, CapturedEvent):
        return {"t": record.t, "event": record.kind, "text": record.text, **record.details}
    if isinstance(record, CaptureHeader):
        return {
            "capture": record.url,
            "schema_id": f"0x{record.schema_id:08X}",
            "started": record.started,
        }
    assert isinstance(record, CaptureEnd)
    return {"t": record.t, "end": True}


def _raw(data: bytes, as_hex: bool) -> list[bytes]:
    if as_hex:
        text = data.decode("ascii", errors="strict")
        return [bytes.fromhex("".join(text.split()))]
    return [data[i : i + CHUNK] for i in range(0, len(data), CHUNK)]


def run(args: argparse.Namespace) -> int:
    try:
        if args.file == "-":
            data = sys.stdin.buffer.read()
        else:
            with open(args.file, "rb") as f:
                data = f.read()
    except OSError as exc:
        print(f"protoduino decode: cannot read {args.file}: {exc.strerror}", file=sys.stderr)
        return 2
    if is_capture(data[:64]):
        return _capture(args, data)
    if args.mcap is not None:
        return error("decode", f"{args.file} is not a capture; --mcap needs one (--capture FILE)")
    try:
        chunks = _raw(data, args.hex)
    except (UnicodeDecodeError, ValueError):
        print(
            f"protoduino decode: {args.file} is not hex text (drop --hex for raw bytes)",
            file=sys.stderr,
        )
        return 2
    decoder = StreamDecoder()
    out = sys.stdout
    for chunk in chunks:
        for item in decoder.feed(chunk):
            out.write(json.dumps(item_json(item)) + "\n")
    return 0


def _capture(args: argparse.Namespace, data: bytes) -> int:
    lines = io.StringIO(data.decode("utf-8", errors="replace"))
    try:
        if args.mcap is not None:
            from ..mcapexport import write_mcap

            counts = write_mcap(read_capture(lines), args.mcap)
            print(
                f"protoduino decode: wrote {args.mcap}: "
                + ", ".join(f"{n} on {topic}" for topic, n in counts.items()),
                file=sys.stderr,
            )
            return 0
        for record in read_capture(lines):
            sys.stdout.write(json.dumps(record_json(record), default=str) + "\n")
    except ProtoduinoError as exc:
        return error("decode", f"{args.file}: {exc}")
    return 0
