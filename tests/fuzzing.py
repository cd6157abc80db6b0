"""Bounded libFuzzer runs shared by the C fuzz-target tests."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest


def libfuzzer_available() -> bool:
    # clang prints the full path of a runtime it has, or just the name back.
    found = subprocess.run(
        ["clang", "-print-file-name=libclang_rt.fuzzer-x86_64.a"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return Path(found).is_absolute() and Path(found).is_file()


def require_fuzz_tools() -> None:
    """Skip, naming what is missing, where no fuzz target can be built."""
    for tool in ("make", "clang"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")
    if not libfuzzer_available():
        pytest.skip("the libFuzzer runtime is not installed (Debian package libclang-rt-14-dev)")


def run_bounded(
    binary: Path, seconds: int, tmp_path: Path, corpora: list[Path], min_runs: int
) -> int:
    """Run ``binary`` for ``seconds``; fail on any finding; return the executions.

    New inputs go to a fresh folder under ``tmp_path`` (listed first, so seed
    corpora stay as generated); crash and leak artifacts land in ``tmp_path``.
    """
    work = tmp_path / "corpus"
    work.mkdir()
    result = subprocess.run(
        [
            str(binary),
            f"-max_total_time={seconds}",
            "-print_final_stats=1",
            f"-artifact_prefix={tmp_path}/",
            str(work),
            *map(str, corpora),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=seconds * 3 + 60,
    )
    log = result.stderr[-6000:]
    runs = re.search(r"stat::number_of_executed_units:\s*(\d+)", result.stderr)
    assert result.returncode == 0, log
    assert runs is not None and int(runs.group(1)) > min_runs, log
    assert not list(tmp_path.glob("crash-*")) and not list(tmp_path.glob("leak-*")), log
    assert "ERROR:" not in result.stderr, log
    return int(runs.group(1))
