"""The Uno firmware's RAM budget holds: static data + the deepest stack + 256 B free <= 2,048 B.

The ATmega328P has 2 KB of RAM and no MMU: the stack grows down from RAMEND
towards the static variables, and a stack that reaches them corrupts them
silently (a transmit ring 28 bytes larger once did exactly that on every Pose:
the device hung). The runner (tools/avrsim) records the lowest stack pointer
after every instruction, interrupts included; this test drives every command at
its largest, several in flight so that the UART interrupts land inside the
deepest decode, with every kind of input configured and reporting (the
control socket moves them all the time: pin-change, counter and ADC interrupts
land anywhere, and reports compete with the Acks for the transmit ring), and
compares that low-water mark with the end of the firmware's static data (the
linker's ``_end``, after .data, .bss and .noinit; the firmware has no heap).

The budget (issue 21, docs/protocol.md and firmware/README.md): the ATmega328P's 2,048 B of
RAM hold the static data, the deepest stack measured here, and 256 B kept free for the users'
own code. The test fails when those 256 B are not free.
"""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino import Board, CommandRejectedError, Servo
from protoduino.messages import ArduinoIn, Status
from protoduino.simboard import runner_command
from protoduino.simcontrol import SimControl
from protoduino_dev import build
from protoduino_dev.runnerstats import snapshot

pytestmark = pytest.mark.avr

#: The ATmega328P's RAM (0x100 .. RAMEND = 0x8FF).
RAM_BYTES = 2048
RAM_START = 0x100
#: Kept free for the users' own code (issue 21's budget). It also covers what a
#: single run's low-water mark can miss: an interrupt landing at that point with a
#: frame of its own (two can nest, about 20 bytes each).
FREE_BYTES = 256

STARTUP_TIMEOUT = 10.0

#: The Uno firmware's pins: counters on 2 and 3 (INT0, INT1), servos on 4..11 (its eight
#: channels), digital inputs on 12 and 13, analog inputs on 14..19 (A0..A5).
COUNTER_PINS = (2, 3)
SERVO_PINS = range(4, 12)
DIGITAL_INPUT_PINS = (12, 13)
ANALOG_PINS = range(14, 20)


def _symbol(elf: Path, name: str) -> int:
    """The data-space address of ``name`` in the ELF (avr-nm adds 0x800000 to RAM)."""
    out = subprocess.run(["avr-nm", str(elf)], check=True, capture_output=True, text=True).stdout
    for line in out.splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[2] == name:
            return int(fields[0], 16) & 0xFFFF
    raise AssertionError(f"{name} is not in {elf}")


class StatsRunner(BoardProcess):
    """The emulated Uno running the firmware, with the runner's ``--stats FILE``."""

    def __init__(self, elf: Path, stats: Path, control: Path) -> None:
        self.stats = stats
        self.control = control
        cmd = runner_command(elf, control=control)
        cmd[-1:-1] = ["--stats", str(stats)]
        super().__init__(cmd, startup=STARTUP_TIMEOUT)

    def snapshot(self) -> dict[str, Any]:
        """The counters now."""
        return snapshot(self.proc.pid, self.stats)


@pytest.fixture
def uno(tmp_path: Path) -> Iterator[tuple[StatsRunner, Path]]:
    missing = missing_tool("make", "cc", "avr-gcc", "avr-nm", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build.build_runner()
    elf = build.build_firmware()
    runner = StatsRunner(elf, tmp_path / "stats.jsonl", tmp_path / "control.sock")
    try:
        yield runner, elf
    finally:
        runner.stop(strict=False)


def _get_info() -> ArduinoIn:
    msg = ArduinoIn()
    msg.get_info.SetInParent()
    return msg


def _oversized_pose() -> ArduinoIn:
    """A Pose with one item more than the firmware's bound (8): nanopb refuses it while it
    is as deep in the decode as a Pose can take it."""
    msg = ArduinoIn()
    for pin in (*SERVO_PINS, 12):
        msg.pose.items.add().servo.pin = pin
    return msg


def test_every_command_at_its_largest_leaves_the_ram_budget(
    uno: tuple[StatsRunner, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    runner, elf = uno
    static_end = _symbol(elf, "_end")
    with Board.open(runner.port, window=4) as board, SimControl(runner.control) as control:
        servos: list[Servo] = [board.servo(pin, safe=90) for pin in SERVO_PINS]
        for pin in COUNTER_PINS:
            board.counter(pin, edge="both", rate_hz=1000)
            control.pulses(pin, 100_000, 5_000)  # 10,000 edges a second each, all test long
        for pin in DIGITAL_INPUT_PINS:
            board.digital_input(pin)
        for pin in ANALOG_PINS:
            board.analog_input(pin, rate_hz=1000, threshold=0)
        for round_ in range(20):
            for pin in ANALOG_PINS:
                control.analog(pin, (round_ * 97 + pin * 31) % 1024)
            for pin in DIGITAL_INPUT_PINS:
                control.level(pin, (round_ + pin) & 1)
            # Four of the largest at once: the next frame's bytes arrive (receive
            # interrupt) and the last Ack leaves (transmit interrupt) during each decode.
            pose: dict[Servo | Any, int | bool] = {s: 30 + round_ for s in servos}
            calls: list[Future[Any]] = [
                board.submit_pose(pose),
                board.submit_read_outputs(),
                board.submit_ping(bytes(range(64))),
                board.submit_pose({s: 150 - round_ for s in servos}),
            ]
            for call in calls:
                call.result(timeout=30)
            board.request(_get_info())
            with pytest.raises(CommandRejectedError) as refused:
                board.request(_oversized_pose())
            assert refused.value.status == Status.STATUS_DECODE_ERROR
        assert board.stats.input_reports > 20  # the inputs did report meanwhile
        board.stop()
        board.release_all()
    stats = runner.snapshot()
    assert stats["sp_min"] <= stats["ramend"], stats  # the stack was used at all
    static = static_end - RAM_START
    # SP points at the next free byte: the bytes above it, up to RAMEND, are in use.
    stack = stats["ramend"] - stats["sp_min"]
    free = RAM_BYTES - static - stack
    with capsys.disabled():  # the figures belong in every test log, not only on failure
        print(
            f"\nUno RAM: static {static} B + deepest stack {stack} B "
            f"(at 0x{stats['sp_min_pc']:x}) = {static + stack} B; {free} B free "
            f"(budget: {FREE_BYTES} B free)"
        )
    assert free >= FREE_BYTES, (
        f"only {free} B of RAM free: static {static} B + deepest stack {stack} B "
        f"(lowest SP 0x{stats['sp_min']:x} at 0x{stats['sp_min_pc']:x}) + {FREE_BYTES} B "
        f"> {RAM_BYTES} B"
    )
