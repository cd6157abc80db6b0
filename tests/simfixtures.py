"""The ``sim_board`` fixture: a started simulated board with a trace, one per backend.

Imported by conftest.py. Adding a backend to the shared end-to-end suite is
one line: append its name to ``SIM_BACKENDS`` (it must also be known to
``protoduino.simboard.BACKENDS``).
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from protoduino.simboard import SimBoard

#: Every backend the end-to-end tests run against.
SIM_BACKENDS = ["native", "avr"]

#: Tools each backend needs to be built; a missing one skips its tests.
_NEEDS = {"native": ("make", "gcc"), "avr": ("make", "gcc", "avr-gcc")}


@pytest.fixture(params=SIM_BACKENDS)
def sim_board(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SimBoard]:
    """A started board (``.port`` to open) writing its trace to a fresh temporary file."""
    backend: str = request.param
    for tool in _NEEDS.get(backend, ()):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (needed to build the {backend} board)")
    trace = tmp_path / f"trace-{backend}.jsonl"
    board = SimBoard(backend, trace=trace)
    board.start()
    try:
        yield board
    finally:
        board.stop()


#: The emulated Uno measures pulses on its pins: a few microseconds off. The native board is exact.
PULSE_TOLERANCE_US = 3


def pin_values(trace: list[dict[str, Any]], pin: int) -> list[int]:
    """The values one pin took, in the trace's order."""
    return [int(e["value"]) for e in trace if e["pin"] == pin]


def wait_until(predicate: Callable[[], bool], timeout: float = 60.0) -> bool:
    """Poll ``predicate`` until it holds (True) or ``timeout`` seconds pass (False): the
    verdict is the predicate's; the timeout only bounds how long a failing test waits."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def wait_for_pin(
    sim: SimBoard, pin: int, ok: Callable[[list[int]], bool], timeout: float = 30.0
) -> list[int]:
    """Wait until ``ok`` holds for the values ``pin`` took in the trace; return them.

    The verdict is the trace's (what the pin did), not the wall clock's:
    ``timeout`` only bounds how long a failing test waits. A command that
    returned once acked has reached the device, not yet the pin (a servo
    shows a new width at its next 20 ms frame, measured over two frames on
    the emulated Uno), so a test that then changes the pin again must first
    wait here for the change it wants to see.
    """
    deadline = time.monotonic() + timeout
    while True:
        values = pin_values(sim.trace(), pin)
        if ok(values):
            return values
        if time.monotonic() > deadline:
            raise AssertionError(f"pin {pin}: the trace shows {values}")
        time.sleep(0.02)
