"""The complete arm example in docs/api.md runs, as written, against both simulated boards."""

from __future__ import annotations

import functools
import re
import runpy
import sys
from pathlib import Path

import pytest
from protoduino.simboard import SimBoard
from simfixtures import PULSE_TOLERANCE_US, wait_for_pin

API_MD = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def arm_example() -> str:
    text = API_MD.read_text()
    found = re.search(r"<!-- arm example:.*?-->\n```python\n(.*?)```", text, re.S)
    assert found, "docs/api.md lost its arm example"
    return found.group(1)


def near(want: int, values: list[int]) -> bool:
    return bool(values) and abs(values[-1] - want) <= PULSE_TOLERANCE_US


def test_the_arm_example_runs(
    sim_board: SimBoard,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    script = tmp_path / "arm.py"
    script.write_text(arm_example())
    monkeypatch.setattr(sys, "argv", [str(script), sim_board.port])
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    assert "where the device drives now:" in out and "acknowledged: 1472 1183 1667" in out
    # The last command: the base (pin 3, 120 degrees/s limit) at 100 degrees.
    wait_for_pin(sim_board, 3, functools.partial(near, 544 + 100 * 1856 // 180), timeout=10)
    wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])
