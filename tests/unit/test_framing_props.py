"""Properties of the host codec (hypothesis): framing must never pass a damaged
packet and never lose a good one to damage around it.

Every stream-decoder property runs on both implementations: the pure-Python
``PyStreamDecoder`` (the reference and the fallback) and the C accelerator
``protoduino._speedups.StreamDecoder`` (what ``framing.StreamDecoder`` is when
it was built). Both are also held to ``_reference_decode``, the recovery
policy written out one byte at a time, item for item: same classes, same
PacketType members, same reasons and raw bytes, same counts.
"""

from __future__ import annotations

import functools
import gc
import random
import shutil
import sys
import sysconfig
import tracemalloc
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Protocol

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from protoduino import framing
from protoduino.constants import MAX_ENCODED_FRAME, MAX_PAYLOAD, PacketType
from protoduino.framing import PyStreamDecoder, decode_frame, frame_packet
from protoduino.packets import BadFrame, Packet

ROOT = Path(__file__).resolve().parents[2]

speedups: ModuleType | None
try:
    from protoduino import _speedups as speedups
except ImportError:
    speedups = None


class Decoder(Protocol):
    """What both implementations offer."""

    counts: Counter[str]

    def feed(self, data: bytes | bytearray | memoryview, /) -> list[Packet | BadFrame]: ...
    def feed_all(self, chunks: Iterable[bytes], /) -> list[Packet | BadFrame]: ...
    def reset(self) -> None: ...


DecoderClass = Callable[[], Decoder]

NO_C = (
    "protoduino._speedups not built: it needs a C compiler and the Python headers "
    "(python3-dev); test_accelerator_is_built_where_it_can_be says which is missing"
)
C_DECODER: DecoderClass | None = None if speedups is None else speedups.StreamDecoder
IMPLEMENTATIONS = [
    pytest.param(PyStreamDecoder, id="python"),
    pytest.param(C_DECODER, id="c", marks=pytest.mark.skipif(speedups is None, reason=NO_C)),
]
implementations = pytest.mark.parametrize("impl", IMPLEMENTATIONS)


def _exact(items: Sequence[Packet | BadFrame]) -> list[tuple[object, ...]]:
    """Items with the class of every value: a plain tuple, an int where a PacketType member
    belongs or a bytearray where bytes belong all compare equal to the real thing, and must
    not pass."""
    return [(type(item), *((type(v), v) for v in item)) for item in items]


def _counts_of(items: Iterable[Packet | BadFrame]) -> Counter[str]:
    return Counter("packets" if isinstance(i, Packet) else i.reason for i in items)


def _cut(stream: bytes, cuts: Iterable[int]) -> list[bytes]:
    points = sorted(cuts)
    return [stream[a:b] for a, b in zip([0, *points], [*points, len(stream)], strict=True)]


packets = st.builds(
    Packet,
    st.sampled_from(list(PacketType)),
    st.integers(0, 255),
    st.binary(max_size=MAX_PAYLOAD),
)


def _wire(p: Packet) -> bytes:
    return frame_packet(p.type, p.seq, p.payload)


@implementations
@given(packets)
def test_round_trip(impl: DecoderClass, p: Packet) -> None:
    out = impl().feed(_wire(p))
    assert _exact(out) == _exact([p])


@given(packets)
def test_no_zero_inside_a_frame_and_bounded_size(p: Packet) -> None:
    wire = _wire(p)
    assert wire[-1] == 0
    assert 0 not in wire[:-1]
    assert len(wire) - 1 <= MAX_ENCODED_FRAME


@implementations
@given(
    st.lists(st.one_of(packets.map(_wire), st.binary(max_size=300)), max_size=8),
    st.data(),
)
def test_output_does_not_depend_on_chunking(
    impl: DecoderClass, parts: list[bytes], data: st.DataObject
) -> None:
    stream = b"".join(parts)
    reference = impl()
    whole = reference.feed(stream)
    chunks = _cut(stream, data.draw(st.lists(st.integers(0, len(stream)), max_size=20)))
    decoder = impl()
    assert _exact(decoder.feed_all(chunks)) == _exact(whole)
    assert decoder.counts == reference.counts


