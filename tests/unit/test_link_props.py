"""Property tests: the receive path and the link state machine take anything without breaking.

The decoder and the parsers may refuse input only with the project's own
errors. The link (``protoduino.link``) with the request layer above it
(``protoduino.rpc``) is driven by a hypothesis state machine through exactly
the callbacks the transport's I/O thread makes: arbitrary bytes and packets,
RESET_ACKs with right and wrong versions and schemas, events, SEQ jumps,
Acks for known and unknown ids, ticks far into the future, a lost and
reopened port. Nothing may escape those callbacks: on the I/O thread any
exception would kill the board.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

import hypothesis.strategies as st
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
)
from protoduino import rpc as rpc_module
from protoduino._generated.schema_id import SCHEMA_ID
from protoduino.constants import MAX_PAYLOAD, ControlCode, EventCode, PacketType
from protoduino.errors import ProtoduinoError, TransportError
from protoduino.events import Event
from protoduino.framing import StreamDecoder, decode_frame
from protoduino.link import Link, LinkState
from protoduino.messages import ArduinoIn, ArduinoOut, parse_in, parse_out, pin_set
from protoduino.packets import BadFrame, Packet, event_payload, parse_control, reset_ack_payload
from protoduino.rpc import Rpc
from protoduino.transport import TransportListener

# --- pure receive path ------------------------------------------------------------------


@given(st.lists(st.binary(max_size=400), max_size=8))
def test_stream_decoder_takes_any_bytes(chunks: list[bytes]) -> None:
    decoder = StreamDecoder()
    for chunk in chunks:
        for item in decoder.feed(chunk):
            assert isinstance(item, Packet | BadFrame)
            if isinstance(item, Packet):
                assert item.type in tuple(PacketType) and len(item.payload) <= MAX_PAYLOAD


PARSERS: list[Callable[[bytes], object]] = [parse_control, parse_in, parse_out, decode_frame]


@pytest.mark.parametrize("parse", PARSERS, ids=lambda f: f.__name__)
@given(data=st.binary(max_size=300))
def test_parsers_refuse_only_with_protocol_errors(
    parse: Callable[[bytes], object], data: bytes
) -> None:
    with contextlib.suppress(ProtoduinoError):
        parse(data)


# --- the link state machine ---------------------------------------------------------------


class FakeClock:
    """The clock the link and the request layer are given: it moves when the test moves it."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class FakeTransport:
    """What Link uses of a Transport, recording what would be written."""

    def __init__(self) -> None:
        self.url = self.name = "fake://"
        self.connected = True
        self.rx_since_open = 0
        self.rx_head = b""
        self.sent: list[tuple[PacketType, bytes, bool]] = []

    def start(self, listener: TransportListener) -> None:
        pass  # the machine calls the listener itself
        self.rx_since_open = 0  # what the link reports when the handshake fails
        self.rx_head = b""

    def send(self, ptype: PacketType, payload: bytes, *, reset_seq: bool = False) -> None:
        self.sent.append((ptype, payload, reset_seq))

    def clear_queue(self) -> None:
        pass

    #: The line rate the link set (Link's RESET retries may change it; no rate is emulated).
    baudrate = 115200

    def set_baudrate(self, rate: int) -> None:
        self.baudrate = rate

    def recent_frames(self) -> tuple[str, ...]:
        return ()

    def close(self) -> None:
        self.connected = False

    def command_ids(self) -> list[int]:
        ids = []
        for ptype, payload, _ in self.sent[-40:]:
            if ptype is PacketType.COMMAND:
                msg = ArduinoIn()
                msg.ParseFromString(payload)
                ids.append(msg.message_id)
        return ids


#: None: the SEQ the host expects (mostly), else any SEQ (a gap or a desync).
seqs: st.SearchStrategy[int | None] = st.integers(0, 9).flatmap(
    lambda k: st.none() if k < 8 else st.integers(0, 255)
)


