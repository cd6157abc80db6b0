"""The ``fake`` and ``board`` fixtures: a scripted fake device on a pty, and a Board on it.

Imported by conftest.py. A module that tests another board (a simulated one)
defines its own ``board`` fixture, which takes precedence over this one.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from protoduino import Board
from protoduino.testing import PtyDevice


@pytest.fixture
def fake(tmp_path: Path) -> Iterator[PtyDevice]:
    """A fake device answering like the firmware; its handler can be replaced per test."""
    with PtyDevice(tmp_path) as device:
        yield device


@pytest.fixture
def board(fake: PtyDevice) -> Iterator[Board]:
    """A Board on ``fake``: short Ack timeout, no automatic Ping (tests send what they mean)."""
    with Board.open(fake.port, ack_timeout=0.1, ping=False) as b:
        yield b
