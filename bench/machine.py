"""The facts about the machine and software a benchmark ran on, for the report's header."""

from __future__ import annotations

import datetime as dt
import importlib.metadata
import os
import platform
import subprocess
from collections.abc import Iterable
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo, else whatever ``platform`` knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def package_version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def git_commit(root: Path) -> str:
    """The checked-out commit; the tree may hold uncommitted work besides."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() or "unknown"


def protobuf_backend() -> str:
    try:
        from google.protobuf.internal import api_implementation
    except ImportError:  # pragma: no cover - protobuf is a dependency
        return "unknown"
    return str(api_implementation.Type())


def describe(root: Path, packages: Iterable[str]) -> list[tuple[str, str]]:
    """(what, value) rows: date, commit, CPU, OS, Python and the versions of ``packages``."""
    from protoduino.framing import ACCELERATED, COBS_NATIVE

    load = ", ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    rows = [
        ("date (UTC)", dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M")),
        ("commit", git_commit(root)),
        ("CPU", f"{cpu_model()}, {os.cpu_count()} logical cores"),
        ("load average at start", load),
        ("OS", platform.platform()),
        ("Python", f"{platform.python_implementation()} {platform.python_version()}"),
        ("protobuf backend", protobuf_backend()),
        ("cobs implementation", "C extension" if COBS_NATIVE else "pure-Python fallback"),
        (
            "protoduino stream decoder",
            "C accelerator (protoduino._speedups) built"
            if ACCELERATED
            else "pure Python only (protoduino._speedups not built)",
        ),
    ]
    seen: set[str] = set()
    for name in packages:
        if name.lower() in seen:
            continue
        seen.add(name.lower())
        rows.append((name, package_version(name)))
    return rows
