"""The command and pin-mode declarations: complete, consistent, and what the device obeys.

Each command's handling and each pin mode are declared once, as options in
proto/protoduino.proto; `protoduino gen` writes the firmware's table
(firmware/generated/pd_tables.h) and the host's (host/protoduino/_generated/tables.py)
from one reading of them, and tests/contract/test_codegen.py checks that both committed
files are that output. What is left to check here is what the declarations say: that
the rules the protocol text states hold for every command (which may run twice, which
a fired failsafe refuses, which feature each needs), and that the generator refuses a
declaration naming something the schema does not have.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from protoduino import commands
from protoduino._generated import protoduino_pb2 as pb
from protoduino_dev import cmdtables, codegen

ROOT = codegen.repo_root()


def test_every_arduino_in_member_is_declared_once() -> None:
    kinds = commands.arduino_in_kinds()
    assert set(kinds) == set(commands.COMMANDS), "the generated table vs the schema"
    assert len(kinds) == len(commands.COMMANDS)
    for kind in kinds:
        cmd = commands.COMMANDS[kind]
        assert cmd.kind == kind
        if cmd.result is not None:
            assert cmd.result in {f.name for f in pb.Ack.DESCRIPTOR.oneofs_by_name["result"].fields}


def test_only_controls_and_poses_are_refused_once_the_failsafe_ran_out() -> None:
    """sets_output (PD_CMD_SETS_OUTPUT) marks what sets a commanded value: each pin mode's
    Control, and a Pose (several of them at once); an Init drives the safe value."""
    for kind, cmd in commands.COMMANDS.items():
        assert cmd.sets_output == (cmd.is_control or kind == "pose"), kind


def test_what_may_run_twice() -> None:
    """Idempotent commands skip the dedupe window: they must change no output. The liveness
    messages are among them (a repeated Ping must still count as liveness); a ClearInterlock
    is not (a late duplicate must never clear a later trip)."""
    idempotent = {kind for kind, cmd in commands.COMMANDS.items() if cmd.idempotent}
    for kind in idempotent:
        cmd = commands.COMMANDS[kind]
        assert cmd.pin_mode is None and not cmd.sets_output, kind
    assert {"ping", "heartbeat", "get_info", "read_outputs"} <= idempotent
    assert not idempotent & {"clear_interlock", "stop", "release", "release_all", "pose"}


def test_every_command_needs_the_feature_the_host_checks() -> None:
    """A pin mode's commands need its feature on the device (PD_FEATURE_<NAME>), the one
    the host checks before sending; ClearInterlock comes with digital inputs; the rest
    are in every build but UserCall, which comes with a user service."""
    for kind, cmd in commands.COMMANDS.items():
        if cmd.pin_mode is not None:
            assert cmd.feature == cmd.pin_mode.feature, kind
        elif kind == "clear_interlock":
            assert cmd.feature == "digital_input"
        elif kind == "user_call":  # a firmware built with a user service (docs/services.md)
            assert cmd.feature == "user"
        else:
            assert cmd.feature is None, kind
        if cmd.feature is not None:
            assert pb.Feature.Value(f"FEATURE_{cmd.feature.upper()}") > 0


def test_pin_modes_and_their_commands() -> None:
    names = [m.name for m in commands.PIN_MODES]
    assert len(set(names)) == len(names)
    bits = [m.feature_bit for m in commands.PIN_MODES]
    assert len(set(bits)) == len(bits), "one Feature per pin mode"
    assert set(bits) <= {1 << v.number for v in pb.Feature.DESCRIPTOR.values if v.number != 0}
    for mode in commands.PIN_MODES:
        assert commands.COMMANDS[mode.init].pin_mode is mode
        assert commands.COMMANDS[mode.init].is_init
        assert commands.COMMANDS[mode.init].needs_init is None
        if mode.pins:
            assert mode.pins in pb.PinBit.DESCRIPTOR.values_by_name
        kinds = [mode.init]
        if mode.control is not None:
            assert commands.COMMANDS[mode.control].needs_init == mode.init
            kinds.append(mode.control)
        for kind in kinds:
            # Both carry the pin in a field named `pin` (the restore rule reads it).
            sub = pb.ArduinoIn.DESCRIPTOR.fields_by_name[kind].message_type
            assert sub is not None and "pin" in sub.fields_by_name


def test_undeclared_command_is_not_idempotent() -> None:
    assert commands.command("no_such_command").idempotent is False
    assert commands.command("servo_control").needs_init == "servo_init"
    assert commands.command("ping").needs_init is None


def test_the_firmware_has_no_table_of_its_own() -> None:
    """The device's dispatch expands the generated table (a missing handler cmd_<name> or a
    pin mode missing from PD_MODES fails the C build: an undeclared function, and a count
    that pd_outputs.c checks against PD_MODE_COUNT)."""
    dispatch = (ROOT / "firmware/core/pd_dispatch.c").read_text()
    assert '#include "pd_tables.h"' in dispatch
    assert "#define PD_COMMANDS" not in dispatch
    assert "enum {\n    PD_MODE_FREE" not in (ROOT / "firmware/core/pd_outputs.h").read_text()


def _tables_of(tmp_path: Path, edit: tuple[str, str]) -> cmdtables.Tables:
    """The tables of the schema with one edit (old, new) made in protoduino.proto."""
    source = (ROOT / "proto" / codegen.PROTO_NAME).read_text()
    assert source.count(edit[0]) == 1, edit[0]
    proto = tmp_path / "proto"
    proto.mkdir()
    (proto / codegen.PROTO_NAME).write_text(source.replace(*edit))
    (proto / codegen.OPTIONS_PROTO).write_text((ROOT / "proto" / codegen.OPTIONS_PROTO).read_text())
    desc = tmp_path / "schema.desc"
    codegen._protoc(
        ["-I.", "--include_imports", f"--descriptor_set_out={desc}", codegen.PROTO_NAME], proto
    )
    return cmdtables.read_tables(desc.read_bytes())


@pytest.mark.parametrize(
    ("edit", "complaint"),
    [
        (
            ('result: "ping_echo"', 'result: "no_such_result"'),
            "not an Ack.result member",
        ),
        (
            ('init: "counter_init"', 'init: "counter_start"'),
            "not an ArduinoIn.data member",
        ),
        (
            ('(command).feature = "FEATURE_DIGITAL_INPUT"', '(command).feature = "FEATURE_X"'),
            "not a Feature value",
        ),
        (
            ('pins: "PIN_PWM"', 'pins: "PIN_PMW"'),
            "not a PinBit flag",
        ),
        (
            ("Pose pose = 6 [(command).sets_output = true];", "Pose pose = 6;"),
            None,
        ),
        (
            ('{name: "counter" init: "counter_init"', '{name: "counter" init: "pwm_init"'),
            "already belongs to pwm",
        ),
    ],
)
def test_the_generator_checks_the_declarations(
    tmp_path: Path, edit: tuple[str, str], complaint: str | None
) -> None:
    """A declaration that names what the schema lacks stops `protoduino gen`; a valid edit
    reaches the generated table."""
    if complaint is None:
        tables = _tables_of(tmp_path, edit)
        pose = next(c for c in tables.commands if c.kind == "pose")
        assert pose.sets_output is False
        assert "X(pose, 1, 0, 0)" in cmdtables.c_header(tables)
        return
    with pytest.raises(cmdtables.TableError, match=complaint):
        _tables_of(tmp_path, edit)


def test_a_feature_off_by_default(tmp_path: Path) -> None:
    """A Feature declared off by default is 0 unless the build defines it, still has its
    DeviceInfo.features bit, and is not among make's FEATURES (nor the host's list of them)."""
    counter = '[(pin_mode) = {name: "counter" init: "counter_init" pins: "PIN_COUNTER"}];\n'
    extra = "  FEATURE_EXTRA = 8 [(feature).off_by_default = true];\n"  # 7 is FEATURE_USER
    tables = _tables_of(tmp_path, (counter, counter + extra))
    assert ("extra", 8, False) in tables.features
    assert ("user", 7, False) in tables.features  # the real one: user services
    header = cmdtables.c_header(tables)
    assert "#ifndef PD_FEATURE_EXTRA\n#define PD_FEATURE_EXTRA 0\n#endif" in header
    assert "#define PD_FEATURE_COUNTER 1\n" in header
    assert "(PD_FEATURE_EXTRA ? 1u << 8 : 0u)" in header
    assert "extra" not in cmdtables.make_fragment(tables)
    assert "'extra'" not in cmdtables.python_module(tables)
    assert "'counter'," in cmdtables.python_module(tables)
