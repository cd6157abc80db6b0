"""A board program whose shared library is missing is named before any board starts (issue 38).

On a bare system a wheel's ``pd_sim`` built without its libraries bundled could not load
libjansson, and the API said only "the native board exited (code 127) before printing its
port". Here a program needing a library that is not installed (built, then its library
removed) stands in for it: the API, ``protoduino sim`` and its ``--detach`` must name the
library, and the Debian package where it is one protoduino's programs link.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from boardprocess import missing_tool
from protoduino import simboard
from protoduino.errors import BuildError
from protoduino.simboard import LIBRARY_PACKAGES, SimBoard, check_loadable

SONAME = "libpdmissing.so.1"


@pytest.fixture(scope="module")
def needs_missing(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A program linked with a shared library that has since been deleted."""
    missing = missing_tool("gcc")
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    tmp = tmp_path_factory.mktemp("libs")
    (tmp / "lib.c").write_text("int pd_missing(void) { return 0; }\n")
    (tmp / "main.c").write_text("int pd_missing(void);\nint main(void) { return pd_missing(); }\n")
    lib = tmp / SONAME
    subprocess.run(
        ["gcc", "-shared", "-fPIC", f"-Wl,-soname,{SONAME}", "-o", str(lib), str(tmp / "lib.c")],
        check=True,
    )
    program = tmp / "pd_sim"
    subprocess.run(["gcc", "-o", str(program), str(tmp / "main.c"), str(lib)], check=True)
    lib.unlink()
    return program


def test_the_api_names_the_missing_library(needs_missing: Path) -> None:
    with pytest.raises(BuildError) as raised, SimBoard("native", firmware=needs_missing) as sim:
        sim.start()
    message = str(raised.value)
    assert SONAME in message and "code 127" not in message, message
    assert "install the package that has" in message


@pytest.mark.parametrize("detach", [False, True])
def test_sim_command_names_the_missing_library(
    needs_missing: Path, tmp_path: Path, detach: bool
) -> None:
    cli = Path(sys.executable).parent / "protoduino"
    args = [str(cli), "sim", "--firmware", str(needs_missing)]
    if detach:
        args += ["--detach", "--pid-file", str(tmp_path / "pid")]
    result = subprocess.run(
        args, capture_output=True, text=True, timeout=120, check=False, stdin=subprocess.DEVNULL
    )
    assert result.returncode != 0
    assert SONAME in result.stderr and "code 127" not in result.stderr, result.stderr
    assert "protoduino sim:" in result.stderr  # said by protoduino, not only by the loader


def test_a_known_library_is_named_with_its_package(
    monkeypatch: pytest.MonkeyPatch, needs_missing: Path
) -> None:
    monkeypatch.setattr(simboard, "missing_libraries", lambda _p: ["libjansson.so.4"])
    with pytest.raises(BuildError, match=r"sudo apt install libjansson4 \(Debian"):
        check_loadable(needs_missing, "the simulated board")


def test_a_program_whose_libraries_load_passes(needs_missing: Path) -> None:
    python = Path(os.path.realpath(sys.executable))
    assert check_loadable(python, "python") == python


@pytest.mark.skipif(shutil.which("dpkg") is None, reason="dpkg is not installed (not Debian)")
@pytest.mark.parametrize("soname", sorted(LIBRARY_PACKAGES))
def test_each_library_is_in_the_package_named(soname: str) -> None:
    result = subprocess.run(
        ["dpkg", "-S", f"*/{soname}"], capture_output=True, text=True, check=False
    )
    if result.returncode != 0:
        pytest.skip(f"{soname} is not installed here (dpkg -S found no package)")
    packages = {line.split(":", 1)[0] for line in result.stdout.splitlines()}
    assert LIBRARY_PACKAGES[soname] in packages, result.stdout
