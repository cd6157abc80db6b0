"""The emulated Uno's inputs (``--control``) and its PWM measurement, against the test program.

The runner's test program (tools/avrsim/testprog/testprog.c) reads pins, the
ADC and an INT0 edge counter on request and makes Timer2 PWM like Arduino's
analogWrite, so the control socket and the trace are checked against plain
AVR code before the firmware uses them: what the program reads is what the
AVR's registers hold after the runner drove the pin or the ADC.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from boardprocess import missing_tool
from protoduino.errors import SimControlError
from protoduino.simcontrol import SimControl
from protoduino_dev import build
from test_avrsim import RUNNER_TOOLS, Runner

pytestmark = pytest.mark.avr


class InputRunner(Runner):
    """The runner with a control socket, and the program's answers."""

    def __init__(self, tmp: Path) -> None:
        # A Unix socket path must stay under 108 bytes: not in pytest's tmp_path.
        self.socket_dir = Path(tempfile.mkdtemp(prefix="pd-avrsim-"))
        self.control = SimControl(self.socket_dir / "control")
        super().__init__(tmp, "--control", str(self.control.path))

    def ask(self, line: str) -> int:
        """Send a query (R, A, E) and return the number in its answer (after the echo)."""
        self.port.reset_input_buffer()
        echo = line.encode() + b"\n"
        self.port.write(echo)
        got = b""
        deadline = time.monotonic() + 5.0
        while not (got.startswith(echo) and got.count(b"\n") >= 2) and time.monotonic() < deadline:
            got += self.port.read(64)
        assert got.startswith(echo) and got.count(b"\n") >= 2, f"no answer to {line!r}: {got!r}"
        return int(got.split(b"\n")[1].split()[-1])

    def stop(self, sig: int = 15) -> int:
        self.control.close()
        try:
            return super().stop(sig)
        finally:
            assert not self.control.path.exists()  # the runner removed its socket
            self.socket_dir.rmdir()


@pytest.fixture(scope="module")
def uno(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InputRunner]:
    missing = missing_tool(*RUNNER_TOOLS, simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build.build_runner()
    build.build_test_program()
    runner = InputRunner(tmp_path_factory.mktemp("avrsim-inputs"))
    yield runner
    runner.stop()


def test_a_driven_level_is_what_the_avr_reads_and_outlasts_port_writes(uno: InputRunner) -> None:
    """simavr re-raises an input's pull-up on every write to its port; a driven level stays."""
    uno.command("U4 1")  # pin 4: input with pull-up
    assert uno.ask("R4") == 1
    uno.control.level(4, 0)
    assert uno.ask("R4") == 0
    uno.command("D7 1")  # writes PORTD, the port of pin 4
    uno.command("D7 0")
    assert uno.ask("R4") == 0
    uno.control.level(4, 1)
    assert uno.ask("R4") == 1


def test_analog_values_are_exact_counts(uno: InputRunner) -> None:
    for pin, counts in ((14, 0), (15, 1), (16, 512), (17, 1000), (18, 1022), (19, 1023)):
        uno.control.analog(pin, counts)
        assert uno.ask(f"A{pin - 14}") == counts


def test_pulses_are_counted_by_the_external_interrupt(uno: InputRunner) -> None:
    """100 pulses at 2 kHz and 500 at 20 kHz: every rising edge reaches INT0."""
    uno.control.level(2, 0)
    before = uno.ask("E")
    start = uno.control.pulses(2, 100, 2000)
    uno.control.pulses(5, 1, 10)  # another pin's train does not touch pin 2
    # The train lasts 50 ms of emulated time; the count is judged once it is over.
    deadline = time.monotonic() + 10.0
    while uno.ask("E") - before < 100 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.05)
    assert uno.ask("E") - before == 100
    assert uno.ask("R2") == 0  # back at the level it started from
    assert start > 0
    uno.control.pulses(2, 500, 20000)
    deadline = time.monotonic() + 10.0
    while uno.ask("E") - before < 600 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.05)
    assert uno.ask("E") - before == 600


def test_refusals_are_explained(uno: InputRunner) -> None:
    with pytest.raises(SimControlError, match=r"analog inputs are pins 14\.\.19"):
        uno.control.analog(3, 10)
    with pytest.raises(SimControlError, match="serial link"):
        uno.control.level(1, 0)
    with pytest.raises(SimControlError, match="no such pin"):
        uno.control.level(20, 0)
    with pytest.raises(SimControlError, match=r"\"analog\" must be 0..1023"):
        uno.control.analog(14, 1024)
    with pytest.raises(SimControlError, match="unknown key"):
        uno.control.send({"pin": 2, "volts": 3})
    uno.control.level(2, 1)  # still answering


def _pwm(uno: InputRunner, pin: int, duty: int, since: int) -> dict[str, Any]:
    return uno.wait_for(
        lambda line: line["pin"] == pin and line["mode"] == "pwm" and line["value"] == duty,
        since=since,
    )


def test_pwm_duty_is_measured_at_the_pin(uno: InputRunner) -> None:
    """Timer2's compare outputs, measured from high and low times in whole timer ticks."""
    for duty in (128, 1, 254, 64, 0, 255, 200):
        since = uno.command(f"P3 {duty}")
        _pwm(uno, 3, duty, since)
    since = uno.command("P11 77")
    _pwm(uno, 11, 77, since)
    pin3 = [line["value"] for line in uno.trace() if line["pin"] == 3]
    assert pin3 == [128, 1, 254, 64, 0, 255, 200]  # one line per change, nothing between
