"""Properties of the host codec (hypothesis): framing must never pass a damaged
packet and never lose a good one to damage around it."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
from protoduino.constants import MAX_ENCODED_FRAME, MAX_PAYLOAD, PacketType
from protoduino.framing import StreamDecoder, decode_frame, frame_packet
from protoduino.packets import BadFrame, Packet

packets = st.builds(
    Packet,
    st.sampled_from(list(PacketType)),
    st.integers(0, 255),
    st.binary(max_size=MAX_PAYLOAD),
)


def _wire(p: Packet) -> bytes:
    return frame_packet(p.type, p.seq, p.payload)


@given(packets)
def test_round_trip(p: Packet) -> None:
    assert StreamDecoder().feed(_wire(p)) == [p]


@given(packets)
def test_no_zero_inside_a_frame_and_bounded_size(p: Packet) -> None:
    wire = _wire(p)
    assert wire[-1] == 0
    assert 0 not in wire[:-1]
    assert len(wire) - 1 <= MAX_ENCODED_FRAME


@given(
    st.lists(st.one_of(packets.map(_wire), st.binary(max_size=300)), max_size=8),
    st.data(),
)
def test_output_does_not_depend_on_chunking(parts: list[bytes], data: st.DataObject) -> None:
    stream = b"".join(parts)
    whole = StreamDecoder().feed(stream)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=20)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    decoder = StreamDecoder()
    assert decoder.feed_all(chunks) == whole
    reference = StreamDecoder()
    reference.feed(stream)
    assert decoder.counts == reference.counts


@given(packets, st.data())
def test_any_single_corrupted_byte_is_rejected(p: Packet, data: st.DataObject) -> None:
    wire = bytearray(_wire(p))
    i = data.draw(st.integers(0, len(wire) - 2))  # any byte of the frame, not the delimiter
    new = data.draw(st.integers(0, 255).filter(lambda b: b != wire[i]))
    wire[i] = new
    out = StreamDecoder().feed(bytes(wire))
    assert not any(isinstance(item, Packet) for item in out), out


@given(packets, st.data())
def test_any_burst_of_up_to_16_bits_is_rejected(p: Packet, data: st.DataObject) -> None:
    wire = bytearray(_wire(p))
    nbits = (len(wire) - 1) * 8
    length = data.draw(st.integers(1, min(16, nbits)))
    start = data.draw(st.integers(0, nbits - length))
    # A burst: first and last bit of the window flipped, anything in between.
    pattern = 1 | (1 << (length - 1)) | data.draw(st.integers(0, (1 << length) - 1))
    for k in range(length):
        if pattern >> k & 1:
            bit = start + k
            wire[bit // 8] ^= 0x80 >> (bit % 8)
    out = StreamDecoder().feed(bytes(wire))
    assert not any(isinstance(item, Packet) for item in out), out


@given(
    st.lists(packets, min_size=1, max_size=4),
    st.lists(st.binary(min_size=1, max_size=600), max_size=4),
)
@settings(max_examples=200)
def test_garbage_between_frames_never_loses_the_next_good_frame(
    good: list[Packet], garbage: list[bytes]
) -> None:
    """Garbage ends at a delimiter (its own, or the lone 0x00 a sender emits
    before a frame after trouble); every good frame after it comes through."""
    stream = b""
    for i, p in enumerate(good):
        if i < len(garbage):
            stream += garbage[i] + b"\x00"
        stream += _wire(p)
    out = StreamDecoder().feed(stream)
    got = [item for item in out if isinstance(item, Packet)]
    # Garbage might by chance contain a valid frame; all good frames must be there, in order.
    it = iter(got)
    assert all(any(g == p for g in it) for p in good)


def test_overflow_is_discarded_and_counted_and_the_next_frame_survives() -> None:
    p = Packet(PacketType.DATA, 9, b"\x01\x02")
    junk = b"\x55" * (MAX_ENCODED_FRAME + 100)
    decoder = StreamDecoder()
    out = decoder.feed(junk + b"\x00" + _wire(p))
    assert out == [BadFrame("overflow", junk[: MAX_ENCODED_FRAME + 1]), p]
    assert decoder.counts["overflow"] == 1
    assert decoder.counts["packets"] == 1


def test_frame_of_exactly_max_encoded_size_is_accepted() -> None:
    p = Packet(PacketType.COMMAND, 1, bytes(range(1, 256)))
    wire = _wire(p)
    assert len(wire) - 1 == MAX_ENCODED_FRAME
    assert StreamDecoder().feed(wire) == [p]


def test_lone_delimiters_are_ignored() -> None:
    p = Packet(PacketType.CONTROL, 0, b"\x02")
    assert StreamDecoder().feed(b"\x00\x00" + _wire(p) + b"\x00") == [p]


def _reference_decode(stream: bytes) -> list[Packet | BadFrame]:
    """The recovery policy written as plainly as possible, one byte at a time."""
    out: list[Packet | BadFrame] = []
    buf = bytearray()
    skipping = False
    for byte in stream:
        if byte == 0:
            if not skipping and buf:
                out.append(decode_frame(bytes(buf)))
            buf.clear()
            skipping = False
        elif not skipping:
            buf.append(byte)
            if len(buf) > MAX_ENCODED_FRAME:
                out.append(BadFrame("overflow", bytes(buf)))
                buf.clear()
                skipping = True
    return out


@given(
    st.lists(
        st.one_of(
            packets.map(_wire),
            st.binary(max_size=40),
            st.binary(min_size=250, max_size=600),
            packets.map(_wire).map(lambda w: w[: len(w) // 2]),
        ),
        max_size=10,
    ),
    st.data(),
)
def test_stream_decoder_matches_the_plain_reference(
    parts: list[bytes], data: st.DataObject
) -> None:
    stream = b"".join(parts)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    assert StreamDecoder().feed_all(chunks) == _reference_decode(stream)
