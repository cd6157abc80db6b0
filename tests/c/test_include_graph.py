"""The firmware flows one way: its include graph and its call graph go only down the layers.

``LAYERS`` is the firmware's layer order, declared once, lowest first (docs/architecture.md
draws it). Every file of ``firmware/`` belongs to exactly one layer: a module (``pd_link``: its
``.h`` and ``.c``) or, where its data sits lower than its code, one file (``pd_inputs.h``: the
inputs' state is part of the device value, ``pd_inputs.c`` acts on the whole device). A file may
include, and call what is defined in, its own layer or a lower one, and the graph of files has no
cycle: so a received byte goes up from the HAL through the codecs and the link to the core, which
alone decides what runs, and every call from there goes down again.

The includes are read from the sources (``#include "..."``); the calls come from the compiler
(GCC's ``-fcallgraph-info``, one graph per translation unit of ``firmware/core``), each callee
placed in the file that defines it (a ``.c``, or the header of a ``static inline``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FIRMWARE = ROOT / "firmware"
NANOPB = ROOT / ".deps" / "nanopb"

#: The firmware's layers, lowest first. A name without a suffix is a module (its .h and .c); a
#: name with one is that file alone; a name ending in "/" is every file of that folder.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "boundary and generated",
        (
            "pd_hal.h",
            "pd_pinset.h",
            "pd_rom.h",
            "pd_features.h",
            "pd_caps.h",
            "pd_config.h",
            "generated/",
        ),
    ),
    ("codecs", ("pd_crc", "pd_cobs", "pd_packet", "pd_encode")),
    ("link", ("pd_link",)),
    (
        "device parts",
        (
            "pd_failsafe",
            "pd_pintable",  # the pin table, below every mode (pd_pintable.h)
            "pd_servo",  # the output modes, each one unit
            "pd_digital",
            "pd_pwm",
            "pd_outputs",
            "pd_inputs.h",
            "pd_inputs_state.c",
            "pd_dedupe",
            "pd_user.h",  # the user service's table and state (docs/services.md)
        ),
    ),
    ("device state", ("pd_state.h",)),
    ("outgoing messages", ("pd_out",)),
    (
        "commands and inputs",
        (
            "pd_dispatch",
            "pd_inputs.c",  # the inputs' poll and report, above the input modes
            "pd_input_modes",  # what the input modes share, below them
            "pd_digital_input.c",  # the input modes, each one file (pd_input_modes.h)
            "pd_analog_input.c",
            "pd_counter.c",
            "pd_user.c",
        ),
    ),
    ("core", ("pd_core",)),
    # ramsizes/: not firmware, the Uno build's sizes of the core's parts (firmware/Makefile).
    ("platforms", ("posix/", "simcontrol/", "avr/", "arduino/", "ramsizes/")),
)

SOURCE_SUFFIXES = (".c", ".h", ".ino")
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)
#: -fcallgraph-info's VCG: nodes carry "name\nfile:line:col", edges name their ends by title.
NODE = re.compile(r'node: \{ title: "([^"]+)" label: "([^"\\]+)\\n([^":]+):\d+:\d+"')
EDGE = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')


def layer_table(
    layers: tuple[tuple[str, tuple[str, ...]], ...], files: Iterable[str]
) -> dict[str, int]:
    """Each file (relative to firmware/) to its layer's index; raises if one has none or two."""
    table: dict[str, int] = {}
    for rel in sorted(files):
        name = Path(rel).name
        stem = Path(rel).stem
        # The most specific name wins: a file, then its module, then its folder.
        found: list[tuple[int, int]] = []
        for index, (_title, names) in enumerate(layers):
            for entry in names:
                if entry == name:
                    found.append((0, index))
                elif "." not in entry and not entry.endswith("/") and entry == stem:
                    found.append((1, index))
                elif entry.endswith("/") and rel.startswith(entry):
                    found.append((2, index))
        if not found:
            raise AssertionError(f"firmware/{rel} is in no layer: add it to LAYERS")
        found.sort()
        if len(found) > 1 and found[0][0] == found[1][0] and found[0][1] != found[1][1]:
            raise AssertionError(f"firmware/{rel} is in two layers")
        table[rel] = found[0][1]
    return table


