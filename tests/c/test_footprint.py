"""The default Uno firmware fits issue 21's flash budget: at most 26,624 B.

26 KB of the 32,256 B that Optiboot leaves, so that users' own code has room
beside it. RAM has its own budget (static data + the deepest stack + 256 B free
<= 2,048 B), which needs the stack's measurement: tests/e2e/test_stack_margin.py.
StandardFirmata (the hex the bench races, part 9) and StandardFirmataPlus
(15,202 B / 1,274 B) stay in the bench as a comparison, not a limit. The build itself
prints the figures (``make -C firmware avr``); this test checks that it does,
measures them again with ``avr-size`` and enforces the budget.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from protoduino_dev import rambudget

ROOT = Path(__file__).resolve().parents[2]
ELF = ROOT / "build" / "avr" / "protoduino.elf"
FLASH_BUDGET = 26_624
#: The ATmega328P's RAM: the static data alone must leave room for a stack.
RAM_BYTES = 2_048


def test_uno_firmware_within_the_flash_budget(
    record_property: Callable[[str, object], None], capsys: pytest.CaptureFixture[str]
) -> None:
    for tool in ("make", "avr-gcc", "avr-size", "avr-objcopy"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (Debian packages gcc-avr, binutils-avr)")
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "avr"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    printed = re.search(r"flash (\d+) B .*static RAM (\d+) B", build.stdout)
    assert printed, f"the build did not print the sizes:\n{build.stdout}"

    sections = rambudget.sections(ELF)
    flash = sections[".text"] + sections.get(".data", 0)
    ram = sections.get(".data", 0) + sections.get(".bss", 0) + sections.get(".noinit", 0)
    assert (int(printed.group(1)), int(printed.group(2))) == (flash, ram)

    record_property("flash_bytes", flash)
    record_property("static_ram_bytes", ram)
    with capsys.disabled():  # the figures belong in every test log, not only on failure
        sys.stdout.write(
            f"\nUno firmware: flash {flash} B (budget {FLASH_BUDGET}), static RAM {ram} B "
            f"(budget with the stack: tests/e2e/test_stack_margin.py)\n"
        )
    assert flash <= FLASH_BUDGET
    assert ram < RAM_BYTES


def _quoted(doc: Path, name: str) -> str:
    """The figure ``name`` a document quotes between its bench markers (bench.report.quote)."""
    found = re.findall(rf"<!-- bench:{name} -->(.*?)<!-- /bench:{name} -->", doc.read_text(), re.S)
    assert len(found) == 1, f"{doc}: {len(found)} quotes of {name}"
    return str(found[0])


def test_the_readmes_quote_the_builds_figures() -> None:
    """firmware/README.md's and README.md's footprint and firmware/README.md's static RAM
    breakdown are this build's (the bench writes them; `python -m bench.firmware` rewrites
    them after a change), not a figure of another time."""
    for tool in ("make", "avr-gcc", "avr-size", "avr-nm"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (Debian packages gcc-avr, binutils-avr)")
    static = rambudget.build_static_ram()
    sections = rambudget.sections(ELF)
    flash = sections[".text"] + sections.get(".data", 0)
    rerun = "rerun `python -m bench.firmware`"
    for doc in (ROOT / "firmware/README.md", ROOT / "README.md"):
        figures = re.match(
            r"flash ([\d,]+) B of .* static RAM ([\d,]+) B", _quoted(doc, "footprint")
        )
        assert figures, f"{doc}: the footprint quote does not give flash and static RAM"
        quoted = tuple(int(n.replace(",", "")) for n in figures.groups())
        assert quoted == (flash, static.total), (
            f"{doc}: {quoted}, the build {flash, static.total}: {rerun}"
        )
    assert _quoted(ROOT / "firmware/README.md", "static_ram") == static.describe(), rerun
    # The parts are read, not guessed: each exists in this build, and they fit in the total.
    assert static.rest >= 0 and min(static.core.values()) > 0


def test_nano_profile_within_the_budgets(capsys: pytest.CaptureFixture[str]) -> None:
    """The Nano's profile of the build (``make avr BOARD=nano``: A6 and A7 as pins 20 and 21)
    fits the same flash budget, and its static RAM is the Uno's and its two more pins' bytes
    of the pin registry (PD_MAX_PINS 22), nothing else: the stack margin the Uno's stack test
    measures holds for it with 2 B less."""
    for tool in ("make", "avr-gcc", "avr-size"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (Debian packages gcc-avr, binutils-avr)")
    sizes = {}
    for board, elf in (("uno", ELF), ("nano", ROOT / "build" / "avr-nano" / "protoduino.elf")):
        build = subprocess.run(
            ["make", "-s", "-C", str(ROOT / "firmware"), "avr", f"BOARD={board}"],
            capture_output=True,
            text=True,
            check=False,
            timeout=300,
        )
        assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
        sections = rambudget.sections(elf)
        sizes[board] = (
            sections[".text"] + sections.get(".data", 0),
            sections.get(".data", 0) + sections.get(".bss", 0) + sections.get(".noinit", 0),
        )
    (flash, ram), (_, uno_ram) = sizes["nano"], sizes["uno"]
    with capsys.disabled():
        sys.stdout.write(f"\nNano firmware: flash {flash} B, static RAM {ram} B\n")
    assert flash <= FLASH_BUDGET
    assert ram == uno_ram + 2


#: The Mega 2560's flash less its stk500v2 bootloader's 8 KB, and its RAM.
MEGA_FLASH = 253_952
MEGA_RAM = 8_192
#: The Mega build's own flash budget: an eighth of its flash (the rest is the user's).
MEGA_FLASH_BUDGET = 32_768


def test_mega_build_within_the_budgets(capsys: pytest.CaptureFixture[str]) -> None:
    """The Mega 2560's build (``make avr BOARD=mega``, the ATmega2560) within its own budget
    (firmware/README.md, The Mega 2560): flash at most 32 KB, an eighth of the Mega's, so
    over 220 KB stay the user's; static RAM at most a quarter of its 8,192 B, within the
    Uno's 2,048 B, which leaves over 6 KB for the stack, whose deepest point
    tests/e2e/test_mega.py::test_the_mega_ram_budget_holds measures on the emulated Mega. Its
    70 pins, 24 servos and six PWM outputs cost more than the Uno's budget holds."""
    for tool in ("make", "avr-gcc", "avr-size"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (Debian packages gcc-avr, binutils-avr)")
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "avr", "BOARD=mega"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    sections = rambudget.sections(ROOT / "build" / "avr-mega" / "protoduino.elf")
    flash = sections[".text"] + sections.get(".data", 0)
    ram = sections.get(".data", 0) + sections.get(".bss", 0) + sections.get(".noinit", 0)
    with capsys.disabled():
        sys.stdout.write(
            f"\nMega firmware: flash {flash} B of {MEGA_FLASH}, static RAM {ram} B of {MEGA_RAM}\n"
        )
    assert flash <= MEGA_FLASH_BUDGET <= MEGA_FLASH
    assert ram <= RAM_BYTES <= MEGA_RAM
