"""Benchmark part 5 (docs/performance.md).

The Uno firmware's flash and static RAM, and its cycles per command.

* Footprint: ``make -C firmware avr`` builds ``build/avr/protoduino.elf``; ``avr-size -A``
  gives its sections. Flash = .text + .data (the initial values of .data live in flash),
  static RAM = .data + .bss, as the firmware's Makefile and tests/c/test_footprint.py count them.
  Against issue 21's budget: flash <= 26,624 B; static RAM + the deepest stack + 256 B free
  <= 2,048 B (the stack as tests/e2e/test_stack_margin.py measures it; here the static RAM
  and what it leaves). Per feature: the firmware built without each pin mode
  (``make avr FEATURES=...``), the difference is the mode's cost; StandardFirmata and
  StandardFirmataPlus beside it, as what each carries for its size, not as a limit.
* Cycles per command: the emulated Uno runs with the runner's ``--stats`` and ``--profile``
  (tools/avrsim). The firmware sleeps whenever it has nothing to do, so its awake cycles are
  its CPU use; between two snapshots, ``N`` commands are sent one at a time through the public
  API, and the awake cycles the idle board spends in the same emulated time (its clock and
  servo interrupts, measured first) are subtracted. The profile of the servo-write block, mapped
  to the ELF's symbols with ``avr-nm``, says where those cycles go.
* The same write on StandardFirmata (issue 35: the device judged in cycles, beside Firmata's):
  StandardFirmata never sleeps, so its awake cycles say nothing; for both firmwares the
  cycles a block of writes added are its ``--profile`` less the idle board's, scaled to the
  same emulated time, address by address, the positive differences summed (the idle loop's
  own cycles that the writes displaced count for nothing). On protoduino this agrees with
  its awake cycles net of idle, which checks the method.
* CPU share at the highest command rate: a window of 4 servo writes in flight (part 3's best
  window), the awake share measured over it.
"""

from __future__ import annotations

import bisect
import logging
import os
import re
import shutil
import subprocess
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from tempfile import TemporaryDirectory

from protoduino import Board
from protoduino.errors import BuildError
from protoduino_dev import build as builds
from protoduino_dev import runnerstats
from protoduino_dev.rambudget import (
    FREE_BYTES,
    RamBudget,
    StaticRam,
    build_static_ram,
    exercise,
    sections,
)

from . import charts
from .boards import UNO_HZ, BoardUnavailableError, CycleCounter, CycleStats, started, started_hex
from .core import (
    Chart,
    Context,
    MissingDependencyError,
    Section,
    SectionResult,
    Target,
    fmt_rate,
    md_table,
)
from .peers import firmata_board
from .peers import protoduino as protoduino_peer
from .throughput import drive, servo_line

log = logging.getLogger(__name__)

#: The budget (issue 21): the default firmware, every pin mode in, leaves users' code room.
FLASH_BUDGET = 26_624
#: RAM kept free beside the static data and the deepest stack (tests/e2e/test_stack_margin.py).
RAM_FREE = FREE_BYTES
#: For comparison, not a limit: StandardFirmata (digital and analog I/O, PWM, servos, I2C; no
#: CRC, no acks, no failsafe), the hex that the race runs (part 9: bench/peers/firmata_board.py
#: reads its size), and StandardFirmataPlus, built with the same avr-gcc 5.4 (the project's
#: reference sizes).
FIRMATA_PLUS = (15_202, 1_274)


def firmata_sizes() -> tuple[str, str]:
    """StandardFirmata's flash and static RAM as the report shows them, from the race's hex."""
    size = firmata_board.footprint()
    if size is None:
        return ("-", "-")  # not fetched: firmata_board.FETCH_STEP fetches it
    return (f"{size.flash:,} B", f"{size.static_ram:,} B")


#: What each carries, per protoduino feature (their sketches' own feature lists).
FEATURE_ROWS = (
    ("servo", "Servo", "yes", "yes"),
    ("digital_output", "digital output", "yes", "yes"),
    (
        "digital_input",
        "digital input (debounce, interlocks)",
        "yes, no debounce or interlock",
        "yes, no debounce or interlock",
    ),
    ("analog_input", "analog input", "yes, one rate for all", "yes, one rate for all"),
    ("pwm", "PWM", "yes", "yes"),
    ("counter", "pulse counter", "no", "no"),
)
#: The ATmega328P: 32 KB flash of which Optiboot keeps 0.5 KB (1 KB here, see tools/avrsim), 2 KB
#: RAM.
FLASH_TOTAL = 32_768
RAM_TOTAL = 2_048
IDLE_SECONDS = 0.5
#: StandardFirmata's writes have no answer: one every FIRMATA_GAP_S of wall time (a write is
#: 3 bytes, 0.52 ms at its 57600 baud), the last one given FIRMATA_GAP_S to be done.
FIRMATA_GAP_S = 0.005
#: Issue 35's goals: awake cycles per digital write and per servo write on the emulated Uno.
GOAL_CYCLES = {"digital": 3_000, "servo": 3_500}
MAX_RATE_WINDOW = 4
PROFILE_ROWS = 14

