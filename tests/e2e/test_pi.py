"""The Raspberry Pi's wheel in the suite (issue 38): aarch64, installed and driven under qemu.

``tools/build_wheels.sh`` cross-builds the manylinux aarch64 wheel. It is installed with pip
into a venv inside a fresh arm64 Debian 12 tree (``tools/arm64_tree.sh run``: Python 3.11 and
nothing else, as on Raspberry Pi OS bookworm; no libjansson, no simavr), whose programs run
under qemu-user with a Pi 4's CPU (``QEMU_CPU=cortex-a72``) through binfmt_misc. There, arm64
Python drives both boards the wheel carries, through the API and through the CLI, and each is
judged at the pin by the board's trace. Every command runs in the tree (chroot) in a private
mount namespace holding /dev and /proc, so nothing is left mounted however the test ends.
pip fetches the wheel's declared dependencies from PyPI (the versions of constraints.txt).
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from boardprocess import BoardProcess, missing_tool

pytestmark = [pytest.mark.slow, pytest.mark.avr]

ROOT = Path(__file__).resolve().parents[2]
#: Upper bounds only (a build, a pip install under qemu, a start): nothing is judged by them.
BUILD_TIMEOUT = 900.0
COMMAND_TIMEOUT = 300.0
BINFMT = Path("/proc/sys/fs/binfmt_misc")
VENV = "/opt/protoduino"


def _binfmt_problem() -> str | None:
    """None when aarch64 programs run through qemu, else why not (mounting it if needed)."""
    if not (BINFMT / "register").exists():
        result = subprocess.run(
            ["mount", "-t", "binfmt_misc", "binfmt_misc", str(BINFMT)],
            capture_output=True,
            text=True,
            check=False,
        )
        if result.returncode != 0:
            return f"binfmt_misc cannot be mounted here: {result.stderr.strip()}"
    if not (BINFMT / "qemu-aarch64").exists():
        subprocess.run(
            ["update-binfmts", "--enable", "qemu-aarch64"], capture_output=True, check=False
        )
    if not (BINFMT / "qemu-aarch64").exists():
        return "qemu-aarch64 is not registered in binfmt_misc (update-binfmts failed)"
    return None


def _skip_reason() -> str | None:
    if platform.machine() != "x86_64":
        return "the aarch64 wheel is cross-built on x86_64 (this machine is not)"
    if os.geteuid() != 0:
        return "root (chroot into the arm64 tree, binfmt_misc)"
    missing = missing_tool(
        "debootstrap", "aarch64-linux-gnu-gcc", "qemu-aarch64-static", "unshare", "avr-gcc"
    )
    if missing is not None:
        return f"{missing} is not installed"
    if not (ROOT / ".deps" / "nanopb" / "pb_decode.c").exists():
        return "the nanopb C runtime (./tools/dev.sh setup fetches it) is not installed"
    return _binfmt_problem()


@dataclass(frozen=True)
class Pi:
    """A fresh arm64 tree with the wheel installed in its venv ``VENV``."""

    tree: Path

    def wrap(self, *args: str) -> list[str]:
        """``args`` run in the tree, exec'd all the way (a signal reaches the program)."""
        script = (
            'mount --rbind /dev "$0/dev" && mount -t proc proc "$0/proc" && '
            'exec chroot "$0" /usr/bin/env -i PATH=' + VENV + '/bin:/usr/bin:/bin HOME=/root "$@"'
        )
        return ["unshare", "--mount", "sh", "-c", script, str(self.tree), *args]

    def run(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            self.wrap(*args),
            capture_output=True,
            text=True,
            timeout=COMMAND_TIMEOUT,
            check=False,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "QEMU_CPU": "cortex-a72"},
        )

    def inside(self, path: str) -> Path:
        """The host's path of the tree's ``path``."""
        return self.tree / path.lstrip("/")


