"""The user-service client layer (protoduino.services) on the pty fake (PtyDevice).

A hand-written client stands in for a generated one (the same base class and calls, with
protoduino's own Ping as request and reply message), so this tier needs no generator: the
fingerprint check, replies decoded, the handler's codes as named errors, a lost reply, the
host's own refusals, the submit form, and reports (callback and latest).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from concurrent.futures import Future
from typing import Any, ClassVar

import protoduino
import pytest
from protoduino import Board
from protoduino._generated import protoduino_pb2 as pb
from protoduino.errors import UserError
from protoduino.services import Report, ServiceClient
from protoduino.testing import PtyDevice, ack

FINGERPRINT = 0x0BADCAFE


class RefusedError(UserError):
    NAME: ClassVar[str] = "PROBE_ERROR_REFUSED"


class Probe(ServiceClient):
    PROTO = "probe.proto"
    FINGERPRINT = FINGERPRINT
    ERRORS: ClassVar[dict[int, type[UserError]]] = {7: RefusedError}

    def echo(self, request: pb.Ping, method: int = 1) -> pb.Ping:
        return self._call(method, "Echo", request, pb.Ping, pb.Ping)

    def submit_echo(self, request: pb.Ping) -> Future[pb.Ping]:
        return self._submit(1, "Echo", request, pb.Ping, pb.Ping)

    def on_level(self, callback: Any) -> Any:
        return self._on_report(5, pb.Ping, callback)

    def level(self) -> Report[pb.Ping] | None:
        return self._latest(5, pb.Ping)


def answer(fake: PtyDevice, msg: Any) -> list[Any]:
    """The fake's service: 1 echoes with a '!', 2 refuses with code 7, 3 answers without
    its reply (as a repeat from the dedupe window), 4 refuses with an undeclared code."""
    kind = msg.WhichOneof("data")
    if kind != "user_call":
        return fake.default_reply(msg)
    call = msg.user_call
    out = ack(msg.message_id)
    if call.method == 1:
        request = pb.Ping.FromString(call.request)
        out.ack.user_reply = pb.Ping(payload=request.payload + b"!").SerializeToString()
    elif call.method in (2, 4):
        out.ack.status = pb.STATUS_USER_ERROR
        out.ack.user_code = 7 if call.method == 2 else 99
    elif call.method in REFUSALS:
        out.ack.status = REFUSALS[call.method]
    return [out]


#: Methods the fake refuses with a device status, as the failsafe, an interlock or dispatch do.
REFUSALS = {
    5: pb.STATUS_INTERLOCK_ACTIVE,
    6: pb.STATUS_FAILSAFE_EXPIRED,
    7: pb.STATUS_NO_FREE_RESOURCE,
}


@pytest.fixture
def board(fake: PtyDevice) -> Iterator[Board]:
    fake.user_fingerprint = FINGERPRINT
    fake.handler = lambda msg: answer(fake, msg)
    with Board.open(fake.port, ack_timeout=0.1, ping=False) as b:
        yield b


def test_calls_replies_and_named_errors(board: Board) -> None:
    probe = Probe(board)
    assert probe.echo(pb.Ping(payload=b"hi")).payload == b"hi!"
    assert probe.submit_echo(pb.Ping(payload=b"x")).result(timeout=10).payload == b"x!"
    with pytest.raises(RefusedError) as refused:
        probe.echo(pb.Ping(), method=2)
    assert refused.value.code == 7 and "PROBE_ERROR_REFUSED" in str(refused.value)
    assert refused.value.status == pb.STATUS_USER_ERROR
    with pytest.raises(UserError) as other:
        probe.echo(pb.Ping(), method=4)
    assert type(other.value) is UserError and other.value.code == 99
    with pytest.raises(protoduino.UserReplyLostError):
        probe.echo(pb.Ping(), method=3)


def test_the_failsafes_and_an_interlocks_refusals_name_the_rpc_and_the_remedy(
    board: Board,
) -> None:
    probe = Probe(board)
    with pytest.raises(protoduino.InterlockActiveError) as interlock:
        probe.echo(pb.Ping(), method=5)
    assert str(interlock.value).startswith(
        "Echo refused by the device: STATUS_INTERLOCK_ACTIVE: an interlock input tripped"
    )
    assert "board.clear_interlock(), then call Echo again" in str(interlock.value)
    with pytest.raises(protoduino.CommandRejectedError) as expired:
        probe.echo(pb.Ping(), method=6)
    assert expired.value.status == pb.STATUS_FAILSAFE_EXPIRED
    assert "the failsafe fired" in str(expired.value)
    assert "board.ping() re-arms it, then call Echo again" in str(expired.value)
    board.liveness = "heartbeat"  # the remedy follows the board's liveness source
    with pytest.raises(protoduino.CommandRejectedError) as beat:
        probe.echo(pb.Ping(), method=6)
    assert "board.heartbeat() re-arms it" in str(beat.value)
    with pytest.raises(protoduino.CommandRejectedError) as other:  # any other: as it was
        probe.echo(pb.Ping(), method=7)
    assert str(other.value) == "user_call rejected by the device: STATUS_NO_FREE_RESOURCE"


def test_the_host_refuses_what_cannot_be_sent(board: Board, fake: PtyDevice) -> None:
    probe = Probe(board)
    sent = len(fake.arrivals("user_call"))
    with pytest.raises(protoduino.ArgumentTypeError, match=r"takes a protoduino\.Ping"):
        probe.echo(pb.Stop())  # type: ignore[arg-type]
    with pytest.raises(protoduino.ArgumentError, match="more than 64"):
        probe.echo(pb.Ping(payload=bytes(63)))
    with pytest.raises(protoduino.ArgumentError, match=r"1\.\.255"):
        board.call_user(0, b"")
    assert len(fake.arrivals("user_call")) == sent


def test_another_fingerprint_is_refused_by_name(board: Board) -> None:
    class Other(Probe):
        FINGERPRINT = 0x12345678

    with pytest.raises(protoduino.UserSchemaError) as error:
        Other(board)
    assert "probe.proto" in str(error.value)
    assert "0x12345678" in str(error.value) and f"0x{FINGERPRINT:08X}" in str(error.value)


def test_reports_reach_their_callback_and_the_latest(board: Board, fake: PtyDevice) -> None:
    probe = Probe(board)
    got: list[bytes] = []
    done = threading.Event()

    def on_level(report: Report[pb.Ping]) -> None:
        got.append(report.value.payload)
        done.set()

    probe.on_level(on_level)
    fake.user_report(5, pb.Ping(payload=b"level").SerializeToString(), coalesced=3)
    assert done.wait(10)
    assert got == [b"level"]
    latest = probe.level()
    assert latest is not None and latest.coalesced == 3 and latest.age >= 0
