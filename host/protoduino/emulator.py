"""The emulated Uno's pieces and the flashing logic.

Builds (each through ``make``, so repeated calls cost a few milliseconds):

- the simavr runner ``build/avrsim/avrsim`` and its test program
  (``tools/avrsim/``),
- Optiboot in a 1 KB boot section at 0x7C00 (``build/optiboot/optiboot.hex``),
- the firmware's Uno build (``make -C firmware avr``: ``build/avr/protoduino.{elf,hex}``).

``flash()`` uploads an Intel hex through a board's bootloader with avrdude,
exactly as for a real Uno; against the runner started with
``runner_command(boot_address=OPTIBOOT_ADDRESS, auto_reset=True, ...)`` the
same code path writes and verifies the emulated flash.
"""

from __future__ import annotations

import logging
import os
import select
import shutil
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from .errors import BuildError, FlashError

logger = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
BUILD = ROOT / "build"
AVRSIM_DIR = ROOT / "tools" / "avrsim"
FIRMWARE_DIR = ROOT / "firmware"

RUNNER = BUILD / "avrsim" / "avrsim"
TEST_PROGRAM = BUILD / "avrsim" / "testprog.elf"
OPTIBOOT_HEX = BUILD / "optiboot" / "optiboot.hex"
#: Start of the 1 KB boot section (hfuse BOOTSZ = 10) where Optiboot is linked.
OPTIBOOT_ADDRESS = 0x7C00
FIRMWARE_ELF = BUILD / "avr" / "protoduino.elf"
FIRMWARE_HEX = BUILD / "avr" / "protoduino.hex"

MCU = "atmega328p"
DEFAULT_BAUD = 115200
#: Upper bound for one avrdude run (about 1.5 s for 11 KB; avrdude's own
#: retries against a silent port take longer, but not this long).
FLASH_TIMEOUT = 120.0
_TAIL_CHARS = 4000


def _make(directory: Path, *targets: str) -> None:
    # One make helper for the project (with its build lock), from simboard.
    from .simboard import make

    make(directory, *targets)


def build_runner() -> Path:
    """Build the simavr runner (cached by make) and return its path."""
    _make(AVRSIM_DIR, "runner")
    return RUNNER


def build_test_program() -> Path:
    """Build the runner's own AVR test program and return its ELF."""
    _make(AVRSIM_DIR, "testprog")
    return TEST_PROGRAM


def build_optiboot() -> Path:
    """Build Optiboot for the 1 KB boot section and return its hex."""
    _make(AVRSIM_DIR, "optiboot")
    return OPTIBOOT_HEX


def build_firmware() -> Path:
    """Build the firmware's Uno target and return its ELF."""
    _make(FIRMWARE_DIR, "avr")
    return FIRMWARE_ELF


def build_firmware_hex() -> Path:
    """Build the firmware's Uno target and return its flashable hex."""
    _make(FIRMWARE_DIR, "avr")
    return FIRMWARE_HEX


def strip_to_hex(elf: Path, out: Path) -> Path:
    """Write ``elf`` as Intel hex without the sections avrdude would reject.

    ``.eeprom`` and simavr's ``.mmcu`` live at addresses outside the flash;
    avrdude notices that only after it has erased the chip.
    """
    objcopy = shutil.which("avr-objcopy")
    if objcopy is None:
        raise BuildError("avr-objcopy is not installed (Debian package binutils-avr)")
    cmd = [objcopy, "-O", "ihex", "-R", ".eeprom", "-R", ".mmcu", str(elf), str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=60)
    if result.returncode != 0:
        raise BuildError(f"avr-objcopy failed on {elf}: {result.stderr.strip()}")
    return out


def runner_command(
    firmware: Path | None = None,
    *,
    trace: Path | None = None,
    link: Path | None = None,
    hex_files: Sequence[Path] = (),
    boot_address: int | None = None,
    auto_reset: bool = False,
) -> list[str]:
    """The runner's command line (same options as the native board, plus flashing ones).

    ``boot_address`` starts the MCU there (BOOTRST) with the external-reset
    flag set, as after pressing reset; ``auto_reset`` resets it whenever a
    client opens the port, as a real Uno's DTR line does.
    """
    cmd = [str(RUNNER), "--mcu", MCU, "--freq", "16000000"]
    if trace is not None:
        cmd += ["--trace", str(trace)]
    if link is not None:
        cmd += ["--link", str(link)]
    for hex_file in hex_files:
        cmd += ["--hex", str(hex_file)]
    if boot_address is not None:
        cmd += ["--boot", f"0x{boot_address:X}"]
    if auto_reset:
        cmd.append("--auto-reset")
    if firmware is not None:
        cmd.append(str(firmware))
    return cmd


def _explain_failure(port: str, output: str) -> str:
    lowered = output.lower()
    if "can't open device" in lowered or "ser_open" in lowered:
        return f"cannot open serial port {port}: check the port name (protoduino flash PORT)"
    if (
        "not in sync" in lowered
        or "not responding" in lowered
        or "getsync" in lowered
        or "stk500_recv" in lowered
    ):
        return (
            f"no bootloader answered on {port}: is it an Uno with Optiboot, and is no other "
            "program holding the port? (press reset just before flashing if auto-reset is off)"
        )
    if "verification error" in lowered or "mismatch" in lowered:
        return f"the flash on {port} did not verify after writing: try again"
    if "signature" in lowered:
        return f"the device on {port} is not an ATmega328P (see avrdude's output above)"
    return f"avrdude failed on {port}"


def flash(
    port: str,
    hex_file: Path,
    *,
    baud: int = DEFAULT_BAUD,
    progress: TextIO | None = None,
    timeout: float = FLASH_TIMEOUT,
) -> None:
    """Upload ``hex_file`` to the Uno on ``port`` through its bootloader.

    avrdude's output (its progress bars included) is copied to ``progress`` as
    it comes. Raises FlashError with a plain explanation when the port does not
    exist, no bootloader answers, or the upload fails.
    """
    if not os.path.exists(port):
        raise FlashError(f"serial port {port} does not exist: check the port name")
    if not hex_file.is_file():
        raise FlashError(f"no firmware file {hex_file}")
    avrdude = shutil.which("avrdude")
    if avrdude is None:
        raise FlashError("avrdude is not installed (Debian package avrdude)")
    cmd = [
        avrdude,
        "-c",
        "arduino",
        "-p",
        MCU,
        "-b",
        str(baud),
        "-P",
        port,
        "-U",
        f"flash:w:{hex_file}:i",
    ]
    logger.info("running %s", " ".join(cmd))
    proc = subprocess.Popen(
        cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    tail = ""
    deadline = time.monotonic() + timeout
    try:
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise FlashError(f"avrdude did not finish within {timeout:.0f} s on {port}")
            ready, _, _ = select.select([fd], [], [], min(remaining, 0.5))
            if not ready:
                continue
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            text = chunk.decode("utf-8", errors="replace")
            tail = (tail + text)[-_TAIL_CHARS:]
            if progress is not None:
                progress.write(text)
                progress.flush()
        rc = proc.wait(timeout=max(deadline - time.monotonic(), 1.0))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    if rc != 0:
        error = FlashError(_explain_failure(port, tail))
        error.add_note("avrdude output (end):\n" + tail.strip()[-1500:])
        raise error