class LinkMachine(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.clock = FakeClock()
        self.events: list[Event] = []
        self.transport = FakeTransport()
        self.rpc = Rpc(
            notify=self.events.append, ack_timeout=0.25, ping=True, window=4, clock=self.clock
        )
        self.link = Link(
            self.transport,
            self.rpc,
            handshake_timeout=5.0,
            notify=self.events.append,
            clock=self.clock,
            next_id=self.rpc.next_message_id,
        )
        self.rpc.attach(self.link)
        self.decoder = StreamDecoder()
        self.calls: list[rpc_module.Call] = []

    # Every callback the I/O thread makes must return normally, whatever it is given.
    def _io(self, fn: Callable[..., object], *args: Any) -> None:
        fn(*args)

    def _seq(self, seq: int | None) -> int:
        return self.link.expected_seq if seq is None else seq

    def _packet(self, ptype: PacketType, seq: int | None, payload: bytes) -> None:
        self._io(self.link.transport_received, [Packet(ptype, self._seq(seq), payload)])

    @initialize(reopened=st.booleans(), handshake=st.booleans())
    def open(self, reopened: bool, handshake: bool) -> None:
        self._io(self.link.transport_opened, reopened)
        if handshake:  # most runs start ACTIVE, to reach the request layer quickly
            self._packet(PacketType.CONTROL, 0, reset_ack_payload(1, SCHEMA_ID))

    @rule(data=st.binary(max_size=300))
    def raw_bytes(self, data: bytes) -> None:
        self._io(self.link.transport_received, self.decoder.feed(data))

    @rule(ptype=st.sampled_from(PacketType), seq=seqs, payload=st.binary(max_size=40))
    def any_packet(self, ptype: PacketType, seq: int | None, payload: bytes) -> None:
        self._packet(ptype, seq, payload)

    @rule(seq=st.sampled_from([0, 0, 7]))
    def reset_ack(self, seq: int) -> None:
        self._packet(PacketType.CONTROL, seq, reset_ack_payload(1, SCHEMA_ID))

    @rule(
        version=st.sampled_from([1, 0, 2, 255]),
        schema=st.sampled_from([SCHEMA_ID, SCHEMA_ID ^ 1, 0]),
        rare=st.integers(0, 9),
    )
    def reset_ack_mismatch(self, version: int, schema: int, rare: int) -> None:
        # A mismatch fails the link for good: rarely, so that runs go on past it.
        if rare == 0:
            self._packet(PacketType.CONTROL, 0, reset_ack_payload(version, schema))

    @rule(
        code=st.one_of(st.sampled_from(EventCode), st.integers(0, 255)),
        detail=st.binary(max_size=4),
        seq=seqs,
    )
    def device_event(self, code: int, detail: bytes, seq: int | None) -> None:
        self._packet(PacketType.CONTROL, seq, event_payload(int(code), detail))

    @rule(code=st.integers(0, 255), seq=seqs, rest=st.binary(max_size=6))
    def control(self, code: int, seq: int | None, rest: bytes) -> None:
        self._packet(PacketType.CONTROL, seq, bytes([code]) + rest)

    @rule(
        pick=st.integers(0, 50),
        status=st.integers(0, 15),
        echo=st.one_of(st.none(), st.binary(max_size=8)),
        seq=seqs,
        twice=st.booleans(),
    )
    def ack(self, pick: int, status: int, echo: bytes | None, seq: int | None, twice: bool) -> None:
        ids = self.transport.command_ids()
        out = ArduinoOut()
        out.ack.message_id = ids[pick % len(ids)] if ids and pick < 40 else pick * 7919
        out.ack.status = status  # type: ignore[assignment]
        if echo is not None:
            out.ack.ping_echo = echo
        for _ in range(2 if twice else 1):
            self._packet(PacketType.DATA, seq, out.SerializeToString())

    @rule(seq=seqs, status=st.sampled_from([0, 0, 0, 4]))
    def device_answers(self, seq: int | None, status: int) -> None:
        """A well-behaved device: one Ack for each command in flight, echo included."""
        for call in self.rpc.state().inflight:
            out = ArduinoOut()
            out.ack.message_id = call.message_id
            out.ack.status = status  # type: ignore[assignment]
            out.ack.ping_echo = parse_in(call.payload).ping.payload
            self._packet(PacketType.DATA, seq, out.SerializeToString())

    @rule(kind=st.sampled_from(["failsafe", "input_report", "decode_error"]), seq=seqs)
    def device_message(self, kind: str, seq: int | None) -> None:
        out = ArduinoOut()
        if kind == "failsafe":
            out.failsafe.active = True
            out.failsafe.cause = 1  # type: ignore[assignment]
        elif kind == "input_report":
            out.input_report.digital_pins = pin_set(1 << 2)
        else:
            out.decode_error.count = 3
        self._packet(PacketType.DATA, seq, out.SerializeToString())

    @rule(dt=st.one_of(st.floats(0, 0.3), st.floats(0, 12)))
    def tick(self, dt: float) -> None:
        self.clock.now += dt
        self._io(self.link.transport_tick, self.clock.now)

    @rule()
    def port_lost(self) -> None:
        self.transport.connected = False
        self._io(self.link.transport_lost, TransportError("port vanished"))

    @precondition(lambda self: not self.transport.connected)
    @rule()
    def port_back(self) -> None:
        self.transport.connected = True
        self._io(self.link.transport_opened, True)

    @rule(payload=st.binary(max_size=8))
    def submit(self, payload: bytes) -> None:
        msg = ArduinoIn()
        msg.ping.payload = payload
        # A call may be refused (the board is closed), with the project's errors only.
        with contextlib.suppress(ProtoduinoError):
            self.calls.append(self.rpc.submit(msg))

    @rule(on=st.booleans())
    def pinging(self, on: bool) -> None:
        self.rpc.pinging = on

    @precondition(lambda self: len(self.calls) > 30)
    @rule()
    def close(self) -> None:
        self.rpc.close()
        self.link.close()

    @invariant()
    def consistent(self) -> None:
        assert self.link.state in tuple(LinkState)
        rpc = self.rpc
        state = rpc.state()
        assert len(state.inflight) <= rpc.window
        assert all(call.message_id in state.open_calls for call in state.inflight)
        # The call bound: no call awaits its Ack past its round of retries, even after
        # a tick far later than due.
        for call in state.inflight:
            assert self.clock.now < call.round_start + rpc.round_time
        for call in self.calls:
            if call.done.is_set():
                assert (call.ack is None) != (call.error is None)
                assert call.error is None or isinstance(call.error, ProtoduinoError)
        if self.link.state is LinkState.ACTIVE:
            assert self.link.down_error is None
        # Sent frames respect the protocol: RESET with SEQ 0, payloads within bounds.
        for ptype, payload, reset_seq in self.transport.sent[-5:]:
            assert len(payload) <= MAX_PAYLOAD
            if reset_seq:
                assert ptype is PacketType.CONTROL and payload[0] == ControlCode.RESET


LinkMachine.TestCase.settings = settings(
    max_examples=150,
    stateful_step_count=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
test_link_state_machine = LinkMachine.TestCase
