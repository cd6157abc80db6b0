"""The README's command examples, run as written (the device paths swapped for test boards).

Every ``protoduino ...`` line in the README's ``sh`` blocks belongs to one
block below and is run by it, against the board it assumes: the real-Uno block
flashes an emulated Uno that holds only Optiboot, then drives it; the capture
block runs on the simulated board; the remote block goes through ser2net. The
pins are judged from the board's own trace. The command table's synopses are
checked against the parsers: every option it shows exists.
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from boardprocess import missing_tool
from protoduino import Board
from protoduino.cli.main import COMMANDS, build_parser, main
from protoduino.readback import DeviceInfo
from protoduino.simboard import SimBoard, runner_command
from protoduino_dev import build
from simfixtures import PULSE_TOLERANCE_US, pin_values, wait_for_pin
from test_flash import EmulatedUno as UnoProcess
from test_flash import missing_flash_tool
from test_remote import Ser2net

# pyserial 3.5's rfc2217 reader thread uses the old threading setters.
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning:serial.rfc2217")

README = Path(__file__).resolve().parents[2] / "README.md"
UNO_PORT = "/dev/ttyACM0"

#: Each example block, named by a line only it contains (a part of it; the whole line where
#: another block's line holds it too: :func:`holds`).
BLOCKS = {
    "install": "protoduino demo\n",
    "uno": "protoduino ports",
    "capture": "--capture robot.jsonl",
    "remote": "rfc2217://raspberrypi.local:7000",
    "ros2": "protoduino ros2 --sim",
    "mega": "--board mega",
}


def example_blocks() -> list[list[str]]:
    """The ``protoduino`` lines of each ``sh`` block of the README, comments dropped."""
    blocks = re.findall(r"```sh\n(.*?)```", README.read_text(), flags=re.S)
    out = []
    for block in blocks:
        lines = [
            line.split("  #")[0].strip()
            for line in block.splitlines()
            if line.startswith("protoduino ")
        ]
        if lines:
            out.append(lines)
    return out


def holds(lines: list[str], marker: str) -> bool:
    """One of ``lines`` holds ``marker`` (its end, if the marker ends in a newline)."""
    return any(marker in f"{line}\n" for line in lines)


def block(name: str) -> list[str]:
    found = [b for b in example_blocks() if holds(b, BLOCKS[name])]
    assert len(found) == 1, f"README: {len(found)} example blocks contain {BLOCKS[name]!r}"
    return found[0]


def run(line: str, replace: dict[str, str]) -> int:
    for old, new in replace.items():
        line = line.replace(old, new)
    argv = shlex.split(line)
    assert argv[0] == "protoduino"
    return main(argv[1:])


def test_every_example_block_is_run() -> None:
    for lines in example_blocks():
        owners = [n for n, marker in BLOCKS.items() if holds(lines, marker)]
        assert len(owners) == 1, f"README example block run by no test (or two): {lines}"


def test_the_command_table_matches_the_parsers() -> None:
    rows = re.findall(r"^\| `protoduino (\w+)([^`]*)` \|", README.read_text(), flags=re.M)
    assert {name for name, _ in rows} == set(COMMANDS)
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    subparsers: dict[str, argparse.ArgumentParser] = sub.choices
    for name, synopsis in rows:
        known = {o for a in subparsers[name]._actions for o in a.option_strings}
        shown = re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", synopsis)
        assert [o for o in shown if o not in known] == [], f"protoduino {name}{synopsis}"


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)  # the examples write their files where they run
    return tmp_path


@pytest.fixture
def blank_uno(tmp_path: Path) -> Iterator[tuple[UnoProcess, Path]]:
    """An emulated Uno with only Optiboot in its flash, reset on open, writing a trace."""
    missing = missing_flash_tool()
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    build.build_runner()
    build.build_optiboot()
    trace = tmp_path / "uno-trace.jsonl"
    uno = UnoProcess(
        runner_command(
            hex_files=[build.OPTIBOOT_HEX],
            boot_address=build.OPTIBOOT_ADDRESS,
            auto_reset=True,
            trace=trace,
            link=tmp_path / "uno",
        )
    )
    yield uno, trace
    uno.close()


@pytest.mark.avr
def test_the_real_uno_examples(
    blank_uno: tuple[UnoProcess, Path], workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    uno, trace = blank_uno

    def pin(number: int) -> list[int]:
        changes = [json.loads(x) for x in trace.read_text().splitlines() if x.strip()]
        return pin_values(changes, number)

    def wait(number: int, ok: Callable[[list[int]], bool]) -> None:
        """The change reached the pin: an Ack says the device took it, a servo shows it at
        its next 20 ms frame; the next command's open resets the Uno (its DTR auto-reset)."""
        deadline = time.monotonic() + 10.0
        while not ok(pin(number)):
            assert time.monotonic() < deadline, f"pin {number}: {pin(number)}"
            time.sleep(0.02)

    lines = block("uno")
    commands = [shlex.split(x)[1] for x in lines]
    assert commands == ["ports", "flash", "info", "servo", "pin", "pwm", "read"]
    for line in lines:
        assert run(line, {UNO_PORT: uno.port}) == 0, line
        if " servo " in line:  # servo 9 45: 544 + 45 * (2400 - 544) / 180 us
            wait(9, lambda v: any(abs(x - 1008) <= PULSE_TOLERANCE_US for x in v))
        if " pin " in line:
            wait(13, lambda v: v[-1:] == [1])
        if " pwm " in line:  # measured at the pin from the timer's compare output
            wait(3, lambda v: 128 in v)
    out = capsys.readouterr().out
    assert "pin 2 digital: 1 (" in out  # nothing drives pin 2: its pull-up reads high
    assert "num_pins          20" in out
    assert "handshakes        1" in out  # info's link counters


