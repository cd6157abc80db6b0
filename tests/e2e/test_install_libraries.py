"""README's Install section names every system library the wheel's programs need at run time.

The wheel carries the simulated board and the emulated Uno's runner (setup.py's PROGRAMS), but
not the shared libraries they link: a user who installs only the wheel meets a missing one as
the program's loader error. So the programs are built as setup.py builds them for the wheel,
their ``DT_NEEDED`` entries read (``readelf -d``), and each library beyond the C library's own
must be named by its Debian package, which Debian names after the soname: libjansson.so.4 is
``libjansson4``.
"""

from __future__ import annotations

import ast
import re
import subprocess
from pathlib import Path

import pytest
from boardprocess import missing_tool

ROOT = Path(__file__).resolve().parents[2]
#: The programs of the wheel that run on the host (the others are the Uno's firmware).
HOST_PROGRAMS = ("pd_sim", "avrsim")
#: The C library's own parts and the loader: there wherever Python runs.
LIBC = re.compile(r"(libc|libm|libpthread|libdl|librt|ld-linux[\w-]*)\.so\.")
SONAME = re.compile(r"(lib[\w+-]*?)\.so\.(\d+)")


def _wheel_programs() -> dict[str, tuple[str, list[str], str]]:
    """setup.py's PROGRAMS, read from its source (importing setup.py would run the build)."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "PROGRAMS" for t in node.targets
        ):
            programs: dict[str, tuple[str, list[str], str]] = ast.literal_eval(node.value)
            return programs
    raise AssertionError("setup.py has no PROGRAMS")


def _needed(program: Path) -> list[str]:
    out = subprocess.run(
        ["readelf", "-d", str(program)], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    return re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", out)


def _install_section() -> str:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    start = readme.index("\n## Install\n")
    return readme[start : readme.index("\n## ", start + 1)]


def test_debian_package_names_follow_the_soname() -> None:
    assert SONAME.fullmatch("libjansson.so.4") and SONAME.sub(r"\1\2", "libjansson.so.4") == (
        "libjansson4"
    )
    assert LIBC.match("libc.so.6") and LIBC.match("ld-linux-x86-64.so.2")
    assert not LIBC.match("libsimavr.so.2")


def test_the_install_section_names_every_library_the_programs_need(tmp_path: Path) -> None:
    missing = missing_tool("make", "gcc", "readelf", simavr=True)
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    programs = _wheel_programs()
    section = _install_section()
    unnamed = {}
    for name in HOST_PROGRAMS:
        directory, args, built = programs[name]
        subprocess.run(
            ["make", "-s", "-C", str(ROOT / directory), f"BUILD={tmp_path}", *args],
            check=True,
            capture_output=True,
            timeout=600,
        )
        needed = [lib for lib in _needed(tmp_path / built) if not LIBC.match(lib)]
        assert needed, f"{name} links no library beyond libc: is readelf reading it?"
        for lib in needed:
            match = SONAME.fullmatch(lib)
            assert match, f"{name}: {lib} is not a soname of the lib*.so.N kind"
            package = f"{match[1]}{match[2]}"
            if not re.search(rf"\b{re.escape(package)}\b", section):
                unnamed[lib] = f"{package} (needed by {name})"
    assert unnamed == {}, f"README's Install section does not name {unnamed}"
