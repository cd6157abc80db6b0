"""Types of the C accelerator (host/protoduino/_speedups.c); see framing.PyStreamDecoder."""

from collections import Counter
from collections.abc import Iterable

from .packets import BadFrame, Packet

#: SHA-256 of the sources the module was built from (setup.py's source_digest()).
SOURCE_DIGEST: str
MAX_ENCODED_FRAME: int

class StreamDecoder:
    counts: Counter[str]
    def __init__(self) -> None: ...
    def reset(self) -> None: ...
    def feed(self, data: bytes | bytearray | memoryview, /) -> list[Packet | BadFrame]: ...
    def feed_all(self, chunks: Iterable[bytes], /) -> list[Packet | BadFrame]: ...
