"""``protoduino flash`` for real: avrdude through Optiboot on the emulated Uno, and through the
stk500v2 bootloader on the emulated Mega 2560.

The runner starts at the bootloader's address (BOOTRST: Optiboot's 1 KB boot section at
0x7C00, the Mega's 8 KB one at 0x3E000) on an otherwise erased flash and resets the MCU when
a client opens its port while no other holds it, as a real board's DTR auto-reset does.
``protoduino flash`` builds the firmware, avrdude writes and verifies it through the
bootloader, and the test then talks to the freshly flashed firmware.

The Mega's stk500v2 bootloader (Debian's Arduino core, the one Mega 2560 boards ship with)
waits about 0.7 s after a reset for a byte (the application starts 0.78 s after the reset on
the emulated clock: the bootloader's LED on pin 13 goes off then), and a byte in that window
keeps it in the bootloader until the line has been silent for 4 to 6 s: a host that sends as
soon as it opens the port keeps it there. So the test holds the port
open, silent, for 2 s of the board's own clock after the reset, then runs ``protoduino info``
on the port (its open, the port already held, resets nothing: DTR is already asserted).
"""

from __future__ import annotations

import json
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


class EmulatedMega(EmulatedUno):
    """The emulated Mega 2560 with its stk500v2 bootloader (Debian's hex) alone in the flash,
    started at the bootloader, auto-reset on open."""

    def __init__(self, link: Path) -> None:
        build.build_runner()
        build.build_stk500v2()
        cmd = runner_command(
            hex_files=[build.STK500V2_HEX],
            boot_address=build.STK500V2_ADDRESS,
            auto_reset=True,
            link=link,
            mcu="atmega2560",
        )
        super().__init__(cmd)


@pytest.fixture
def blank_mega(tools: None, tmp_path: Path) -> Iterator[EmulatedMega]:
    board = EmulatedMega(tmp_path / "mega")
    yield board
    board.close()


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


def test_flash_a_mega_through_stk500v2_then_info_reads_mega(blank_mega: EmulatedMega) -> None:
    result = _protoduino("flash", blank_mega.port, "--board", "mega")
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    # avrdude's own report: the ATmega2560's signature, through the stk500v2 ("wiring") protocol.
    assert "device signature = 0x1e9801" in output
    assert "bytes of flash verified" in output
    # At once: the open resets the board into its bootloader, which starts the application
    # when the handshake's first RESETs tell it to (transport.BOOTLOADER_LEAVE).
    info = _protoduino("info", blank_mega.port, "--json")
    assert info.returncode == 0, info.stdout + info.stderr
    found = json.loads(info.stdout)["info"]
    assert found["board"] == "mega"
    assert found["schema_id"] == f"0x{protoduino.SCHEMA_ID:08X}"


def test_flash_a_nano_through_optiboot_then_info_reads_nano(blank_uno: EmulatedUno) -> None:
    """The Nano (the IDE's "ATmega328P", Optiboot at 115200) is the Uno's chip and bootloader:
    the emulated Uno stands for it, and the Nano's firmware says so."""
    result = _protoduino("flash", blank_uno.port, "--board", "nano")
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "device signature = 0x1e950f" in output
    assert "bytes of flash verified" in output
    info = _protoduino("info", blank_uno.port, "--json")  # Optiboot lets go within 5 s
    assert info.returncode == 0, info.stdout + info.stderr
    assert json.loads(info.stdout)["info"]["board"] == "nano"


def test_flash_refuses_an_elf_built_for_another_chip(tools: None, tmp_path: Path) -> None:
    elf = build.build_firmware_board("mega")
    result = _protoduino("flash", str(tmp_path / "ttyACM0"), "--board", "uno", "--hex", str(elf))
    assert result.returncode == 1
    assert "is built for the ATmega2560, the uno's chip is the ATmega328P" in result.stderr
