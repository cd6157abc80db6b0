"""The simavr runner (tools/avrsim) against its own AVR test program.

The test program (tools/avrsim/testprog/testprog.c) makes servo pulses the way
the Arduino Servo library does (a Timer1 compare interrupt toggling pins) and
echoes UART bytes; lines like ``S9 1500`` command it. These tests check the
runner itself: the pty bridge, pulse widths measured at the pin from emulated
cycles, immunity to simavr's pin re-raise artefact, the trace format, pacing,
reset, several boards at once and clean exits. The real firmware is covered by
the shared end-to-end suite and tests/e2e/test_flash.py.

Each runner costs about a quarter of a CPU core while it runs, so one board is
shared per module where the state allows.
"""

from __future__ import annotations

import json
import os
import random
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial
from boardprocess import BoardProcess, missing_tool
from protoduino.simboard import runner_command
from protoduino_dev import build
from protoduino_dev.runnerstats import snapshot

pytestmark = pytest.mark.avr

STARTUP_TIMEOUT = 10.0


#: What building and running the runner with its test program takes.
RUNNER_TOOLS = ("make", "cc", "avr-gcc")


@pytest.fixture(scope="module")
def built() -> tuple[Path, Path]:
    missing = missing_tool(*RUNNER_TOOLS, simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    return build.build_runner(), build.build_test_program()


class Runner:
    """One avrsim process with the test program, its trace and its port."""

    def __init__(
        self, tmp: Path, *extra: str, link: Path | None = None, program: Path = build.TEST_PROGRAM
    ) -> None:
        self.trace_path = tmp / f"trace-{id(self)}.jsonl"
        cmd = runner_command(program, trace=self.trace_path, link=link)
        cmd[-1:-1] = list(extra)
        self.started = time.monotonic()
        self.process = BoardProcess(cmd, startup=STARTUP_TIMEOUT)
        self.proc = self.process.proc
        self.first_line = self.process.port
        self.port = serial.Serial(self.first_line, 115200, timeout=0.2)

    def command(self, line: str) -> int:
        """Send one command line, wait for its echo (the program parsed it).

        Returns the number of trace lines before the command, for wait_for(since=).
        """
        since = len(self.trace())
        self.port.reset_input_buffer()
        data = line.encode() + b"\n"
        self.port.write(data)
        got = b""
        deadline = time.monotonic() + 5.0
        while not got.endswith(data) and time.monotonic() < deadline:
            got += self.port.read(64)
        assert got.endswith(data), f"no echo of {line!r}: {got!r}"
        return since

    def trace(self) -> list[dict[str, Any]]:
        if not self.trace_path.exists():
            return []
        lines = self.trace_path.read_text().splitlines()
        return [json.loads(line) for line in lines if line.endswith("}")]

    def wait_for(
        self, predicate: Callable[[dict[str, Any]], bool], *, since: int = 0, timeout: float = 30.0
    ) -> dict[str, Any]:
        """The first trace line from index ``since`` on that matches."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in self.trace()[since:]:
                if predicate(line):
                    return line
            time.sleep(0.02)
        raise AssertionError(f"no matching trace line in {self.trace()}")

    def stop(self, sig: int = signal.SIGTERM) -> int:
        """Close the port, signal the runner, and return its exit status (it must exit)."""
        self.port.close()
        rc = self.process.stop(sig, timeout=5)
        assert rc is not None
        return rc


def _servo(pin: int, value: int | None = None) -> Callable[[dict[str, Any]], bool]:
    def match(line: dict[str, Any]) -> bool:
        return bool(
            line["pin"] == pin
            and line["mode"] == "servo"
            and (value is None or abs(line["value"] - value) <= 3)
        )

    return match


@pytest.fixture(scope="module")
def board(built: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runner]:
    """One board for the tests that only add state (never reset it or stop it)."""
    runner = Runner(tmp_path_factory.mktemp("avrsim"), "--glitch", "10")
    yield runner
    runner.stop()


def test_first_stdout_line_is_the_port_and_echo_is_exact(board: Runner) -> None:
    assert board.first_line.startswith("/dev/pts/")
    # Every byte value; the final newline ends the line the program collects.
    data = bytes(range(256)) * 4 + b"\n"
    board.port.reset_input_buffer()
    board.port.write(data)
    got = b""
    deadline = time.monotonic() + 5.0
    while len(got) < len(data) and time.monotonic() < deadline:
        got += board.port.read(len(data) - len(got))
    assert got == data


def test_pulse_widths_follow_the_commanded_widths(board: Runner) -> None:
    """Widths come from emulated cycles: a command's difference shows exactly."""
    widths = {}
    for us in (1000, 1500, 2000, 2001):
        since = board.command(f"S9 {us}")
        widths[us] = board.wait_for(_servo(9), since=since)["value"]
    # At the pin the program's pulses are its command plus a constant interrupt
    # latency of about a microsecond, as with the Servo library.
    for us, measured in widths.items():
        assert abs(measured - us) <= 2
    assert widths[1500] - widths[1000] == 500
    assert widths[2000] - widths[1500] == 500
    assert widths[2001] - widths[2000] == 1


def test_trace_format_and_only_changes(board: Runner) -> None:
    board.command("S9 1700")
    board.command("D13 1")
    board.wait_for(lambda line: line["pin"] == 13 and line["value"] == 1)
    board.command("D13 0")
    board.wait_for(lambda line: line["pin"] == 13 and line["value"] == 0)
    board.command("S9 1700")  # same value again: no new line
    time.sleep(0.2)
    lines = board.trace()
    for line in lines:
        assert list(line) == ["t", "pin", "mode", "value"]
        assert isinstance(line["t"], float) and line["t"] >= 0
        assert line["mode"] in ("servo", "digital")
        assert 2 <= line["pin"] <= 19
    raw = board.trace_path.read_text().splitlines()
    assert all(json.loads(r) for r in raw)  # every line is complete JSON
    pin9 = [line for line in lines if line["pin"] == 9]
    assert [line["value"] for line in pin9].count(pin9[-1]["value"]) == 1
    assert all(line["mode"] == "servo" for line in pin9)
    pin13 = [line["value"] for line in lines if line["pin"] == 13]
    assert pin13[-2:] == [1, 0]
    times = [line["t"] for line in lines if line["pin"] == 13]
    assert times == sorted(times)


def test_spurious_reraises_leave_the_measurement_alone(board: Runner) -> None:
    """--glitch 10 re-raises pin 10's IRQ with the opposite level every 50 us.

    An IRQ listener that trusted the raised values would report pulses of a few
    microseconds (this is simavr 1.6's artefact when other bits of the port are
    written); the runner reads the port registers and compares with the previous
    level, so pin 10 shows exactly its commanded pulse and nothing else, while
    the test program also rewrites PORTB continuously from its main loop.
    """
    since = board.command("S10 1200")
    board.wait_for(_servo(10, 1200), since=since)
    time.sleep(0.5)  # ~25 frames, ~10,000 injected glitches (more or fewer: same verdict)
    pin10 = [line for line in board.trace()[since:] if line["pin"] == 10]
    # Every width measured is the commanded one: a glitch would show as a pulse
    # of a few microseconds. Within 2 us, since the test program's own interrupt
    # latency may move an edge by a cycle or two from frame to frame.
    assert pin10
    assert all(abs(line["value"] - 1200) <= 2 for line in pin10), pin10


def test_emulated_time_is_paced_to_real_time(board: Runner) -> None:
    """Timestamps are emulated time, and pacing keeps it from running ahead of the wall clock.

    Free-running, simavr emulates 3 to 6 times faster than real time; paced, a
    change is never dated later than the wall time since the runner started.
    (Under CPU contention emulation may lag behind; that is not asserted.)
    """
    board.command("S9 1234")
    line = board.wait_for(_servo(9, 1234))
    elapsed_wall = time.monotonic() - board.started
    assert 0 < line["t"] <= elapsed_wall + 0.01


#: One byte's time on the line at 115200 baud, 8N1 (the runner counts 10 bits a byte;
#: simavr's UART takes 11 bits, longer).
BYTE_S = 10 / 115200


def test_an_answer_never_arrives_before_the_line_could_carry_it(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    """Emulated time runs ahead of the wall clock by up to a pass of the runner's
    loop; what the UART sends must still reach the host no earlier than a line
    would deliver it, or round trips would measure shorter than the line allows.
    A byte and its echo: at least two byte times, whatever the load (a slow
    machine only makes it longer)."""
    runner = Runner(tmp_path)  # its own: the echoed bytes make a line the program rejects
    try:
        for _ in range(20):
            start = time.perf_counter()
            runner.port.write(b"x")
            assert runner.port.read(1) == b"x"
            assert time.perf_counter() - start >= 2 * BYTE_S
    finally:
        runner.stop()


#: How far ahead of the wall clock emulated time may run (tools/avrsim PD_AHEAD_NS),
#: and so how late a host byte may enter the UART after the runner read it.
MAX_RX_LAG_S = 50e-6

#: Passes per emulated second of a sleeping board: about one per timer event (the
#: firmware's tick is 1 kHz; 1,200 measured), not one per 50 us.
MAX_IDLE_PASSES_PER_SECOND = 5_000

#: Main-loop passes per emulated second the pacing allows: a pass runs emulated
#: time at most 50 us ahead of the wall clock and then waits, or wakes for
#: host bytes (with the input buffer full, at most one per byte time as the
#: UART takes them: 10,695 a second). A loop that does not wait makes hundreds
#: of thousands.
MAX_PASSES_PER_SECOND = 50_000


def test_a_full_input_buffer_is_waited_on_not_polled(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    """Three times the runner's 4 KB input buffer at once: while the emulated
    UART takes a byte per byte time, the pty stays readable; polling it for
    input then returned at once, every pass, and spun a core."""
    stats = tmp_path / "stats.jsonl"
    runner = Runner(tmp_path, "--stats", str(stats))
    sent = 12_000
    try:
        start = snapshot(runner.proc.pid, stats)
        runner.port.write(b"x" * sent)  # the pty's buffers take it all at once
        # The runner's buffer stays full until the pty has nothing left for it.
        deadline = time.monotonic() + 60.0  # bounds a failing wait only
        end = snapshot(runner.proc.pid, stats)
        while end["uart_rx_bytes"] - start["uart_rx_bytes"] < sent - 4096:
            assert time.monotonic() < deadline, end
            time.sleep(0.05)
            end = snapshot(runner.proc.pid, stats)
    finally:
        runner.stop()
    emulated = end["t"] - start["t"]
    passes = end["passes"] - start["passes"]
    assert passes <= MAX_PASSES_PER_SECOND * emulated, (passes, emulated)


def test_a_host_byte_enters_the_uart_when_it_is_read_while_the_mcu_sleeps(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    """The firmware sleeps between interrupts, and simavr skips a sleeping core
    ahead to its next cycle timer (the firmware's 1 ms tick). Emulated time was
    then up to a millisecond ahead of the wall clock, and a byte from the host
    entered the UART that much after it was written: every round trip measured
    on the emulated Uno paid it (280 us at the median), although no real Uno
    would. The runner now stops a sleeping core at its pacing target, so a byte
    enters at most PD_AHEAD_NS (50 us) after the wall-clock time it was read at,
    whatever the load: that bound is the runner's own arithmetic on its own
    clocks (rx_lag_max), so the test's pauses vary only the phase, not the verdict."""
    stats = tmp_path / "stats.jsonl"
    runner = Runner(tmp_path, "--stats", str(stats), program=build.build_firmware())
    rng = random.Random(11)
    sent = 60
    try:
        start = snapshot(runner.proc.pid, stats)
        for _ in range(sent):
            # A lone frame delimiter: the firmware ignores it and goes back to sleep.
            runner.port.write(b"\x00")
            time.sleep(rng.uniform(0.0, 0.003))  # phases against the tick; not judged
        deadline = time.monotonic() + 30.0  # bounds a failing wait only
        end = snapshot(runner.proc.pid, stats)
        while end["uart_rx_bytes"] - start["uart_rx_bytes"] < sent:
            assert time.monotonic() < deadline, end
            time.sleep(0.02)
            end = snapshot(runner.proc.pid, stats)
        time.sleep(0.3)  # idle: its length does not change the verdict below
        idle = snapshot(runner.proc.pid, stats)
    finally:
        runner.stop()
    assert end["rx_lag_max"] <= end["freq"] * MAX_RX_LAG_S + 1, end
    # Nor does the runner wake an idle board every PD_AHEAD_NS (20,000 passes a
    # second): it waits for the next timer event, the firmware's 1 ms tick.
    emulated = idle["t"] - end["t"]
    assert idle["passes"] - end["passes"] <= MAX_IDLE_PASSES_PER_SECOND * emulated, (end, idle)


def test_answer_time_runs_from_the_last_byte_in_to_the_first_byte_out(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    """The runner's answer counters (what the bench reports as the firmware's answer
    time): one per host burst answered, counted in emulated cycles from the burst's last
    byte ready in UDR0 to the next byte the UART sends. The test program echoes each
    byte from its main loop, within a few dozen cycles; a clock started at the first byte
    of a burst, or at the byte's entry into simavr's FIFO, would count a byte time more."""
    stats = tmp_path / "stats.jsonl"
    runner = Runner(tmp_path, "--stats", str(stats))
    calls = 20
    try:
        start = snapshot(runner.proc.pid, stats)
        for _ in range(calls):
            runner.port.write(b"y")
            assert runner.port.read(1) == b"y"
        end = snapshot(runner.proc.pid, stats)
    finally:
        runner.stop()
    answers = end["answers"] - start["answers"]
    cycles = end["answer_cycles"] - start["answer_cycles"]
    assert answers == calls, (start, end)
    assert 0 < cycles / answers < end["freq"] * BYTE_S / 4, (start, end)


def test_stopped_pulses_give_a_zero_line(board: Runner) -> None:
    board.command("S10 1300")
    board.wait_for(_servo(10, 1300))
    board.command("X10")
    zero = board.wait_for(lambda line: line["pin"] == 10 and line["value"] == 0)
    assert zero["mode"] == "servo"


def test_reset_keeps_the_port_and_zeroes_the_outputs(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    runner = Runner(tmp_path)
    try:
        runner.command("S9 1600")
        runner.command("D13 1")
        on9 = runner.wait_for(_servo(9, 1600))
        on13 = runner.wait_for(lambda line: line["pin"] == 13 and line["value"] == 1)
        runner.proc.send_signal(signal.SIGUSR1)
        zero9 = runner.wait_for(lambda line: line["pin"] == 9 and line["value"] == 0)
        zero13 = runner.wait_for(
            lambda line: line["pin"] == 13 and line["value"] == 0 and line["mode"] == "digital"
        )
        # Emulated time goes on across the reset (no restart from 0).
        assert zero9["t"] > on9["t"] and zero13["t"] > on13["t"]
        # Same port, same open file: the restarted program answers again.
        runner.command("S9 1100")
        runner.wait_for(_servo(9, 1100))
        assert runner.proc.poll() is None
    finally:
        assert runner.stop() == 0


def test_several_boards_at_once_and_clean_exit(built: tuple[Path, Path], tmp_path: Path) -> None:
    links = [tmp_path / f"uno{i}" for i in range(3)]
    runners = [Runner(tmp_path, link=link) for link in links]
    try:
        assert [r.first_line for r in runners] == [str(link) for link in links]
        ptys = {os.path.realpath(link) for link in links}
        assert len(ptys) == 3
        for i, runner in enumerate(runners):
            runner.command(f"S9 {1000 + 300 * i}")
        for i, runner in enumerate(runners):
            runner.wait_for(_servo(9, 1000 + 300 * i))
            assert [line["value"] for line in runner.trace() if line["pin"] == 9] == [
                runner.wait_for(_servo(9))["value"]
            ]
    finally:
        codes = [
            runner.stop(sig)
            for runner, sig in zip(
                runners, (signal.SIGINT, signal.SIGTERM, signal.SIGTERM), strict=True
            )
        ]
    assert codes == [130, 0, 0]  # SIGINT says so (128 + 2), as a shell does
    for link in links:
        assert not link.exists() and not link.is_symlink()
