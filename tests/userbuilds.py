"""The user-service examples (examples/, docs/services.md), the C tests' probe service
(tests/c/user) and the trace tests' toggler (tests/e2e/toggler) built for both boards, and
their generated clients, for the tiers that run them (e2e, reliability)."""

from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
import threading
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
#: Services that are not in examples/: their folder (NAME.proto and NAME.c in it).
FOLDERS = {"probe": ROOT / "tests" / "c" / "user", "toggler": ROOT / "tests" / "e2e" / "toggler"}
#: Where `make ... USER_PROTO=examples/NAME/NAME.proto` puts a user build, per backend.
PROGRAMS = {"native": "sim/pd_sim", "avr": "avr/protoduino.elf"}
#: Tools each backend's build needs; a missing one skips the test.
NEEDS = {"native": ("make", "gcc"), "avr": ("make", "gcc", "avr-gcc")}
_built: set[str] = set()
_lock = threading.Lock()


def need(backend: str) -> None:
    for tool in NEEDS[backend]:
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (needed to build the {backend} board)")


def build_example(name: str) -> Path:
    """Build examples/NAME (or a folder of FOLDERS) for both boards (make caches it); its
    build folder."""
    need("avr")
    folder = FOLDERS.get(name, EXAMPLES / name)
    with _lock:
        if name not in _built:
            subprocess.run(
                [
                    "make",
                    "-s",
                    "-C",
                    str(ROOT / "firmware"),
                    "sim",
                    "avr",
                    f"USER_PROTO={folder / (name + '.proto')}",
                    f"USER_SRC={folder / (name + '.c')}",
                ],
                check=True,
                capture_output=True,
            )
            _built.add(name)
    return ROOT / "build" / "user" / name


def program(name: str, backend: str) -> Path:
    """examples/NAME's board program for ``backend`` (a SimBoard's ``firmware=``)."""
    return build_example(name) / PROGRAMS[backend]


def client(name: str, monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """The generated client module of examples/NAME (its messages are its ``pb``)."""
    gen = build_example(name) / "gen"
    monkeypatch.syspath_prepend(str(gen))
    for module in (f"{name}_client", f"{name}_pb2"):
        sys.modules.pop(module, None)
    return importlib.import_module(f"{name}_client")


def nested_proto(levels: int) -> str:
    """A .proto whose message Level<levels> nests ``levels`` levels of messages (Level1 has
    no message field), and message Empty; the caller adds the service."""
    lines = ['syntax = "proto3";', "", "message Level1 { uint32 value = 1; }"]
    lines += [
        f"message Level{n} {{ uint32 value = 1; Level{n - 1} down = 2; }}"
        for n in range(2, levels + 1)
    ]
    return "\n".join([*lines, "message Empty {}", ""])