#: ATmega328P interrupt vectors the firmware uses.
VECTORS = {
    "__vector_11": "TIMER1_COMPA: servo pulse edges",
    "__vector_16": "TIMER0_OVF: millisecond clock (every 1,024 us)",
    "__vector_18": "USART_RX: byte into the receive ring",
    "__vector_19": "USART_UDRE: byte out of the transmit ring",
}

#: Groups of functions for the profile summary: (group, rule), first match wins.
GROUPS: tuple[tuple[str, Callable[[str], bool]], ...] = (
    (
        "frame transmit: packet, CRC and COBS encoding into the transmit ring (pd_link_send)",
        lambda n: n.startswith("pd_link_send"),
    ),
    (
        "nanopb decoding (pb_decode and its field iterator)",
        lambda n: (
            n.startswith("pb_")
            or n
            in {
                "load_descriptor_values",
                "advance_iterator",
                "decode_basic_field",
                "decode_field",
                "decode_static_field",
                "decode_pointer_field",
                "decode_callback_field",
                "buf_read",
                "read_raw_value",
            }
        ),
    ),
    (
        "generated decoders of the pin modes' Controls (fast_*, generated/pd_fastdec.h)",
        lambda n: n.startswith("fast_"),
    ),
    ("CRC-16 (pd_crc16_*)", lambda n: n.startswith("pd_crc16")),
    (
        "Ack encoding (pd_encode.c)",
        lambda n: n.startswith(("put", "open_msg", "close_msg", "pd_encode", "pd_out_send")),
    ),
    (
        "interrupt handlers",
        lambda n: n.startswith("__vector_") or n == "pd_avr_uart_tx_next",
    ),
    (
        "register save/restore (-mcall-prologues) and libgcc arithmetic",
        lambda n: n.startswith("__"),
    ),
    (
        "main loop: receive ring, COBS decoding, packet checks, dispatch, outputs (inlined "
        "into main by LTO; COBS and the CRC's call per byte as bytes arrive)",
        lambda n: n == "main",
    ),
)

#: Chart labels for the groups above.
SHORT = {
    GROUPS[0][0]: "frame transmit",
    GROUPS[1][0]: "nanopb decoding",
    GROUPS[2][0]: "generated decoders",
    GROUPS[3][0]: "CRC-16",
    GROUPS[4][0]: "Ack encoding",
    GROUPS[5][0]: "interrupts",
    GROUPS[6][0]: "prologues, libgcc",
    GROUPS[7][0]: "main loop (inlined)",
}

#: The servo write's profile before issue 11's I/O engine (polled transmit, bit-by-bit CRC,
#: all of a frame's work at its delimiter), as the previous run of this bench measured it:
#: docs/performance.md at commit 9cbea13 (not re-measured: that firmware speaks another
#: schema). Cycles per command by SHORT group, the idle load included.
BEFORE_COMMIT = "9cbea13"
BEFORE_SERVO_CYCLES = 50_574
BEFORE_GROUPS: dict[str, float] = {
    "frame transmit": 21_688,
    "nanopb decoding": 15_806,
    "main loop (inlined)": 4_959,
    "CRC-16": 3_022,
    "prologues, libgcc": 2_956,
    "interrupts": 1_686,
    "Ack encoding": 983,
    "everything else": 846,
}

KINDS: tuple[tuple[str, str], ...] = (
    ("servo", "servo write"),
    ("digital", "digital write"),
    ("ping", "Ping, empty"),
    ("ping64", "Ping, 64-byte payload"),
)


@dataclass(frozen=True, slots=True)
class Footprint:
    text: int
    data: int
    bss: int

    @property
    def flash(self) -> int:
        return self.text + self.data

    @property
    def ram(self) -> int:
        return self.data + self.bss


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise BoardUnavailableError(f"`{name}` is not installed (Debian package binutils-avr)")
    return path


def footprint(elf: Path) -> Footprint:
    """The ELF's sections as ``avr-size -A`` reports them."""
    _tool("avr-size")
    sizes = sections(elf)
    return Footprint(sizes.get(".text", 0), sizes.get(".data", 0), sizes.get(".bss", 0))


