"""``protoduino gen robot.proto``: what it writes for both sides, and what it refuses.

The end-to-end tests (tests/e2e/test_services.py) run the examples' generated code on
both boards; here the generator itself: the fingerprint's rules, the typed client under
mypy --strict, the C it writes compiles with the core's warnings, and a .proto it cannot
carry is refused with a message saying what to change.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from protoduino import servicegen
from protoduino.cli.main import main
from protoduino.errors import ServiceGenError
from userbuilds import nested_proto

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "blinker" / "blinker.proto"


def gen(proto: Path, out: Path) -> servicegen.Generated:
    return servicegen.generate(proto, out)


def test_the_command_writes_both_sides(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["gen", str(EXAMPLE), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    for name in (
        "blinker.pb.c",
        "blinker.pb.h",
        "blinker_service.c",
        "blinker_service.h",
        "blinker_pb2.py",
        "blinker_pb2.pyi",
        "blinker_client.py",
    ):
        assert (tmp_path / name).is_file(), name
        assert str(tmp_path / name) in printed
    header = (tmp_path / "blinker_service.h").read_text()
    assert "uint8_t blinker_start_blink(pd_user_ctx_t *ctx, const blinker_Blink *request," in header
    client = (tmp_path / "blinker_client.py").read_text()
    for method in ("def start_blink(", "def submit_start_blink(", "async def start_blink("):
        assert method in client
    assert "class BadPeriodError(BlinkerError)" in client


def test_the_fingerprint_ignores_comments_not_fields(tmp_path: Path) -> None:
    source = EXAMPLE.read_text()
    a = tmp_path / "a" / "blinker.proto"
    b = tmp_path / "b" / "blinker.proto"
    c = tmp_path / "c" / "blinker.proto"
    for path, text in (
        (a, "// a comment of mine\n" + source),
        (b, source),
        (c, source.replace("uint32 period_ms = 2;", "uint32 period_ms = 3;")),
    ):
        path.parent.mkdir()
        path.write_text(text)
    fa = gen(a, tmp_path / "out-a").service.fingerprint
    fb = gen(b, tmp_path / "out-b").service.fingerprint
    fc = gen(c, tmp_path / "out-c").service.fingerprint
    assert fa == fb != fc


def test_the_client_is_typed_for_mypy_strict(tmp_path: Path) -> None:
    gen(EXAMPLE, tmp_path)
    user = tmp_path / "use_it.py"
    user.write_text(
        "import protoduino\n"
        "from blinker_client import Blinker, BadPeriodError\n"
        "import blinker_pb2 as pb\n\n"
        "def run(board: protoduino.Board) -> int:\n"
        "    blinker = Blinker(board)\n"
        "    try:\n"
        "        reply = blinker.start_blink(pb.Blink(pin=13, period_ms=40))\n"
        "    except BadPeriodError as error:\n"
        "        return error.code\n"
        "    return reply.half_ms\n"
    )
    wrong = tmp_path / "wrong.py"
    wrong.write_text(
        "import protoduino\n"
        "from blinker_client import Blinker\n"
        "import blinker_pb2 as pb\n\n"
        "def run(board: protoduino.Board) -> str:\n"
        "    return Blinker(board).count(pb.Blink()).count\n"
    )
    cmd = [sys.executable, "-m", "mypy", "--strict", "--no-incremental"]
    ok = subprocess.run(
        [*cmd, "blinker_client.py", "use_it.py"],
        check=False,
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert ok.returncode == 0, ok.stdout + ok.stderr
    bad = subprocess.run(
        [*cmd, "wrong.py"], check=False, cwd=tmp_path, capture_output=True, text=True
    )
    assert bad.returncode == 1
    assert 'incompatible type "Blink"; expected "Empty"' in bad.stdout
    assert 'Incompatible return value type (got "int", expected "str")' in bad.stdout


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_the_c_compiles_with_the_core_warnings(tmp_path: Path) -> None:
    gen(EXAMPLE, tmp_path)
    nanopb = ROOT / ".deps" / "nanopb"
    result = subprocess.run(
        [
            "gcc",
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-Wshadow",
            "-Wstrict-prototypes",
            "-Wmissing-prototypes",
            "-DPD_FEATURE_USER=1",
            f"-I{ROOT / 'firmware' / 'core'}",
            f"-I{ROOT / 'firmware' / 'generated'}",
            f"-I{nanopb}",
            f"-I{tmp_path}",
            "-c",
            str(tmp_path / "blinker_service.c"),
            str(tmp_path / "blinker.pb.c"),
        ],
        check=False,
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize(
    ("text", "options", "message"),
    [
        (
            'syntax = "proto3"; message A { uint32 x = 1; }',
            "",
            "declare exactly one service, not 0",
        ),
        (
            'syntax = "proto3"; import "other.proto"; message A { uint32 x = 1; }'
            " service S { rpc F(A) returns (A); }",
            "",
            "imports (other.proto) are not supported",
        ),
        (
            'syntax = "proto3"; message A { string name = 1; } service S { rpc F(A) returns (A); }',
            "",
            "message A has no size bound: give each of its string, bytes and repeated fields",
        ),
        (
            'syntax = "proto3"; message A { bytes blob = 1; } service S { rpc F(A) returns (A); }',
            "A.blob max_size:100",
            "message A takes up to 102 bytes on the wire, more than 64",
        ),
        (
            'syntax = "proto3"; message A { uint32 x = 1; }'
            " service S { rpc F(stream A) returns (A); }",
            "",
            "rpc F: a client stream is not supported",
        ),
        (
            'syntax = "proto3"; enum Errors { NONE = 0; JAMMED = 1; }'
            " message A { uint32 x = 1; } service S { rpc F(A) returns (A); }",
            "",
            "enum Errors: the handlers' error codes are the enum named after the service, "
            "SError (<Service>Error); any other is not read, and its codes would arrive as a "
            "plain UserError: rename it SError",
        ),
    ],
)
def test_what_it_cannot_carry_is_refused_by_name(
    tmp_path: Path, text: str, options: str, message: str
) -> None:
    (tmp_path / "other.proto").write_text('syntax = "proto3"; message O {}')
    proto = tmp_path / "mine.proto"
    proto.write_text(text)
    if options:
        (tmp_path / "mine.options").write_text(options)
    with pytest.raises(ServiceGenError, match=r"^mine\.proto: ") as error:
        gen(proto, tmp_path / "out")
    assert message in str(error.value)


@pytest.mark.parametrize(
    "rpc",
    [
        "rpc F(Level{n}) returns (Empty);",
        "rpc F(Empty) returns (Level{n});",
        "rpc F(Empty) returns (stream Level{n});",
    ],
)
def test_a_message_nested_deeper_than_the_stack_allows_is_refused(
    tmp_path: Path, rpc: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The Uno's stack bounds how deep a user message nests (issue 32: deeper ones ran the
    stack into static data); the largest accepted is measured in test_stack_margin.py."""
    top = servicegen.MAX_USER_LEVELS
    accepted = tmp_path / "ok" / "mine.proto"
    accepted.parent.mkdir()
    accepted.write_text(nested_proto(top) + f"service S {{ {rpc.format(n=top)} }}\n")
    gen(accepted, tmp_path / "out-ok")
    refused = tmp_path / "mine.proto"
    refused.write_text(nested_proto(top + 1) + f"service S {{ {rpc.format(n=top + 1)} }}\n")
    chain = " > ".join(f"Level{n}" for n in range(top + 1, 0, -1))
    expected = (
        f"mine.proto: message Level{top + 1} nests {top + 1} levels of messages ({chain}), "
        f"more than the {top} a user message may have"
    )
    with pytest.raises(ServiceGenError) as error:
        gen(refused, tmp_path / "out")
    assert str(error.value).startswith(expected), error.value
    assert main(["gen", str(refused), "--out", str(tmp_path / "out-cli")]) == 1
    assert expected in capsys.readouterr().err


