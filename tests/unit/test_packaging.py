"""What the runtime package carries and what it leaves to the development tools (dev/)."""

from __future__ import annotations

import subprocess
import sys

from protoduino.cli.main import COMMANDS


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


def test_dev_commands_without_the_dev_tools_say_how_to_get_them() -> None:
    # None in sys.modules makes every import of protoduino_dev fail as if not installed.
    dev_commands = [name for name, mod in COMMANDS.items() if mod.startswith("protoduino_dev")]
    # `gen` is the user's command (a service's code, docs/services.md); without a .proto it is
    # the development generator of protoduino's own schema, and says so the same way.
    assert sorted(dev_commands) == ["soak"]
    result = _python(
        "import sys\n"
        "sys.modules['protoduino_dev'] = None\n"
        "from protoduino.cli.main import main\n"
        "sys.exit(main(['gen']))\n"
    )
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "`protoduino gen` is a development command" in result.stderr
    assert "./tools/dev.sh setup" in result.stderr and "protoduino gen robot.proto" in result.stderr
    for name in dev_commands:
        result = _python(
            "import sys\n"
            "sys.modules['protoduino_dev'] = None\n"
            "from protoduino.cli.main import main\n"
            f"sys.exit(main([{name!r}, '--some-option', 'x']))\n"
        )
        assert result.returncode == 2, (result.stdout, result.stderr)
        assert f"protoduino {name}: `protoduino {name}` is a development command" in result.stderr
        assert "./tools/dev.sh setup" in result.stderr
    # The user commands still work without them.
    result = _python(
        "import sys\nsys.modules['protoduino_dev'] = None\n"
        "from protoduino.cli.main import main\nsys.exit(main(['ports']))\n"
    )
    assert result.returncode == 0, result.stderr
