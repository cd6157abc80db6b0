"""The command and pin-mode declarations: complete, and the same on both sides.

The host declares each command once (host/protoduino/commands.py); the firmware
has its command table (PD_COMMANDS in pd_dispatch.c) and its pin modes
(PD_MODE_* in pd_outputs.h). These tests read the firmware's tables from its
source so a command added on one side only fails here, not on a lossy line.
"""

from __future__ import annotations

import re
from pathlib import Path

from protoduino import commands
from protoduino._generated import protoduino_pb2 as pb

ROOT = Path(__file__).resolve().parents[2]
DISPATCH = ROOT / "firmware" / "core" / "pd_dispatch.c"
OUTPUTS_H = ROOT / "firmware" / "core" / "pd_outputs.h"


#: One X(name, feature, flags, result) line of PD_COMMANDS.
_ENTRY = r"X\((\w+),\s*(\w+),\s*([\w|]+),\s*(\w+)\)"


def _firmware_table() -> list[tuple[str, str, str, str]]:
    text = DISPATCH.read_text()
    table = re.search(r"#define PD_COMMANDS\(X\)(.*?)\n\n", text, re.S)
    assert table, "PD_COMMANDS not found in pd_dispatch.c"
    entries: list[tuple[str, str, str, str]] = re.findall(_ENTRY, table.group(1))
    assert entries, "PD_COMMANDS has no entries"
    return entries


def _firmware_flags() -> dict[str, str]:
    return {name: flags for name, _feature, flags, _result in _firmware_table()}


def test_only_controls_are_refused_once_the_failsafe_ran_out() -> None:
    """PD_CMD_COMMANDS marks what sets a commanded value: each pin mode's Control, and a
    Pose (several of them at once)."""
    for kind, flags in _firmware_flags().items():
        controls = commands.command(kind).needs_init is not None or kind == "pose"
        assert ("PD_CMD_COMMANDS" in flags) == controls, kind


def _firmware_commands() -> dict[str, tuple[bool, str | None]]:
    """name -> (idempotent, Ack.result member) from the X(...) lines of PD_COMMANDS."""
    out: dict[str, tuple[bool, str | None]] = {}
    for name, _feature, flags, result in _firmware_table():
        assert name not in out, f"{name} is in PD_COMMANDS twice"
        match = re.fullmatch(r"protoduino_Ack_(\w+)_tag", result)
        assert match or result == "0", f"{name}: unexpected result {result}"
        out[name] = ("PD_CMD_IDEMPOTENT" in flags, match.group(1) if match else None)
    return out


def test_every_arduino_in_member_is_declared_once() -> None:
    kinds = commands.arduino_in_kinds()
    assert set(kinds) == set(commands.COMMANDS), "host/protoduino/commands.py vs the schema"
    for kind in kinds:
        cmd = commands.COMMANDS[kind]
        assert cmd.kind == kind
        if cmd.result is not None:
            assert cmd.result in pb.Ack.DESCRIPTOR.fields_by_name


def test_firmware_command_table_agrees_with_the_host() -> None:
    firmware = _firmware_commands()
    assert set(firmware) == set(commands.arduino_in_kinds()), "PD_COMMANDS vs the schema"
    for kind, (idempotent, result) in firmware.items():
        cmd = commands.COMMANDS[kind]
        assert cmd.idempotent == idempotent, f"{kind}: idempotent differs"
        assert cmd.result == result, f"{kind}: Ack result differs"


def test_pin_modes_agree_with_the_firmware() -> None:
    names = re.findall(r"^\s*PD_MODE_(\w+)\s*[,=]", OUTPUTS_H.read_text(), re.M)
    names = [n.lower() for n in names if n not in ("FREE", "COUNT")]
    assert names == [m.name for m in commands.PIN_MODES]
    for mode in commands.PIN_MODES:
        assert commands.COMMANDS[mode.init].pin_mode is mode
        assert commands.COMMANDS[mode.init].needs_init is None
        if mode.control is not None:
            assert commands.COMMANDS[mode.control].needs_init == mode.init
            # Both carry the pin in a field named `pin` (the restore rule reads it).
            for kind in (mode.init, mode.control):
                sub = pb.ArduinoIn.DESCRIPTOR.fields_by_name[kind].message_type
                assert sub is not None and "pin" in sub.fields_by_name


def test_undeclared_command_is_not_idempotent() -> None:
    assert commands.command("no_such_command").idempotent is False
    assert commands.command("servo_control").needs_init == "servo_init"
    assert commands.command("ping").needs_init is None


def test_every_command_needs_the_feature_the_host_checks() -> None:
    """A pin mode's commands need its feature on the device (PD_FEATURE_<NAME>), the one
    the host checks before sending; ClearInterlock comes with digital inputs; the rest
    are in every build (1)."""
    for name, feature, _flags, _result in _firmware_table():
        mode = commands.COMMANDS[name].pin_mode
        if mode is not None:
            assert feature == f"PD_FEATURE_{mode.feature.upper()}", name
        elif name == "clear_interlock":
            assert feature == "PD_FEATURE_DIGITAL_INPUT"
        elif name == "user_call":  # a firmware built with a user service (docs/services.md)
            assert feature == "PD_FEATURE_USER"
        else:
            assert feature == "1", name
