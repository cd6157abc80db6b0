"""The ``sim_board`` fixture: a started simulated board with a trace, one per backend.

Imported by conftest.py. Adding a backend to the shared end-to-end suite is
one line: append its name to ``SIM_BACKENDS`` (it must also be known to
``protoduino.simboard.BACKENDS``).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

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
