"""The Uno firmware stays below StandardFirmataPlus in flash and static RAM.

StandardFirmataPlus, built with the same toolchain (docs: TOOLCHAIN reference
sizes), needs 15,202 B of flash and 1,274 B of static RAM; protoduino aims to
stay below StandardFirmata (13,212 B and 1,069 B), which does digital and
analog I/O, PWM, servos and I2C with no CRC, no acks and no failsafe. The
build itself prints the figures (``make -C firmware avr``); this test checks
that it does, measures them again with ``avr-size`` and enforces the limit.
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
FLASH_LIMIT = 15_202
RAM_LIMIT = 1_274
FLASH_AIM = 13_212
RAM_AIM = 1_069


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


def test_uno_firmware_below_standard_firmata_plus(
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
            f"\nUno firmware: flash {flash} B (aim {FLASH_AIM}, limit {FLASH_LIMIT}), "
            f"static RAM {ram} B (aim {RAM_AIM}, limit {RAM_LIMIT})\n"
        )
    assert flash < FLASH_LIMIT
    assert ram < RAM_LIMIT
