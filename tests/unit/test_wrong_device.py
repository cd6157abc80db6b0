"""A device that does not speak protoduino is diagnosed from what it sent (or did not send)."""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest
from protoduino import Board, HandshakeError
from protoduino.link import describe_received

SKETCH = (
    b"Hello from setup! Blink sketch v2 starting, LED on pin 13, "
    b"baud 115200, waiting for nothing in particular...\r\n"
)


@contextlib.contextmanager
def pty_device(tmp_path: Path, answer: bytes) -> Iterator[str]:
    """A pty whose other end sends ``answer`` each time the host writes (as a sketch
    that prints on reset would), and nothing else."""
    master, slave = os.openpty()
    tty.setraw(slave)
    link = tmp_path / "tty"
    link.symlink_to(os.ttyname(slave))
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            ready, _, _ = select.select([master], [], [], 0.05)
            if ready:
                try:
                    os.read(master, 4096)
                except OSError:
                    return
                if answer:
                    os.write(master, answer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield str(link)
    finally:
        stop.set()
        thread.join(2.0)
        os.close(master)
        os.close(slave)


def test_a_port_full_of_text_is_named(tmp_path: Path) -> None:
    with pty_device(tmp_path, SKETCH) as port, pytest.raises(HandshakeError) as info:
        Board.open(port, handshake_timeout=0.5)
    text = str(info.value)
    assert "bytes of text, not protoduino frames: 'Hello from setup! Blink" in text
    assert "...'" in text


def test_silence_is_named(tmp_path: Path) -> None:
    with pty_device(tmp_path, b"") as port, pytest.raises(HandshakeError) as info:
        Board.open(port, handshake_timeout=0.3)
    assert "(received nothing)" in str(info.value)


def test_descriptions() -> None:
    assert describe_received(0, b"", 0) == "received nothing"
    assert describe_received(118, SKETCH[:64], 0) == (
        "received 118 bytes of text, not protoduino frames: "
        "'Hello from setup! Blink sketch v2 starti...'"
    )
    assert describe_received(5, b"hi\r\n\x00", 0) == (
        "received 5 bytes of text, not protoduino frames: 'hi'"
    )
    assert describe_received(3, b"\xff\xfe\x01", 0) == (
        "received 3 bytes, not protoduino frames: ff fe 01"
    )
    assert describe_received(90, bytes(range(1, 65)), 0).endswith("0f 10 ...")
    assert describe_received(40, b"\x01\x02", 2) == "received 2 protoduino frames but no RESET_ACK"


def test_a_device_that_answered_before_is_not_blamed_on_the_firmware(tmp_path: Path) -> None:
    """Issue 20, item 1: a re-handshake that times out says what is known, not "flash it"."""
    from protoduino import Event, EventKind
    from protoduino.testing import PtyDevice

    with PtyDevice(tmp_path) as fake:
        board = Board.open(fake.port, ack_timeout=0.1, handshake_timeout=0.3, ping=False)
        with board:
            failed = threading.Event()
            texts: list[str] = []

            def record(event: Event) -> None:
                if event.kind is EventKind.DISCONNECTED and "RESET" in event.text:
                    texts.append(event.text)
                    failed.set()

            board.on_event(record)
            fake.answer_reset = False
            fake.reboot()  # EVENT BOOT: the board handshakes again, and hears nothing
            assert failed.wait(30.0)
            with pytest.raises(HandshakeError) as info:
                board.ping()  # waits for the link, then fails with the same reason
    for text in (texts[0], str(info.value)):
        assert "firmware is flashed" not in text
        assert "answered this board before" in text
        assert "0.3 s" in text
