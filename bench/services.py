"""Benchmark part 10 (docs/performance.md): user services (issue 22, docs/services.md).

* Round trip: a user call against a built-in command of the same size, on the emulated Uno
  running the blinker example's firmware (``make -C firmware avr USER_PROTO=...``). The user
  call is the blinker's ``StopBlink`` (nothing blinks: it answers the toggle count), the
  built-in a digital write (off, on a pin the blinker does not use): both change outputs, so
  both go through the dedupe window, and their COMMAND payloads are the same length (checked;
  since protocol version 4 numbered ArduinoIn by use, no Ping is as long as a user call). Both
  are timed through the public API (``time.perf_counter``, call to return with the Ack),
  alternating one by one with a random pause before each, so a slow spell of the shared
  machine lands on both. The ratio of the medians is the figure; the Acks' sizes are shown
  (the user reply is decoded with the user's schema on the host as well).
* Footprint: flash and static RAM (``avr-size -A``) of the default firmware, built as part 5
  builds it (bench/firmware.py: ``protoduino_dev.build.build_firmware``) in this run: it has
  no user service, and what the mechanism costs there is its 2 B table entry and a few
  instructions; then the two examples' firmwares with every built-in pin mode, and the blinker
  with only the pin modes it needs beside it, each also as its difference from that default.
"""

from __future__ import annotations

import importlib
import random
import subprocess
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

from protoduino import Board
from protoduino._generated import protoduino_pb2 as pb
from protoduino.simboard import SimBoard
from protoduino_dev import build as builds

from .boards import (
    UNO_HZ,
    BoardUnavailableError,
    CycleCounter,
    Percentiles,
    missing_tool,
)
from .core import Context, Section, SectionResult, Target, md_table
from .firmware import Footprint, footprint

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
#: The goal: a user call's median round trip within this factor of the built-in's.
TARGET_RATIO = 1.05
#: Untimed calls of each kind first.
WARMUP = 10
MAX_GAP = 0.002


def _make(*args: str) -> None:
    result = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), *args],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    if result.returncode != 0:
        raise BoardUnavailableError(f"make {' '.join(args)} failed:\n{result.stderr[-2000:]}")


def build_example(name: str, build: Path, features: str | None = None) -> Path:
    """examples/NAME's Uno firmware built into ``build``; its ELF."""
    args = [
        "avr",
        f"BUILD={build}",
        f"USER_PROTO={EXAMPLES / name / (name + '.proto')}",
        f"USER_SRC={EXAMPLES / name / (name + '.c')}",
    ]
    if features is not None:
        args.append(f"FEATURES={features}")
    _make(*args)
    found = sorted((build / "user" / name).glob("avr*/protoduino.elf"))
    if not found:
        raise BoardUnavailableError(f"no ELF for {name} in {build}")
    return found[-1]


#: The built-in's pin: a digital output the blinker does not blink in this part.
BUILTIN_PIN = 12


def builtin_command() -> bytes:
    """The built-in the user call is set against: a digital write, off, on BUILTIN_PIN."""
    msg = pb.ArduinoIn(message_id=0x7FFFFFFF)
    msg.digital_control.pin = BUILTIN_PIN
    msg.digital_control.level = False
    return msg.SerializeToString()


def _stats_board(elf: Path, stats: Path) -> SimBoard:
    """The emulated Uno running ``elf`` with the runner's --stats counters."""
    return SimBoard("avr", firmware=elf, options=("--stats", str(stats)))


def round_trips(
    elf: Path, gen: Path, samples: int, stats: Path
) -> tuple[Percentiles, Percentiles, str, tuple[float, float]]:
    sys.path.insert(0, str(gen))
    try:
        for module in ("blinker_client", "blinker_pb2"):
            sys.modules.pop(module, None)
        client = importlib.import_module("blinker_client")
    finally:
        sys.path.remove(str(gen))
    user_msg = pb.ArduinoIn(message_id=0x7FFFFFFF)
    user_msg.user_call.method = 2  # StopBlink
    user_msg.user_call.request = b""
    builtin_in = builtin_command()
    if len(builtin_in) != len(user_msg.SerializeToString()):
        raise ValueError("the built-in and the user call differ in size")
    user: list[float] = []
    builtin: list[float] = []
    rng = random.Random(8)
    with _stats_board(elf, stats) as sim:
        sim.start()
        counter = CycleCounter(sim, stats)
        with Board.open(sim.port, window=4, baudrate=115_200) as board:
            blinker = client.Blinker(board)
            empty = client.pb.Empty()
            output = board.digital_output(BUILTIN_PIN, safe=False)
            for _ in range(WARMUP):
                blinker.stop_blink(empty)
                output.write(False)
            for _ in range(samples):
                for kind in (0, 1):
                    time.sleep(rng.uniform(0, MAX_GAP))
                    t0 = time.perf_counter()
                    if kind == 0:
                        blinker.stop_blink(empty)
                    else:
                        output.write(False)
                    (user if kind == 0 else builtin).append(time.perf_counter() - t0)
            reply = client.pb.Toggles()
            reply.CopyFrom(blinker.stop_blink(empty))
            # The firmware's answer time: the command's last byte to the Ack's first, in the
            # Uno's cycles (the runner's counters), each kind in a block of its own.
            answer: list[float] = []
            for call in (lambda: blinker.stop_blink(empty), lambda: output.write(False)):
                before = counter.snapshot()
                for _ in range(samples):
                    call()
                delta = counter.snapshot() - before
                answer.append(delta.answer_cycles / max(1, delta.answers))
    ack_user = pb.Ack(message_id=0x7FFFFFFF, user_reply=reply.SerializeToString())
    ack_builtin = pb.Ack(message_id=0x7FFFFFFF)
    sizes = (
        f"command payload {len(builtin_in)} B each; Ack {len(ack_user.SerializeToString())} B "
        f"(user, with its reply) and {len(ack_builtin.SerializeToString())} B (digital write)"
    )
    return Percentiles.of(user), Percentiles.of(builtin), sizes, (answer[0], answer[1])


