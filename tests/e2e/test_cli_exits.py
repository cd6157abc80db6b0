"""What the commands print and exit with when interrupted or given a wrong value (issue 20,
item 10): Ctrl-C on ``ping`` keeps ping(8)'s summary, Ctrl-C on ``demo`` ends cleanly, a
pin the device lacks or reserves is a bad value (2), ``flash`` refuses a file that is not
Intel hex before avrdude, ``ports --json`` is always one JSON array."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from protoduino.cli.main import main
from protoduino.simboard import SimBoard
from serial.tools import list_ports
from simfixtures import SIM_BACKENDS

#: Bounds a failing (hanging) command only.
HANG = 60.0


@pytest.fixture
def native(tmp_path: Path) -> Iterator[SimBoard]:
    with SimBoard("native", trace=tmp_path / "trace.jsonl") as sim:
        sim.start()
        yield sim


#: A shell's foreground job has SIGINT at its default even where the suite itself runs
#: with SIGINT ignored (started in the background by a non-interactive shell, or by a CI
#: runner): the command is exec'd with it reset, as the terminal would have it, so
#: Python installs its KeyboardInterrupt handler again.
DEFAULT_SIGINT = (
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"
)


def _interrupt_after(
    argv: list[str], marker: str, env: dict[str, str] | None = None
) -> tuple[int, str, str]:
    """Run the command in a process group of its own (as a shell's foreground job), and
    once a stdout line contains ``marker`` send SIGINT to the whole group, as Ctrl-C does."""
    proc = subprocess.Popen(
        [sys.executable, "-c", DEFAULT_SIGINT, "-m", "protoduino.cli.main", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
        env=None if env is None else {**os.environ, **env},
    )
    seen: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            seen.append(line)
            if marker in line:
                os.killpg(proc.pid, signal.SIGINT)
                break
        out, err = proc.communicate(timeout=HANG)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, "".join(seen) + out, err


def test_ctrl_c_on_ping_prints_the_summary(native: SimBoard) -> None:
    rc, out, err = _interrupt_after(["ping", native.port, "-c", "100000", "-i", "0.01"], "ping 3:")
    assert rc == 0, err  # every ping counted was answered, as ping(8) exits 0
    summary = re.search(r"--- .*: (\d+) sent, (\d+) answered, 0 lost \(interrupted\)", out)
    assert summary is not None, out
    sent, answered = int(summary[1]), int(summary[2])
    assert sent == answered >= 3
    assert "rtt min/avg/max/stddev = " in out
    assert "Traceback" not in err


def test_ctrl_c_on_demo_ends_cleanly(tmp_path: Path) -> None:
    rc, out, err = _interrupt_after(["demo"], "sweeping")
    assert rc == 130
    assert "interrupted: the Board is closed and the simulated board stopped" in out
    assert "disconnected" not in err and "multiple access" not in err, err
    started = re.search(r"\(pid (\d+)\)", out)
    assert started is not None, out
    assert _gone(int(started[1])), "the demo left its simulated board running"


def test_ctrl_c_on_watch_exits_130(sim_board: SimBoard) -> None:
    rc, out, err = _interrupt_after(["watch", sim_board.port, "2"], "pin 2 digital:")
    assert rc == 130, (out, err)
    assert "Traceback" not in err


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_ctrl_c_on_sim_exits_130(backend: str) -> None:
    rc, out, err = _interrupt_after(["sim", "--backend", backend], "/dev/")  # its port first
    assert rc == 130, (out, err)


def test_ctrl_c_on_ros2_exits_130() -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (needed to build the native board)")
    pytest.importorskip("cyclonedds", reason="cyclonedds (the ros2 extra) is missing")
    pytest.importorskip("rosbags.typesys", reason="rosbags is not installed")
    import test_ros2 as ros

    env = {"CYCLONEDDS_URI": ros.LOOPBACK, "ROS_DOMAIN_ID": str(ros.DOMAIN)}
    rc, out, err = _interrupt_after(["ros2", "--sim", "native"], "topics:", env)
    assert rc == 130, (out, err)
    assert "protoduino ros2: stopped" in err  # it stopped as on SIGTERM, the outputs safe


def _gone(pid: int) -> bool:
    """Exited: no such process, or a zombie waiting for its parent."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return True
    return state in ("Z", "X")


@pytest.mark.parametrize(
    ("argv", "why"),
    [
        (["servo", "{port}", "0", "45"], "pin 0 is reserved"),
        (["pin", "{port}", "1", "on"], "pin 1 is reserved"),
        (["servo", "{port}", "99", "45"], "pin 99 does not exist"),
        (["pwm", "{port}", "4", "100"], "pin 4 cannot be a pwm pin"),  # refused before sending
    ],
)
def test_a_pin_the_device_lacks_or_reserves_exits_2(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str], argv: list[str], why: str
) -> None:
    rc = main([a.format(port=sim_board.port) for a in argv])
    assert rc == 2
    assert why in capsys.readouterr().err


def test_flash_refuses_a_file_that_is_not_intel_hex_before_avrdude(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_avrdude(*args: object, **kwargs: object) -> None:
        raise AssertionError("avrdude ran")

    monkeypatch.setattr("protoduino.flashing.subprocess.Popen", no_avrdude)
    plain = tmp_path / "plain.txt"
    plain.write_text("these are notes, not firmware\n")
    assert main(["flash", "/dev/null", "--hex", str(plain)]) == 1  # /dev/null: a port that exists
    err = capsys.readouterr().err
    assert "is not an Intel hex file (line 1: a record starts with ':')" in err
    bad_sum = tmp_path / "bad.hex"
    bad_sum.write_text(":100000000C9434000C9446000C9446000C944600FF\n:00000001FF\n")
    assert main(["flash", "/dev/null", "--hex", str(bad_sum)]) == 1
    assert "line 1: bad checksum" in capsys.readouterr().err
    no_end = tmp_path / "cut.hex"
    no_end.write_text(":100000000C9434000C9446000C9446000C9446006A\n")
    assert main(["flash", "/dev/null", "--hex", str(no_end)]) == 1
    assert "no end-of-file record" in capsys.readouterr().err


def test_ports_json_is_an_array_even_with_no_port(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(list_ports, "comports", lambda: [])
    assert main(["ports", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == []
