"""``protoduino decode``: a capture, or raw wire bytes, as one JSON object per frame.

A capture (``--capture FILE`` of any board command, ``Board.open(capture=)``)
is recognised by its header line; each frame then carries its time and
direction, and the link counters and events come along. Anything else is read
as the bytes of one direction of the line (raw, or hex text with ``--hex``).
``--mcap OUT`` writes an MCAP file for Foxglove instead of JSON.

It streams: the input is read in chunks and every record is written as it is
read, so memory stays the same whatever the file's size. Exit status: 0; 1
when the capture is damaged (lines that are not records, binary garbage, a
missing start: each reported on stderr, the rest still decoded) or the input
is neither a capture nor wire bytes (no frame in it); 2 when it cannot be read.
Piped into a reader that stops early (``| head``), it ends quietly with 0.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from ..capture import (
    CapturedEvent,
    CapturedFrame,
    CapturedStats,
    CaptureEnd,
    CaptureHeader,
    Record,
)
from ..capturereader import Damage, LineSplitter, RawLine, is_capture, read_capture
from ..errors import ArgumentError, ProtoduinoError
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
        header: dict[str, Any] = {
            "capture": record.url,
            "version": record.version,
            "schema_id": f"0x{record.schema_id:08X}",
            "started": record.started,
        }
        if record.part > 1:
            header["part"] = record.part
        return header
    assert isinstance(record, CaptureEnd)
    end: dict[str, Any] = {"t": record.t, "end": True}
    if record.rotated:
        end["rotated"] = True
    return end


class _Damages:
    """Damaged capture lines: the first few on stderr, all of them counted."""

    SHOWN = 10

    def __init__(self, name: str) -> None:
        self.name = name
        self.count = 0

    def __call__(self, damage: Damage) -> None:
        self.count += 1
        if self.count <= self.SHOWN:
            print(f"protoduino decode: {self.name}: {damage}", file=sys.stderr)

    def verdict(self) -> int:
        """The exit status: 1 (and a summary) if anything was damaged."""
        if not self.count:
            return 0
        hidden = f" ({self.count - self.SHOWN} not shown)" if self.count > self.SHOWN else ""
        return error(
            "decode",
            f"{self.name}: the capture is damaged: {self.count} problem(s){hidden}; "
            "what could be read is above",
        )


def run(args: argparse.Namespace) -> int:
    name = "stdin" if args.file == "-" else str(args.file)
    try:
        f: IO[bytes] = sys.stdin.buffer if args.file == "-" else open(args.file, "rb")  # noqa: SIM115
    except OSError as exc:
        print(f"protoduino decode: cannot read {args.file}: {exc.strerror}", file=sys.stderr)
        return 2
    try:
        nuls, head = _skip_nuls(f)
        if not head and not nuls:
            return error("decode", f"{name} is empty")
        if is_capture(head):
            return _capture(args, name, f, nuls, head)
        if args.mcap is not None:
            return error("decode", f"{name} is not a capture; --mcap needs one (--capture FILE)")
        return _raw(args, name, f, head)
    except BrokenPipeError:
        raise  # stdout's reader left (`| head`), not the input: main() ends quietly
    except OSError as exc:
        print(f"protoduino decode: cannot read {name}: {exc.strerror}", file=sys.stderr)
        return 2
    finally:
        if f is not sys.stdin.buffer:
            f.close()


def _skip_nuls(f: IO[bytes]) -> tuple[int, bytes]:
    """NUL bytes at the start (a capture copied while truncated begins with a hole; between
    raw frames they are empty frames), and the first chunk after them."""
    nuls = 0
    while chunk := f.read(CHUNK):
        head = chunk.lstrip(b"\0")
        nuls += len(chunk) - len(head)
        if head:
            return nuls, head
    return nuls, b""


def _chunks(f: IO[bytes], head: bytes) -> Iterator[bytes]:
    if head:
        yield head
    while chunk := f.read(CHUNK):
        yield chunk


def _raw(args: argparse.Namespace, name: str, f: IO[bytes], head: bytes) -> int:
    """Raw wire bytes (or their hex text), streamed; refused if no frame is in them."""
    chunks = _chunks(f, head)
    if args.hex:
        chunks = _unhex(chunks)
    decoder = StreamDecoder()
    out = sys.stdout
    frames = 0
    trailing = 0  # bytes after the last delimiter
    try:
        for chunk in chunks:
            for item in decoder.feed(chunk):
                frames += 1
                out.write(json.dumps(item_json(item)) + "\n")
            cut = chunk.rfind(b"\0")
            trailing = trailing + len(chunk) if cut < 0 else len(chunk) - cut - 1
    except ValueError:
        print(
            f"protoduino decode: {name} is not hex text (drop --hex for raw bytes)",
            file=sys.stderr,
        )
        return 2
    if not frames:
        hint = "" if args.hex else "; hex text needs --hex"
        return error(
            "decode",
            f"{name} is not a capture and holds no protoduino frame ({trailing} bytes without "
            f"a frame delimiter){hint}",
        )
    if trailing:
        print(
            f"protoduino decode: {name}: {trailing} bytes after the last frame delimiter "
            "(a frame cut off) were not decoded",
            file=sys.stderr,
        )
    return 0


def _unhex(chunks: Iterator[bytes]) -> Iterator[bytes]:
    """Hex text (whitespace anywhere) as bytes, chunk by chunk; ValueError if it is not."""
    carry = ""
    for chunk in chunks:
        try:
            digits = carry + "".join(chunk.decode("ascii").split())
        except UnicodeDecodeError:
            raise ArgumentError("not ASCII") from None
        cut = len(digits) - len(digits) % 2
        carry = digits[cut:]
        yield bytes.fromhex(digits[:cut])
    if carry:
        raise ArgumentError("an odd number of hex digits")


def _capture(args: argparse.Namespace, name: str, f: IO[bytes], nuls: int, head: bytes) -> int:
    damages = _Damages(name)
    if nuls:
        damages(
            Damage(
                1,
                f"the file starts with {nuls} NUL bytes (the start of this capture was lost: "
                "copied while it was being truncated?)",
            )
        )
    lines = _lines(_chunks(f, head))
    try:
        records = read_capture(lines, on_damage=damages)
        if args.mcap is not None:
            from ..mcapexport import write_mcap

            counts = write_mcap(records, args.mcap)
            print(
                f"protoduino decode: wrote {args.mcap}: "
                + ", ".join(f"{n} on {topic}" for topic, n in counts.items()),
                file=sys.stderr,
            )
        else:
            out = sys.stdout
            for record in records:
                out.write(json.dumps(record_json(record), default=str) + "\n")
    except ProtoduinoError as exc:
        return error("decode", f"{name}: {exc}")
    return damages.verdict()


def _lines(chunks: Iterator[bytes]) -> Iterator[RawLine]:
    splitter = LineSplitter()
    for chunk in chunks:
        yield from splitter.feed(chunk)
    last = splitter.finish()
    if last is not None:
        yield last
