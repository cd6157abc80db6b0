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

ROOT = Path(__file__).resolve().parents[2]
ELF = ROOT / "build" / "avr" / "protoduino.elf"
FLASH_BUDGET = 26_624
#: The ATmega328P's RAM: the static data alone must leave room for a stack.
RAM_BYTES = 2_048


def _sections(elf: Path) -> dict[str, int]:
    out = subprocess.run(
        ["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    sizes: dict[str, int] = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0].startswith(".") and parts[1].isdigit():
            sizes[parts[0]] = int(parts[1])
    return sizes


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

    sections = _sections(ELF)
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
