"""Loader for tests/vectors/wire_v1.json, shared by the Python tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from protoduino.packets import ErrorReason

VECTORS_PATH = Path(__file__).parent / "vectors" / "wire_v1.json"

#: The vectors file names each invalid frame; this is the drop reason the
#: receiver must report for it (docs/protocol.md sections 2 and 3).
INVALID_FRAME_REASONS: dict[str, ErrorReason] = {
    "crc flipped": "crc",
    "len larger than payload": "length",
    "len smaller than payload": "length",
    "unknown type 0x07": "type",
    "short packet (4 bytes)": "length",
    "cobs code byte points past end": "cobs",
    "noise bytes": "cobs",
    "random bytes": "cobs",
}


def load() -> dict[str, Any]:
    data: dict[str, Any] = json.loads(VECTORS_PATH.read_text())
    return data
