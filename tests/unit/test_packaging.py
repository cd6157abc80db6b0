"""What the runtime package carries and what it leaves to the development tools (dev/)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from protoduino import plugins
from protoduino.cli.main import COMMANDS, DEV_COMMANDS

#: Run first in a fresh interpreter: no installed distribution declares anything, as in a
#: user's installation without the development tools.
NO_PLUGINS = "import importlib.metadata as m\nm.entry_points = lambda **kw: m.EntryPoints(())\n"


def _python(code: str) -> subprocess.CompletedProcess[str]:
    # A fresh interpreter: this one has long imported the development tools.
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False, timeout=120
    )


def test_importing_protoduino_leaves_faulty_urls_and_dev_tools_out() -> None:
    result = _python(
        "import sys, serial, protoduino, protoduino.simboard, protoduino.cli.main\n"
        "print(sorted(m for m in sys.modules if m.startswith('protoduino_dev')))\n"
        "print(serial.protocol_handler_packages)\n"
        "try:\n"
        "    serial.serial_for_url('faulty://loop://', do_not_open=True)\n"
        "except ValueError as e:\n"
        "    print('refused:', e)\n"
    )
    assert result.returncode == 0, result.stderr
    dev_modules, handlers, refused = result.stdout.splitlines()
    assert dev_modules == "[]"
    assert "protoduino_dev.urlhandler" not in handlers
    assert refused.startswith("refused:") and "faulty" in refused


def test_importing_the_dev_tools_registers_faulty_urls() -> None:
    result = _python(
        "import serial, protoduino_dev\n"
        "print(type(serial.serial_for_url('faulty://loop://', do_not_open=True)).__module__)\n"
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "protoduino_dev.urlhandler.protocol_faulty"


def test_the_dev_tools_declare_what_they_add_by_entry_point() -> None:
    # The runtime names no module of theirs: each addition is found in its group.
    assert [ep.name for ep in plugins.declared(plugins.COMMANDS)] == sorted(DEV_COMMANDS)
    assert all(COMMANDS[name] == plugins.COMMANDS for name in DEV_COMMANDS)
    assert [ep.name for ep in plugins.declared(plugins.SERIAL_URLS)] == ["faulty"]
    (source,) = plugins.declared(plugins.PROGRAMS)
    assert source.value == "protoduino_dev.build:build_program"
    (schema,) = plugins.declared(plugins.GENERATORS)
    assert (schema.name, schema.value) == ("schema", "protoduino_dev.cli.gen")


def test_without_a_declared_program_source_the_bundled_copy_is_asked_for() -> None:
    result = _python(
        NO_PLUGINS + "import sys\nsys.modules['protoduino_dev'] = None\n"
        "from protoduino import programs\n"
        "try:\n    programs.locate(programs.NATIVE_SIM)\n"
        "except Exception as e:\n    print(type(e).__name__, e)\n"
    )
    assert result.returncode == 0, result.stderr
    # An editable checkout bundles nothing: without the tools, nothing builds it either.
    assert result.stdout.startswith("BuildError this protoduino installation carries no pd_sim")


def test_gen_without_a_proto_and_without_the_dev_tools_says_how_to_get_them() -> None:
    # `gen` is the user's command (a service's code, docs/services.md); without a .proto it is
    # the development generator of protoduino's own schema, found by entry point.
    assert COMMANDS["gen"] == "protoduino.cli.gen"
    for prelude in ("", NO_PLUGINS):
        result = _python(
            prelude + "import sys\n"
            "sys.modules['protoduino_dev'] = None\n"
            "from protoduino.cli.main import main\n"
            "sys.exit(main(['gen']))\n"
        )
        assert result.returncode == 2, (result.stdout, result.stderr)
        assert "`protoduino gen` is a development command" in result.stderr
        assert "./tools/dev.sh setup" in result.stderr
        assert "protoduino gen robot.proto" in result.stderr


@pytest.mark.parametrize("declared", [False, True], ids=["not-declared", "declared-but-gone"])
def test_dev_commands_without_the_dev_tools_say_how_to_get_them(declared: bool) -> None:
    # None in sys.modules makes every import of protoduino_dev fail; without NO_PLUGINS the
    # entry points are still declared (metadata left behind by a removed package).
    prelude = "" if declared else NO_PLUGINS
    for name in DEV_COMMANDS:
        result = _python(
            prelude + "import sys\n"
            "sys.modules['protoduino_dev'] = None\n"
            "from protoduino.cli.main import main\n"
            f"sys.exit(main([{name!r}, '--some-option', 'x']))\n"
        )
        assert result.returncode == 2, (result.stdout, result.stderr)
        assert f"protoduino {name}: `protoduino {name}` is a development command" in result.stderr
        assert "./tools/dev.sh setup" in result.stderr
    # The user commands still work without them.
    result = _python(
        NO_PLUGINS + "import sys\nsys.modules['protoduino_dev'] = None\n"
        "from protoduino.cli.main import main\nsys.exit(main(['ports']))\n"
    )
    assert result.returncode == 0, result.stderr
