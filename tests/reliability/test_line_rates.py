"""Faults at the agreed line rate, on boards whose line carries bytes only at matching rates.

The boards start with ``--line-check`` (firmware/simcontrol/pd_linerate.h) and the host
opens them through ``faulty://``, which hands the rate on to the board's pseudo-terminal:
a byte crosses only while both ends run at the same rate, as on a real UART. So a device
that resets (back at its opening rate, 115200) is deaf and mute to a host still at the
agreed 1,000,000 (issue 32). Verdicts come from the board's events and the errors its calls
raise; the bound only limits how long a failing test waits.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Iterator
from pathlib import Path

import protoduino_dev  # noqa: F401  (registers faulty://)
import pytest
from protoduino import AckTimeoutError, Board, DeviceRebootedError
from protoduino.events import Event, EventKind
from protoduino.simboard import SimBoard
from simfixtures import SIM_BACKENDS, wait_for_pin

BOUND = 30.0  # seconds: only how long a failing test waits


@pytest.fixture(params=SIM_BACKENDS)
def rated(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SimBoard]:
    """A started board whose line checks rates."""
    backend: str = request.param
    sim = SimBoard(backend, trace=tmp_path / "trace.jsonl", options=("--line-check",))
    try:
        sim.start()
        yield sim
    finally:
        sim.stop()


def test_a_reset_at_the_agreed_rate_is_a_reboot_not_ack_timeouts(rated: SimBoard) -> None:
    """The device resets while the link runs at 1,000,000: its EVENT BOOT goes out at
    115200 and is lost. The calls sent meanwhile may or may not have run: they must fail
    with DeviceRebootedError once the host finds the reboot, not with AckTimeoutError while
    it waits for the watchdog (5 s: four writes failed so)."""
    events: queue.Queue[Event] = queue.Queue()
    url = f"faulty://{rated.port}?paused=1&name=rates-{rated.backend}-{time.monotonic_ns()}"
    with Board.open(url) as board:
        board.on_event(events.put)
        assert board.baudrate == 1_000_000  # agreed through faulty:// on a checking line
        led = board.digital_output(13, safe=False)
        led.on()
        wait_for_pin(rated, 13, lambda v: v[-1:] == [1])
        rated.reboot()
        errors: list[Exception] = []
        rebooted = False
        level = False
        deadline = time.monotonic() + BOUND
        while not rebooted:
            assert time.monotonic() < deadline, f"no REBOOTED event; calls raised {errors}"
            try:
                led.write(level)
            except (AckTimeoutError, DeviceRebootedError) as error:
                errors.append(error)
            level = not level
            while not events.empty():
                if events.get().kind is EventKind.REBOOTED:
                    rebooted = True
        assert not [e for e in errors if isinstance(e, AckTimeoutError)], errors
        assert board._link.reboots == 1
        led.write(True)  # after the restore, at the rate agreed again
        wait_for_pin(rated, 13, lambda v: v[-1:] == [1])
        assert board.baudrate == 1_000_000
