"""docs/services.md's tutorial, run as written: its files, its commands, its Python, on both boards;
and its *Reference*, checked against the headers a handler is compiled with.

Each step is a fenced block after a ``<!-- services step: KIND -->`` marker: ``file PATH``
writes the block to PATH, ``shell`` runs it with sh, ``python`` runs it (with the backend as
its argument) and ``output`` is what that script must print. They run in order, in an empty
folder, with ``$PROTODUINO`` the checkout and this environment's ``protoduino`` on the PATH.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SERVICES_MD = ROOT / "docs" / "services.md"
STEP = re.compile(r"<!-- services step: (\w+)(?: (\S+))? -->\n```\w*\n(.*?)```", re.S)


def steps() -> list[tuple[str, str | None, str]]:
    found = [(m.group(1), m.group(2), m.group(3)) for m in STEP.finditer(SERVICES_MD.read_text())]
    kinds = [kind for kind, _, _ in found]
    assert kinds.count("python") == 1 and kinds.count("output") == 1, kinds
    assert "file" in kinds and "shell" in kinds, kinds
    return found


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, str]:
    """The tutorial's folder after its file and shell steps; its script and expected output."""
    for tool in ("make", "gcc", "avr-gcc"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (the tutorial builds for both boards)")
    work = tmp_path_factory.mktemp("tutorial")
    env = {
        **os.environ,
        "PROTODUINO": str(ROOT),
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
    }
    script = expected = ""
    for kind, arg, body in steps():
        if kind == "file":
            assert arg is not None
            (work / arg).parent.mkdir(parents=True, exist_ok=True)
            (work / arg).write_text(body)
        elif kind == "shell":
            result = subprocess.run(
                ["sh", "-e", "-c", body],
                check=False,
                cwd=work,
                env=env,
                capture_output=True,
                text=True,
            )
            assert result.returncode == 0, f"{body}\n{result.stdout}{result.stderr}"
        elif kind == "python":
            script = body
        elif kind == "output":
            expected = body
    (work / "call.py").write_text(script)
    return work, "call.py", expected


@pytest.mark.parametrize("backend", ["native", "avr"])
def test_the_tutorial_runs_as_written(tutorial: tuple[Path, str, str], backend: str) -> None:
    work, script, expected = tutorial
    result = subprocess.run(
        [sys.executable, script, backend],
        check=False,
        cwd=work,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout == expected


CORE = ROOT / "firmware" / "core"
#: A function's declaration in a header: its return type, name and parameters, up to ";".
PROTOTYPE = re.compile(r"^[A-Za-z_][\w \t*]*?\b(pd_\w+)\s*\([^;{)]*\)\s*;", re.M)
#: A signature in the doc's tables: `... name(...);`
DOCUMENTED = re.compile(r"`([^`]*?\b(\w+)\([^`]*\);)`")


def normalised(signature: str) -> str:
    return re.sub(r"\s+", " ", signature).replace("( ", "(").replace(" )", ")").strip()


def prototypes(text: str) -> dict[str, str]:
    """Each function a header declares, by name, its declaration on one line."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return {m.group(1): normalised(m.group(0)) for m in PROTOTYPE.finditer(text)}


def reference() -> str:
    text = SERVICES_MD.read_text()
    return text.split("\n## Reference\n", 1)[1].split("\n## ", 1)[0]


def test_the_reference_gives_every_callable_function_with_the_headers_signature() -> None:
    """Every function pd_user.h offers handlers (its part "for handlers") and every pd_hal.h
    function is in the doc with the header's exact signature, or (pd_hal.h's) named as not
    for a service; the doc names nothing the headers do not declare."""
    ref = reference()
    documented = {m.group(2): normalised(m.group(1)) for m in DOCUMENTED.finditer(ref)}
    user_h = (CORE / "pd_user.h").read_text()
    for_handlers = prototypes(user_h.split("--- for handlers")[1].split("--- for the core")[0])
    hal = prototypes((CORE / "pd_hal.h").read_text())
    assert len(for_handlers) >= 5 and len(hal) >= 20  # the parser found the headers' functions
    core_only = ref.split("**Not for a service**", 1)[1].split("\n\n", 1)[0]
    not_for = set(re.findall(r"`(pd_hal_\w+)`", core_only))
    for name, signature in for_handlers.items():
        assert documented.get(name) == signature, (name, signature)
    for name, signature in hal.items():
        if name in not_for:
            assert name not in documented, name
        else:
            assert documented.get(name) == signature, (name, signature)
    stale = {n for n in documented if n.startswith("pd_")} - set(for_handlers) - set(hal)
    assert not stale and not_for <= set(hal), (stale, not_for - set(hal))


def test_the_reference_gives_what_the_generator_declares(tmp_path: Path) -> None:
    """The functions a user implements, as `protoduino gen` declares them for the tutorial."""
    from protoduino import servicegen

    body = next(b for kind, arg, b in steps() if kind == "file" and str(arg).endswith(".proto"))
    proto = tmp_path / "tally.proto"
    proto.write_text(body)
    servicegen.generate(proto, tmp_path / "gen")
    header = tmp_path / "gen" / "tally_service.h"
    declared = normalised(re.sub(r"/\*.*?\*/", "", header.read_text(), flags=re.S))
    implemented = [
        normalised(m.group(1))
        for m in DOCUMENTED.finditer(reference())
        if m.group(2).startswith("tally_") and "<" not in m.group(1)
    ]
    assert len(implemented) == 4, implemented  # a call and the three hooks
    for signature in implemented:
        assert signature in declared, signature
