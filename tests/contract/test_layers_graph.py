"""The import graph of host/ and dev/ flows one way; no firmware target reaches into tools/.

The Python layer order is declared once, below, bottom first (the firmware's is declared once
too, in tests/c/test_include_graph.py, which checks its include and call graphs). A module may
use its own layer and the layers beneath it, never one above; and no group of modules may use
each other in a circle, even within one layer. Every module must be in a layer, so a new one is
placed on purpose. The graph is read from the sources (``ast``), so it stays true as the code
changes; docs/architecture.md draws the same order.
"""

from __future__ import annotations

import ast
import fnmatch
import graphlib
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from protoduino.commands import PIN_MODES

ROOT = Path(__file__).resolve().parents[2]

#: Python, bottom first: (layer, module patterns). dev/ sits above the whole runtime: the
#: runtime finds the development tools by entry point (protoduino.plugins), never by import.
PYTHON_LAYERS: Sequence[tuple[str, Sequence[str]]] = (
    (
        "declarations",
        (
            "protoduino._generated*",
            "protoduino._version",
            "protoduino.constants",
            "protoduino.errors",
            "protoduino.clock",
            "protoduino.plugins",
            "protoduino.closing",
            "protoduino.toolrun",
            "protoduino.commands",
        ),
    ),
    (
        "wire",
        ("protoduino.packets", "protoduino._speedups", "protoduino.framing", "protoduino.messages"),
    ),
    (
        "io",
        (
            "protoduino.transport",
            "protoduino.events",
            "protoduino.flashing",
            "protoduino.simcontrol",
            "protoduino.programs",
        ),
    ),
    (
        "link",
        (
            "protoduino.link",
            "protoduino.capture",
            "protoduino.capturereader",
            "protoduino.capturefollow",
        ),
    ),
    ("session", ("protoduino.session",)),
    ("values", ("protoduino.arguments", "protoduino.readback")),
    ("requests", ("protoduino.rpc", "protoduino.inputs", "protoduino.userreports")),
    # Each pin mode's host code; the board composes them (none imports it).
    ("modes", ("protoduino.modes", "protoduino.modes.*")),
    (
        "api",
        (
            "protoduino.wiring",
            "protoduino.boardoptions",
            "protoduino.outputs",
            "protoduino.board",
            "protoduino.testing",
            "protoduino.aio",
            "protoduino.services",
            "protoduino.mcapexport",
            "protoduino.simboard",
            "protoduino",
        ),
    ),
    (
        "applications",
        (
            "protoduino.cli",
            "protoduino.cli.*",
            "protoduino.ros2",
            "protoduino.ros2.*",
            "protoduino.console",
            "protoduino.console.*",
            "protoduino.servicegen",
        ),
    ),
    ("development", ("protoduino_dev", "protoduino_dev.*")),
)


def layer_of(name: str, layers: Sequence[tuple[str, Sequence[str]]]) -> int | None:
    for index, (_, patterns) in enumerate(layers):
        if any(fnmatch.fnmatchcase(name, pattern) for pattern in patterns):
            return index
    return None


def python_modules() -> dict[str, Path]:
    """Every module of the runtime and the development tools, by dotted name."""
    found: dict[str, Path] = {}
    for base in (ROOT / "host", ROOT / "dev"):
        for package in ("protoduino", "protoduino_dev"):
            for path in (base / package).rglob("*.py") if (base / package).is_dir() else ():
                parts = path.relative_to(base).with_suffix("").parts
                name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
                found[name] = path
            for path in (base / package).rglob("*.pyi") if (base / package).is_dir() else ():
                # A C extension's stub stands for the module (_speedups).
                parts = path.relative_to(base).with_suffix("").parts
                found.setdefault(".".join(parts), path)
    return found


def python_imports(name: str, path: Path, known: Iterable[str]) -> set[str]:
    """The project modules ``name`` imports, anywhere in the file (a deferred import counts)."""
    known = set(known)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()

    def add(target: str) -> None:
        # The longest known module that TARGET names (a function imported from a module
        # counts as that module).
        while target and target not in known:
            target = target.rpartition(".")[0]
        if target and target != name:
            out.add(target)

    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                module = f"{base}.{node.module}" if node.module else base
            else:
                module = node.module or ""
            for alias in node.names:
                add(f"{module}.{alias.name}")
    return out


