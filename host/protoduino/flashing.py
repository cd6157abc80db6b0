"""Flashing the Uno: upload the firmware's Intel hex through its bootloader with avrdude.

``flash()`` talks to the bootloader exactly as the Arduino IDE does; against the emulated Uno
started with Optiboot and auto-reset (``protoduino.simboard.runner_command``) the same code
path writes and verifies the emulated flash (tests/e2e/test_flash.py).
"""

from __future__ import annotations

import logging
import os
import select
import shutil
import subprocess
import time
from pathlib import Path
from typing import TextIO

from .errors import BuildError, FlashError

logger = logging.getLogger(__name__)

MCU = "atmega328p"
DEFAULT_BAUD = 115200
#: Upper bound for one avrdude run (about 1.5 s for 11 KB; avrdude's own
#: retries against a silent port take longer, but not this long).
FLASH_TIMEOUT = 120.0
_TAIL_CHARS = 4000


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


def check_hex(path: Path) -> None:
    """Refuse a file that is not Intel hex, before avrdude (which would first spend a
    minute on the bootloader, or erase the chip) reads it.

    Every line is a record ``:LLAAAATT<data>CC``: hex digits, the length ``LL``
    matching the data, the checksum ``CC`` making the record's bytes sum to 0,
    and the last record the end-of-file one (type 01). A dozen lines here rather
    than a dependency: avrdude does the real parsing, this only stops a wrong file.
    """
    try:
        f = path.open("rb")
    except OSError as error:
        raise FlashError(f"cannot read the firmware file {path}: {error.strerror}") from error
    last_type = None
    with f:
        for number, raw in enumerate(f, 1):
            line = raw.strip()
            if not line:
                continue
            problem = _hex_record_problem(line)
            if problem is not None:
                raise FlashError(
                    f"{path} is not an Intel hex file (line {number}: {problem}); give the "
                    "firmware's .hex, or its .elf"
                )
            last_type = int(line[7:9], 16)
    if last_type != 1:
        raise FlashError(f"{path} is not a whole Intel hex file: no end-of-file record")


def _hex_record_problem(line: bytes) -> str | None:
    if not line.startswith(b":"):
        return "a record starts with ':'"
    try:
        record = bytes.fromhex(line[1:].decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        return "not hex digits"
    if len(record) < 5 or len(record) != record[0] + 5:
        return "its length does not match its byte count"
    if sum(record) & 0xFF:
        return "bad checksum"
    return None


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
    check_hex(hex_file)
    avrdude = shutil.which("avrdude")
    if avrdude is None:
        raise FlashError(
            "avrdude is not installed; it is the one tool protoduino flash needs "
            "(Debian, Ubuntu, Raspberry Pi OS: sudo apt install avrdude)"
        )
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
