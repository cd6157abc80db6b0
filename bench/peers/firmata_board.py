"""StandardFirmata driven through pyFirmata2, for the race (bench/race.py).

pyFirmata2 (a bench dependency already, see tools/bench_setup.sh) is what a Python user of
Firmata would call, so its own ``Pin.write`` puts the bytes on the wire and its own reader thread
parses the analog reports: the host CPU the race reports for Firmata is that library's.

Also here: StandardFirmata's footprint read from its Intel hex, since there is no ELF to ask
(``avr-size`` counts the hex's bytes; the end of static RAM is the constant that avr-libc's
start-up loop ``__do_clear_bss`` compares X with).
"""

from __future__ import annotations

import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

from ..core import require

ROOT = Path(__file__).resolve().parents[2]
#: Where tools/fetch_firmata.sh puts StandardFirmata's Uno hex (from avrgirl-arduino 5.0.1).
HEX = ROOT / ".deps" / "firmata" / "StandardFirmata.cpp.hex"
FETCH_STEP = "tools/fetch_firmata.sh (run by tools/dev.sh setup and by tools/bench_setup.sh)"

#: StandardFirmata's line (its sketch's Firmata.begin(57600)).
BAUD = 57_600
#: Its sampling interval's floor: it raises anything below to 10 ms.
MIN_SAMPLING_MS = 10
#: The Uno's SRAM starts after the 256 B of registers and I/O.
RAM_START = 0x100


class FirmataBoard:
    """One StandardFirmata board on ``port``, through pyFirmata2 with the Uno's layout.

    pyFirmata2's ``Board`` waits 5 s after opening the port for the Uno's reset (its
    BOARD_SETUP_WAIT_TIME); the emulated Uno has no bootloader, but the wait also covers the
    sketch's start-up blink, after which it reads the line.
    """

    def __init__(self, port: str) -> None:
        self._firmata: Any = require("pyfirmata2.pyfirmata2", "pyFirmata2")
        boards: Any = require("pyfirmata2.boards", "pyFirmata2")
        self.board: Any = self._firmata.Board(port, boards.BOARDS["arduino"], baudrate=BAUD)

    def close(self) -> None:
        self.board.exit()

    def digital_output(self, pin: int) -> Any:
        """Pin ``pin`` as an output (SET_PIN_MODE), its pyFirmata2 ``Pin``."""
        p = self.board.digital[pin]
        p.mode = self._firmata.OUTPUT
        return p

    def servo(self, pin: int, degrees: int) -> Any:
        """Pin ``pin`` as a servo (SERVO_CONFIG, 544..2400 us) at ``degrees``."""
        self.board.servo_config(pin, 544, 2400, degrees)
        return self.board.digital[pin]

    def stream_analog(
        self, channels: int, seconds: float, board_time: Callable[[], float]
    ) -> dict[int, float]:
        """Reports per second of each of the first ``channels`` analog inputs, sampled at the
        firmware's fastest interval, per second of ``board_time`` (the board's own clock,
        as protoduino's rates are counted: a board that runs behind the wall clock is not
        charged for it). Counted from a quarter of ``seconds`` in, when every channel runs."""
        counts = dict.fromkeys(range(channels), 0)

        def recorder(ch: int) -> Callable[[float], None]:
            def record(_value: float) -> None:  # pyFirmata2's reader thread
                counts[ch] += 1

            return record

        pins = [self.board.analog[ch] for ch in range(channels)]
        for ch, pin in enumerate(pins):
            pin.register_callback(recorder(ch))
            pin.enable_reporting()
        self.board.samplingOn(MIN_SAMPLING_MS)
        time.sleep(seconds / 4)
        before, t0 = dict(counts), board_time()
        time.sleep(seconds)
        after, t1 = dict(counts), board_time()
        for pin in pins:
            pin.disable_reporting()
        self.board.samplingOff()
        return {ch: (after[ch] - before[ch]) / (t1 - t0) for ch in range(channels)}


@contextmanager
def opened(port: str) -> Iterator[FirmataBoard]:
    board = FirmataBoard(port)
    try:
        yield board
    finally:
        board.close()


@dataclass(frozen=True, slots=True)
class HexFootprint:
    flash: int
    static_ram: int


def footprint() -> HexFootprint | None:
    """StandardFirmata's flash and static RAM from the race's hex, or None without it."""
    return hex_footprint(HEX) if HEX.exists() else None


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise FileNotFoundError(f"`{name}` is not installed (Debian package binutils-avr)")
    return path


def _ldi(word: int) -> tuple[int, int]:
    """(register, constant) of an ``ldi`` instruction word (1110 KKKK dddd KKKK, r16..r31)."""
    return 16 + (word >> 4 & 0xF), (word >> 4 & 0xF0) | (word & 0xF)


def hex_footprint(hex_file: Path) -> HexFootprint:
    """Flash and static RAM of a program given as Intel hex.

    Flash: the bytes the hex holds (``avr-size`` on ihex). Static RAM: ``__bss_end`` - 0x100,
    read from avr-libc's ``__do_clear_bss``:  ``ldi r18, hi8(__bss_end)`` four words before
    ``st X+, r1; cpi r26, lo8(__bss_end); cpc r27, r18``.
    """
    out = subprocess.run(
        [_tool("avr-size"), str(hex_file)], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    fields = out.splitlines()[1].split()
    flash = int(fields[0]) + int(fields[1])  # text + data: an ihex is all "data" to avr-size
    with TemporaryDirectory() as tmp:
        image = Path(tmp) / "flash.bin"
        subprocess.run(
            [_tool("avr-objcopy"), "-I", "ihex", "-O", "binary", str(hex_file), str(image)],
            check=True,
            timeout=60,
        )
        data = image.read_bytes()
    words = [data[i] | data[i + 1] << 8 for i in range(0, len(data) - 1, 2)]
    for i in range(4, len(words) - 2):
        st, cpi, cpc = words[i], words[i + 1], words[i + 2]
        if st != 0x921D or cpc != 0x07B2 or cpi & 0xF0F0 != 0x30A0:
            continue
        reg, hi = _ldi(words[i - 4])
        if words[i - 4] & 0xF000 != 0xE000 or reg != 18:
            continue
        lo = (cpi >> 4 & 0xF0) | (cpi & 0xF)
        return HexFootprint(flash, (hi << 8 | lo) - RAM_START)
    raise ValueError(f"{hex_file}: no avr-libc __do_clear_bss loop found")