def violations(edges: Iterable[tuple[str, str, str]], layer_of: Mapping[str, int]) -> list[str]:
    """Edges (from, to, what) that go up a layer, and the cycles among files."""
    found = []
    graph: dict[str, set[str]] = {}
    for src, dst, what in edges:
        if src == dst:
            continue
        graph.setdefault(src, set()).add(dst)
        if layer_of[dst] > layer_of[src]:
            found.append(
                f"{src} ({LAYERS[layer_of[src]][0]}) -> {dst} ({LAYERS[layer_of[dst]][0]}): {what}"
            )
    # Depth-first search for a back edge: a cycle, even within one layer.
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                found.append("cycle: " + " -> ".join([*path[path.index(nxt) :], nxt]))
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    return found


def firmware_files() -> list[str]:
    return sorted(
        str(p.relative_to(FIRMWARE))
        for p in FIRMWARE.rglob("*")
        if p.suffix in SOURCE_SUFFIXES and p.is_file()
    )


def include_edges(files: list[str]) -> tuple[list[tuple[str, str, str]], list[str]]:
    """Quoted includes resolved within firmware/: the including folder, core/, generated/, or
    the one file of that name (the Arduino library's flat src/ holds core's pd_config.h); and
    the ones a core or generated file makes to anything else (it must make none)."""
    by_name: dict[str, list[str]] = {}
    for rel in files:
        by_name.setdefault(Path(rel).name, []).append(rel)
    edges = []
    outside = []
    for rel in files:
        text = (FIRMWARE / rel).read_text(encoding="utf-8")
        for header in INCLUDE.findall(text):
            here = str(Path(rel).parent / header)
            candidates = [here] if here in files else []
            candidates += [
                f"{d}/{header}" for d in ("core", "generated") if f"{d}/{header}" in files
            ]
            if not candidates and len(by_name.get(header, [])) == 1:
                candidates = by_name[header]
            if candidates:
                edges.append((rel, candidates[0], f'#include "{header}"'))
            elif rel.startswith(("core/", "generated/")):
                outside.append(f'{rel}: #include "{header}"')
    return edges, outside


def call_edges(
    tmp: Path, files: list[str], defines: tuple[str, ...] = ()
) -> list[tuple[str, str, str]]:
    """Calls between firmware files, from GCC's call graph of every core translation unit
    (built with `defines`, such as a feature's switch: ``-DPD_FEATURE_USER=1``)."""
    sources = [rel for rel in files if rel.startswith("core/") and rel.endswith(".c")]
    defined: dict[str, str] = {}  # node title -> the file that defines it
    graphs: list[str] = []
    for rel in sources:
        out = tmp / (Path(rel).stem + ".o")
        subprocess.run(
            [
                "gcc", "-std=c99", "-O0", "-fcallgraph-info", "-c",
                f"-I{FIRMWARE / 'core'}", f"-I{FIRMWARE / 'generated'}", f"-I{NANOPB}",
                *defines, "-o", str(out), str(FIRMWARE / rel),
            ],
            check=True, capture_output=True, text=True, timeout=120, cwd=tmp,
        )  # fmt: skip
        text = out.with_suffix(".ci").read_text(encoding="utf-8")
        graphs.append(text)
        for line in text.splitlines():
            node = NODE.search(line)
            if node and "shape" not in line:  # defined here (declared-only nodes are ellipses)
                defined[node.group(1)] = node.group(3)
    edges = []
    for text in graphs:
        for src, dst in EDGE.findall(text):
            if src in defined and dst in defined:
                caller = str(Path(defined[src]).resolve().relative_to(FIRMWARE))
                callee = str(Path(defined[dst]).resolve().relative_to(FIRMWARE))
                edges.append((caller, callee, f"{src.split(':')[-1]} calls {dst.split(':')[-1]}"))
    return edges


