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

import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import Future
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino import Board, servicegen
from protoduino.simboard import runner_command
from protoduino.simcontrol import SimControl
from protoduino_dev import build, stackwalk
from protoduino_dev.rambudget import ANALOG_PINS, CALL_TIMEOUT, COUNTER_PINS, RamBudget, exercise
from protoduino_dev.runnerstats import snapshot
from userbuilds import ROOT, nested_proto

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


#: The most stack one level of a nested decode takes in nanopb (the frames of pb_decode_inner,
#: decode_field and decode_basic_field): 125 B with its extension and callback decoders out of
#: line (firmware/avr/pd_avr_pb_decode.c), 163 B when the compiler inlined them and their locals
#: sat in every level's frames.
NANOPB_LEVEL_BYTES = 128


def test_a_level_of_a_nested_decode_takes_at_most_128_bytes(uno: tuple[StatsRunner, Path]) -> None:
    """The deepest point's chain as the runner kept it: the bytes from one pb_decode_inner's
    return address to the next. The deepest point is mostly a Pose decoded in full (four
    levels), but interrupts stacked on a three-level decode reach about as deep (CI's run at
    909cfd1 kept one such, the interrupts' frames unnamed), so any chain of two levels or more
    is measured."""
    runner, elf = uno
    with Board.open(runner.port, window=4) as board, SimControl(runner.control) as control:
        exercise(board, control)
    runner.snapshot()  # the runner writes its --stack file with its counters
    frames = stackwalk.walk(elf, runner.stack.read_bytes())
    levels = [frame.depth for frame in frames if frame.function == "pb_decode_inner"]
    assert 2 <= len(levels) <= 4, stackwalk.describe(frames)
    steps = [deeper - outer for outer, deeper in pairwise(levels)]
    assert max(steps) <= NANOPB_LEVEL_BYTES, (steps, stackwalk.describe(frames))


#: The deepest service a user may have: its one rpc takes and returns a message of
#: servicegen.MAX_USER_LEVELS levels, which the handler echoes.
DEEP_HANDLER = """#include "deep_service.h"

static uint32_t calls;

uint8_t deep_echo(pd_user_ctx_t *ctx, const Level{n} *request, Level{n} *reply)
{{
    (void)ctx;
    *reply = *request;
    calls++;
    return 0;
}}

void deep_safe(pd_user_ctx_t *ctx, uint8_t pin) {{ (void)ctx; (void)pin; }}
void deep_release(pd_user_ctx_t *ctx, uint8_t pin) {{ (void)ctx; (void)pin; }}
void deep_poll(pd_user_ctx_t *ctx, uint32_t now_ms) {{ (void)ctx; (void)now_ms; }}
"""


def _make_deep(folder: Path, levels: int) -> subprocess.CompletedProcess[str]:
    """`make avr` (every pin mode) with a service of ``levels`` levels, built in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    proto, handler = folder / "deep.proto", folder / "deep.c"
    proto.write_text(
        nested_proto(levels)
        + f"service Deep {{ rpc Echo(Level{levels}) returns (Level{levels}); }}\n"
    )
    handler.write_text(DEEP_HANDLER.format(n=levels))
    return subprocess.run(
        [
            "make",
            "-s",
            "-C",
            str(ROOT / "firmware"),
            "avr",
            f"BUILD={folder / 'build'}",
            f"USER_PROTO={proto}",
            f"USER_SRC={handler}",
        ],
        check=False,
        capture_output=True,
        text=True,
        timeout=600,
    )


def _deep_request(pb: Any, levels: int) -> Any:
    message = getattr(pb, f"Level{levels}")(value=0xFFFFFFFF)
    if levels > 1:
        message.down.CopyFrom(_deep_request(pb, levels - 1))
    return message


def test_the_build_refuses_a_user_message_nested_too_deep(tmp_path: Path) -> None:
    missing = missing_tool("make", "avr-gcc")
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    levels = servicegen.MAX_USER_LEVELS + 1
    built = _make_deep(tmp_path, levels)
    assert built.returncode != 0
    assert (
        f"message Level{levels} nests {levels} levels of messages" in built.stderr
        and f"more than the {levels - 1} a user message may have" in built.stderr
    ), built.stderr
    assert not (tmp_path / "build" / "user" / "deep" / "avr" / "protoduino.elf").exists()


def test_a_user_call_at_the_deepest_accepted_nesting_stays_within_the_firmwares_own_stack(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """servicegen.MAX_USER_LEVELS on the emulated Uno with every pin mode in: the firmware's
    own deepest scenario first, then the deepest user calls, four in flight with the inputs'
    interrupts landing: the user calls take the stack no deeper than the firmware's own."""
    missing = missing_tool("make", "cc", "avr-gcc", "avr-nm", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    levels = servicegen.MAX_USER_LEVELS
    built = _make_deep(tmp_path, levels)
    assert built.returncode == 0, built.stderr
    gen = tmp_path / "build" / "user" / "deep" / "gen"
    sys.path.insert(0, str(gen))
    try:
        import deep_pb2 as pb  # type: ignore[import-not-found]
    finally:
        sys.path.remove(str(gen))
        sys.modules.pop("deep_pb2", None)
    request = _deep_request(pb, levels)
    elf = tmp_path / "build" / "user" / "deep" / "avr" / "protoduino.elf"
    build.build_runner()
    runner = StatsRunner(elf, tmp_path / "stats.jsonl", tmp_path / "control.sock")
    try:
        with Board.open(runner.port, window=4) as board, SimControl(runner.control) as control:
            exercise(board, control)
            own = RamBudget.of(elf, runner.snapshot(), runner.stack)
            for pin in COUNTER_PINS:
                board.counter(pin, edge="both", rate_hz=1000)
                control.pulses(pin, 100_000, 5_000)
            for pin in ANALOG_PINS:
                board.analog_input(pin, rate_hz=1000, threshold=0)
            for round_ in range(20):
                for pin in ANALOG_PINS:
                    control.analog(pin, (round_ * 97 + pin * 31) % 1024)
                calls: list[Future[bytes]] = [
                    board.submit_call_user(1, request.SerializeToString()) for _ in range(4)
                ]
                for call in calls:
                    assert (
                        pb.__dict__[f"Level{levels}"].FromString(call.result(timeout=CALL_TIMEOUT))
                        == request
                    )
        deepest = RamBudget.of(elf, runner.snapshot(), runner.stack)
    finally:
        runner.stop(strict=False)
    with capsys.disabled():
        sys.stdout.write(
            f"\nUno RAM, a service of {levels} levels: the firmware's own {own.stack} B of "
            f"stack, with the user calls {deepest.describe()}\n"
        )
    assert deepest.stack <= own.stack, (own.describe(), deepest.describe())
