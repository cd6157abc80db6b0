"""protoduino: a realistic device-to-host stream, its receive path, and the servo command bytes.

Everything here uses the project's own encoders and decoders (``framing``, ``packets``,
``messages`` and the generated ``protoduino_pb2``); nothing is built by hand.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Iterable
from typing import Protocol

from protoduino import framing
from protoduino._generated import protoduino_pb2 as pb
from protoduino.constants import MAX_MESSAGE_ID, ControlCode, EventCode, PacketType
from protoduino.errors import ProtocolError
from protoduino.framing import COBS_NATIVE, PyStreamDecoder, frame_packet
from protoduino.messages import parse_out, pin_set, serialize_out
from protoduino.packets import BadFrame, Packet, event_payload, parse_control

from . import RxCase, Slot, WireSample, chunked

#: A session's first message id: since protocol version 5 ids are 1..127 per session, one
#: varint byte (until version 4 a random 32-bit start made them 5 bytes in 15 cases of 16).
FIRST_MESSAGE_ID = 1

#: What a busy link's device-to-host traffic is made of, by weight: one Ack per command or Ping
#: (some with a non-OK status, Pings echoing 8 bytes), the inputs' reports, the occasional
#: CONTROL EVENT and Failsafe event. (Until protocol version 3 the mix had a CONTROL HEARTBEAT
#: and a Log event in the places of the last two, although no device sent either.)
MIX: tuple[tuple[str, int], ...] = (
    ("Ack OK (command)", 60),
    ("Ack with a non-OK status", 5),
    ("Ack echoing an 8-byte Ping", 10),
    ("CONTROL EVENT", 15),
    ("Failsafe event", 4),
    ("InputReport", 6),
)


class Decoder(Protocol):
    """What the receive path needs from a stream decoder (``framing.StreamDecoder``'s API)."""

    def feed(self, data: bytes) -> list[Packet | BadFrame]: ...


#: protoduino's two stream decoders, measured side by side: ``framing.StreamDecoder`` is the C
#: accelerator (``protoduino._speedups``) where it was built, ``PyStreamDecoder`` the pure-Python
#: reference and fallback. Without a build only the latter is listed.
DECODERS: tuple[tuple[str, Callable[[], Decoder]], ...] = (
    *((("protoduino (C accelerator)", framing.StreamDecoder),) if framing.ACCELERATED else ()),
    ("protoduino (pure Python)", PyStreamDecoder),
)


def parser_kind(decoder: Callable[[], Decoder]) -> str:
    """How ``decoder`` turns bytes into packets, for the report."""
    if decoder is PyStreamDecoder:
        cobs = "C extension" if COBS_NATIVE else "pure-Python fallback"
        return (
            f"pure Python (`PyStreamDecoder`); COBS from `cobs` ({cobs}), CRC from "
            "`binascii.crc_hqx`; protobuf upb"
        )
    if framing.ACCELERATED and decoder is framing.StreamDecoder:
        return (
            "C (`protoduino._speedups`: one call per read; the firmware's own pd_cobs.c, its "
            "pd_crc.c through a 256-entry table); protobuf upb"
        )
    return getattr(decoder, "__qualname__", repr(decoder))


class StandInRequestLayer:
    """The per-packet work of the link and request layers, without threads or I/O.

    For each packet: SEQ accounting as docs/protocol.md section 6 asks, then DATA is parsed as
    ``ArduinoOut`` with the project's ``messages.parse_out`` and an Ack resolves its pending call
    by ``message_id`` (a dict lookup, as a request layer keyed by id does), while events and
    CONTROL packets go to a listener. What it leaves out (locks, futures, logging) would cost the
    same whichever decoder fed it.
    """

    __slots__ = (
        "bad",
        "dispatched",
        "events",
        "expected_seq",
        "listener",
        "lost",
        "parse",
        "pending",
    )

    def __init__(
        self,
        pending: dict[int, Slot],
        listener: Callable[[object], None] | None = None,
        parse: Callable[[bytes], pb.ArduinoOut] = parse_out,
    ) -> None:
        self.pending = pending
        self.parse = parse
        self.listener: Callable[[object], None] = listener or (lambda _event: None)
        self.expected_seq = 0
        self.lost = 0
        self.events = 0
        self.bad = 0
        self.dispatched = 0

    def on_items(self, items: Iterable[Packet | BadFrame]) -> None:
        for item in items:
            if isinstance(item, Packet):
                self.on_packet(item)
            else:
                self.bad += 1

    def on_packet(self, packet: Packet) -> None:
        lost = (packet.seq - self.expected_seq) & 0xFF
        if lost:
            self.lost += lost
        self.expected_seq = (packet.seq + 1) & 0xFF
        if packet.type is PacketType.DATA:
            try:
                msg = self.parse(packet.payload)
            except ProtocolError:
                self.bad += 1
                return
            if msg.WhichOneof("data") == "ack":
                ack = msg.ack
                waiter = self.pending.get(ack.message_id)
                if waiter is not None:
                    waiter.value = ack
            else:
                self.events += 1
                self.listener(msg)
        elif packet.type is PacketType.CONTROL:
            try:
                control = parse_control(packet.payload)
            except ProtocolError:
                self.bad += 1
                return
            if control.code is ControlCode.EVENT:
                self.events += 1
                self.listener(control)
        else:  # a COMMAND reaching the host is dropped and counted (section 4)
            self.bad += 1
            return
        self.dispatched += 1


def mixed_stream(frames: int, seed: int) -> tuple[bytes, list[int]]:
    """``frames`` device-to-host frames drawn from :data:`MIX`; returns the bytes and the ids
    of every Ack (the calls a request layer would have pending)."""
    rng = random.Random(seed)
    kinds = [name for name, _ in MIX]
    weights = [weight for _, weight in MIX]
    next_id = FIRST_MESSAGE_ID
    ids: list[int] = []
    out: list[bytes] = []
    for seq_count in range(frames):
        seq = seq_count & 0xFF
        kind = rng.choices(kinds, weights)[0]
        if kind == "CONTROL EVENT":
            out.append(frame_packet(PacketType.CONTROL, seq, event_payload(EventCode.DESYNC)))
            continue
        msg = pb.ArduinoOut()
        if kind.startswith("Ack"):
            msg.ack.message_id = next_id
            ids.append(next_id)
            next_id = next_id % MAX_MESSAGE_ID + 1
            if kind == "Ack with a non-OK status":
                msg.ack.status = pb.STATUS_OUT_OF_RANGE
            elif kind == "Ack echoing an 8-byte Ping":
                msg.ack.ping_echo = rng.randbytes(8)
        elif kind == "Failsafe event":
            msg.failsafe.active = rng.random() < 0.5
            msg.failsafe.cause = pb.FAILSAFE_CAUSE_PING_TIMEOUT
        else:
            msg.input_report.digital_pins = pin_set(1 << 7)
            msg.input_report.digital_levels = pin_set(rng.getrandbits(1) << 7)
        # An Ack with only its id and STATUS_OK goes short (ack_ok), as the firmware sends it.
        out.append(frame_packet(PacketType.DATA, seq, serialize_out(msg)))
    return b"".join(out), ids


def rx_case(
    frames: int,
    chunk: int,
    seed: int,
    *,
    decoder: Callable[[], Decoder] = framing.StreamDecoder,
    parse: Callable[[bytes], pb.ArduinoOut] = parse_out,
    name: str = "protoduino",
    stages: str = "",
) -> RxCase:
    """The full receive path: stream decoder -> packets -> ArduinoOut -> stand-in request layer.

    ``decoder`` and ``parse`` default to the project's own.
    """
    stream, ids = mixed_stream(frames, seed)
    chunks = chunked(stream, chunk)
    pending = {message_id: Slot() for message_id in ids}

    def run() -> int:
        dec = decoder()
        layer = StandInRequestLayer(pending, parse=parse)
        for data in chunks:
            layer.on_items(dec.feed(data))
        return layer.dispatched

    return RxCase(
        name=name,
        package="protoduino",
        parser=parser_kind(decoder),
        stages=stages
        or "StreamDecoder.feed -> Packet -> messages.parse_out (ArduinoOut) or parse_control -> "
        "SEQ check, Ack resolved by message_id in a dict, events to a listener",
        stream=stream,
        frames=frames,
        run=run,
    )


def framing_only_case(
    frames: int,
    chunk: int,
    seed: int,
    *,
    decoder: Callable[[], Decoder] = framing.StreamDecoder,
    name: str = "protoduino, framing only",
) -> RxCase:
    """The same stream through the stream decoder alone: the framing layer's share."""
    stream, _ids = mixed_stream(frames, seed)
    chunks = chunked(stream, chunk)

    def run() -> int:
        dec = decoder()
        good = 0
        for data in chunks:
            for item in dec.feed(data):
                if isinstance(item, Packet):
                    good += 1
        return good

    return RxCase(
        name=name,
        package="protoduino",
        parser=parser_kind(decoder),
        stages="stream decoder -> Packet, nothing parsed or dispatched",
        stream=stream,
        frames=frames,
        run=run,
    )


def payload_case(frames: int, chunk: int, seed: int, *, control: bool, name: str = "") -> RxCase:
    """The payloads of the same stream, already out of the decoder, through the parsing the
    request layer does: ``messages.parse_out`` for DATA (``control=False``) or
    ``packets.parse_control`` for CONTROL. Timed over the whole stream, so its time per stream
    frame is that stage's share of the receive path; ``run`` returns ``frames`` once every
    payload of its kind parsed."""
    stream, _ids = mixed_stream(frames, seed)
    packets = [item for item in PyStreamDecoder().feed(stream) if isinstance(item, Packet)]
    kind = PacketType.CONTROL if control else PacketType.DATA
    payloads = [p.payload for p in packets if p.type is kind]
    parse: Callable[[bytes], object] = parse_control if control else parse_out

    def run() -> int:
        parsed = 0
        for payload in payloads:
            parse(payload)
            parsed += 1
        return frames if parsed == len(payloads) and len(packets) == frames else parsed

    what = "packets.parse_control" if control else "messages.parse_out (protobuf upb)"
    return RxCase(
        name=name or f"{kind.name} payloads through {what}",
        package="protoduino",
        parser=what,
        stages=f"the {len(payloads):,} {kind.name} payloads of the stream, parsed",
        stream=stream,
        frames=frames,
        run=run,
    )


def servo_messages(message_id: int) -> tuple[pb.ArduinoIn, pb.ArduinoIn, pb.ArduinoOut]:
    """ServoInit (setup), ServoControl to 90 degrees (command) and its Ack, for pin 9."""
    init = pb.ArduinoIn(message_id=message_id, servo_init=pb.ServoInit(pin=9, safe_degrees=90))
    command = pb.ArduinoIn(
        message_id=message_id + 1, servo_control=pb.ServoControl(pin=9, degrees=90)
    )
    ack = pb.ArduinoOut(ack=pb.Ack(message_id=message_id + 1, status=pb.STATUS_OK))
    return init, command, ack


def _frames(message_id: int) -> tuple[bytes, bytes, bytes]:
    init, command, ack = servo_messages(message_id)
    return (
        frame_packet(PacketType.COMMAND, 1, init.SerializeToString()),
        frame_packet(PacketType.COMMAND, 2, command.SerializeToString()),
        frame_packet(PacketType.DATA, 1, serialize_out(ack)),  # the short Ack
    )


def wire_sample() -> WireSample:
    setup, command, ack = _frames(FIRST_MESSAGE_ID)
    return WireSample(
        library="protoduino",
        package="protoduino",
        encoder="protoduino_pb2 + framing.frame_packet (COBS, CRC-16, 0x00 delimiter)",
        setup=setup,
        setup_what="COMMAND ServoInit{pin 9, safe 90 deg}",
        command=command,
        command_what="COMMAND ServoControl{pin 9, degrees 90}",
        ack=ack,
        ack_what="DATA ack_ok{message_id} (the short Ack: STATUS_OK, nothing else)",
        check="CRC-16/CCITT-FALSE",
        notes=(
            "message ids 1..127 per session, one varint byte (protocol version 5); an Ack "
            "with only its id and STATUS_OK goes in its short form"
        ),
    )
