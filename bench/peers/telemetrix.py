"""Telemetrix (part 4): SERVO_ATTACH, then SERVO_WRITE, with the library's own encoder.

``Telemetrix.__init__`` opens a serial port, starts threads and handshakes with the
Telemetrix4Arduino sketch, so the benchmark makes the object without ``__init__``, gives it a
port that records writes and the servo feature flag the sketch would report, and calls the
library's ``set_pin_mode_servo`` and ``servo_write``.
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


def wire_sample() -> WireSample:
    module: Any = require("telemetrix.telemetrix", "telemetrix")
    constants: Any = require("telemetrix.private_constants", "telemetrix")
    board = object.__new__(module.Telemetrix)
    port = _Recorder()
    board.serial_port = port
    board.ip_address = None
    board.shutdown_on_exception = False
    board.reported_features = constants.PrivateConstants.SERVO_FEATURE
    board.set_pin_mode_servo(9, 544, 2400)
    setup = b"".join(port.written)
    port.written.clear()
    board.servo_write(9, 90)
    return WireSample(
        library="Telemetrix",
        package="telemetrix",
        encoder="telemetrix Telemetrix.set_pin_mode_servo + servo_write",
        setup=setup,
        setup_what="SERVO_ATTACH pin 9, 544..2400 us",
        command=b"".join(port.written),
        command_what="SERVO_WRITE pin 9, 90",
        ack=None,
        ack_what="none: Telemetrix does not acknowledge a servo write (it reports only "
        "'servo unavailable' on attach)",
        check="none",
        notes="length-prefixed, no checksum",
    )
