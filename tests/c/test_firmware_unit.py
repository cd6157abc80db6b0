"""The firmware's C unit tests under ASan/UBSan, a bounded libFuzzer run, and constants.

The C tests live in tests/c/ and are built and run by ``make -C firmware unit``
(which prints "N passed, M failed" last). The fuzz target feeds arbitrary bytes
through the whole receive path; here it runs for FUZZ_SECONDS, and for as long
as you like with ``make -C firmware fuzz-long`` (10 million runs by default).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from fuzzing import require_fuzz_tools, run_bounded

ROOT = Path(__file__).resolve().parents[2]
FIRMWARE = ROOT / "firmware"
FUZZ_BIN = ROOT / "build" / "fuzz" / "pd_fuzz"
FUZZ_CORPUS = ROOT / "build" / "fuzz" / "corpus"
FUZZ_SECONDS = 20
#: The C suite has this many tests or more; fewer means some were not run.
MIN_C_TESTS = 60
BUILD_TIMEOUT = 300


def _need(*tools: str) -> None:
    for tool in tools:
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")


def _make(target: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["make", "-s", "-C", str(FIRMWARE), target],
        capture_output=True,
        text=True,
        check=False,
        timeout=BUILD_TIMEOUT,
    )


@pytest.mark.parametrize(
    "target",
    [
        "unit",
        # Every C test again with the Mega build's capacities (core/pd_caps.h: 70
        # pins, 24 servos in 5 bits of owner slot, 6 timers, 6 PWM outputs): a ReadOutputs
        # answer of 24 servos, past 127 B, byte for byte as pb_encode writes it.
        "unit-mega",
    ],
)
def test_c_unit_tests_under_sanitizers(target: str) -> None:
    _need("make", "gcc")
    result = _make(target)
    output = result.stdout + result.stderr
    summary = re.findall(r"^(\d+) passed, (\d+) failed$", result.stdout, re.MULTILINE)
    assert summary, f"no test summary from `make -C firmware {target}`:\n{output[-4000:]}"
    passed, failed = (int(n) for n in summary[-1])
    assert result.returncode == 0 and failed == 0, output[-4000:]
    assert passed >= MIN_C_TESTS, output[-4000:]
    assert "runtime error" not in output  # UBSan reports without aborting otherwise


def test_c_unit_tests_with_a_user_service() -> None:
    """Every C test again with PD_FEATURE_USER and the probe service (tests/c/user), plus
    the user-service tests (tests/c/test_user.c): the mechanism under the sanitizers."""
    _need("make", "gcc")
    result = _make("unit-user")
    output = result.stdout + result.stderr
    summary = re.findall(r"^(\d+) passed, (\d+) failed$", result.stdout, re.MULTILINE)
    assert summary, f"no test summary from `make -C firmware unit-user`:\n{output[-4000:]}"
    passed, failed = (int(n) for n in summary[-1])
    assert result.returncode == 0 and failed == 0, output[-4000:]
    assert passed >= MIN_C_TESTS + 8, output[-4000:]
    assert "runtime error" not in output


@pytest.mark.slow
def test_fuzz_receive_path_bounded(tmp_path: Path) -> None:
    require_fuzz_tools()
    build = _make("fuzz")
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    seeds = sorted(FUZZ_CORPUS.iterdir())
    assert len(seeds) > 20, "the seed corpus was not generated"
    run_bounded(FUZZ_BIN, FUZZ_SECONDS, tmp_path, [FUZZ_CORPUS], min_runs=10_000)
