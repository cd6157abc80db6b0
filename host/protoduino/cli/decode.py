"""``protoduino decode``: turn a capture of wire bytes into one JSON object per frame."""

from __future__ import annotations

import argparse
import json
import sys
from typing import BinaryIO

from ..framing import StreamDecoder
from ..messages import packet_to_json
from ..packets import Packet

HELP = "decode a capture of wire bytes (raw, or hex text with --hex) into JSON lines"

CHUNK = 65536


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", default="-", help="capture file, or - for stdin")
    parser.add_argument(
        "--hex", action="store_true", help="the input is hex text (whitespace ignored)"
    )


def _chunks(stream: BinaryIO, as_hex: bool) -> list[bytes]:
    data = stream.read()
    if as_hex:
        text = data.decode("ascii", errors="strict")
        return [bytes.fromhex("".join(text.split()))]
    return [data[i : i + CHUNK] for i in range(0, len(data), CHUNK)]


def run(args: argparse.Namespace) -> int:
    try:
        if args.file == "-":
            chunks = _chunks(sys.stdin.buffer, args.hex)
        else:
            with open(args.file, "rb") as f:
                chunks = _chunks(f, args.hex)
    except OSError as error:
        print(f"protoduino decode: cannot read {args.file}: {error.strerror}", file=sys.stderr)
        return 2
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
            if isinstance(item, Packet):
                obj = packet_to_json(item)
            else:
                obj = {"ok": False, "error": item.reason, "raw": item.raw.hex()}
            out.write(json.dumps(obj) + "\n")
    return 0
