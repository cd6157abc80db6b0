"""The line rate (docs/protocol.md 5, *Line rate*; issue 23) on both boards.

A pseudo-terminal carries bytes whatever rate either end set, so each board is
started with ``--line-check`` (firmware/simcontrol/pd_linerate.h): a byte crosses
only when the host's termios rate is the device's (the native board's
``pd_hal_set_baud``, the emulated Uno's UBRR0 as its firmware writes it), and
``--line-max`` / ``--line-max-out`` make a line that cannot carry the faster
rates (both ways, or from the device only: a device whose answers are lost after
the switch). So a test passes only if both ends really run at the rate the host
reports. Verdicts come from the link's own record (rates agreed, failed, fallbacks),
what the device answers, and the emulated Uno's --stats (its UART's rate and byte
time after the switch), never from wall-clock time.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import protoduino
import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino import programs
from protoduino.board import PoseOutput, PoseValue
from protoduino.simboard import SimBoard, runner_command
from protoduino_dev import build
from protoduino_dev.runnerstats import snapshot
from simfixtures import SIM_BACKENDS

_NEEDS = {"native": ("make", "gcc"), "avr": ("make", "gcc", "avr-gcc")}

StartBoard = Callable[..., SimBoard]


@pytest.fixture(params=SIM_BACKENDS)
def start_board(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[StartBoard]:
    """Starts a board of the backend with the given extra options (stopped at the end)."""
    backend: str = request.param
    for tool in _NEEDS[backend]:
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (needed to build the {backend} board)")
    boards: list[SimBoard] = []

    def start(*options: str) -> SimBoard:
        board = SimBoard(backend, trace=tmp_path / f"trace-{backend}.jsonl", options=options)
        boards.append(board)
        board.start()
        return board

    yield start
    for board in boards:
        board.stop()


def _works(board: protoduino.Board) -> None:
    """A command round trip at the rate the line runs at."""
    board.ping(b"\x00\x55\xaa\xff" * 8)
    led = board.digital_output(13, safe=False)
    led.write(True)


#: The rates each board offers (RESET_ACK FLAGS): the Uno firmware leaves 1,000,000 out
#: while its receive ring is below PD_AVR_RX_FAST_1M (firmware/avr/pd_avr_main.c says
#: why), the native board has no UART to limit it.
OFFERED = {"native": (1_000_000, 500_000, 250_000), "avr": (1_000_000, 500_000, 250_000)}


def test_agreement_reaches_the_fastest_common_rate(start_board: StartBoard) -> None:
    sim = start_board("--line-check")
    with protoduino.Board.open(sim.port) as board:
        assert board._link.device_baudrates == OFFERED[sim.backend]
        assert board.baudrate == OFFERED[sim.backend][0]
        assert board._link.baud_switches == 1
        assert board._link.baud_fallbacks == 0
        _works(board)


def test_a_rate_the_line_cannot_carry_falls_back(start_board: StartBoard) -> None:
    sim = start_board("--line-max", "200000")
    with protoduino.Board.open(sim.port) as board:
        # Every offered rate fails its probe; each time both ends return to the opening
        # rate and the next rate down is tried (three times on the native board), and the
        # line ends where it opened.
        assert board._link.failed_baudrates == set(OFFERED[sim.backend])
        assert board._link.baud_fallbacks == len(OFFERED[sim.backend])
        assert board.baudrate == 115_200
        _works(board)


def test_a_device_that_does_not_answer_after_the_switch_falls_back(
    start_board: StartBoard,
) -> None:
    # The device hears the host at every faster rate, but its answers are lost: it
    # must not stay there (a probe does not confirm the switch), or the host, back at
    # the opening rate, could never reach it again.
    sim = start_board("--line-max-out", "200000")
    with protoduino.Board.open(sim.port) as board:
        assert board._link.failed_baudrates == set(OFFERED[sim.backend])
        assert board.baudrate == 115_200
        _works(board)


def test_a_pinned_rate_runs_no_agreement(start_board: StartBoard) -> None:
    sim = start_board("--line-check")
    with protoduino.Board.open(sim.port, baudrate=115_200) as board:
        assert board.baudrate == 115_200
        assert board._link.baud_switches == 0
        _works(board)  # with --line-check: the device is at 115,200 too


def test_a_new_host_finds_a_device_left_at_the_fast_rate(start_board: StartBoard) -> None:
    # A pty does not reset the device on open (a real Uno's DTR does): the second
    # host opens at 115,200 while the device still runs at the agreed rate. Its
    # RESET retries alternate rates and find it there.
    sim = start_board("--line-check")
    with protoduino.Board.open(sim.port) as first:
        assert first.baudrate == OFFERED[sim.backend][0]
    with protoduino.Board.open(sim.port) as second:
        assert second.baudrate == OFFERED[sim.backend][0]
        assert second._link.baud_switches == 0  # found there, nothing to agree
        _works(second)


def test_the_emulated_uart_follows_the_switch(tmp_path: Path) -> None:
    """The emulated Uno only: its runner's --stats state UART0's rate and byte time."""
    for tool in _NEEDS["avr"]:
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (needed to build the avr board)")
    stats = tmp_path / "stats.jsonl"
    with SimBoard("avr", options=("--line-check", "--stats", str(stats))) as sim:
        sim.start()
        with protoduino.Board.open(sim.port) as board:
            _works(board)
            line = snapshot(sim.pid, stats)
    # UBRR0 1 with U2X: 1,000,000 baud, and simavr's byte time (11 bits of 16 cycles).
    assert line["uart_baud"] == 1_000_000
    assert line["uart_byte_cycles"] == 11 * 8 * 2
    # Nothing the device sent was lost to a rate mismatch. (A host may lose its first
    # probe: it can follow the BAUD_ACK before the device, which waits for the ack's
    # last bit to leave, has switched; that is what the probe's retries are for.)
    assert line["line_lost_out"] == 0


def test_poses_beside_input_reports_are_never_retransmitted(start_board: StartBoard) -> None:
    """The agreed rate under the load that once lost frames on the emulated Uno.

    A Pose of six servo items and four digital outputs in its masks (62 to 68-byte frames; longer
    than the Uno's receive ring of before protocol version 5, 48 B, so the host let it go
    alone) arriving while input reports are built: at 1,000,000 baud with that ring the bytes
    of such a Pose (then six items, 64 B) were lost at every retransmission
    (firmware/avr/pd_avr_main.c). Judged by the link's counters: every Pose acknowledged at
    its first transmission, no frame dropped either way, no receive overflow, and reports
    really went meanwhile.
    """
    sim = start_board("--line-check")
    with protoduino.Board.open(sim.port, window=4, ping=False) as board:
        assert board.baudrate == OFFERED[sim.backend][0]
        servos = [board.servo(pin) for pin in (9, 10, 3, 5, 6, 11)]
        outputs = [board.digital_output(pin) for pin in (2, 4, 7, 8)]
        for pin in range(14, 20):
            board.analog_input(pin, rate_hz=500.0, heartbeat=0.01)
        before = board.stats
        poses = []
        for i in range(150):
            targets: dict[PoseOutput, PoseValue] = {
                servo: (10 + i % 160) if n % 2 else (170 - i % 160)
                for n, servo in enumerate(servos)
            }
            for bit, output in enumerate(outputs):
                targets[output] = bool((i >> bit) & 1)
            poses.append(board.submit_pose(targets))
        for pose in poses:
            pose.result(timeout=60)
        stats = board.stats
    assert stats.retransmits == before.retransmits, stats
    assert stats.device_rx_overflows == 0 and not stats.dropped, stats
    assert stats.input_reports > before.input_reports


def test_a_real_style_uno_on_a_line_that_carries_only_115200_opens(tmp_path: Path) -> None:
    """Issue 32: the emulated Uno with Optiboot in front of the firmware, reset by every open
    (a real Uno's DTR), on a line that carries only 115200 (a bridge that cannot go faster).

    The bootloader takes its share of the handshake's budget; each rate then fails its
    probe, and the RESETs that follow a fallback must reach the device as soon as it is
    back at the opening rate (they waited out the handshake's grown backoff: 5 s was not
    enough, HandshakeError three opens out of three). Judged by the link's record: opened,
    every offered rate failed or untried, at 115200, and a round trip works, three times.
    """
    missing = missing_tool("make", "cc", "avr-gcc", "avr-objcopy", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed (needed to build the avr board and Optiboot)")
    if not Path("/usr/share/arduino").exists():
        pytest.skip("arduino-core-avr is not installed (Optiboot's sources)")
    build.build_runner()
    build.build_optiboot()
    cmd = runner_command(
        programs.locate(programs.FIRMWARE_ELF),
        hex_files=[build.OPTIBOOT_HEX],
        boot_address=build.OPTIBOOT_ADDRESS,
        auto_reset=True,
        link=tmp_path / "uno",
    )
    uno = BoardProcess([*cmd[:-1], "--line-max", "115200", cmd[-1]])
    try:
        for _ in range(3):
            with protoduino.Board.open(uno.port) as board:
                assert board.baudrate == 115_200
                assert board._link.failed_baudrates <= set(OFFERED["avr"])
                assert board._link.baud_switches == 0
                _works(board)
    finally:
        uno.stop(timeout=5, strict=False)