def firmware_modules() -> dict[str, list[Path]]:
    """Every C file of firmware/ grouped by stem (pd_link.c and pd_link.h are ``pd_link``)."""
    found: dict[str, list[Path]] = {}
    for path in sorted((ROOT / "firmware").rglob("*")):
        if path.suffix in (".c", ".h", ".ino") and "build" not in path.parts:
            stem = path.name.rsplit(".", 1)[0]
            found.setdefault(stem, []).append(path)
    return found


INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def violations(
    graph: Mapping[str, set[str]], layers: Sequence[tuple[str, Sequence[str]]]
) -> list[str]:
    """Each unplaced module, each use of a higher layer, and a cycle if there is one."""
    problems = []
    for name in sorted(graph):
        if layer_of(name, layers) is None:
            problems.append(f"{name} is in no layer: declare it in {Path(__file__).name}")
    for name, uses in sorted(graph.items()):
        mine = layer_of(name, layers)
        for used in sorted(uses):
            theirs = layer_of(used, layers)
            if mine is not None and theirs is not None and theirs > mine:
                problems.append(
                    f"{name} ({layers[mine][0]}) uses {used} ({layers[theirs][0]}), a higher layer"
                )
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        problems.append("cycle: " + " -> ".join(exc.args[1]))
    return problems


def python_graph() -> dict[str, set[str]]:
    modules = python_modules()
    return {name: python_imports(name, path, modules) for name, path in modules.items()}


def test_the_python_layers_flow_one_way() -> None:
    graph = python_graph()
    assert "protoduino.board" in graph and "protoduino_dev.build" in graph
    assert violations(graph, PYTHON_LAYERS) == []


def test_the_runtime_imports_no_development_tooling() -> None:
    # Said by the layers already; here by name, since it is the rule that matters most.
    graph = python_graph()
    runtime = {name: uses for name, uses in graph.items() if not name.startswith("protoduino_dev")}
    assert runtime and all(
        not used.startswith("protoduino_dev") for uses in runtime.values() for used in uses
    )


def test_firmware_targets_reach_nowhere_outside_firmware() -> None:
    """No firmware build includes from tools/ (the simulated board's control socket lives in
    firmware/simcontrol; the emulated Uno's runner in tools/avrsim includes it from there)."""
    makefile = (ROOT / "firmware" / "Makefile").read_text()
    assert "tools/simcontrol" not in makefile
    assert not re.search(r"-I\s*\$\(ROOT\)/tools", makefile)
    for paths in firmware_modules().values():
        for path in paths:
            assert "tools/" not in "".join(INCLUDE.findall(path.read_text(errors="replace")))


def test_the_checker_sees_an_upward_use_and_a_cycle() -> None:
    """The verdicts above can fail: a made-up graph with both faults is caught."""
    layers = (("low", ("a",)), ("high", ("b", "c")))
    assert violations({"a": {"b"}, "b": set(), "c": set()}, layers) == [
        "a (low) uses b (high), a higher layer"
    ]
    problems = violations({"a": set(), "b": {"c"}, "c": {"b"}}, layers)
    assert len(problems) == 1 and problems[0].startswith("cycle: ")
    assert violations({"a": set(), "x": set()}, layers)[0].startswith("x is in no layer")


def _init_members_used(path: Path) -> set[str]:
    """The pin modes' Init members (``msg.servo_init``, ...) that ``path``'s code touches."""
    inits = {mode.init for mode in PIN_MODES}
    tree = ast.parse(path.read_text(), str(path))
    return {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr in inits}


def test_each_pin_mode_is_one_module_that_the_board_composes() -> None:
    """Issue 36, item 5: each pin mode's host code (its Init's checks and message, the record
    a restore resends, its handle) is a module of its own, named as the schema declares the
    mode (``commands.PIN_MODES``); the board builds no mode's Init itself, and no mode module
    uses the board (the modes layer sits below it)."""
    modules = python_modules()
    graph = python_graph()
    for mode in PIN_MODES:
        name = f"protoduino.modes.{mode.name}"
        assert name in modules, f"pin mode {mode.name!r} has no module {name}"
        assert _init_members_used(modules[name]) == {mode.init}, name
        assert not any(used == "protoduino.board" for used in graph[name]), name
        assert "protoduino.modes." + mode.name in graph["protoduino.board"]
    assert _init_members_used(modules["protoduino.board"]) == set()