def test_a_message_that_contains_itself_is_refused(tmp_path: Path) -> None:
    proto = tmp_path / "mine.proto"
    proto.write_text(
        'syntax = "proto3"; message A { B b = 1; } message B { A a = 1; }'
        " service S { rpc F(A) returns (A); }"
    )
    with pytest.raises(
        ServiceGenError, match=r"^mine\.proto: message A contains itself \(A > B > A\)"
    ):
        gen(proto, tmp_path / "out")


def test_error_names_and_method_names() -> None:
    assert servicegen.snake("StartBlink") == "start_blink"
    assert servicegen.snake("GetHTTPStatus") == "get_http_status"
    assert servicegen.camel("PIN_UNAVAILABLE") == "PinUnavailable"


def test_an_error_named_like_a_builtin_gets_the_services_name(tmp_path: Path) -> None:
    proto = tmp_path / "meter.proto"
    proto.write_text(
        'syntax = "proto3"; enum MeterError { METER_ERROR_NONE = 0; METER_ERROR_VALUE = 1;'
        " METER_ERROR_STUCK = 2; } message A { uint32 x = 1; } service Meter {"
        " rpc Read(A) returns (A); }"
    )
    client = (gen(proto, tmp_path / "out").files[-1]).read_text()
    assert "class MeterValueError(MeterError)" in client
    assert "class StuckError(MeterError)" in client