@dataclass(frozen=True, slots=True)
class Symbols:
    """Function address ranges of an ELF, for mapping a flat profile."""

    starts: list[int]
    ends: list[int]
    names: list[str]

    @classmethod
    def of(cls, elf: Path) -> Symbols:
        out = subprocess.run(
            [_tool("avr-nm"), "-n", "-S", "--defined-only", str(elf)],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        ).stdout
        rows = []
        for line in out.splitlines():
            fields = line.split()
            if len(fields) == 4 and fields[2] in "tTwW":
                start, size = int(fields[0], 16), int(fields[1], 16)
                rows.append((start, start + size, fields[3]))
        rows.sort()
        return cls([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows])

    def name(self, address: int) -> str:
        i = bisect.bisect_right(self.starts, address) - 1
        if i >= 0 and address < self.ends[i]:
            return self.names[i]
        return "(no symbol)"


def clean_name(name: str) -> str:
    """A symbol without GCC's clone suffixes: ``pd_link_send.constprop.41`` -> ``pd_link_send``."""
    return re.sub(r"(\.(constprop|isra|part|lto_priv|cold)(\.\d+)?)+$", "", name)


def read_profile(path: Path, symbols: Symbols) -> Counter[str]:
    """Awake cycles by function from a --profile file."""
    by_function: Counter[str] = Counter()
    for line in path.read_text(encoding="utf-8").splitlines():
        address, cycles = line.split()
        by_function[clean_name(symbols.name(int(address, 16)))] += int(cycles)
    return by_function


def read_addresses(path: Path) -> Counter[int]:
    """Awake cycles by flash address from a --profile file."""
    by_address: Counter[int] = Counter()
    for line in path.read_text(encoding="utf-8").splitlines():
        address, cycles = line.split()
        by_address[int(address, 16)] += int(cycles)
    return by_address


def added_cycles(
    idle: Counter[int], idle_cycles: int, busy: Counter[int], busy_cycles: int
) -> float:
    """The cycles a block of work added to an idle board's: ``busy`` (a --profile over
    ``busy_cycles`` emulated cycles) less ``idle`` scaled to the same time, address by
    address, the positive differences summed."""
    scale = busy_cycles / idle_cycles
    return sum(max(0.0, c - idle.get(a, 0) * scale) for a, c in busy.items())


def group_of(function: str) -> str:
    for group, rule in GROUPS:
        if rule(function):
            return group
    return "everything else"


@dataclass(slots=True)
class CycleRun:
    idle_share: float
    per_command: dict[str, float]
    #: Cycles per command by the profile difference (added_cycles), for the StandardFirmata
    #: comparison.
    added: dict[str, float]
    bytes_per_command: dict[str, tuple[float, float]]  # (into the Uno, out of it)
    profile: Counter[str]
    profile_commands: int
    max_rate: float
    max_rate_share: float


def servo_payload_bytes() -> int:
    """The ArduinoIn payload of the benchmarks' servo write (1-byte message id)."""
    _init, command, _ack = protoduino_peer.servo_messages(protoduino_peer.FIRST_MESSAGE_ID)
    return len(command.SerializeToString())


def _busy(delta: CycleStats, idle_share: float) -> float:
    return delta.awake - idle_share * delta.cycles


def measure_cycles(samples: int, commands: int) -> CycleRun:
    symbols = Symbols.of(builds.FIRMWARE_ELF)
    with TemporaryDirectory(prefix="bench-fw-") as tmp:
        stats = Path(tmp) / "stats.jsonl"
        profile_path = Path(tmp) / "profile.txt"
        with started("avr", stats=stats, profile=profile_path) as sim:
            counter = CycleCounter(sim, stats)
            with Board.open(sim.port, ping=False, baudrate=115_200) as board:
                servo = board.servo(9)
                led = board.digital_output(13)
                payload = bytes(range(64))
                ops: dict[str, Callable[[int], object]] = {
                    "servo": lambda i: servo.write(80 + 20 * (i & 1)),
                    "digital": lambda i: led.write(bool(i & 1)),
                    "ping": lambda _i: board.ping(),
                    "ping64": lambda _i: board.ping(payload),
                }
                a = counter.snapshot()
                time.sleep(IDLE_SECONDS)
                idle = counter.snapshot() - a
                idle_share = idle.awake_share
                idle_profile = read_addresses(profile_path)
                per_command: dict[str, float] = {}
                added: dict[str, float] = {}
                io: dict[str, tuple[float, float]] = {}
                profile: Counter[str] = Counter()
                for kind, _label in KINDS:
                    board.ping()  # the failsafe counts from the last Ping: keep it far away
                    before = counter.snapshot()
                    for i in range(samples):
                        ops[kind](i)
                    delta = counter.snapshot() - before
                    per_command[kind] = _busy(delta, idle_share) / samples
                    added[kind] = (
                        added_cycles(
                            idle_profile, idle.cycles, read_addresses(profile_path), delta.cycles
                        )
                        / samples
                    )
                    io[kind] = (delta.uart_rx / samples, delta.uart_tx / samples)
                    if kind == "servo":
                        profile = read_profile(profile_path, symbols)
            with Board.open(
                sim.port, window=MAX_RATE_WINDOW, ping=False, baudrate=115_200
            ) as board:
                servo = board.servo(9)
                before = counter.snapshot()
                seconds, ok, _failed = drive(
                    lambda i: servo.write(80 + 20 * (i & 1)), MAX_RATE_WINDOW, commands
                )
                delta = counter.snapshot() - before
    return CycleRun(
        idle_share,
        per_command,
        added,
        io,
        profile,
        samples,
        ok / seconds if seconds > 0 else 0.0,
        delta.awake_share,
    )