@pytest.fixture(scope="module")
def pi(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Pi]:
    reason = _skip_reason()
    if reason is not None:
        pytest.skip(reason)
    tmp = tmp_path_factory.mktemp("pi")
    subprocess.run(
        [str(ROOT / "tools" / "build_wheels.sh"), str(tmp / "dist"), "aarch64"],
        check=True,
        capture_output=True,
        timeout=BUILD_TIMEOUT,
    )
    (wheel,) = (tmp / "dist").glob("protoduino-*-manylinux_*_aarch64.whl")
    cached = subprocess.run(
        [str(ROOT / "tools" / "arm64_tree.sh"), "run"],
        check=True,
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
    ).stdout.strip()
    tree = tmp / "tree"
    subprocess.run(["cp", "-a", cached, str(tree)], check=True, timeout=BUILD_TIMEOUT)
    # pip reaches PyPI with the host's name service and certificate authorities.
    shutil.copy("/etc/resolv.conf", tree / "etc" / "resolv.conf")
    (tree / "etc" / "ssl" / "certs").mkdir(parents=True, exist_ok=True)
    shutil.copy("/etc/ssl/certs/ca-certificates.crt", tree / "etc/ssl/certs/ca-certificates.crt")
    shutil.copy(wheel, tree / "tmp" / wheel.name)
    shutil.copy(ROOT / "constraints.txt", tree / "tmp" / "constraints.txt")
    (tree / "work").mkdir()
    installed = Pi(tree)
    for step in (
        ("/usr/bin/python3", "-m", "venv", VENV),
        (
            f"{VENV}/bin/pip",
            "install",
            "-q",
            "--disable-pip-version-check",
            "--cert",
            "/etc/ssl/certs/ca-certificates.crt",
            "-c",
            "/tmp/constraints.txt",
            f"/tmp/{wheel.name}",
        ),
    ):
        result = installed.run(*step)
        assert result.returncode == 0, result.stdout + result.stderr
    yield installed
    shutil.rmtree(tree, ignore_errors=True)  # 250 MB


def test_the_tree_is_a_bare_arm64_python(pi: Pi) -> None:
    result = pi.run("python3", "-c", "import platform; print(platform.machine())")
    assert result.stdout.strip() == "aarch64", result.stdout + result.stderr
    # What the wheel's programs link is theirs: the tree has none of it.
    libs = pi.inside("/usr/lib/aarch64-linux-gnu")
    assert not [p.name for p in libs.glob("lib*") if p.name.startswith(("libjansson", "libsimavr"))]


def _wait_for(trace: Path, pin: int, value: int, tolerance: int, timeout: float = 60.0) -> None:
    """Until the trace shows ``pin`` at ``value``; the timeout only bounds a failure."""
    deadline = time.monotonic() + timeout
    seen: list[int] = []
    while time.monotonic() < deadline:
        lines = trace.read_text().splitlines() if trace.exists() else []
        seen = [int(json.loads(x)["value"]) for x in lines if json.loads(x)["pin"] == pin]
        if any(abs(v - value) <= tolerance for v in seen):
            return
        time.sleep(0.1)
    raise AssertionError(f"pin {pin} never reached {value}: the trace shows {seen}")


API_SCRIPT = """
import json, sys, time
import protoduino
from protoduino.simboard import SimBoard

backend, trace = sys.argv[1], sys.argv[2]
with SimBoard(backend, trace=trace) as sim:
    with protoduino.Board.open(sim.start()) as board:
        board.servo(9, safe=90).write_us(2000)
        deadline = time.monotonic() + 60  # bounds a failure only: the test reads the trace
        while time.monotonic() < deadline:
            if any(c["pin"] == 9 and abs(c["value"] - 2000) <= 3 for c in sim.trace()):
                break
            time.sleep(0.05)
        print(json.dumps({"schema_id": board.info.schema_id}))
"""


@pytest.mark.parametrize("backend", ["native", "avr"])
def test_the_api_drives_the_boards_the_wheel_carries(pi: Pi, backend: str) -> None:
    import protoduino

    trace = f"/work/api-{backend}.jsonl"
    result = pi.run(f"{VENV}/bin/python", "-c", API_SCRIPT, backend, trace)
    assert result.returncode == 0, result.stdout + result.stderr
    assert json.loads(result.stdout)["schema_id"] == protoduino.SCHEMA_ID
    _wait_for(pi.inside(trace), 9, 2000, tolerance=3, timeout=1.0)  # already written


@pytest.fixture(params=["native", "avr"])
def sim(pi: Pi, request: pytest.FixtureRequest) -> Iterator[tuple[BoardProcess, Path]]:
    trace = f"/work/cli-{request.param}.jsonl"
    process = BoardProcess(
        pi.wrap("protoduino", "sim", "--backend", request.param, "--trace", trace),
        startup=COMMAND_TIMEOUT,
        what="protoduino sim under qemu",
        owned=False,
        env={**os.environ, "QEMU_CPU": "cortex-a72"},
        stderr=subprocess.PIPE,
    )
    yield process, pi.inside(trace)
    process.stop(strict=False)


def test_the_cli_drives_the_boards_the_wheel_carries(
    pi: Pi, sim: tuple[BoardProcess, Path]
) -> None:
    process, trace = sim
    result = pi.run("protoduino", "servo", process.port, "9", "2000", "--us")
    assert result.returncode == 0, result.stdout + result.stderr
    _wait_for(trace, 9, 2000, tolerance=3)
