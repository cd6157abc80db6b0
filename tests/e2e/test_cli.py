"""The command line: every command's --help, and each board command end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from protoduino import __version__
from protoduino.cli.main import COMMANDS, main
from protoduino.cli.ports import classify
from protoduino.simboard import SimBoard
from protoduino.testing import PtyDevice
from simfixtures import PULSE_TOLERANCE_US, pin_values, wait_for_pin

MINE = ["ports", "ping", "servo", "pin", "pwm", "read", "watch", "info", "monitor", "demo"]


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert f"protoduino {command}" in out


def test_host_commands_are_registered() -> None:
    assert [c for c in MINE if c not in COMMANDS] == []


def test_ports_classifies_usb_ids(capsys: pytest.CaptureFixture[str]) -> None:
    assert classify(0x2341, 0x0043) == "arduino"
    assert classify(0x1A86, 0x7523) == "clone?"
    assert classify(0x1234, 0x0001) == ""
    assert classify(None, None) == ""
    assert main(["ports", "--all"]) == 0
    assert main(["ports", "--json"]) == 0
    for line in capsys.readouterr().out.splitlines():
        if line.startswith("{"):
            assert "device" in json.loads(line)


def test_missing_port_is_a_clean_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(tmp_path / "no-such-port")]) == 1
    err = capsys.readouterr().err
    assert "protoduino info:" in err and "no-such-port" in err


def test_info(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", fake.port]) == 0
    out = capsys.readouterr().out
    assert "board             virtual" in out
    assert "pwm_pins          [3, 5, 6, 9, 10, 11]" in out
    assert "timers            ['free', 'servos']" in out
    # The link counters, as README and --help promise.
    assert "link counters" in out
    counters = dict(line.split(maxsplit=1) for line in out.splitlines() if " " in line)
    assert counters["handshakes"] == "1"
    assert counters["acks"] == "3"  # GetInfo, ConfigureFailsafe, then the Ping that measured rtt
    assert main(["info", fake.port, "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["info"]["num_pins"] == 20
    assert obj["stats"]["handshakes"] == 1
    assert obj["info"]["pwm_pins"] == [3, 5, 6, 9, 10, 11]
    assert obj["info"]["features"] == sorted(
        ["servo", "digital_output", "digital_input", "analog_input", "pwm", "counter"]
    )


def test_ping(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ping", fake.port, "-c", "3", "-i", "0.01", "-s", "4"]) == 0
    out = capsys.readouterr().out
    assert "3 sent, 3 answered, 0 lost" in out
    assert "rtt min/avg/max/stddev" in out
    assert [bytes(p.msg.ping.payload) for p in fake.arrivals("ping")][-3:] == [b"\0\1\2\3"] * 3


def test_ping_counts_losses(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    fake.handler = lambda msg: [] if msg.WhichOneof("data") == "ping" else fake.default_reply(msg)
    assert main(["ping", fake.port, "-c", "1", "--ack-timeout", "0.05", "-q"]) == 1
    assert "1 sent, 0 answered, 1 lost" in capsys.readouterr().out


def test_servo_and_pin(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["servo", fake.port, "9", "45"]) == 0
    assert fake.values[9] == 45
    assert main(["servo", fake.port, "9", "1500", "--us"]) == 0
    assert fake.values[9] == 1500
    assert main(["pin", fake.port, "13", "on"]) == 0
    assert fake.values[13] == 1
    assert main(["pin", fake.port, "13", "off", "--safe", "on"]) == 0
    assert fake.values[13] == 0
    assert fake.arrivals("digital_init")[-1].msg.digital_init.safe_level is True
    out = capsys.readouterr().out
    assert "servo 9: 45 degrees" in out and "pin 13: on" in out


def test_servo_takes_a_real_angle_as_the_api_does(
    fake: PtyDevice, capsys: pytest.CaptureFixture[str]
) -> None:
    """ANGLE is any real number, rounded as Servo.write rounds (half to even: 45.5 -> 46)."""
    assert main(["servo", fake.port, "9", "45.5"]) == 0
    assert fake.values[9] == 46
    assert main(["servo", fake.port, "9", "1500.4", "--us"]) == 0
    assert fake.values[9] == 1500
    assert main(["servo", fake.port, "9", "180.4"]) == 0  # 180 once rounded: within 0..180
    assert fake.values[9] == 180
    out = capsys.readouterr().out
    assert "servo 9: 46 degrees" in out and "servo 9: 1500 us" in out
    with pytest.raises(SystemExit) as usage:  # 181 once rounded: refused before the port opens
        main(["servo", fake.port, "9", "180.6"])
    assert usage.value.code == 2
    assert "180.6 degrees is outside 0..180" in capsys.readouterr().err


def test_servo_refuses_bad_values_before_sending(
    fake: PtyDevice, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as usage:  # a usage error, before the port is opened
        main(["servo", fake.port, "9", "200"])
    assert usage.value.code == 2
    assert "outside 0..180" in capsys.readouterr().err
    # A reserved pin is a bad value too (2), refused by the host once it has the device's info.
    assert main(["servo", fake.port, "0", "90"]) == 2
    assert "STATUS_RESERVED_PIN" in capsys.readouterr().err
    assert fake.arrivals("servo_init") == []


def test_monitor_readable_and_json(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["monitor", fake.port, "--duration", "0.3", "--stats-every", "0"]) == 0
    out = capsys.readouterr().out
    assert "tx CONTROL seq=0" in out and '"RESET"' in out
    assert "rx DATA" in out and "get_info" in out
    assert "handshakes 1" in out
    assert main(["monitor", fake.port, "--duration", "0.3", "--json", "--no-ping"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert lines[0]["dir"] == "tx" and lines[0]["message"]["code"] == "RESET"
    assert lines[-1]["stats"]["handshakes"] == 1


# --- against the simulated board (the shared sim_board fixture, one per backend) -------------


@pytest.mark.mega
def test_board_commands_against_the_sim(
    sim_board: SimBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    port = sim_board.port
    assert main(["info", port]) == 0
    assert f"firmware_version  {__version__}" in capsys.readouterr().out
    assert main(["ping", port, "-c", "2", "-i", "0.01", "-q"]) == 0
    assert "2 sent, 2 answered, 0 lost" in capsys.readouterr().out
    # Each change is awaited in the trace before the next command: an Ack says the
    # device took the value, the pin shows it at the next servo frame.
    near = PULSE_TOLERANCE_US
    assert main(["servo", port, "9", "0"]) == 0
    wait_for_pin(sim_board, 9, lambda v: bool(v) and abs(v[-1] - 544) <= near)
    assert main(["servo", port, "9", "2000", "--us"]) == 0
    wait_for_pin(sim_board, 9, lambda v: bool(v) and abs(v[-1] - 2000) <= near)
    assert main(["pin", port, "13", "on"]) == 0
    wait_for_pin(sim_board, 13, lambda v: v[-1:] == [1])
    # Every command on a port shares one host session: the device kept pin 13 from
    # the command before, so a servo there is refused ...
    assert main(["servo", port, "13", "90"]) == 1
    assert "STATUS_PIN_IN_USE" in capsys.readouterr().err
    # ... and the same Init again does not touch the pin (before sessions, `pin 13 on`
    # on a pin already on drove it to its safe level first: 1 -> 0 -> 1).
    lines_13 = len(pin_values(sim_board.trace(), 13))
    assert main(["pin", port, "13", "on"]) == 0
    capsys.readouterr()
    assert main(["monitor", port, "--duration", "0.3", "--json"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert any(line.get("message", {}).get("resumed") is True for line in lines)
    # The refused command, the repeated one and the monitor changed nothing at the pins.
    assert abs(pin_values(sim_board.trace(), 9)[-1] - 2000) <= near
    assert pin_values(sim_board.trace(), 13)[lines_13 - 1 :] == [1]
    # A new session: the device releases what the earlier commands configured.
    assert main(["servo", port, "13", "90", "--new-session"]) == 0
    wait_for_pin(sim_board, 9, lambda v: v[-1:] == [0])  # pulses stopped
    wait_for_pin(sim_board, 13, lambda v: abs(v[-1] - 1472) <= near)


@pytest.mark.slow
def test_demo(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo"]) == 0
    out = capsys.readouterr().out
    assert "failsafe active (ping_timeout)" in out
    assert "failsafe in the trace: pin 9 -> 1472 us" in out
    assert "demo done" in out
