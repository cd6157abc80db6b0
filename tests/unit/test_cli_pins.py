"""``protoduino pwm``, ``read`` and ``watch`` against the pty fake (PtyDevice)."""

from __future__ import annotations

import json
from typing import Any

import pytest
from protoduino.cli.main import main
from protoduino.testing import PtyDevice


def test_pwm(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["pwm", fake.port, "3", "127.5", "--safe", "4"]) == 0
    assert capsys.readouterr().out.strip() == "pwm 3: 128"
    (init,) = fake.arrivals("pwm_init")
    assert init.msg.pwm_init.safe_duty == 4 and fake.values[3] == 128
    assert main(["pwm", fake.port, "4", "10"]) == 2  # refused before anything is sent
    err = capsys.readouterr().err
    assert "protoduino pwm:" in err and "STATUS_NOT_SUPPORTED" in err
    assert "3, 5, 6, 9, 10, 11" in err


def test_read_once(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    fake.levels[2] = 0
    assert main(["read", fake.port, "2", "--pull-up", "--debounce", "10"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("pin 2 digital: 0 (") and out.rstrip().endswith("ms old)")
    init = fake.arrivals("digital_input_init")[0].msg.digital_input_init
    assert (init.pull_up, init.debounce_ms) == (True, 10)
    fake.analog[14] = 777
    fake.time_ms = 5000
    assert main(["read", fake.port, "14", "--analog", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["pin"] == 14 and got["kind"] == "analog" and got["value"] == 777
    assert got["time_ms"] == 5000 and got["age"] >= 0
    assert main(["read", fake.port, "3", "--counter", "--edge", "both", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["value"] == 0
    assert fake.arrivals("counter_init")[0].msg.counter_init.edge == 2  # EDGE_BOTH


def test_read_refuses_a_pin_that_cannot(
    fake: PtyDevice, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["read", fake.port, "2", "--analog"]) == 2  # refused before anything is sent
    err = capsys.readouterr().err
    assert "pin 2 cannot be an analog input pin on this virtual" in err
    assert "STATUS_NOT_SUPPORTED" in err
    assert fake.arrivals("analog_input_init") == []


def test_watch_prints_the_values_then_each_change(
    fake: PtyDevice, capsys: pytest.CaptureFixture[str]
) -> None:
    def then_change_both(msg: Any) -> list[Any]:
        replies = fake.default_reply(msg)  # the Ack and the first value
        if msg.WhichOneof("data") == "analog_input_init":  # the second input's Init
            fake.levels[2] = 0
            replies.append(fake.report())
            fake.analog[14] = 99
            replies.append(fake.report(analog=[14]))
        return replies

    fake.analog[14] = 5
    fake.handler = then_change_both
    code = main(["watch", fake.port, "2", "14:analog", "--json", "--count", "2"])
    assert code == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    shown = [(x["pin"], x["kind"], x["value"]) for x in lines]
    # Each input's first value, then the two changes, in the order they came.
    assert shown == [
        (2, "digital", True), (14, "analog", 5), (2, "digital", False), (14, "analog", 99)
    ]  # fmt: skip


def test_pins_by_their_board_names(fake: PtyDevice, capsys: pytest.CaptureFixture[str]) -> None:
    """PIN may be a board name as Arduino writes it: A0 is the device's first analog pin."""
    fake.analog[15] = 321
    assert main(["read", fake.port, "A1", "--analog", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pin"] == 15
    assert main(["pin", fake.port, "a2", "on"]) == 0
    assert fake.arrivals("digital_init")[-1].msg.digital_init.pin == 16 and fake.values[16] == 1
    assert capsys.readouterr().out.strip() == "pin A2: on"
    assert main(["watch", fake.port, "A3:analog", "--json", "--duration", "0.01"]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[0])["pin"] == 17
    assert main(["servo", fake.port, "A6", "90"]) == 2  # the Uno has A0..A5
    assert "pin A6 does not exist" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:
        main(["pin", fake.port, "D3", "on"])
    assert usage.value.code == 2
    assert "'D3' is not a pin (want a number 0..255 or a name such as A0)" in (
        capsys.readouterr().err
    )
