"""Benchmark part 4 (docs/performance.md).

Bytes on the wire to set a servo on pin 9 to 90 degrees, and the ack.

Every byte string comes from the library's own encoder (see each ``bench.peers`` module for how
the encoder is reached without a board); a sample built by hand from a specification would be
marked ``hand_built`` and labelled so in the report. Wire time is at 115200 baud, 8N1 (10 bits
per byte), which is also the lower bound a round trip (part 2) can be compared with.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from protoduino.framing import frame_packet
from protoduino.packets import Packet

from . import charts
from .core import Chart, Context, MissingDependencyError, Section, SectionResult, md_table
from .peers import WireSample, firmata, mavlink, pigweed, protoduino, serialtransfer, telemetrix

log = logging.getLogger(__name__)

BAUD = 115_200
BITS_PER_BYTE = 10

#: The libraries compared, protoduino first: (label, PyPI package, factory).
PEERS: tuple[tuple[str, Callable[[], WireSample]], ...] = (
    ("protoduino", protoduino.wire_sample),
    ("Firmata", firmata.wire_sample),
    ("Telemetrix", telemetrix.wire_sample),
    ("MAVLink 2", mavlink.wire_sample),
    ("pw_rpc over HDLC", pigweed.wire_sample),
    ("pySerialTransfer", serialtransfer.wire_sample),
)


#: The emulated Uno's line: simavr 1.6 times every UART byte as 11 bits, at the rate the
#: firmware's UBRR sets (U2X, UBRR 16: 16 MHz / (8 x 17) = 117,647 baud), so a byte takes
#: 11 x 8 x 17 cycles, 93.5 us, against 86.8 us for 10 bits at 115200. The emulated Uno's
#: round trips and rates are judged against its own line.
EMULATED_BYTE_US = 11 * 8 * 17 / 16.0


def wire_time_us(nbytes: int, baud: int = BAUD) -> float:
    """Time ``nbytes`` take on an 8N1 line, in microseconds."""
    return nbytes * BITS_PER_BYTE / baud * 1e6


def frame_bytes(packet: Packet) -> int:
    """The packet's frame as it went on the wire (COBS, CRC, delimiter), in bytes."""
    return len(frame_packet(packet.type, packet.seq, packet.payload))


def board_byte_us(backend: str) -> float:
    """One byte's time on ``backend``'s line: the emulated Uno's own; 8N1 at BAUD otherwise."""
    return EMULATED_BYTE_US if backend == "avr" else wire_time_us(1)


def _size(data: bytes | None) -> str:
    return "-" if data is None else str(len(data))


def _hex(data: bytes) -> str:
    return " ".join(f"{b:02x}" for b in data)


def _ack_cell(sample: WireSample) -> str:
    if sample.ack is None:
        return "**none**"
    return "yes" if sample.ack_by_protocol else "none (ours, app-level)"


def collect() -> tuple[list[WireSample], list[tuple[str, str]]]:
    """Every sample whose library is installed, and (label, package) for those that are not."""
    samples: list[WireSample] = []
    skipped: list[tuple[str, str]] = []
    for label, factory in PEERS:
        try:
            samples.append(factory())
        except MissingDependencyError as missing:
            log.warning("wire: %s skipped: %s", label, missing)
            skipped.append((label, missing.package))
    return samples, skipped


def run(ctx: Context) -> SectionResult:
    samples, skipped = collect()
    rows = []
    for s in samples:
        total = len(s.command) + (len(s.ack) if s.ack is not None else 0)
        rows.append(
            [
                s.library + (" (hand-built)" if s.hand_built else ""),
                _size(s.setup),
                str(len(s.command)),
                _size(s.ack),
                str(total),
                f"{wire_time_us(total):,.0f}",
                s.check,
                _ack_cell(s),
            ]
        )
    parts = [
        "One servo on pin 9 set to 90 degrees: the one-off setup, the command and the "
        "device's acknowledgement, in bytes on the wire (framing, checksums and delimiters "
        f"included). Wire time is for command + ack at {BAUD} baud, 8N1.\n",
        md_table(
            [
                "protocol",
                "setup B",
                "command B",
                "ack B",
                "command + ack B",
                "wire time us",
                "check",
                "ack",
            ],
            rows,
            "lrrrrrll",
        ),
        "Bytes, as each library's encoder produced them:\n",
    ]
    for s in samples:
        parts.append(f"- **{s.library}** ({s.encoder}; `{s.package}`)")
        if s.setup is not None:
            parts.append(f"  - setup, {s.setup_what}: `{_hex(s.setup)}`")
        else:
            parts.append(f"  - setup: {s.setup_what}")
        parts.append(f"  - command, {s.command_what}: `{_hex(s.command)}`")
        if s.ack is not None:
            parts.append(f"  - ack, {s.ack_what}: `{_hex(s.ack)}`")
        else:
            parts.append(f"  - ack: {s.ack_what}")
        if s.notes:
            parts.append(f"  - {s.notes}")
    parts.append("")
    if skipped:
        parts.append(
            "Not encoded here: "
            + ", ".join(f"{label} (`{package}` not installed)" for label, package in skipped)
            + ".\n"
        )
    unacked = [s.library for s in samples if s.ack is None and s.check == "none"]
    if unacked:
        parts.append(
            " and ".join(unacked)
            + " send no acknowledgement (and no checksum): a corrupted or lost byte moves the "
            "wrong servo, or nothing, and the host never learns of it. The others pay for a "
            "check value, an id to match the answer with, and the answer itself.\n"
        )

    chart_list: list[Chart] = []
    if ctx.chart_dir is not None and samples:
        path = charts.stacked_hbars(
            ctx.chart_dir / "wire.png",
            [s.library for s in samples],
            [
                ("command", [float(len(s.command)) for s in samples]),
                ("ack", [float(len(s.ack)) if s.ack is not None else 0.0 for s in samples]),
            ],
            title="Set servo 9 to 90 degrees: bytes on the wire",
            xlabel="bytes (command + ack)",
        )
        chart_list.append(Chart(path, "Bytes on the wire for one servo command and its ack"))
    packages = sorted({s.package for s in samples})
    return SectionResult("\n".join(parts), [], chart_list, packages)


SECTION = Section(4, "wire", "Bytes on the wire", run)
