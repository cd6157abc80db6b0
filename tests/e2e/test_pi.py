"""The Raspberry Pi's wheel in the suite (issue 38): aarch64, installed and driven under qemu.

``tools/build_wheels.sh`` builds the release wheels (cp311-abi3, manylinux, x86_64, aarch64
and armv7l), and each must carry what its native parts link. The aarch64 one is installed with pip
into a venv inside a fresh arm64 Debian 12 tree (``tools/arm64_tree.sh run``: Python 3.11 and
nothing else, as on Raspberry Pi OS bookworm; no libjansson, no simavr); what it installed also
runs on trixie's Python 3.13 (Debian 13, Raspberry Pi OS trixie). Its programs run under
qemu-user with a Pi 4's CPU (``QEMU_CPU=cortex-a72``) through binfmt_misc. There, arm64
Python drives both boards the wheel carries, through the API and through the CLI, and each is
judged at the pin by the board's trace. Every command runs in the tree (chroot) in a private
mount namespace holding /dev and /proc (``tools/arm64_run.sh``), so nothing is left mounted
however the test ends.
pip fetches the wheel's declared dependencies from PyPI (the versions of constraints.txt).
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import time
import zipfile
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
#: What a wheel's programs may link without carrying it: glibc's and zlib (Debian's
#: Priority: required, in every system), the manylinux policy's own list minus the rest.
SYSTEM_LIBRARIES = {"libc.so.6", "libm.so.6", "libz.so.1"}
#: Each wheel's machine: its ELF machine type.
MACHINES = {"x86_64": "EM_X86_64", "aarch64": "EM_AARCH64", "armv7l": "EM_ARM"}


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
        "debootstrap",
        "aarch64-linux-gnu-gcc",
        "arm-linux-gnueabihf-gcc",
        "qemu-aarch64-static",
        "unshare",
        "avr-gcc",
    )
    if missing is not None:
        return f"{missing} is not installed"
    if not (ROOT / ".deps" / "nanopb" / "pb_decode.c").exists():
        return "the nanopb C runtime (./tools/dev.sh setup fetches it) is not installed"
    return _binfmt_problem()


@dataclass(frozen=True)
class Pi:
    """A fresh arm64 tree with the wheel installed in its venv ``VENV``.

    ``pip_cache`` (below .deps/, per Debian release) is the tree's pip cache: the downloads and
    the wheel pip builds from cobs' sdist are kept between runs, as on a Pi installed twice.
    """

    tree: Path
    pip_cache: Path
    #: The CPU qemu emulates: a Pi 4's by default; qemu-arm (32-bit) has no cortex-a72.
    cpu: str = "cortex-a72"

    def wrap(self, *args: str) -> list[str]:
        """``args`` run in the tree (tools/arm64_run.sh: a signal reaches the program)."""
        return [str(ROOT / "tools" / "arm64_run.sh"), str(self.tree), str(self.pip_cache), *args]

    def run(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            self.wrap(*args),
            capture_output=True,
            text=True,
            timeout=COMMAND_TIMEOUT,
            check=False,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "QEMU_CPU": self.cpu},
        )

    def inside(self, path: str) -> Path:
        """The host's path of the tree's ``path``."""
        return self.tree / path.lstrip("/")


@pytest.fixture(scope="module")
def wheels(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Machine -> its release wheel, as tools/build_wheels.sh makes them."""
    reason = _skip_reason()
    if reason is not None:
        pytest.skip(reason)
    dist = tmp_path_factory.mktemp("dist")
    result = subprocess.run(
        [str(ROOT / "tools" / "build_wheels.sh"), str(dist)],
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    found = {
        arch: list(dist.glob(f"protoduino-*-cp311-abi3-manylinux_*_{arch}.whl"))
        for arch in MACHINES
    }
    assert all(len(paths) == 1 for paths in found.values()), sorted(dist.iterdir())
    return {arch: paths[0] for arch, paths in found.items()}


@pytest.mark.parametrize("arch", sorted(MACHINES))
def test_each_wheel_carries_what_its_native_parts_link(
    wheels: dict[str, Path], arch: str, tmp_path: Path
) -> None:
    from elftools.elf.dynamic import DynamicSection
    from elftools.elf.elffile import ELFFile

    with zipfile.ZipFile(wheels[arch]) as archive:
        archive.extractall(tmp_path)
    carried = {p.name for p in (tmp_path / "protoduino.libs").iterdir()}
    native = [
        path
        for path in tmp_path.rglob("*")
        if path.is_file() and path.read_bytes()[:4] == b"\x7fELF" and path.suffix != ".elf"
    ]
    # The two programs, the extension and what they carry (libjansson, libsimavr, libelf).
    assert {"pd_sim", "avrsim"} <= {p.name for p in native}, native
    assert any(p.name.startswith("_speedups.abi3") for p in native), native
    assert any(name.startswith("libjansson") for name in carried), carried
    for path in native:
        with path.open("rb") as stream:
            elf = ELFFile(stream)
            assert elf["e_machine"] == MACHINES[arch]
            needed = {
                tag.needed  # type: ignore[attr-defined]  # set per tag kind by pyelftools
                for section in elf.iter_sections()
                if isinstance(section, DynamicSection)
                for tag in section.iter_tags("DT_NEEDED")
            }
        assert {n for n in needed - carried if not n.startswith("ld-linux")} <= SYSTEM_LIBRARIES, (
            path,
            needed,
        )


def _fresh_tree(suite: str, tmp: Path, arch: str = "arm64") -> Path:
    """A copy of the cached tree of ``suite`` (Debian ``arch``), with the host's DNS and CAs."""
    cached = subprocess.run(
        [str(ROOT / "tools" / "arm64_tree.sh"), "run", suite],
        check=True,
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
        env={**os.environ, "ARCH": arch},
    ).stdout.strip()
    tree = tmp / "tree"
    subprocess.run(["cp", "-a", cached, str(tree)], check=True, timeout=BUILD_TIMEOUT)
    # pip reaches PyPI with the host's name service and certificate authorities.
    shutil.copy("/etc/resolv.conf", tree / "etc" / "resolv.conf")
    (tree / "etc" / "ssl" / "certs").mkdir(parents=True, exist_ok=True)
    shutil.copy("/etc/ssl/certs/ca-certificates.crt", tree / "etc/ssl/certs/ca-certificates.crt")
    (tree / "work").mkdir()
    return tree


def _pip_cache(name: str) -> Path:
    path = ROOT / ".deps" / "arm64" / f"pip-cache-{name}"
    path.mkdir(parents=True, exist_ok=True)
    return path


def _install(tree: Path, wheel: Path, pip_cache: Path, cpu: str = "cortex-a72") -> Pi:
    """``wheel`` pip-installed with its declared dependencies in a new venv in ``tree``."""
    shutil.copy(wheel, tree / "tmp" / wheel.name)
    shutil.copy(ROOT / "constraints.txt", tree / "tmp" / "constraints.txt")
    installed = Pi(tree, pip_cache, cpu)
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
    return installed


@pytest.fixture(scope="module")
def pi(wheels: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Iterator[Pi]:
    """Raspberry Pi OS bookworm's Python 3.11 with the wheel pip-installed in a venv."""
    tree = _fresh_tree("bookworm", tmp_path_factory.mktemp("pi"))
    yield _install(tree, wheels["aarch64"], _pip_cache("bookworm"))
    shutil.rmtree(tree, ignore_errors=True)  # 250 MB


def test_the_tree_is_a_bare_arm64_python_with_the_c_decoder(pi: Pi) -> None:
    result = pi.run(
        f"{VENV}/bin/python",
        "-c",
        "import json, platform, sys\n"
        "from protoduino import framing\n"
        "print(json.dumps([platform.machine(), sys.version_info[:2], "
        "framing.StreamDecoder.__module__]))",
    )
    assert result.returncode == 0, result.stdout + result.stderr
    machine, version, decoder = json.loads(result.stdout)
    assert machine == "aarch64"
    assert tuple(version) == (3, 11)
    assert decoder == "protoduino._speedups"  # the wheel's C accelerator loads on this Python
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


def test_the_installed_wheel_runs_on_trixies_python_3_13(
    pi: Pi, wheels: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
) -> None:
    """Raspberry Pi OS trixie (Debian 13) ships Python 3.13: the cp311-abi3 wheel serves it.

    pip's own acceptance is its tag rule (checked with packaging, as pip does). What the wheel
    installed runs there: the bookworm venv's packages (the wheel and its dependencies, all
    pure Python or abi3) on trixie's Python 3.13, without pip (creating a venv and installing
    under qemu takes trixie's Python several minutes, too long for the suite); the C decoder
    loads, and the simulated board is driven through the API, judged at its pin.
    """
    from packaging.tags import cpython_tags
    from packaging.utils import parse_wheel_filename

    # Debian 13's glibc is 2.41: every manylinux_2_x up to it.
    platforms = [f"manylinux_2_{minor}_aarch64" for minor in range(41, 16, -1)]
    supported = set(cpython_tags(python_version=(3, 13), abis=["cp313"], platforms=platforms))
    assert parse_wheel_filename(wheels["aarch64"].name)[3] & supported

    tree = _fresh_tree("trixie", tmp_path_factory.mktemp("trixie"))
    try:
        shutil.copytree(
            pi.inside(f"{VENV}/lib/python3.11/site-packages"), tree / "opt" / "site", symlinks=True
        )
        trixie = Pi(tree, _pip_cache("trixie"))
        trace = "/work/api-native.jsonl"
        check = (
            "import json, sys\n"
            "from protoduino import framing\n"
            "print(json.dumps([sys.version_info[:2], framing.StreamDecoder.__module__]))\n"
        )
        result = trixie.run("env", "PYTHONPATH=/opt/site", "python3", "-c", check)
        assert result.returncode == 0, result.stdout + result.stderr
        version, decoder = json.loads(result.stdout)
        assert tuple(version) == (3, 13) and decoder == "protoduino._speedups"
        result = trixie.run(
            "env", "PYTHONPATH=/opt/site", "python3", "-c", API_SCRIPT, "native", trace
        )
        assert result.returncode == 0, result.stdout + result.stderr
        _wait_for(trixie.inside(trace), 9, 2000, tolerance=0, timeout=1.0)  # already written
    finally:
        shutil.rmtree(tree, ignore_errors=True)


def test_the_armv7l_wheel_drives_both_boards_on_32_bit_pi_os(
    wheels: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
) -> None:
    """32-bit Raspberry Pi OS (armhf, bookworm): the armv7l wheel installed and driven alike."""
    if not (BINFMT / "qemu-arm").exists():
        subprocess.run(["update-binfmts", "--enable", "qemu-arm"], capture_output=True, check=False)
    if not (BINFMT / "qemu-arm").exists():
        pytest.skip("qemu-arm is not registered in binfmt_misc (update-binfmts failed)")
    tree = _fresh_tree("bookworm", tmp_path_factory.mktemp("armhf"), arch="armhf")
    try:
        # A Pi 2's CPU (a Pi 3 or 4 runs 32-bit Raspberry Pi OS in its 32-bit mode alike).
        armhf = _install(tree, wheels["armv7l"], _pip_cache("armhf-bookworm"), "cortex-a7")
        result = armhf.run(
            "python",
            "-c",
            "import platform; from protoduino import framing; "
            "print(platform.machine(), framing.StreamDecoder.__module__)",
        )
        assert result.stdout.split() == ["armv7l", "protoduino._speedups"], result.stderr
        for backend in ("native", "avr"):
            trace = f"/work/api-{backend}.jsonl"
            result = armhf.run("python", "-c", API_SCRIPT, backend, trace)
            assert result.returncode == 0, result.stdout + result.stderr
            _wait_for(armhf.inside(trace), 9, 2000, tolerance=3, timeout=1.0)  # already written
    finally:
        shutil.rmtree(tree, ignore_errors=True)