def measure_firmata(writes: int) -> dict[str, float] | None:
    """StandardFirmata's cycles per digital write (pin 13) and servo write (pin 9) on the same
    runner, by the profile difference (:func:`added_cycles`); None without its hex."""
    fb = firmata_board
    if not fb.HEX.exists():
        return None
    out: dict[str, float] = {}
    with TemporaryDirectory(prefix="bench-fw-firmata-") as tmp:
        stats = Path(tmp) / "stats.jsonl"
        profile_path = Path(tmp) / "profile.txt"
        with (
            started_hex(fb.HEX, stats=stats, profile=profile_path) as sim,
            fb.opened(sim.port) as board,
        ):
            counter = CycleCounter(sim, stats)
            led = board.digital_output(13)
            servo = board.servo(9, 90)
            time.sleep(FIRMATA_GAP_S)
            a = counter.snapshot()
            time.sleep(IDLE_SECONDS)
            idle = counter.snapshot() - a
            idle_profile = read_addresses(profile_path)
            ops: dict[str, Callable[[int], object]] = {
                "digital": lambda i: led.write(i & 1),
                "servo": lambda i: servo.write(80 + 20 * (i & 1)),
            }
            for kind, op in ops.items():
                before = counter.snapshot()
                for i in range(writes):
                    op(i)
                    time.sleep(FIRMATA_GAP_S)
                delta = counter.snapshot() - before
                out[kind] = (
                    added_cycles(
                        idle_profile, idle.cycles, read_addresses(profile_path), delta.cycles
                    )
                    / writes
                )
    return out


def feature_costs(full: Footprint) -> dict[str, Footprint]:
    """Each pin mode's footprint: the default firmware less the one built without that mode."""
    costs: dict[str, Footprint] = {}
    for feature in builds.FEATURES:
        without = footprint(
            builds.build_firmware_features(f for f in builds.FEATURES if f != feature)
        )
        costs[feature] = Footprint(
            full.text - without.text, full.data - without.data, full.bss - without.bss
        )
    return costs


def _features_markdown(size: Footprint, costs: dict[str, Footprint]) -> str:
    rows = [
        [
            label,
            f"{costs[name].flash:,} B",
            f"{costs[name].ram:,} B",
            firmata,
            plus,
        ]
        for name, label, firmata, plus in FEATURE_ROWS
    ]
    rows.append(
        [
            "**the whole firmware**",
            f"**{size.flash:,} B**",
            f"**{size.ram:,} B**",
            " / ".join(firmata_sizes()),
            f"{FIRMATA_PLUS[0]:,} B / {FIRMATA_PLUS[1]:,} B",
        ]
    )
    return (
        "Footprint per feature: the default firmware less the one built without that pin mode "
        "(`make -C firmware avr FEATURES=...`, every other mode in); what StandardFirmata and "
        "StandardFirmataPlus carry of it, for comparison. The rest of protoduino's flash is "
        "what every build has: the link (COBS, CRC, SEQ, sessions), nanopb's decoder, the Acks, "
        "exactly-once, the failsafe, poses.\n\n"
        + md_table(
            ["feature", "flash", "static RAM", "StandardFirmata", "StandardFirmataPlus"], rows
        )
    )


