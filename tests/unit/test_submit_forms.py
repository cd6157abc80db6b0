"""Every command has a ``submit_`` form and an awaitable one (issue 20, item 12).

The README promises it; a command added without them fails here. A command is a public
method whose body sends and waits (``self._send``, ``self._rpc.call``, ``self._rpc.wait``).
"""

from __future__ import annotations

import inspect
import re
from concurrent.futures import Future

import protoduino
from protoduino import Board, aio
from protoduino.testing import PtyDevice

SENDS = re.compile(r"self\._send\(|self\._rpc\.call\(|self\._rpc\.wait\(")


def _commands(cls: type) -> list[str]:
    return [
        name
        for name, fn in inspect.getmembers(cls, inspect.isfunction)
        if not name.startswith(("_", "submit")) and SENDS.search(inspect.getsource(fn))
    ]


def test_every_board_command_has_a_submit_and_an_awaitable_form() -> None:
    commands = _commands(Board)
    # The classification itself: what the walk must find.
    assert {"heartbeat", "release", "release_all", "stop", "ping", "pose", "servo"} <= set(commands)
    for name in commands:
        assert callable(getattr(Board, f"submit_{name}", None)), f"Board.submit_{name}"
        assert inspect.iscoroutinefunction(getattr(aio.Board, name, None)), f"aio.Board.{name}"


def test_every_output_command_has_a_submit_and_an_awaitable_form() -> None:
    pairs = {
        protoduino.Servo: (aio.Servo, {"write": "submit", "write_us": "submit_us"}),
        protoduino.DigitalOutput: (aio.DigitalOutput, {"write": "submit"}),
    }
    for cls, (acls, named) in pairs.items():
        for name, fn in inspect.getmembers(cls, inspect.isfunction):
            if name.startswith(("_", "submit", "to_")) or name in ("on", "off"):
                continue
            submit = named.get(name, f"submit_{name}")
            assert callable(getattr(cls, submit, None)), f"{cls.__name__}.{submit}"
            assert inspect.iscoroutinefunction(getattr(acls, name, None)), f"aio {name}"
            assert fn is not None


def test_the_submit_forms_send_and_resolve(board: Board, fake: PtyDevice) -> None:
    servo = board.servo(9)
    board.digital_output(12)
    board.digital_output(13)
    futures: list[Future[None]] = [
        board.submit_heartbeat(),
        servo.submit_release(),
        board.submit_release(12),
    ]
    for future in futures:
        assert future.result(timeout=30) is None
    # The host forgot the outputs at the Acks; the device freed the pins.
    assert servo.value is None and sorted(fake.pins) == [13]
    assert [r.msg.release.pin for r in fake.arrivals("release")] == [9, 12]
    assert board.submit_release_all().result(timeout=30) is None
    msg = protoduino.messages.ArduinoIn()
    msg.ping.payload = b"hi"
    assert bytes(board.submit_request(msg).result(timeout=30).ping_echo) == b"hi"
    kinds = [r.kind for r in fake.arrivals()]
    assert kinds[-5:] == ["heartbeat", "release", "release", "release_all", "ping"]
