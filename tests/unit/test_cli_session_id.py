"""The command line's session id names the device, not the string it was given (issue 32)."""

from __future__ import annotations

from pathlib import Path

from protoduino.cli.options import cli_session


def test_a_link_to_the_port_is_the_same_session(tmp_path: Path) -> None:
    device = tmp_path / "ttyACM0"
    device.touch()
    by_id = tmp_path / "usb-Arduino_Uno_8573-if00"
    by_id.symlink_to(device)
    assert cli_session(str(by_id)) == cli_session(str(device))
    assert cli_session(str(tmp_path / "ttyACM1")) != cli_session(str(device))


def test_a_url_is_the_same_session_whatever_its_case_and_options() -> None:
    plain = cli_session("rfc2217://pi:7000")
    assert cli_session("RFC2217://Pi:7000?ign_set_control&logging=debug") == plain
    assert cli_session("rfc2217://pi:7001") != plain