@pytest.mark.avr
@pytest.mark.slow
def test_the_install_examples(
    blank_uno: tuple[UnoProcess, Path], workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """flash (on an Uno holding only Optiboot), info (the flashed firmware answers), sim (its
    port answers), demo (passes)."""
    uno, _trace = blank_uno
    lines = block("install")
    assert [shlex.split(x)[1] for x in lines] == ["flash", "info", "sim", "demo"]
    assert run(lines[0], {UNO_PORT: uno.port}) == 0
    assert run(lines[1], {UNO_PORT: uno.port}) == 0
    with Board.open(uno.port) as board:  # the flashed firmware answers
        assert board.info.num_pins == 20
    assert started(lines[2]).board == "sim"
    assert run(lines[3], {}) == 0
    assert "demo done" in capsys.readouterr().out


def started(line: str) -> DeviceInfo:
    """A README ``protoduino sim`` line run as a process, until the board on the port it
    prints first answered a ping: what that board says of itself."""
    sim = subprocess.Popen(
        [sys.executable, "-m", "protoduino.cli.main", *shlex.split(line)[1:]],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()  # the port comes first
        with Board.open(port) as board:
            assert board.ping() > 0
            return board.info
    finally:
        sim.terminate()
        sim.wait(10)
        assert sim.stdout is not None
        sim.stdout.close()


@pytest.mark.avr
@pytest.mark.slow
def test_the_emulated_mega_examples(capsys: pytest.CaptureFixture[str]) -> None:
    """sim (the board on its port says it is a Mega), demo (passes on the Mega: connected to
    its firmware, the failsafe in its trace)."""
    missing = missing_tool("make", "cc", "avr-gcc", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    lines = block("mega")
    assert [shlex.split(x)[1] for x in lines] == ["sim", "demo"]
    assert started(lines[0]).board == "mega"
    assert run(lines[1], {}) == 0
    out = capsys.readouterr().out
    assert "connected: mega firmware" in out and "demo done" in out, out


def test_the_capture_examples(
    workdir: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (needed to build the native board)")
    with SimBoard("native", trace=tmp_path / "trace.jsonl") as sim:
        sim.start()
        lines = block("capture")
        for line in lines:
            assert run(line, {UNO_PORT: sim.port}) == 0, line
        wait_for_pin(sim, 9, lambda v: bool(v) and v[-1] == 1008)
    out = capsys.readouterr().out
    assert '"servo_control":{"pin":9,"degrees":45}' in out  # monitor --follow
    assert '"servo_control": {"pin": 9, "degrees": 45}' in out  # decode
    assert (workdir / "robot.mcap").stat().st_size > 0


def test_the_remote_example(sim_board: SimBoard, tmp_path: Path) -> None:
    if shutil.which("ser2net") is None:
        pytest.skip("ser2net is not installed (tools/dev.sh setup installs it)")
    server = Ser2net(sim_board.port, tmp_path)
    server.start()
    try:
        for line in block("remote"):
            local = f"rfc2217://127.0.0.1:{server.port}"
            assert run(line, {"rfc2217://raspberrypi.local:7000": local}) == 0, line
    finally:
        server.stop()


def test_the_ros2_example(workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The bridge in one command on the simulated board it starts, as written, on a loopback
    DDS domain of its own: a Twist and a servo angle from an independent ROS 2 peer (rosbags'
    codec, tests/e2e/test_ros2.py) reach the pins, and Ctrl-C stops it with the outputs safe."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (needed to build the native board)")
    pytest.importorskip("cyclonedds", reason="cyclonedds (the ros2 extra) is missing")
    pytest.importorskip("rosbags.typesys", reason="rosbags is not installed")
    import signal

    import test_ros2 as ros
    from cyclonedds.domain import DomainParticipant

    (line,) = block("ros2")
    monkeypatch.setenv("CYCLONEDDS_URI", ros.LOOPBACK)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(ros.DOMAIN))
    out = workdir / "bridge.log"
    argv = [sys.executable, "-m", "protoduino.cli.main", *shlex.split(line)[1:]]
    with out.open("w") as log:
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT)
    try:
        ros._until(lambda: "topics:" in out.read_text() or proc.poll() is not None, "the bridge")
        assert proc.poll() is None, out.read_text()
        text = out.read_text()
        assert "simulated board (native) on /dev/" in text
        for topic in ("cmd_vel", "servo/pan", "battery", "bumper", "sensors/encoders"):
            assert f"/robot1/{topic}  " in text, text
        trace = workdir / "trace.jsonl"

        def pin(number: int) -> list[int]:
            return pin_values([json.loads(x) for x in trace.read_text().splitlines()], number)

        graph = ros.Graph(DomainParticipant(ros.DOMAIN))
        cmd_vel = graph.publisher("/robot1/cmd_vel", "geometry_msgs/msg/Twist")
        pan = graph.publisher("/robot1/servo/pan", "std_msgs/msg/Float64")
        pan(ros.ros("std_msgs/msg/Float64", data=45.0))
        ros._until(lambda: pin(9)[-1:] == [1008], "the servo at 45 degrees")
        cmd_vel(ros._twist(0.25, 0.0))  # both wheels ahead at half their top speed
        ros._until(lambda: pin(5)[-1:] == [128] and pin(6)[-1:] == [128], "the motors")
        proc.send_signal(signal.SIGINT)  # Ctrl-C
        assert proc.wait(30) == 130, out.read_text()  # interrupted, as README's table says
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "protoduino ros2: stopped" in out.read_text()
    assert pin(5)[-1] == 0 and pin(6)[-1] == 0  # the device's Stop: the motors safe
    assert 1472 in pin(9)[pin(9).index(1008) :]  # the servo back at its safe 90 degrees


def python_example() -> str:
    """The README's first Python block (the one that opens /dev/ttyACM0)."""
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks and UNO_PORT in blocks[0]
    return str(blocks[0])


def test_the_python_example_runs(sim_board: SimBoard, capsys: pytest.CaptureFixture[str]) -> None:
    """As written, with the port swapped: every pin mode it shows exists, on pins that can do
    it, and none clashes with another (the simulated boards keep the Uno's pin rules)."""
    code = python_example().replace(f'"{UNO_PORT}"', repr(sim_board.port))
    exec(compile(code, "README.md", "exec"), {"__name__": "readme"})
    out = capsys.readouterr().out
    assert "DeviceInfo(" in out  # print(board.info, board.stats) ran
    assert any(e["pin"] == 3 and e.get("mode") == "pwm" for e in sim_board.trace())