def measure_ram(elf: Path) -> RamBudget:
    """The RAM budget on the emulated Uno: the deepest stack of tests/e2e/test_stack_margin.py's
    scenario (protoduino_dev.rambudget) beside the static data."""
    with TemporaryDirectory() as tmp:
        stats = Path(tmp) / "stats.jsonl"
        with (
            started("avr", stats=stats) as sim,
            Board.open(sim.port, window=4, baudrate=115_200) as board,
        ):
            exercise(board, sim.control)
            row = runnerstats.snapshot(sim.pid, stats)
    return RamBudget.of(elf, row)


def run(ctx: Context) -> SectionResult:
    load = os.getloadavg()[0]
    try:
        static = build_static_ram()
        elf = builds.FIRMWARE_ELF
        size = footprint(elf)
        costs = feature_costs(size)
    except (BuildError, BoardUnavailableError, subprocess.SubprocessError, OSError) as error:
        reason = str(error).splitlines()[0]
        log.warning("firmware: not built: %s", reason)
        return SectionResult(
            f"Not run: the Uno firmware could not be built here ({reason}).\n",
            [
                Target("firmware flash", f"<= {FLASH_BUDGET:,} B", "not run", None),
                Target("firmware static RAM", "static + stack + 256 B <= 2,048 B", "not run", None),
            ],
        )
    targets = [
        Target(
            "firmware flash",
            f"<= {FLASH_BUDGET:,} B, every pin mode in (issue 21's budget)",
            f"{size.flash:,} B",
            size.flash <= FLASH_BUDGET,
        ),
    ]
    try:
        ram: RamBudget | None = measure_ram(elf)
    except (BoardUnavailableError, AssertionError, OSError) as error:
        log.warning("firmware: RAM budget not measured: %s", error)
        ram = None
    targets.append(
        Target(
            "firmware RAM",
            f"static + deepest stack + {RAM_FREE} B free <= {RAM_TOTAL:,} B",
            f"{ram.static:,} B + {ram.stack:,} B: {ram.free:,} B free"
            if ram is not None
            else "not measured (the emulated Uno did not run)",
            ram.holds if ram is not None else None,
        )
    )
    parts = [
        "`make -C firmware avr` (avr-gcc -Os, LTO, nanopb with `PB_NO_ERRMSG`, "
        "`PB_WITHOUT_64BIT`, `PB_BUFFER_ONLY`), sections from `avr-size -A "
        "build/avr/protoduino.elf`:\n",
        md_table(
            [
                "",
                ".text",
                ".data",
                ".bss",
                "protoduino",
                "budget",
                "StandardFirmata",
                "StandardFirmataPlus",
                "of the ATmega328P",
            ],
            [
                [
                    "flash (.text + .data)",
                    f"{size.text:,}",
                    f"{size.data:,}",
                    "",
                    f"{size.flash:,} B",
                    f"{FLASH_BUDGET:,} B",
                    firmata_sizes()[0],
                    f"{FIRMATA_PLUS[0]:,} B",
                    f"{size.flash / FLASH_TOTAL * 100:.0f} % of 32 KB",
                ],
                [
                    "static RAM (.data + .bss)",
                    "",
                    f"{size.data:,}",
                    f"{size.bss:,}",
                    f"{size.ram:,} B",
                    f"+ stack + {RAM_FREE} B free <= {RAM_TOTAL:,} B",
                    firmata_sizes()[1],
                    f"{FIRMATA_PLUS[1]:,} B",
                    f"{size.ram / RAM_TOTAL * 100:.0f} % of 2 KB (the stack takes the rest)",
                ],
            ],
        ),
        "StandardFirmata is the 2.4 hex that part 9 races (avrgirl-arduino 5.0.1's, its "
        "static RAM read from its start-up code); StandardFirmataPlus was built here with the "
        "same avr-gcc 5.4 and the Arduino core's flags. StandardFirmata does digital and analog "
        "I/O, PWM, servos and I2C but has no CRC, no acks and no failsafe. README.md and "
        "firmware/README.md quote the flash and RAM figures of this run.\n",
        _footprint_verdict(size, ram),
        _features_markdown(size, costs),
    ]
    try:
        cycles = measure_cycles(ctx.samples, ctx.commands)
    except BoardUnavailableError as error:
        parts.append(f"Cycles per command not measured: {error}.\n")
        return SectionResult("\n".join(parts), targets, quotes=_quotes(size, static, ram))
    parts.append(_cycles_markdown(cycles, ctx, load))
    try:
        firmata = measure_firmata(ctx.samples)
    except (BoardUnavailableError, MissingDependencyError, OSError) as error:
        log.warning("firmware: StandardFirmata's cycles not measured: %s", error)
        firmata = None
    parts.append(_firmata_markdown(cycles, firmata, ctx.samples))
    targets.append(_cycles_target(cycles, firmata))
    chart_list: list[Chart] = []
    if ctx.chart_dir is not None and cycles.profile:
        after = {SHORT.get(g, g): c for g, c in _groups(cycles)}
        labels = sorted(
            set(after) | set(BEFORE_GROUPS),
            key=lambda g: -max(after.get(g, 0.0), BEFORE_GROUPS.get(g, 0.0)),
        )
        path = charts.hbars(
            ctx.chart_dir / "firmware_profile.png",
            labels,
            [
                (f"before ({BEFORE_COMMIT}), cycles", [BEFORE_GROUPS.get(g, 0.0) for g in labels]),
                ("after (this run), cycles", [after.get(g, 0.0) for g in labels]),
            ],
            title="Where a servo write's awake cycles go on the Uno (16 MHz)",
            highlight=0,
        )
        chart_list.append(
            Chart(path, "Awake cycles per servo write on the Uno by part, before and after")
        )
    return SectionResult("\n".join(parts), targets, chart_list, quotes=_quotes(size, static, ram))


