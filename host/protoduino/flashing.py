"""Flashing a board: upload the firmware's Intel hex through its bootloader with avrdude.

``flash()`` talks to the bootloader exactly as the Arduino IDE does (its platform.txt upload
pattern, with boards.txt's programmer and speed per board, :data:`BOARDS`): the Uno and the
Nano through Optiboot (``-c arduino``), the Mega 2560 through its stk500v2 bootloader
(``-c wiring``). Against the emulated Uno started with Optiboot, and the emulated Mega started
with the stk500v2 bootloader of Debian's Arduino core, both with auto-reset
(``protoduino.simboard.runner_command``), the same code path writes and verifies the emulated
flash (tests/e2e/test_flash.py).
"""

from __future__ import annotations

import logging
import os
import select
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from . import programs
from .errors import BuildError, FlashError

logger = logging.getLogger(__name__)

#: The Uno's MCU (the emulated Uno's too: protoduino.simboard).
MCU = "atmega328p"


@dataclass(frozen=True)
class FlashTarget:
    """How avrdude reaches one board's bootloader, as the Arduino IDE's boards.txt says."""

    #: avrdude's part (``-p``) and the chip's name for messages.
    part: str
    chip: str
    #: avrdude's programmer (``-c``): the bootloader's protocol.
    programmer: str
    #: The bootloader's line rate (``-b``).
    baud: int
    bootloader: str
    #: The firmware this installation carries for the board (:mod:`protoduino.programs`).
    firmware: str


#: Board name -> its upload. The Nano is the "ATmega328P" of the IDE's Nano menu, the one
#: shipped since 2018 with Optiboot at 115200 (its "Old Bootloader" runs at 57600: ``--baud
#: 57600``). The Mega 2560's stk500v2 bootloader refuses avrdude's chip erase
#: (STATUS_CMD_FAILED): the IDE passes ``-D`` to every upload, and so does :func:`flash`; the
#: bootloaders erase each page as they write it.
BOARDS: dict[str, FlashTarget] = {
    "uno": FlashTarget(
        "atmega328p", "ATmega328P", "arduino", 115200, "Optiboot", programs.FIRMWARE_HEX
    ),
    "nano": FlashTarget(
        "atmega328p", "ATmega328P", "arduino", 115200, "Optiboot", programs.NANO_FIRMWARE_HEX
    ),
    "mega": FlashTarget(
        "atmega2560",
        "ATmega2560",
        "wiring",
        115200,
        "the stk500v2 bootloader",
        programs.MEGA_FIRMWARE_HEX,
    ),
}
#: Upper bound for one avrdude run (about 1.5 s for 11 KB; avrdude's own
#: retries against a silent port take longer, but not this long).
FLASH_TIMEOUT = 120.0
_TAIL_CHARS = 4000


def board_target(board: str) -> FlashTarget:
    """The upload of ``board``; FlashError naming the known boards for another name."""
    try:
        return BOARDS[board]
    except KeyError:
        raise FlashError(
            f"unknown board {board!r}: protoduino flashes {', '.join(BOARDS)}"
        ) from None


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


def _explain_failure(port: str, output: str, target: FlashTarget) -> str:
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
            f"no bootloader answered on {port}: is it a board with {target.bootloader} (an "
            f"{target.chip}: --board), and is no other program holding the port? (press reset "
            "just before flashing if auto-reset is off)"
        )
    if "verification error" in lowered or "mismatch" in lowered:
        return f"the flash on {port} did not verify after writing: try again"
    if "signature" in lowered:
        return (
            f"the device on {port} is not an {target.chip} (see avrdude's output above; "
            "--board names the board)"
        )
    return f"avrdude failed on {port}"


def flash(
    port: str,
    hex_file: Path,
    *,
    board: str = "uno",
    baud: int | None = None,
    progress: TextIO | None = None,
    timeout: float = FLASH_TIMEOUT,
) -> None:
    """Upload ``hex_file`` to the ``board`` (a name of :data:`BOARDS`) on ``port`` through its
    bootloader, at ``baud`` (default: the board's bootloader's rate).

    avrdude's output (its progress bars included) is copied to ``progress`` as
    it comes. Raises FlashError with a plain explanation when the port does not
    exist, no bootloader answers, or the upload fails.
    """
    target = board_target(board)
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
        target.programmer,
        "-p",
        target.part,
        "-b",
        str(target.baud if baud is None else baud),
        "-P",
        port,
        "-D",
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
        error = FlashError(_explain_failure(port, tail, target))
        error.add_note("avrdude output (end):\n" + tail.strip()[-1500:])
        raise error
