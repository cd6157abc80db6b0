"""What a board reports to its ``on_event`` callbacks, and its counters.

Events are values, never exceptions: the callbacks run on the board's own
event thread (never the I/O thread), one at a time, in the order things
happened, so a slow callback delays other callbacks but never the link.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any


class EventKind(StrEnum):
    """Every kind of event; ``details`` keys are listed with each."""

    #: The link is (again) up. details: rebooted (bool), handshakes (int)
    CONNECTED = "connected"
    #: The link went down. details: reason ("port lost", "watchdog", "desync",
    #: "device rebooted", "handshake failed", ...)
    DISCONNECTED = "disconnected"
    #: The device restarted (EVENT BOOT / NOT_ACTIVE, or its port was reopened).
    REBOOTED = "rebooted"
    #: Session restore finished. details: replayed (int), failed (list of str)
    RESTORED = "restored"
    #: The device entered or left its failsafe state. details: active (bool),
    #: cause ("ping_timeout", "stop", "none")
    FAILSAFE = "failsafe"
    #: A text from the firmware. details: level ("debug".."error"), text (str)
    LOG = "log"
    #: The device could not decode a command. details: count (int, since boot)
    DECODE_ERROR = "decode_error"
    #: The device saw our SEQ jump (details: none) or dropped an over-long frame.
    DEVICE_DESYNC = "device_desync"
    RX_OVERFLOW = "rx_overflow"
    #: The link failed for good (version or schema mismatch). details: error (str)
    ERROR = "error"


@dataclass(frozen=True, slots=True)
class Event:
    kind: EventKind
    #: One readable sentence, for logs and the command line.
    text: str
    details: Mapping[str, Any] = field(default_factory=dict)
    #: time.monotonic() when it happened on the host.
    t: float = field(default_factory=time.monotonic)

    def __str__(self) -> str:
        return f"{self.kind.value}: {self.text}"


@dataclass(frozen=True, slots=True)
class Stats:
    """A snapshot of a board's link counters (``board.stats``)."""

    state: str  # "active", "handshaking", "disconnected", "failed", "closed"
    connected: bool  # the port is open
    rx_bytes: int
    tx_bytes: int
    rx_packets: int
    tx_packets: int
    #: Frames dropped on receipt, by reason: cobs, crc, length, type, overflow,
    #: and "direction" for a COMMAND packet reaching the host.
    dropped: Mapping[str, int]
    seq_lost: int  # packets the device sent that never arrived (SEQ gaps)
    seq_desyncs: int
    handshakes: int
    reconnects: int  # the port was lost and reopened
    reboots: int  # device restarts detected
    watchdog_resets: int
    device_desyncs: int  # EVENT DESYNC from the device
    device_rx_overflows: int
    commands: int  # distinct commands sent (not counting retransmissions)
    acks: int
    retransmits: int
    timeouts: int
    rejected: int  # Acks with a status other than OK
    late_acks: int  # for a command already finished (e.g. a retransmission's twin)
    unknown_acks: int  # for an id this host never sent
    pings: int
    ping_failures: int
    rtt: float | None  # last Ping round trip (seconds)
    last_ping: float | None  # time.monotonic() of the last acknowledged automatic Ping

    def as_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}