def _footprint_verdict(size: Footprint, ram: RamBudget | None) -> str:
    left = FLASH_BUDGET - size.flash
    flash = (
        f"The default firmware, with every pin mode, is {'within' if left >= 0 else 'over'} "
        f"the flash budget ({abs(left):,} B {'left' if left >= 0 else 'over'}). "
    )
    if ram is None:
        return flash + "Its RAM budget was not measured: the emulated Uno did not run.\n"
    return flash + (
        "RAM, on the emulated Uno running tests/e2e/test_stack_margin.py's scenario (every "
        "command at its largest, four in flight, every kind of input reporting): "
        f"{ram.describe()}; the budget {'holds' if ram.holds else 'does not hold'}.\n"
    )


def _quotes(size: Footprint, static: StaticRam, ram: RamBudget | None) -> dict[str, str]:
    """The footprint as README.md and firmware/README.md quote it (bench.report.quote): the
    build's figures (tests/c/test_footprint.py compares them with the build's), and the
    deepest stack when the emulated Uno ran."""
    quotes = build_quotes(size, static)
    if ram is not None:
        quotes["stack"] = stack_quote(ram)
    return quotes


def build_quotes(size: Footprint, static: StaticRam) -> dict[str, str]:
    """The quotes that come from the build alone: the footprint and where the static RAM goes."""
    return {
        "footprint": f"flash {size.flash:,} B of the {FLASH_BUDGET:,} B budget and static RAM "
        f"{size.ram:,} B (static RAM + the deepest stack + {RAM_FREE} B free <= {RAM_TOTAL:,} B; "
        f"for comparison, StandardFirmata (the hex part 9 races): "
        f"{' and '.join(firmata_sizes())}, "
        f"StandardFirmataPlus: {FIRMATA_PLUS[0]:,} B and {FIRMATA_PLUS[1]:,} B)",
        "static_ram": static.describe(),
    }


def stack_quote(ram: RamBudget) -> str:
    """The RAM budget's measured part, as firmware/README.md quotes it."""
    return (
        f"static RAM {ram.static:,} B and a deepest stack of {ram.stack:,} B, so {ram.free:,} B "
        f"stay free"
    )


def _cycles_markdown(c: CycleRun, ctx: Context, load: float) -> str:
    line = servo_line()
    rows = []
    for kind, label in KINDS:
        cycles = c.per_command[kind]
        rx, tx = c.bytes_per_command[kind]
        rows.append(
            [
                label,
                f"{rx:.1f} / {tx:.1f}",
                f"{cycles:,.0f}",
                f"{cycles / UNO_HZ * 1e6:,.0f}",
                fmt_rate(UNO_HZ / cycles),
            ]
        )
    servo = c.per_command["servo"]
    computed_share = servo * c.max_rate / UNO_HZ
    return "\n".join(
        [
            f"### Cycles per received command\n\nOn the emulated Uno (16 MHz), {ctx.samples} "
            "commands of each kind one at a time through the public API; awake cycles between "
            "two snapshots of the runner's counters, minus the idle board's awake share "
            f"({c.idle_share * 100:.2f} % of the cycles: clock tick and servo interrupts) over "
            "the same emulated time. Transmit goes through a ring that the UART's "
            "data-register-empty interrupt drains (firmware/avr/pd_avr_uart.c), so no cycle "
            "waits on the line; the firmware sleeps while an answer goes out. Load average at "
            f"the start of this section: {load:.2f}.\n",
            md_table(
                [
                    "command",
                    "UART bytes in / out",
                    "awake cycles",
                    "us at 16 MHz",
                    "commands/s if never asleep",
                ],
                rows,
            ),
            f"Before issue 11's I/O engine a servo write kept the Uno awake "
            f"{BEFORE_SERVO_CYCLES:,} cycles (the previous run of this bench, docs/performance.md "
            f"at {BEFORE_COMMIT}: polled transmit, bit-by-bit CRC, every step of a frame at its "
            f"delimiter); now {servo:,.0f}, {BEFORE_SERVO_CYCLES / servo:.1f}x fewer. At the "
            f"highest rate measured here ({MAX_RATE_WINDOW} servo writes in flight, "
            f"{fmt_rate(c.max_rate)} commands/s, {c.max_rate / line.duplex * 100:.0f} % of "
            "the full-duplex line), the Uno was awake "
            f"{c.max_rate_share * 100:.0f} % of the time (the one-at-a-time cycles above times "
            f"that rate give {computed_share * 100:.0f} %).\n",
            _profile_markdown(c) if c.profile else "",
        ]
    )


