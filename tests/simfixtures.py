"""The ``sim_board`` fixture: a started simulated board with a trace, one per board.

Imported by conftest.py. A board of the shared end-to-end suite is an id of
``SIM_BOARDS``: the simulated board ("native"), the emulated Uno ("avr") and the
emulated Mega 2560 ("mega"). Every test that takes ``sim_board`` or ``board_id``
runs on ``SIM_BACKENDS``; one marked ``mega`` runs on the Mega too
(:func:`boards_for`, the one place that decides; tests/README.md says which and
why). Adding a board to every test is one line: append its id to
``SIM_BACKENDS``.

A test that needs pins of a kind takes them from the board's DeviceInfo
(:func:`pins_for`), never by a board's numbers, so that the same test serves
every board; a kind the board states no pin for skips the test, naming it.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from protoduino.board import Board
from protoduino.commands import PinMode
from protoduino.readback import DeviceInfo
from protoduino.simboard import SimBoard

#: The boards of the end-to-end tests, by id: SimBoard's backend and board.
SIM_BOARDS: dict[str, tuple[str, str]] = {
    "native": ("native", "uno"),
    "avr": ("avr", "uno"),
    "mega": ("avr", "mega"),
}

#: The boards every test of the shared fixture runs on.
SIM_BACKENDS = ["native", "avr"]

#: The board a test marked ``mega`` runs on as well (``--all-boards``: every test).
MEGA = "mega"

#: Tools each backend needs to be built; a missing one skips its tests.
_NEEDS = {"native": ("make", "gcc"), "avr": ("make", "gcc", "avr-gcc")}


def boards_for(node: pytest.Function | pytest.Metafunc, all_boards: bool = False) -> list[str]:
    """The board ids a test runs on: ``SIM_BACKENDS``, and the Mega if it is marked ``mega``
    (or ``all_boards``, pytest's ``--all-boards``)."""
    marked = node.definition if isinstance(node, pytest.Metafunc) else node
    if all_boards or marked.get_closest_marker(MEGA) is not None:
        return [*SIM_BACKENDS, MEGA]
    return list(SIM_BACKENDS)


def need_tools(board_id: str) -> None:
    """Skip the test, naming the tool, if one ``board_id``'s build needs is missing."""
    backend = SIM_BOARDS[board_id][0]
    for tool in _NEEDS[backend]:
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (needed to build the {board_id} board)")


def new_sim(board_id: str, **kwargs: Any) -> SimBoard:
    """A SimBoard (not started) of ``board_id``; ``kwargs`` are SimBoard's (trace=, ...)."""
    backend, board = SIM_BOARDS[board_id]
    return SimBoard(backend, board=board, **kwargs)


def sim_args(board_id: str) -> list[str]:
    """``protoduino sim`` and ``demo``'s options that start ``board_id``."""
    backend, board = SIM_BOARDS[board_id]
    return ["--backend", backend, *(["--board", board] if board != "uno" else [])]


@pytest.fixture
def sim_board(board_id: str, tmp_path: Path) -> Iterator[SimBoard]:
    """A started board (``.port`` to open) writing its trace to a fresh temporary file."""
    need_tools(board_id)
    board = new_sim(board_id, trace=tmp_path / f"trace-{board_id}.jsonl")
    board.start()
    try:
        yield board
    finally:
        board.stop()


def device_info(sim: SimBoard) -> DeviceInfo:
    """What a started board states about itself (a Board opened for it and closed)."""
    with Board.open(sim.port) as board:
        return board.info


def pins_for(
    board: Board | DeviceInfo, mode: PinMode, count: int = 1, avoid: tuple[int, ...] = ()
) -> tuple[int, ...]:
    """``count`` pins that can do ``mode`` on ``board``, as its DeviceInfo states them, lowest
    first, none of ``avoid``; fewer than ``count`` skips the test, with the DeviceInfo's
    reason (a board without analog inputs skips an analog test, saying so)."""
    info = board.info if isinstance(board, Board) else board
    found = tuple(p for p in info.pins_for(mode) if p not in avoid)
    if len(found) < count:
        besides = f" besides {', '.join(map(str, avoid))}" if avoid else ""
        pytest.skip(
            f"the {info.board} board's DeviceInfo states {len(found)} {mode.name} pins"
            f"{besides}; the test needs {count}"
        )
    return found[:count]


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
