"""Every subcommand refuses bad values itself: exit status 2, one line on stderr, no traceback.

Each case names the words its refusal must contain, so that a case cannot
pass by failing for another reason (a misspelled option is a usage error too).
No port is opened: the values are refused while the command line is parsed.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from protoduino.cli.main import COMMANDS, build_parser, main

P = "/nonexistent/port"  # never opened: every case fails before that

BAD: list[tuple[list[str], str]] = [
    (["gen", "--out"], "expected one argument"),
    (["decode", "--mcap"], "expected one argument"),
    (["decode", "/nonexistent/capture"], "cannot read"),
    (["ports", "--json=yes"], "ignored explicit argument"),
    (["ping", P, "-c", "-1"], "-1 is out of range"),
    (["ping", P, "-c", "0"], "0 is out of range"),
    (["ping", P, "-c", "many"], "'many' is not an integer"),
    (["ping", P, "-i", "-1"], "-1 is out of range"),
    (["ping", P, "-i", "nan"], "nan is out of range"),
    (["ping", P, "-s", "65"], "65 is out of range (want 0..64)"),
    (["ping", P, "--baud", "0"], "0 is out of range"),
    (["ping", P, "--handshake-timeout", "-1"], "-1 is out of range"),
    (["info", P, "--ack-timeout", "0"], "0 is out of range (want > 0)"),
    (["info", P, "--ack-timeout", "inf"], "inf is out of range"),
    (["info", P, "--ack-timeout", "soon"], "'soon' is not a number"),
    (["outputs", P, "--ack-timeout", "0"], "0 is out of range (want > 0)"),
    (["outputs", P, "--json=yes"], "ignored explicit argument"),
    (["servo", P, "-1", "90"], "-1 is out of range"),
    (["servo", P, "9", "181"], "181 degrees is outside 0..180"),
    (["servo", P, "9", "-5"], "-5 degrees is outside 0..180"),
    (["servo", P, "9", "300", "--us"], "300 us is outside 544..2400"),
    (["servo", P, "9", "90", "--safe", "200"], "200 is out of range (want 0..180)"),
    (["servo", P, "9", "90", "--min-us", "100"], "100 is out of range (want 400..2600)"),
    (["servo", P, "9", "90", "--min-us", "2000", "--max-us", "1000"], "must be below"),
    (["servo", P, "9", "90", "--hold", "-1"], "-1 is out of range"),
    (["pin", P, "-3", "on"], "-3 is out of range"),
    (["pin", P, "13", "maybe"], "invalid choice: 'maybe'"),
    (["pin", P, "13", "on", "--safe", "2"], "invalid choice: '2'"),
    (["pin", P, "13", "on", "--hold", "-0.5"], "-0.5 is out of range"),
    (["pwm", P, "3", "256"], "256 is out of range (want 0..255)"),
    (["pwm", P, "3", "-1"], "-1 is out of range"),
    (["pwm", P, "3", "10", "--safe", "nan"], "nan is out of range"),
    (["read", P, "2", "--analog", "--counter"], "not allowed with argument"),
    (["read", P, "2", "--debounce", "256"], "256 is out of range (want 0..255)"),
    (["read", P, "2", "--edge", "up"], "invalid choice: 'up'"),
    (["watch", P, "2:foo"], "'foo' is not an input kind"),
    (["watch", P, "2", "2:analog"], "each pin at most once"),
    (["watch", P, "2", "--count", "0"], "0 is out of range"),
    (["watch", P], "the following arguments are required: PIN"),
    (["monitor"], "give either PORT or --follow CAPTURE"),
    (["monitor", P, "--follow", "x.jsonl"], "give either PORT or --follow CAPTURE"),
    (["monitor", P, "--from-start"], "--from-start goes with --follow"),
    (["monitor", P, "--duration", "-1"], "-1 is out of range"),
    (["monitor", P, "--stats-every", "-2"], "-2 is out of range"),
    (["flash", P, "--baud", "fast"], "'fast' is not an integer"),
    (["sim", "--backend", "foo"], "invalid choice: 'foo'"),
    (["sim", "--pid-file", "x.pid"], "--pid-file and --log go with --detach"),
    (["sim", "--stop", "x.pid", "--detach"], "--stop PIDFILE takes no other option"),
    (["ping", P, "--capture-max", "5"], "--capture-max goes with --capture FILE"),
    (["ping", P, "--capture", "c.jsonl", "--capture-max", "0.001"], "0.001 is out of range"),
    (["demo", "--backend", "foo"], "invalid choice: 'foo'"),
    (["ros2", P], "--config FILE is required with a PORT"),
    (["ros2"], "give a PORT or --sim"),
    (["ros2", P, "--sim"], "give a PORT or --sim"),
    (["ros2", "--sim", "foo"], "invalid choice: 'foo'"),
    (["ros2", P, "--config", "robot.yaml", "--trace", "t.jsonl"], "--trace is the simulated"),
    (["ros2", P, "--config", "robot.yaml", "--control", "c.sock"], "--control is the simulated"),
    (["ros2", P, "--config", "robot.yaml", "--domain-id", "-1"], "-1 is out of range"),
    (["console"], "give a PORT or --sim"),
    (["console", P, "--sim"], "give a PORT or --sim"),
    (["console", P, "--trace", "t.jsonl"], "--trace is the simulated"),
    (["console", P, "--failsafe-timeout", "0"], "0 is out of range"),
    (["console", P, "--http-port", "70000"], "70000 is out of range"),
    (["soak", "--backend", "foo"], "invalid choice: 'foo'"),
    (["soak", "--commands", "-1"], "-1 is out of range"),
    (["soak", "--kinds", "ber,nonsense"], "unknown fault kind(s) ['nonsense']"),
    (["soak", "--faults", "ber=2"], "must be a probability"),
    (["soak", "--cut-seconds", "0"], "0 is out of range (want > 0)"),
    (["soak", "--commands", "0", "--kinds", "none"], "nothing to run"),
]


def _one_line_usage_error(err: str, words: str) -> None:
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert words in lines[0], err
    assert lines[0].startswith("protoduino "), err


@pytest.mark.parametrize(("argv", "words"), BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_values_are_usage_errors(
    argv: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code  # type: ignore[assignment]
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    _one_line_usage_error(err, words)


def test_every_subcommand_has_bad_value_cases() -> None:
    assert sorted(COMMANDS) == sorted({argv[0] for argv, _ in BAD})


@pytest.mark.parametrize(
    "argv",
    [["demo", "--backend", "foo"], ["ping", P, "-i", "-1"], ["info", P, "--ack-timeout", "0"]],
)
def test_a_real_process_prints_one_line(argv: list[str]) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "protoduino.cli.main", *argv],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2 and done.stdout == ""
    _one_line_usage_error(done.stderr, "error:")


@pytest.mark.parametrize(
    ("argv", "level"), [(["-v", "ports"], 1), (["ports", "-v"], 1), (["-v", "ports", "-vv"], 3)]
)
def test_verbose_anywhere(argv: list[str], level: int, capsys: pytest.CaptureFixture[str]) -> None:
    args = build_parser().parse_args(argv)
    assert args.verbose + args.verbose_after == level
    assert main(argv) == 0
    assert "Traceback" not in capsys.readouterr().err


#: The console script as pip writes it (its entry point loaded, then called), with a Ctrl-C
#: arriving while the command imports the package: the import of protoduino.board raises
#: KeyboardInterrupt, as SIGINT would at that moment.
CTRL_C_AT_START = """
import importlib.abc, sys
from importlib.metadata import entry_points

class CtrlC(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "protoduino.board":
            raise KeyboardInterrupt
        return None

sys.meta_path.insert(0, CtrlC())
(script,) = entry_points(group="console_scripts", name="protoduino")
sys.exit(script.load()())
"""


def test_ctrl_c_while_the_command_starts_exits_130_without_a_traceback() -> None:
    done = subprocess.run(
        [sys.executable, "-c", CTRL_C_AT_START, "ports"],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    assert (done.returncode, done.stderr) == (130, "")