def _firmata_markdown(c: CycleRun, firmata: dict[str, float] | None, writes: int) -> str:
    head = (
        "### The same write on StandardFirmata\n\n"
        "StandardFirmata (the hex part 9 races) never sleeps, so its awake cycles say nothing: "
        "for both firmwares, the cycles a block of writes added are the runner's `--profile` of "
        "the block less the idle board's profile scaled to the same emulated time, address by "
        "address, the positive differences summed (the idle loop's cycles that the writes "
        "displaced count for nothing). protoduino's writes as above (one at a time, each "
        f"awaiting its Ack); StandardFirmata's through pyFirmata2, {writes} of each, "
        f"one every {FIRMATA_GAP_S * 1e3:.0f} ms (they have no answer), the servo attached and "
        "the pin an output before the idle profile. On protoduino the method gives its awake "
        "cycles net of idle within a few cycles, which checks it.\n"
    )
    if firmata is None:
        return (
            head
            + "\nStandardFirmata's cycles not measured here: its hex is not fetched "
            + (f"({firmata_board.FETCH_STEP}) or pyFirmata2 is not installed.\n")
        )
    rows = []
    for kind, label in (("digital", "digital write"), ("servo", "servo write")):
        ours = c.per_command[kind]
        theirs = firmata[kind]
        rows.append(
            [
                label,
                f"{ours:,.0f}",
                f"{c.added[kind]:,.0f}",
                f"{theirs:,.0f}",
                f"{ours / theirs:.1f}x",
                f"{GOAL_CYCLES[kind]:,}",
            ]
        )
    return "\n".join(
        [
            head,
            md_table(
                [
                    "write",
                    "protoduino awake cycles",
                    "protoduino, profile difference",
                    "StandardFirmata, profile difference",
                    "protoduino / StandardFirmata",
                    "issue 35's goal",
                ],
                rows,
            ),
            "StandardFirmata's write is 3 bytes in and nothing out, at 57600 baud; protoduino's "
            "is 14 to 15 bytes in (COBS, CRC, SEQ, message id) and a 9-byte Ack out, each byte "
            "an interrupt and a pass of the main loop that wakes for it.\n",
        ]
    )


def _cycles_target(c: CycleRun, firmata: dict[str, float] | None) -> Target:
    ours = f"{c.per_command['digital']:,.0f} / {c.per_command['servo']:,.0f}"
    goal = f"<= {GOAL_CYCLES['digital']:,} / <= {GOAL_CYCLES['servo']:,}"
    met = all(c.per_command[k] <= GOAL_CYCLES[k] for k in GOAL_CYCLES)
    if firmata is not None:
        ours += f" (StandardFirmata {firmata['digital']:,.0f} / {firmata['servo']:,.0f})"
        met = met and all(c.per_command[k] < firmata[k] for k in GOAL_CYCLES)
    return Target(
        "awake cycles per digital write / servo write, emulated Uno",
        goal + ", and below StandardFirmata's for the same write (issue 35)",
        ours,
        met,
    )


def _groups(c: CycleRun) -> list[tuple[str, float]]:
    """(group, cycles per command), largest first."""
    groups: Counter[str] = Counter()
    for function, cycles in c.profile.items():
        groups[group_of(function)] += cycles
    return [(g, cycles / c.profile_commands) for g, cycles in groups.most_common()]