@implementations
@given(packets, st.data())
def test_any_single_corrupted_byte_is_rejected(
    impl: DecoderClass, p: Packet, data: st.DataObject
) -> None:
    wire = bytearray(_wire(p))
    i = data.draw(st.integers(0, len(wire) - 2))  # any byte of the frame, not the delimiter
    new = data.draw(st.integers(0, 255).filter(lambda b: b != wire[i]))
    wire[i] = new
    out = impl().feed(bytes(wire))
    assert not any(isinstance(item, Packet) for item in out), out


@implementations
@given(packets, st.data())
def test_any_burst_of_up_to_16_bits_is_rejected(
    impl: DecoderClass, p: Packet, data: st.DataObject
) -> None:
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
    out = impl().feed(bytes(wire))
    assert not any(isinstance(item, Packet) for item in out), out


@implementations
@given(
    st.lists(packets, min_size=1, max_size=4),
    st.lists(st.binary(min_size=1, max_size=600), max_size=4),
)
@settings(max_examples=200)
def test_garbage_between_frames_never_loses_the_next_good_frame(
    impl: DecoderClass, good: list[Packet], garbage: list[bytes]
) -> None:
    """Garbage ends at a delimiter (its own, or the lone 0x00 a sender emits
    before a frame after trouble); every good frame after it comes through."""
    stream = b""
    for i, p in enumerate(good):
        if i < len(garbage):
            stream += garbage[i] + b"\x00"
        stream += _wire(p)
    out = impl().feed(stream)
    got = [item for item in out if isinstance(item, Packet)]
    # Garbage might by chance contain a valid frame; all good frames must be there, in order.
    it = iter(got)
    assert all(any(g == p for g in it) for p in good)


@implementations
def test_overflow_is_discarded_and_counted_and_the_next_frame_survives(
    impl: DecoderClass,
) -> None:
    p = Packet(PacketType.DATA, 9, b"\x01\x02")
    junk = b"\x55" * (MAX_ENCODED_FRAME + 100)
    decoder = impl()
    out = decoder.feed(junk + b"\x00" + _wire(p))
    assert _exact(out) == _exact([BadFrame("overflow", junk[: MAX_ENCODED_FRAME + 1]), p])
    assert decoder.counts["overflow"] == 1
    assert decoder.counts["packets"] == 1


@implementations
def test_frame_of_exactly_max_encoded_size_is_accepted(impl: DecoderClass) -> None:
    p = Packet(PacketType.COMMAND, 1, bytes(range(1, 256)))
    wire = _wire(p)
    assert len(wire) - 1 == MAX_ENCODED_FRAME
    assert _exact(impl().feed(wire)) == _exact([p])
    # The same frame arriving one byte at a time fills the partial buffer exactly.
    decoder = impl()
    assert _exact(decoder.feed_all(wire[i : i + 1] for i in range(len(wire)))) == _exact([p])


@implementations
def test_lone_delimiters_are_ignored(impl: DecoderClass) -> None:
    p = Packet(PacketType.CONTROL, 0, b"\x02")
    decoder = impl()
    assert decoder.feed(b"\x00\x00" + _wire(p) + b"\x00") == [p]
    assert decoder.feed(b"") == []
    assert decoder.feed(b"\x00" * 1000) == []
    assert decoder.counts == Counter(packets=1)


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


def _nonzero_run(low: int, high: int) -> st.SearchStrategy[bytes]:
    """A run without a delimiter of ``low`` to ``high`` bytes: around the overflow limit."""
    return (
        st.integers(low, high)
        .flatmap(lambda n: st.binary(min_size=n, max_size=n))
        .map(lambda b: b.replace(b"\x00", b"\x01"))
    )