def test_the_layer_check_finds_an_upward_edge_and_a_cycle() -> None:
    """The checker itself: it must be able to fail (the link calling the core, as it used to)."""
    layer_of = layer_table(LAYERS, ["core/pd_link.c", "core/pd_core.c", "core/pd_cobs.h"])
    assert violations([("core/pd_core.c", "core/pd_link.c", "")], layer_of) == []
    found = violations(
        [("core/pd_core.c", "core/pd_link.c", ""), ("core/pd_link.c", "core/pd_core.c", "x")],
        layer_of,
    )
    assert any(v.startswith("core/pd_link.c (link) -> core/pd_core.c (core)") for v in found)
    assert any(v.startswith("cycle: ") for v in found)
    with pytest.raises(AssertionError, match="in no layer"):
        layer_table(LAYERS, ["core/pd_new.c"])


def test_includes_go_only_down() -> None:
    files = firmware_files()
    layer_of = layer_table(LAYERS, files)
    edges, outside = include_edges(files)
    assert len(edges) > 40, edges  # the sources were read
    assert outside == [], "core and generated files include only each other"
    assert violations(edges, layer_of) == []


def test_calls_go_only_down(tmp_path: Path) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    if not (NANOPB / "pb.h").is_file():
        pytest.skip("the nanopb runtime is not fetched (./tools/dev.sh setup)")
    files = firmware_files()
    layer_of = layer_table(LAYERS, files)
    edges = call_edges(tmp_path, files)
    # The receive path as the core drives it: found, so the graph is the real one.
    assert ("core/pd_core.c", "core/pd_link.c", "pd_core_rx_byte calls pd_link_rx_byte") in edges
    assert (
        "core/pd_core.c",
        "core/pd_dispatch.c",
        "pd_core_rx_byte calls pd_dispatch_command",
    ) in edges
    assert violations(edges, layer_of) == []


def module_of(rel: str) -> str:
    """A file's module: a .c and the .h of its name are one (``core/pd_user``), as a reader
    and the structure tools (farm-studio) see them; any other file is one of its own."""
    path = Path(rel)
    return str(path.with_suffix("")) if path.suffix in (".c", ".h") else rel


def module_cycles(edges: Iterable[tuple[str, str, str]]) -> list[str]:
    """The cycles among modules of the call graph (a call into a header's static inline
    counts for the header's module)."""
    merged = [(module_of(src), module_of(dst), what) for src, dst, what in edges]
    names = {name for src, dst, _what in merged for name in (src, dst)}
    layer_of = dict.fromkeys(names, 0)  # one layer: only the cycles are found
    return violations(merged, layer_of)


def test_the_module_check_finds_a_cycle_through_a_header() -> None:
    """The checker can fail: a .c calling the inline of a header whose .c calls back."""
    edges = [
        ("core/pd_a.c", "core/pd_b.h", "a calls b's inline"),
        ("core/pd_b.c", "core/pd_a.c", "b calls a"),
    ]
    assert module_cycles(edges) == ["cycle: core/pd_a -> core/pd_b -> core/pd_a"]
    assert module_cycles(edges[:1]) == []


def test_modules_call_in_no_circle(tmp_path: Path) -> None:
    """A pin mode is one unit (issue 36, item 5): the pin table, the modes, the inputs and
    the user service call each other in no loop, a module (.c with its .h) taken whole.
    Before the pin table had a file of its own: pd_inputs -> pd_outputs (the safe-all
    walk) -> pd_user (the user pins' hooks) -> pd_inputs (the report chain)."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    if not (NANOPB / "pb.h").is_file():
        pytest.skip("the nanopb runtime is not fetched (./tools/dev.sh setup)")
    # With a user service: its pins are in the table too.
    edges = call_edges(tmp_path, firmware_files(), ("-DPD_FEATURE_USER=1",))
    assert any(dst == "core/pd_user.h" for _src, dst, _what in edges), "the user's hooks seen"
    assert module_cycles(edges) == []