def test_a_failing_tool_is_each_generators_own_error(tmp_path: Path) -> None:
    """servicegen and the development codegen run their tools through one helper
    (protoduino.toolrun) and each raises its own error, with the tool's command and output."""
    from protoduino_dev import codegen

    cmd = [sys.executable, "-c", "import sys; print('said'); sys.exit('refused')"]
    with pytest.raises(ServiceGenError, match=r"-c .* failed:\nsaid\nrefused") as user:
        servicegen._run(cmd, tmp_path)
    with pytest.raises(codegen.CodegenError, match=r"-c .* failed:\nsaid\nrefused") as dev:
        codegen._run(cmd, tmp_path)
    assert str(user.value) == str(dev.value)


def test_the_shared_tool_helper_imports_nothing_of_the_package() -> None:
    """codegen loads toolrun by its path: it must run where the package cannot be imported
    (the generated files it writes are missing or broken), so toolrun imports the standard
    library only."""
    import ast

    from protoduino import toolrun

    tree = ast.parse(Path(toolrun.__file__).read_text())
    imported = {
        name
        for node in ast.walk(tree)
        if isinstance(node, (ast.Import, ast.ImportFrom))
        for name in (
            [a.name for a in node.names]
            if isinstance(node, ast.Import)
            else [("." * node.level) + (node.module or "")]
        )
    }
    assert imported <= {"__future__", "subprocess", "sys", "pathlib"}, imported


@pytest.mark.parametrize("name", ["strs.Name.text", "Name.text", "*.text"])
def test_an_options_name_may_leave_out_the_package(tmp_path: Path, name: str) -> None:
    """nanopb matches names with their package; the generator takes them either way."""
    proto = tmp_path / "strs.proto"
    proto.write_text(
        'syntax = "proto3"; package strs; message Name { string text = 1; }'
        " service Names { rpc Set(Name) returns (Name); }"
    )
    (tmp_path / "strs.options").write_text(
        f"// the bound of the one string\n{name} max_size:16 // a comment\n"
    )
    gen(proto, tmp_path / "out")
    header = (tmp_path / "out" / "strs.pb.h").read_text()
    assert "char text[16];" in header


def test_a_service_without_its_error_enum_is_told_the_rule(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    proto = tmp_path / "bare.proto"
    proto.write_text(
        'syntax = "proto3"; message A { uint32 x = 1; } service Bare { rpc F(A) returns (A); }'
    )
    assert main(["gen", str(proto), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "Bare: no error enum BareError (<Service>Error)" in printed
    assert main(["gen", str(EXAMPLE), "--out", str(tmp_path / "ex")]) == 0
    assert "no error enum" not in capsys.readouterr().out
