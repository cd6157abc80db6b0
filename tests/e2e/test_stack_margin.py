"""The Uno firmware's RAM budget holds: static data + the deepest stack + 256 B free <= 2,048 B.

The ATmega328P has 2 KB of RAM and no MMU: the stack grows down from RAMEND towards the
static variables, and a stack that reaches them corrupts them silently (a transmit ring 28
bytes larger once did exactly that on every Pose: the device hung). The budget (issue 21,
docs/protocol.md and firmware/README.md) keeps 256 B free for the users' own code besides.
``protoduino_dev.rambudget.exercise`` drives every command at its largest with every kind of
input reporting on the emulated Uno, whose runner records the lowest stack pointer after
every instruction, interrupts included; the test fails when the 256 B are not free.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino import Board
from protoduino.simboard import runner_command
from protoduino.simcontrol import SimControl
from protoduino_dev import build
from protoduino_dev.rambudget import RamBudget, exercise
from protoduino_dev.runnerstats import snapshot

pytestmark = pytest.mark.avr

STARTUP_TIMEOUT = 10.0


class StatsRunner(BoardProcess):
    """The emulated Uno running the firmware, with the runner's ``--stats FILE`` and its
    input-control socket."""

    def __init__(self, elf: Path, stats: Path, control: Path) -> None:
        self.stats = stats
        self.stack = stats.with_suffix(".stack")
        self.control = control
        cmd = runner_command(elf, control=control)
        cmd[-1:-1] = ["--stats", str(stats), "--stack", str(self.stack)]
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


def test_every_command_at_its_largest_leaves_the_ram_budget(
    uno: tuple[StatsRunner, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    runner, elf = uno
    with Board.open(runner.port, window=4) as board, SimControl(runner.control) as control:
        exercise(board, control)
    ram = RamBudget.of(elf, runner.snapshot(), runner.stack)
    # The deepest point is where a budget test should look: it names real frames.
    assert "main" in ram.chain, ram.chain
    with capsys.disabled():  # the figures belong in every test log, not only on failure
        sys.stdout.write(f"\nUno RAM: {ram.describe()}\n")
    assert ram.holds, f"the RAM budget does not hold: {ram.describe()}"
