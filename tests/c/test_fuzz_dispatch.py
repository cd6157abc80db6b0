"""A bounded run of the structure-aware fuzz target (tests/c/fuzz_dispatch.c).

The harness frames every packet itself, so the fuzzer's mutations reach the
nanopb decoder, the dispatcher, the dedupe window, the outputs and the
failsafe rather than dying at the CRC check. ``make -C firmware
fuzz-dispatch-long`` runs it for 10 million executions; docs/reliability.md
records the long runs.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from fuzzing import require_fuzz_tools, run_bounded

ROOT = Path(__file__).resolve().parents[2]
FUZZ_BIN = ROOT / "build" / "fuzz" / "pd_fuzz_dispatch"
FUZZ_USER_BIN = ROOT / "build" / "fuzz" / "pd_fuzz_dispatch_user"
FUZZ_SECONDS = 10


@pytest.mark.slow
def test_fuzz_dispatch_bounded(tmp_path: Path) -> None:
    require_fuzz_tools()
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "fuzz-dispatch"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    run_bounded(FUZZ_BIN, FUZZ_SECONDS, tmp_path, [], min_runs=5_000)


@pytest.mark.slow
def test_fuzz_dispatch_with_a_user_service_bounded(tmp_path: Path) -> None:
    """The same with the probe user service built in (``make -C firmware fuzz-dispatch-user``)."""
    require_fuzz_tools()
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "fuzz-dispatch-user"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    run_bounded(FUZZ_USER_BIN, FUZZ_SECONDS, tmp_path, [], min_runs=5_000)
