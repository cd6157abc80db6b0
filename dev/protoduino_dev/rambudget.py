"""The Uno firmware's RAM budget, measured: static data + the deepest stack + 256 B free <= 2,048 B.

The ATmega328P has 2 KB of RAM and no MMU: the stack grows down from RAMEND towards the
static variables and, if it reaches them, corrupts them silently. The emulated Uno's runner
(tools/avrsim, ``--stats``) records the lowest stack pointer after every instruction,
interrupts included. :func:`exercise` drives the firmware the way that takes its stack
deepest: every command at its largest, four in flight so that the UART interrupts land inside
the deepest decode (a Pose, four nested messages in nanopb), then the fullest Pose (eight
servo items and digital outputs in its masks), with every kind of input configured and
moving (counter, pin-change and ADC interrupts land anywhere, and reports compete with the
Acks for the transmit ring). :class:`RamBudget` compares the low-water mark
with the end of the static data (the linker's ``_end``; the firmware has no heap).

One scenario for ``tests/e2e/test_stack_margin.py`` (which fails when the 256 B are not free)
and for ``python -m bench`` part 5 (which reports it), so both judge the same thing.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterable
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from protoduino import Board, CommandRejectedError, Servo
from protoduino.messages import ArduinoIn, Status
from protoduino.simcontrol import SimControl

from . import build, stackwalk

#: The ATmega328P's RAM (0x100 .. RAMEND = 0x8FF).
RAM_BYTES = 2048
RAM_START = 0x100
#: Kept free for the users' own code (issue 21's budget). It also covers what a single run's
#: low-water mark can miss: an interrupt landing at that point with a frame of its own.
FREE_BYTES = 256

#: The Uno firmware's pins in the scenario: counters on 2 (INT0) and 13 (a pin-change
#: interrupt's, PORTB's), servos on 4..11 (its eight channels), digital inputs on 3 (PORTD's
#: pin-change interrupt) and 12 (PORTB's, beside the counter), analog inputs on 14..19 (A0..A5).
COUNTER_PINS = (2, 13)
SERVO_PINS = range(4, 12)
DIGITAL_INPUT_PINS = (3, 12)
ANALOG_PINS = range(14, 20)
ROUNDS = 20
#: Bounds a failing call only.
CALL_TIMEOUT = 30.0


def symbol(elf: Path, name: str) -> int:
    """The data-space address of ``name`` in the ELF (avr-nm adds 0x800000 to RAM)."""
    out = subprocess.run(
        ["avr-nm", str(elf)], check=True, capture_output=True, text=True, timeout=60
    ).stdout
    for line in out.splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[2] == name:
            return int(fields[0], 16) & 0xFFFF
    raise LookupError(f"{name} is not in {elf}")


def _get_info() -> ArduinoIn:
    msg = ArduinoIn()
    msg.get_info.SetInParent()
    return msg


def _oversized_pose(*, full_decode: bool = False) -> ArduinoIn:
    """A Pose with one item more than the firmware's bound (8): nanopb refuses it while it is
    as deep in the decode as a Pose can take it.

    ``full_decode``: with an unknown field after the Pose (field 127, skipped by nanopb), so
    that the payload is not of the host's usual shape and the firmware takes nanopb's whole
    decode of ArduinoIn, whose walk of the oneof goes one level deeper than the short decode
    (pd_dispatch_decode): the deepest stack is on that way."""
    msg = ArduinoIn()
    for pin in (*SERVO_PINS, DIGITAL_INPUT_PINS[0]):
        msg.pose.items.add().servo.pin = pin
    if full_decode:
        msg.MergeFromString(b"\xf8\x07\x01")  # field 127, varint 1: unknown to the schema
    return msg


def exercise(
    board: Board,
    control: SimControl,
    rounds: int = ROUNDS,
    analog_pins: Iterable[int] = ANALOG_PINS,
    counter_pins: Iterable[int] = COUNTER_PINS,
) -> int:
    """Drive the deepest-stack scenario on an emulated Uno (``board`` opened with window 4,
    ``control`` its input-control socket); returns the InputReports the host received.
    ``analog_pins``: the analog inputs it samples (the Mega's A0..A15 are 54..69); ``counter_pins``
    its counters (the Mega counts on its external interrupts only).

    Raises AssertionError if the device does not answer as it must (an oversized Pose that
    decodes, inputs that never report).
    """
    servos: list[Servo] = [board.servo(pin, safe=90) for pin in SERVO_PINS]
    for pin in counter_pins:
        board.counter(pin, edge="both", rate_hz=1000)
        control.pulses(pin, 100_000, 5_000)  # 10,000 edges a second each, the whole run
    inputs = [board.digital_input(pin) for pin in DIGITAL_INPUT_PINS]
    analog_pins = tuple(analog_pins)
    for pin in analog_pins:
        board.analog_input(pin, rate_hz=1000, threshold=0)
    for round_ in range(rounds):
        for pin in analog_pins:
            control.analog(pin, (round_ * 97 + pin * 31) % 1024)
        for pin in DIGITAL_INPUT_PINS:
            control.level(pin, (round_ + pin) & 1)
        # Four of the largest at once: the next frame's bytes arrive (receive interrupt) and
        # the last Ack leaves (transmit interrupt) during each decode.
        calls: list[Future[Any]] = [
            board.submit_pose({s: 30 + round_ for s in servos}),
            board.submit_read_outputs(),
            board.submit_ping(bytes(range(64))),
            board.submit_pose({s: 150 - round_ for s in servos}),
        ]
        for call in calls:
            call.result(timeout=CALL_TIMEOUT)
        board.request(_get_info())
        for deep in (False, True):
            try:
                board.request(_oversized_pose(full_decode=deep))
            except CommandRejectedError as refused:
                if refused.status != Status.STATUS_DECODE_ERROR:
                    raise AssertionError(f"an oversized Pose was refused with {refused}") from None
            else:
                raise AssertionError("a Pose of 9 items decoded")
    # The fullest Pose of all (protocol version 6): eight servo items and digital outputs in
    # its masks, each applied as its own DigitalControl after the items. No pin is free, so
    # the digital inputs' pins become outputs for it; counters and analog inputs go on.
    for each in inputs:
        each.release()
    outputs = [board.digital_output(pin) for pin in DIGITAL_INPUT_PINS]
    for round_ in range(rounds):
        for pin in analog_pins:
            control.analog(pin, (round_ * 89 + pin * 37) % 1024)
        level = bool(round_ & 1)
        calls = [
            board.submit_pose(
                {**{s: 40 + round_ for s in servos}, **dict.fromkeys(outputs, level)}
            ),
            board.submit_read_outputs(),
            board.submit_ping(bytes(range(64))),
            board.submit_pose(
                {**{s: 140 - round_ for s in servos}, **dict.fromkeys(outputs, not level)}
            ),
        ]
        for call in calls:
            call.result(timeout=CALL_TIMEOUT)
    reports = board.stats.input_reports
    if reports <= rounds:
        raise AssertionError(f"only {reports} InputReports in {rounds} rounds of moving inputs")
    board.stop()
    board.release_all()
    return reports


@dataclass(frozen=True, slots=True)
class RamBudget:
    """Static data and the deepest stack of one run, against the 2,048 B."""

    static: int
    stack: int
    sp_min: int
    sp_min_pc: int
    #: The call chain at the deepest point (:mod:`protoduino_dev.stackwalk`), when the
    #: runner kept the stack's bytes (``--stack FILE``); "" otherwise.
    chain: str = ""

    @classmethod
    def of(cls, elf: Path, stats: dict[str, Any], stack: Path | None = None) -> RamBudget:
        """From the ELF and the runner's --stats line (``sp_min``, ``sp_min_pc``, ``ramend``),
        and its --stack file if given."""
        if stats["sp_min"] > stats["ramend"]:
            raise AssertionError(f"the stack was never used: {stats}")
        chain = ""
        if stack is not None and stack.exists():
            chain = stackwalk.describe(stackwalk.walk(elf, stack.read_bytes()))
        # SP points at the next free byte: the bytes above it, up to RAMEND, are in use.
        return cls(
            symbol(elf, "_end") - RAM_START,
            int(stats["ramend"]) - int(stats["sp_min"]),
            int(stats["sp_min"]),
            int(stats["sp_min_pc"]),
            chain,
        )

    @property
    def free(self) -> int:
        return RAM_BYTES - self.static - self.stack

    @property
    def holds(self) -> bool:
        return self.free >= FREE_BYTES

    def describe(self) -> str:
        where = f"; its calls, bytes from RAMEND: {self.chain}" if self.chain else ""
        return (
            f"static {self.static} B + deepest stack {self.stack} B (lowest SP 0x{self.sp_min:x} "
            f"at 0x{self.sp_min_pc:x}) = {self.static + self.stack} B; {self.free} B free "
            f"(budget: {FREE_BYTES} B free of {RAM_BYTES} B){where}"
        )


#: The parts of the core's state that firmware/ramsizes/pd_ram_sizes.c measures (its
#: ``pd_size_<name>`` arrays), as firmware/README.md names them.
CORE_PARTS = (
    ("packet", "the received packet"),
    ("command", "its decoded command"),
    ("dedupe", "the dedupe window"),
    ("registry", "the pin registry and the outputs' state"),
    ("inputs", "the inputs'"),
    ("rest", "the link, failsafe, session and report state"),
)


@dataclass(frozen=True, slots=True)
class StaticRam:
    """Where the Uno build's static RAM goes (.data + .bss, bytes), read from the build itself:
    the ELF's symbols and the core's parts (:func:`static_ram`)."""

    total: int
    core: dict[str, int]  # CORE_PARTS' names -> bytes; they add up to the core's state
    descriptors: int  # nanopb's message descriptors and submessage tables (.data)
    tx_ring: int
    rx_ring: int
    channels: int  # the servo driver's

    @property
    def rest(self) -> int:
        return (
            self.total
            - sum(self.core.values())
            - self.descriptors
            - self.tx_ring
            - self.rx_ring
            - self.channels
        )

    def describe(self) -> str:
        """The breakdown as firmware/README.md quotes it (bench part 5 writes it there)."""
        core = ", ".join(f"{label} {self.core[name]}" for name, label in CORE_PARTS)
        return (
            f"static RAM {self.total:,} B: the core {sum(self.core.values())} ({core}), "
            f"nanopb's message descriptors {self.descriptors} (.data), the transmit ring "
            f"{self.tx_ring}, the receive ring {self.rx_ring}, the servo driver's channels "
            f"{self.channels}, the rest {self.rest}"
        )


def sections(elf: Path) -> dict[str, int]:
    """The ELF's section sizes as ``avr-size -A`` reports them (flash is .text + .data, static
    RAM .data + .bss)."""
    out = subprocess.run(
        ["avr-size", "-A", str(elf)], check=True, capture_output=True, text=True, timeout=60
    ).stdout
    sizes: dict[str, int] = {}
    for line in out.splitlines():
        fields = line.split()
        if len(fields) >= 2 and fields[0].startswith(".") and fields[1].isdigit():
            sizes[fields[0]] = int(fields[1])
    return sizes


def _sized_symbols(path: Path) -> dict[str, tuple[int, int]]:
    """name -> (address, size) of every sized symbol in an ELF or object (``avr-nm -S``), GCC's
    ``.lto_priv.N`` suffixes dropped."""
    out = subprocess.run(
        ["avr-nm", "-S", str(path)], check=True, capture_output=True, text=True, timeout=60
    ).stdout
    found = {}
    for line in out.splitlines():
        fields = line.split()
        if len(fields) == 4:
            name = fields[3].split(".lto_priv.")[0]
            found[name] = (int(fields[0], 16), int(fields[1], 16))
    return found


def static_ram(elf: Path, sizes: Path) -> StaticRam:
    """The breakdown of ``elf``'s static RAM; ``sizes`` is the same build's pd_ram_sizes.o
    (``make -C firmware avr avr-ram-sizes`` writes both)."""
    symbols = _sized_symbols(elf)
    parts = {name[len("pd_size_") :]: size for name, (_, size) in _sized_symbols(sizes).items()}
    core = {
        "packet": parts["packet"],
        "command": parts["command"],
        "dedupe": parts["dedupe"],
        "registry": parts["outputs"] - parts["inputs"],
        "inputs": parts["inputs"],
    }
    core["rest"] = parts["core"] - sum(core.values())
    if symbols["core"][1] != parts["core"]:
        raise AssertionError(f"{sizes} is not {elf}'s build: core {parts['core']} B")
    # Merged constants (-fmerge-all-constants) share an address: each is counted once.
    descriptors = {
        address: size
        for name, (address, size) in symbols.items()
        if name.startswith("protoduino_") and name.endswith(("_msg", "_submsg_info"))
    }
    size = sections(elf)
    return StaticRam(
        total=size.get(".data", 0) + size.get(".bss", 0),
        core=core,
        descriptors=sum(descriptors.values()),
        tx_ring=symbols["tx_buf"][1],
        rx_ring=symbols["rx_buf"][1],
        channels=symbols["pd_avr_servos"][1],
    )


#: The object pd_ram_sizes.c compiles to beside the default build's ELF (make avr-ram-sizes).
RAM_SIZES_OBJECT = build.FIRMWARE_ELF.parent / "pd_ram_sizes.o"


def build_static_ram() -> StaticRam:
    """Build the default Uno firmware and its parts' sizes; where its static RAM goes."""
    build.make(build.FIRMWARE_DIR, "avr", "avr-ram-sizes")
    return static_ram(build.FIRMWARE_ELF, RAM_SIZES_OBJECT)