def _ms(s: float) -> str:
    return f"{s * 1000:.2f}"


def _size_row(label: str, f: Footprint, default: Footprint) -> list[str]:
    """A build's flash and static RAM, and their difference from the default firmware's."""
    if f == default:
        return [label, f"{f.flash:,}", f"{f.ram:,}", "-"]
    return [
        label,
        f"{f.flash:,}",
        f"{f.ram:,}",
        f"{f.flash - default.flash:+,} / {f.ram - default.ram:+,}",
    ]


def run(ctx: Context) -> SectionResult:
    missing = missing_tool("avr")
    if missing is not None:
        return SectionResult(f"Not run: `{missing}` is not installed.\n")
    with TemporaryDirectory() as tmp:
        build = Path(tmp)
        default = footprint(builds.build_firmware())
        blinker_elf = build_example("blinker", build)
        blinker = footprint(blinker_elf)
        presses = footprint(build_example("presses", build))
        lean = footprint(build_example("blinker", build / "lean", features="digital_output"))
        user, builtin, sizes, answer = round_trips(
            blinker_elf, build / "user" / "blinker" / "gen", ctx.samples, build / "stats.jsonl"
        )
    ratio = user.p50 / builtin.p50
    rows = [
        ["user call `StopBlink` (blinker)", _ms(user.p50), _ms(user.p90), _ms(user.p99)],
        ["built-in digital write, same size", _ms(builtin.p50), _ms(builtin.p90), _ms(builtin.p99)],
    ]
    sizes_rows = [
        _size_row("default firmware (no user service)", default, default),
        _size_row("blinker, every pin mode", blinker, default),
        _size_row("presses, every pin mode", presses, default),
        _size_row('blinker, FEATURES="digital_output"', lean, default),
    ]
    markdown = (
        "A user call and a built-in command of the same size on the emulated Uno (the "
        f"blinker example's firmware), {user.n} of each, alternating; {sizes}. Milliseconds, "
        "call to return with the Ack:\n\n"
        + md_table(["call", "p50", "p90", "p99"], rows)
        + f"\nMedian ratio user / built-in: **{ratio:.3f}**. The firmware's answer time (the "
        "command's last byte to the Ack's first, the emulator's cycle counters, mean of "
        f"{user.n}): user call {answer[0]:,.0f} cycles ({answer[0] / UNO_HZ * 1e6:,.0f} us, "
        "the blinker's handler included), digital write "
        f"{answer[1]:,.0f} cycles ({answer[1] / UNO_HZ * 1e6:,.0f} us). Where the difference goes "
        "(the runner's --profile): the UserCall and the user's messages are decoded and the "
        "reply encoded with nanopb's generic code, where the built-in Ack is written by the "
        "hand-made encoder. Finding the member is cheap for both since protocol version 4 "
        "numbered ArduinoIn by use: `user_call` is field 7, the digital write field 4 (at "
        "field 19, nanopb's walk of the descriptor had cost the user call about 2,500 cycles "
        "more than a Ping at field 2).\n\n"
        "Flash and static RAM (`avr-size -A`; the budget of the default firmware is "
        "26,624 B of flash and static RAM + deepest stack + 256 B free <= 2,048 B), each "
        "built in this run. The default firmware carries the mechanism with no user service "
        f"({default.flash:,} B of flash, {default.ram:,} B of static RAM here; the mechanism "
        "is its 2 B table entry and a few instructions). A service adds nanopb's encoder, its "
        "descriptors and scratch buffers and its handlers; a firmware composes it with the pin "
        "modes it needs:\n\n"
        + md_table(
            ["build", "flash B", "static RAM B", "over the default (flash / RAM B)"], sizes_rows
        )
    )
    target = Target(
        "user call round trip vs a built-in of the same size (emulated Uno)",
        f"within {TARGET_RATIO - 1:.0%}",
        f"{ratio:.3f}x",
        ratio <= TARGET_RATIO,
    )
    return SectionResult(markdown, targets=[target])


SECTION = Section(10, "services", "User services: round trip and footprint", run)
