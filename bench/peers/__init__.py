"""One module per link library: how to feed its receive path and how it encodes a servo command.

Each module offers ``rx_case(...) -> RxCase`` (part 1) and/or ``wire_sample() -> WireSample``
(part 4). Third-party libraries are imported inside those functions through
:func:`bench.core.require`, so importing this package never needs the bench extras, and a missing
library turns into :class:`bench.core.MissingDependencyError` naming the package.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RxCase:
    """A receive-path benchmark: a byte stream held in memory and the code that consumes it.

    ``run`` decodes the whole ``stream`` from a fresh parser state, fed in the case's chunks,
    dispatches every message and returns how many it dispatched (the benchmark checks it equals
    ``frames`` before timing anything, so a parser that silently drops frames is caught).
    """

    name: str
    package: str
    parser: str
    stages: str
    stream: bytes
    frames: int
    run: Callable[[], int]


@dataclass(frozen=True, slots=True)
class WireSample:
    """The bytes one library puts on the wire to set a servo on pin 9 to 90 degrees.

    ``setup`` is the one-off configuration (attach / init), ``command`` the set-point itself,
    ``ack`` the device's acknowledgement, or None where the protocol has none (``ack_what`` then
    says so); ``ack_by_protocol`` is False where the library has no ack and the sample shows an
    application-level reply. ``check`` names the integrity check on the frame. ``hand_built``
    marks bytes made from a specification rather than by the library.
    """

    library: str
    package: str
    encoder: str
    setup: bytes | None
    setup_what: str
    command: bytes
    command_what: str
    ack: bytes | None
    ack_what: str
    check: str
    ack_by_protocol: bool = True
    hand_built: bool = False
    notes: str = ""


class Slot:
    """A pending call's record: the stand-in request layers store the answer here, as a
    future's result would be set."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value: object = None


def chunked(stream: bytes, size: int) -> list[bytes]:
    """``stream`` cut into reads of ``size`` bytes, as a serial port would hand them over."""
    if size < 1:
        raise ValueError("chunk size must be at least 1")
    return [stream[i : i + size] for i in range(0, len(stream), size)]