#: Streams with every kind of damage: good frames, short garbage, frames cut in half, lone
#: delimiters, and runs just under, at and over MAX_ENCODED_FRAME, and far over it.
damaged_streams = st.lists(
    st.one_of(
        packets.map(_wire),
        st.binary(max_size=40),
        st.binary(min_size=250, max_size=600),
        packets.map(_wire).map(lambda w: w[: len(w) // 2]),
        st.just(b"\x00"),
        _nonzero_run(MAX_ENCODED_FRAME - 3, MAX_ENCODED_FRAME + 3),
        _nonzero_run(MAX_ENCODED_FRAME + 4, 3 * MAX_ENCODED_FRAME),
    ),
    max_size=10,
).map(b"".join)


def _as_buffer(chunk: bytes, kind: str) -> bytes | bytearray | memoryview:
    """The same bytes as any buffer ``feed`` accepts; "strided" is a non-contiguous view."""
    if kind == "bytearray":
        return bytearray(chunk)
    if kind == "memoryview":
        return memoryview(chunk)
    if kind == "strided":
        return memoryview(bytes(x for b in chunk for x in (b, 0xEE)))[::2]
    return chunk


@implementations
@given(damaged_streams, st.data())
@settings(max_examples=150)
def test_stream_decoder_matches_the_plain_reference(
    impl: DecoderClass, stream: bytes, data: st.DataObject
) -> None:
    chunks = _cut(stream, data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    kinds = data.draw(
        st.lists(
            st.sampled_from(["bytes", "bytearray", "memoryview", "strided"]),
            min_size=len(chunks),
            max_size=len(chunks),
        )
    )
    decoder = impl()
    got = [
        item
        for chunk, kind in zip(chunks, kinds, strict=True)
        for item in decoder.feed(_as_buffer(chunk, kind))
    ]
    expected = _reference_decode(stream)
    assert _exact(got) == _exact(expected)
    assert decoder.counts == _counts_of(expected)


@pytest.mark.skipif(speedups is None, reason=NO_C)
@given(damaged_streams, st.data())
@settings(max_examples=150)
def test_c_decoder_matches_python_read_by_read(stream: bytes, data: st.DataObject) -> None:
    """Not just the same items overall: the same items from each read, and the same counts
    after it, down to the order of the Counter's keys."""
    assert C_DECODER is not None
    chunks = _cut(stream, data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    c, py = C_DECODER(), PyStreamDecoder()
    for chunk in chunks:
        assert _exact(c.feed(chunk)) == _exact(py.feed(chunk))
        assert list(c.counts.items()) == list(py.counts.items())


@functools.cache
def _noisy_stream(frames: int, seed: int) -> bytes:
    """Good frames with random damage between and inside them, overflows included."""
    rng = random.Random(seed)
    types = list(PacketType)
    parts: list[bytes] = []
    for i in range(frames):
        wire = bytearray(
            _wire(Packet(rng.choice(types), i & 0xFF, rng.randbytes(rng.randrange(20))))
        )
        roll = rng.random()
        if roll < 0.05:
            wire[rng.randrange(len(wire) - 1)] ^= 1 << rng.randrange(8)
        elif roll < 0.07:
            wire[0:0] = rng.randbytes(rng.randrange(1, 3 * MAX_ENCODED_FRAME)).replace(
                b"\x00", b"\x02"
            )
        elif roll < 0.09:
            del wire[rng.randrange(len(wire)) :]
        parts.append(bytes(wire))
    return b"".join(parts)


@functools.cache
def _python_items(stream: bytes) -> list[Packet | BadFrame]:
    """What the Python decoder makes of ``stream`` (the properties above hold it to the
    reference)."""
    return PyStreamDecoder().feed(stream)


@implementations
@pytest.mark.parametrize("size", [1, 7, 1024, 65536, None])
def test_huge_and_tiny_reads_give_the_same_items(impl: DecoderClass, size: int | None) -> None:
    stream = _noisy_stream(20_000, seed=5)
    expected = _python_items(stream)
    reads = (
        [stream] if size is None else [stream[i : i + size] for i in range(0, len(stream), size)]
    )
    decoder = impl()
    assert _exact(decoder.feed_all(reads)) == _exact(expected)
    assert decoder.counts == _counts_of(expected)
    assert {"packets", "crc", "overflow"} <= set(decoder.counts)  # the damage did happen


@implementations
def test_reset_forgets_a_partial_frame_and_an_overflow(impl: DecoderClass) -> None:
    p = Packet(PacketType.DATA, 3, b"ok")
    decoder = impl()
    assert decoder.feed(_wire(p)[:4]) == []
    decoder.reset()
    assert _exact(decoder.feed(_wire(p))) == _exact([p])
    out = decoder.feed(b"\x07" * (MAX_ENCODED_FRAME + 1))  # overflows: skipping to the next 0x00
    assert [item.reason for item in out if isinstance(item, BadFrame)] == ["overflow"]
    decoder.reset()
    assert _exact(decoder.feed(_wire(p))) == _exact([p])  # not swallowed by the skip
    assert decoder.counts == Counter(packets=2, overflow=1)


@implementations
def test_feed_takes_what_bytes_takes(impl: DecoderClass) -> None:
    p = Packet(PacketType.CONTROL, 1, b"\x02")
    assert _exact(impl().feed(list(_wire(p)))) == _exact([p])  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        impl().feed("not bytes")  # type: ignore[arg-type]


@pytest.mark.skipif(speedups is None, reason=NO_C)
def test_c_decoder_survives_a_stress_loop_without_leaks() -> None:
    """100k frames (and their damage) through the C decoder, every kind of buffer, collections
    running: the references it takes to shared objects come back, and memory stays flat."""
    assert C_DECODER is not None
    stream = _noisy_stream(20_000, seed=11)
    rng = random.Random(11)
    kinds = ["bytes", "bytearray", "memoryview", "strided"]
    reads = []
    i = 0
    while i < len(stream):
        n = rng.choice([1, 3, 64, 1024, 9000])
        reads.append(_as_buffer(stream[i : i + n], rng.choice(kinds)))
        i += n
    shared: list[object] = [*PacketType, Packet, BadFrame, "packets", "crc", "cobs", "overflow"]

    def one_pass() -> int:
        decoder = C_DECODER()
        good = 0
        for data in reads:
            good += sum(isinstance(item, Packet) for item in decoder.feed(data))
        return good

    one_pass()  # warm-up: caches and free lists settle
    gc.collect()
    refs = [sys.getrefcount(obj) for obj in shared]
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        good = sum(one_pass() for _ in range(5))
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert good >= 5 * 15_000
    assert [sys.getrefcount(obj) for obj in shared] == refs
    assert grown < 256 * 1024, f"{grown} bytes still allocated after 100k frames"


def test_stream_decoder_is_the_accelerator_when_built() -> None:
    if speedups is None:
        assert framing.StreamDecoder is PyStreamDecoder
        assert not framing.ACCELERATED
    else:
        assert framing.StreamDecoder is speedups.StreamDecoder
        assert framing.ACCELERATED


def test_accelerator_is_built_where_it_can_be() -> None:
    """The extension is optional, so a build that fails (a new warning under -Werror, say)
    would pass silently as a skip; here it fails where a compiler and the headers exist."""
    compiler = str(sysconfig.get_config_var("CC") or "cc").split()[0]
    header = Path(sysconfig.get_paths()["include"]) / "Python.h"
    missing = [
        what
        for what, present in (
            (f"C compiler {compiler}", shutil.which(compiler) is not None),
            (f"Python headers {header} (python3-dev)", header.exists()),
        )
        if not present
    ]
    if missing:
        pytest.skip("cannot build protoduino._speedups here: missing " + ", ".join(missing))
    assert speedups is not None, (
        "protoduino._speedups did not build; run `pip install -e .` and read its output"
    )


@pytest.mark.skipif(speedups is None, reason=NO_C)
def test_accelerator_is_built_from_the_current_sources() -> None:
    """An editable install builds the module once; edits to its C sources need a rebuild."""
    assert speedups is not None
    from importlib.util import module_from_spec, spec_from_file_location

    spec = spec_from_file_location("protoduino_setup", ROOT / "setup.py")
    assert spec is not None and spec.loader is not None
    setup = module_from_spec(spec)
    spec.loader.exec_module(setup)  # its setup() call only runs as __main__
    assert setup.source_digest() == speedups.SOURCE_DIGEST, (
        "protoduino._speedups is stale: rerun `pip install -e .` (tools/dev.sh setup)"
    )
