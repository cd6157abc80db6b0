"""A bounded run of the structure-aware fuzz target (tests/c/fuzz_dispatch.c).

The harness frames every packet itself, so the fuzzer's mutations reach the
nanopb decoder, the dispatcher, the dedupe window, the outputs and the
failsafe rather than dying at the CRC check. ``make -C firmware
fuzz-dispatch-long`` runs it for 10 million executions; docs/reliability.md
records the long runs.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FUZZ_BIN = ROOT / "build" / "fuzz" / "pd_fuzz_dispatch"
FUZZ_SECONDS = 10


def _libfuzzer_available() -> bool:
    found = subprocess.run(
        ["clang", "-print-file-name=libclang_rt.fuzzer-x86_64.a"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return Path(found).is_absolute() and Path(found).is_file()


@pytest.mark.slow
def test_fuzz_dispatch_bounded(tmp_path: Path) -> None:
    for tool in ("make", "clang"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")
    if not _libfuzzer_available():
        pytest.skip("the libFuzzer runtime is not installed (Debian package libclang-rt-14-dev)")
    build = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "fuzz-dispatch"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    work = tmp_path / "corpus"
    work.mkdir()
    result = subprocess.run(
        [
            str(FUZZ_BIN),
            f"-max_total_time={FUZZ_SECONDS}",
            "-print_final_stats=1",
            f"-artifact_prefix={tmp_path}/",
            str(work),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=FUZZ_SECONDS * 3 + 60,
    )
    log = result.stderr[-6000:]
    runs = re.search(r"stat::number_of_executed_units:\s*(\d+)", result.stderr)
    assert result.returncode == 0, log
    assert runs is not None and int(runs.group(1)) > 5_000, log
    assert not list(tmp_path.glob("crash-*")) and not list(tmp_path.glob("leak-*")), log
    assert "ERROR:" not in result.stderr, log