def _profile_markdown(c: CycleRun) -> str:
    total = sum(c.profile.values())
    n = c.profile_commands
    groups = dict(_groups(c))
    short = {SHORT.get(g, g): cycles for g, cycles in groups.items()}
    group_rows = [
        [
            group,
            f"{BEFORE_GROUPS.get(SHORT.get(group, group), 0):,.0f}",
            f"{cycles:,.0f}",
            f"{cycles * n / total * 100:.0f} %",
        ]
        for group, cycles in groups.items()
    ]
    function_rows = [
        [
            f"`{function}`" + (f" ({VECTORS[function]})" if function in VECTORS else ""),
            f"{cycles / n:,.0f}",
            f"{cycles / total * 100:.1f} %",
        ]
        for function, cycles in c.profile.most_common(PROFILE_ROWS)
    ]
    nanopb = short.get("nanopb decoding", 0.0)
    generated = short.get("generated decoders", 0.0)
    return "\n".join(
        [
            "### Profile of a servo write on the Uno\n",
            f"Awake cycles by function over the {n} servo writes above (the runner's "
            "`--profile`: cycles charged to the flash address that spent them, mapped with "
            "`avr-nm`; LTO inlines most of the firmware's own code into `main`). Per command, "
            f"the idle load included; *before* is the run at {BEFORE_COMMIT}:\n",
            md_table(["where", "before", "after", "share after"], group_rows, "lrrr"),
            md_table(["function", "cycles per command", "share"], function_rows, "lrr"),
            "What changed: the Ack goes into a transmit ring that an interrupt drains (the "
            f"polled wait was {BEFORE_GROUPS['frame transmit']:,.0f} cycles); the CRC is "
            "avr-libc's `_crc_xmodem_update`, a byte a step with no table; each received byte "
            "is COBS-decoded and folded into the CRC as it arrives, and a command's payload "
            "is decoded as soon as its last byte is in, so at the delimiter only the checks "
            "and the command remain (part 2's round trip). Issue 35: the main loop polls "
            "(failsafe, servo steps, inputs, reports) only on a pass with news (a clock tick, "
            "an input's interrupt, a delimiter, the transmit ring emptied), not after every "
            "byte in or out (about 1,450 cycles a write); the receive interrupt is in "
            "assembly as the transmit one is (about 14 cycles a byte received); and the pin "
            "modes' Controls are "
            "decoded by generated code (`protoduino gen`: generated/pd_fastdec.h, held to "
            "nanopb by the C tests and the fuzzer), where nanopb's field iterator took about "
            "1,500 cycles a digital write and 2,000 a servo write: the servo write's "
            f"{servo_payload_bytes()}-byte message takes {generated:,.0f} cycles of the "
            f"generated decoder here ({nanopb:,.0f} of nanopb's), and nanopb stays the decoder "
            "of every other command. Then about 1,000 cycles a digital write and 1,130 a servo "
            "write from smaller steps (a digital write's share): the dedupe window's `add` "
            "skips its search for a stale entry of the id when the id just moved N (no entry "
            "can hold it then; about 265) and `forget_old` tells an entry out of reach without "
            "comparing it with N (about 110), the generated decoders read a one-byte varint "
            "with no call and no stack frame (`fast_byte` inlined, nanopb's reader for a "
            "longer one out of line: no `__prologue_saves__`; about 290), a pin's bit in a pin "
            "set is built by bytes, not by a 32-bit shift (about 25, 80 a servo write), and "
            "the main loop reads one byte of the clock, keeps sleep enabled and reads the "
            "receive ring's tail once a byte (about 280). Then the main loop sleeps on "
            "through the interrupts that make no pass due (firmware/avr/pd_avr_main.c): a "
            "pass only at a received delimiter, every second received byte, the transmit "
            "ring emptied, the clock tick or an input's change (each handler sets a bit of "
            "GPIOR0 with one `sbi`), where every byte received or sent made one (about 60 "
            "cycles each: about 800 a digital write), and the transmit ring's emptying "
            "makes the pass poll only when a report waits for it (about 110).\n",
        ]
    )


SECTION = Section(5, "firmware", "Firmware", run)


def write_build_quotes() -> list[Path]:
    """Rewrite the figures that come from the build alone (:func:`build_quotes`) in the
    documents that quote them, without running the rest of the bench: after a firmware
    change, which tests/c/test_footprint.py otherwise reports. Returns the files changed."""
    from . import report

    quotes = build_quotes(footprint(builds.FIRMWARE_ELF), build_static_ram())
    return report.quote(report.QUOTING, quotes)


if __name__ == "__main__":  # python -m bench.firmware
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for changed in write_build_quotes():
        log.info("rewrote the build's figures in %s", changed)
