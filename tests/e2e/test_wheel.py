"""protoduino installed like any Python package: the wheel, in a fresh virtual environment.

``python -m build`` makes the sdist and, from it, the wheel, which carries the firmware of the
Uno, the Nano and the Mega 2560, the simulated board and the emulated boards' runner
(setup.py). The wheel is installed into a new venv in a temporary folder, outside the checkout,
without the development tools, and the user commands run from there: ``demo``, ``sim`` on both
backends and as the emulated Mega, and ``flash`` through Optiboot on the emulated Uno and
through the stk500v2 bootloader on the emulated Mega (the same setups as
tests/e2e/test_flash.py). Each is judged by what the board did
(its trace, or the flashed firmware answering the handshake), not by the command's words alone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import protoduino
import pytest
from boardprocess import BoardProcess, missing_tool
from protoduino.packets import parse_control
from test_flash import (
    EmulatedMega,
    handshake,
    missing_flash_tool,
    start_blank_uno,
)

pytestmark = [pytest.mark.slow, pytest.mark.avr]

ROOT = Path(__file__).resolve().parents[2]
#: Upper bounds only (a build, a pip install, a demo): nothing is judged by them.
BUILD_TIMEOUT = 600.0
COMMAND_TIMEOUT = 180.0


@dataclass(frozen=True)
class Installed:
    """A venv with the wheel installed, and a working folder outside the checkout."""

    venv: Path
    cwd: Path

    def env(self, path: str | None = None) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH")}
        env["PATH"] = path if path is not None else f"{self.venv / 'bin'}:{os.environ['PATH']}"
        return env

    def program(self, name: str) -> str:
        return str(self.venv / "bin" / name)

    def run(
        self, *args: str, path: str | None = None, timeout: float = COMMAND_TIMEOUT
    ) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [self.program(args[0]), *args[1:]],
            cwd=self.cwd,
            env=self.env(path),
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
            stdin=subprocess.DEVNULL,
        )


def _missing() -> str | None:
    missing = missing_tool("make", "gcc", "avr-gcc", "avr-objcopy")
    if missing is None and not (ROOT / ".deps" / "nanopb" / "pb_decode.c").exists():
        return "the nanopb C runtime (./tools/dev.sh setup fetches it)"
    return missing or missing_flash_tool()


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    missing = _missing()
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    tmp = tmp_path_factory.mktemp("wheel")
    dist = tmp / "dist"
    subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(dist), str(ROOT)],
        cwd=tmp,
        check=True,
        capture_output=True,
        timeout=BUILD_TIMEOUT,
    )
    wheels = sorted(dist.glob("protoduino-*.whl"))
    assert len(wheels) == 1, wheels
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=BUILD_TIMEOUT)
    subprocess.run(
        [
            str(venv / "bin" / "python"),
            "-m",
            "pip",
            "install",
            "-q",
            "-c",
            str(ROOT / "constraints.txt"),
            str(wheels[0]),
        ],
        cwd=tmp,
        check=True,
        capture_output=True,
        timeout=BUILD_TIMEOUT,
    )
    work = tmp / "work"
    work.mkdir()
    return Installed(venv, work)


def test_the_wheel_carries_the_runtime_and_its_programs_only(installed: Installed) -> None:
    result = installed.run(
        "python",
        "-c",
        "import importlib.util, json, protoduino\n"
        "from protoduino import programs\n"
        "print(json.dumps({'package': protoduino.__file__,\n"
        "    'dev': importlib.util.find_spec('protoduino_dev') is not None,\n"
        "    'programs': {n: str(programs.locate(n)) for n in programs.NAMES}}))\n",
    )
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout)
    package = Path(found["package"]).parent
    assert package.is_relative_to(installed.venv), package
    assert found["dev"] is False
    for name, path in found["programs"].items():
        assert Path(path).parent == package / "_programs", (name, path)
    assert os.access(found["programs"]["pd_sim"], os.X_OK)
    assert os.access(found["programs"]["avrsim"], os.X_OK)
    for name in ("protoduino.hex", "protoduino-mega.hex", "protoduino-nano.hex"):
        hex_lines = Path(found["programs"][name]).read_text().splitlines()
        assert hex_lines[0].startswith(":") and hex_lines[-1] == ":00000001FF", name  # Intel hex
    # The live console works offline: its plotting library is package data (setup.py).
    assert (package / "console" / "static" / "vendor" / "uPlot.iife.min.js").is_file()


def test_dev_commands_say_they_need_the_checkout(installed: Installed) -> None:
    result = installed.run("protoduino", "soak", "--commands", "10")
    assert result.returncode == 2
    assert "is a development command" in result.stderr


def test_demo(installed: Installed) -> None:
    trace = installed.cwd / "demo-trace.jsonl"
    result = installed.run("protoduino", "demo", "--trace", str(trace))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "demo done" in result.stdout
    changes = [json.loads(line) for line in trace.read_text().splitlines()]
    # The servo swept, then the failsafe put it back at its safe width.
    servo = [c["value"] for c in changes if c["pin"] == 9]
    assert len(set(servo)) > 5 and servo[-1] == 1472, servo


class SimProcess(BoardProcess):
    """``protoduino sim`` from the installed venv, with its trace."""

    def __init__(self, installed: Installed, backend: str, trace: Path, *options: str) -> None:
        self.trace_path = trace
        super().__init__(
            [
                installed.program("protoduino"),
                "sim",
                "--backend",
                backend,
                "--trace",
                str(trace),
                *options,
            ],
            startup=30.0,
            what="protoduino sim",
            owned=False,  # a board started on purpose has no owner: the fixture stops it
            cwd=installed.cwd,
            env=installed.env(),
            stderr=subprocess.PIPE,
        )

    def wait_for(self, pin: int, value: int, tolerance: int, timeout: float = 10.0) -> None:
        """Until the trace shows ``pin`` at ``value``; the timeout only bounds a failure."""
        deadline = time.monotonic() + timeout
        seen: list[int] = []
        while time.monotonic() < deadline:
            lines = self.trace_path.read_text().splitlines() if self.trace_path.exists() else []
            seen = [int(json.loads(x)["value"]) for x in lines if json.loads(x)["pin"] == pin]
            if any(abs(v - value) <= tolerance for v in seen):
                return
            time.sleep(0.05)
        raise AssertionError(f"pin {pin} never reached {value}: the trace shows {seen}")

    def close(self) -> None:
        self.stop(strict=False)


@pytest.fixture(params=["native", "avr"])
def sim(installed: Installed, request: pytest.FixtureRequest) -> Iterator[SimProcess]:
    process = SimProcess(installed, request.param, installed.cwd / f"{request.node.name}.jsonl")
    yield process
    process.close()


def test_sim_runs_the_board_that_user_commands_drive(installed: Installed, sim: SimProcess) -> None:
    result = installed.run("protoduino", "servo", sim.port, "9", "2000", "--us")
    assert result.returncode == 0, result.stderr
    sim.wait_for(9, 2000, tolerance=3)  # the emulated Uno measures at its pin: a few us off
    result = installed.run("protoduino", "info", sim.port, "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["info"]["schema_id"] == f"0x{protoduino.SCHEMA_ID:08X}"


@pytest.mark.parametrize("board", ["uno", "nano"])
def test_flash_uploads_the_carried_firmware(
    installed: Installed, tmp_path: Path, board: str
) -> None:
    """The Uno's firmware, or the Nano's (the emulated Uno has the Nano's chip and Optiboot)."""
    uno = start_blank_uno(tmp_path / "uno")
    try:
        options = () if board == "uno" else ("--board", board)
        result = installed.run("protoduino", "flash", uno.port, *options)
        output = result.stdout + result.stderr
        assert result.returncode == 0, output
        assert "bytes of flash verified" in output
        ack = handshake(uno.port, timeout=10.0)
        info = installed.run("protoduino", "info", uno.port, "--json")
    finally:
        uno.close()
    control = parse_control(ack.payload)
    assert control.schema_id == protoduino.SCHEMA_ID
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["info"]["board"] == board


def test_sim_runs_the_emulated_mega(installed: Installed) -> None:
    sim = SimProcess(installed, "avr", installed.cwd / "mega.jsonl", "--board", "mega")
    try:
        result = installed.run("protoduino", "info", sim.port, "--json")
    finally:
        sim.close()
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["info"]["board"] == "mega"


def test_flash_uploads_the_carried_mega_firmware(installed: Installed, tmp_path: Path) -> None:
    mega = EmulatedMega(tmp_path / "mega")
    try:
        result = installed.run("protoduino", "flash", mega.port, "--board", "mega")
        output = result.stdout + result.stderr
        assert result.returncode == 0, output
        assert "protoduino-mega.hex" in output  # the wheel's copy, not the Uno's
        assert "device signature = 0x1e9801" in output
        assert "bytes of flash verified" in output
        info = installed.run("protoduino", "info", mega.port, "--json")  # bootloader and all
    finally:
        mega.close()
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["info"]["board"] == "mega"


def test_flash_without_avrdude_says_what_to_install(installed: Installed, tmp_path: Path) -> None:
    port = tmp_path / "ttyACM0"
    port.touch()
    # Only the venv on PATH: no avrdude.
    result = installed.run("protoduino", "flash", str(port), path=str(installed.venv / "bin"))
    assert result.returncode == 1
    assert "avrdude is not installed" in result.stderr
    assert "apt install avrdude" in result.stderr
