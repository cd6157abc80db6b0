"""``protoduino flash`` for real: avrdude through Optiboot on the emulated Uno.

The runner starts at Optiboot's address (BOOTRST, 1 KB boot section) on an
otherwise erased flash and resets the MCU whenever a client opens its port, as
a real Uno's DTR auto-reset does. ``protoduino flash`` builds the firmware,
avrdude writes and verifies it through the bootloader, and the test then
handshakes with the freshly flashed firmware using the host codec.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import protoduino
import pytest
import serial
from boardprocess import BoardProcess, missing_tool
from protoduino.constants import PROTOCOL_VERSION, ControlCode, PacketType
from protoduino.flashing import strip_to_hex
from protoduino.framing import StreamDecoder, frame_packet
from protoduino.packets import Packet, parse_control, reset_payload
from protoduino.simboard import runner_command
from protoduino_dev import build

pytestmark = pytest.mark.avr

FLASH_TIMEOUT = 120.0


def missing_flash_tool() -> str | None:
    """What flashing the emulated Uno through Optiboot needs and this machine lacks."""
    missing = missing_tool("make", "cc", "avr-gcc", "avr-objcopy", "avrdude", simavr=True)
    if missing is None and not (
        Path(build.AVRSIM_DIR).exists() and Path("/usr/share/arduino").exists()
    ):
        return "arduino-core-avr (Optiboot sources)"
    return missing


def _protoduino(*args: str, timeout: float = FLASH_TIMEOUT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "protoduino.cli.main", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        stdin=subprocess.DEVNULL,
    )


class EmulatedUno(BoardProcess):
    """An emulated Uno process (runner) and its port."""

    def close(self) -> None:
        self.stop(timeout=5, strict=False)


@pytest.fixture(scope="module")
def tools() -> None:
    missing = missing_flash_tool()
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build.build_runner()
    build.build_optiboot()


def start_blank_uno(link: Path) -> EmulatedUno:
    """Optiboot alone in the flash, started at the bootloader, auto-reset on open."""
    build.build_runner()
    build.build_optiboot()
    cmd = runner_command(
        hex_files=[build.OPTIBOOT_HEX],
        boot_address=build.OPTIBOOT_ADDRESS,
        auto_reset=True,
        link=link,
    )
    return EmulatedUno(cmd)


@pytest.fixture
def blank_uno(tools: None, tmp_path: Path) -> Iterator[EmulatedUno]:
    board = start_blank_uno(tmp_path / "uno")
    yield board
    board.close()


def handshake(port: str, timeout: float) -> Packet:
    """RESET until RESET_ACK (covers the ~1 s Optiboot spends after the open's reset)."""
    decoder = StreamDecoder()
    reset = b"\x00" + frame_packet(PacketType.CONTROL, 0, reset_payload(PROTOCOL_VERSION))
    deadline = time.monotonic() + timeout
    with serial.Serial(port, 115200, timeout=0.1) as link:
        while time.monotonic() < deadline:
            link.write(reset)
            resend = time.monotonic() + 0.3
            while time.monotonic() < resend:
                for item in decoder.feed(link.read(256)):
                    if (
                        isinstance(item, Packet)
                        and item.type == PacketType.CONTROL
                        and item.payload[:1] == bytes((ControlCode.RESET_ACK,))
                    ):
                        return item
    raise AssertionError(f"no RESET_ACK from {port} within {timeout} s")


def test_flash_through_optiboot_then_handshake(blank_uno: EmulatedUno) -> None:
    result = _protoduino("flash", blank_uno.port)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    # avrdude's own report, passed through to the user.
    assert "device signature = 0x1e950f" in output
    assert "bytes of flash verified" in output
    assert "Writing | " in output
    ack = handshake(blank_uno.port, timeout=10.0)
    control = parse_control(ack.payload)
    assert control.version == PROTOCOL_VERSION
    assert control.schema_id == protoduino.SCHEMA_ID


def test_flash_reports_a_port_that_does_not_exist(tools: None, tmp_path: Path) -> None:
    missing = tmp_path / "ttyACM9"
    result = _protoduino("flash", str(missing), "--hex", os.devnull)
    assert result.returncode == 1
    assert f"serial port {missing} does not exist" in result.stderr


def test_flash_reports_when_no_bootloader_answers(tools: None, tmp_path: Path) -> None:
    """A board running the runner's test program (an echo, no bootloader)."""
    program = build.build_test_program()
    board = EmulatedUno(runner_command(program))
    try:
        hex_file = strip_to_hex(program, tmp_path / "testprog.hex")
        result = _protoduino("flash", board.port, "--hex", str(hex_file))
    finally:
        board.close()
    assert result.returncode == 1
    assert f"no bootloader answered on {board.port}" in result.stderr
    assert "not in sync" in result.stderr  # avrdude's own words are shown too
