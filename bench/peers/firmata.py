"""Firmata with pyFirmata2 (part 4): SERVO_CONFIG, then an analog write of the angle.

pyFirmata2 is the maintained fork; the original pyFirmata 1.1.0 does not import on Python 3.11
(it calls ``inspect.getargspec``, removed in 3.11). Its ``Board`` opens a serial port and
waits for the Arduino's reset in ``__init__``, so the benchmark makes the object without
``__init__``, gives it the Uno's pin layout and a port that records writes, and then calls the
library's own ``servo_config`` and ``Pin.write``: the bytes are pyFirmata2's.
"""

from __future__ import annotations

from typing import Any

from ..core import require
from . import WireSample


class _Recorder:
    def __init__(self) -> None:
        self.written: list[bytes] = []

    def write(self, data: bytes | bytearray) -> int:
        self.written.append(bytes(data))
        return len(data)

    def close(self) -> None:
        """Board.exit() closes its port."""


def wire_sample() -> WireSample:
    firmata: Any = require("pyfirmata2.pyfirmata2", "pyFirmata2")
    boards: Any = require("pyfirmata2.boards", "pyFirmata2")
    board = object.__new__(firmata.Board)
    port = _Recorder()
    board.sp = port
    board.samplerThread = None  # Board.__del__ calls exit(), which looks for it
    board.setup_layout(boards.BOARDS["arduino"])
    # SERVO_CONFIG sysex, then the first angle as an analog message; we set it up at 0 deg so
    # that the command below is the one that moves the servo to 90.
    board.servo_config(9, 544, 2400, 0)
    setup = b"".join(port.written)
    port.written.clear()
    board.digital[9].write(90)
    command = b"".join(port.written)
    return WireSample(
        library="Firmata",
        package="pyFirmata2",
        encoder="pyFirmata2 Board.servo_config + Pin.write",
        setup=setup,
        setup_what="SERVO_CONFIG sysex (pin 9, 544..2400 us) + analog write of 0 deg",
        command=command,
        command_what="ANALOG_MESSAGE pin 9 = 90 (pins above 15 need EXTENDED_ANALOG sysex)",
        ack=None,
        ack_what="none: Firmata has no acknowledgement; a lost or corrupted byte goes unnoticed",
        check="none",
        notes="no checksum either; MIDI-style 7-bit data bytes",
    )
