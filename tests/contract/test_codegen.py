"""The committed generated code must be exactly what the schema generates."""

from __future__ import annotations

import re
from pathlib import Path

import protoduino
import pytest
from protoduino import constants
from protoduino._generated import protoduino_pb2 as pb
from protoduino_dev import codegen

ROOT = codegen.repo_root()


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, codegen.Result]:
    out = tmp_path_factory.mktemp("gen")
    return out, codegen.generate(out)


def test_every_generated_file_matches_the_committed_one(
    regenerated: tuple[Path, codegen.Result],
) -> None:
    out, _ = regenerated
    for rel in codegen.GENERATED_FILES:
        fresh = (out / rel).read_bytes()
        committed = (ROOT / rel).read_bytes()
        assert fresh == committed, f"{rel} is stale: run `protoduino gen` and commit"


def test_schema_id_is_the_same_on_both_sides(regenerated: tuple[Path, codegen.Result]) -> None:
    _, result = regenerated
    assert result.schema_id == protoduino.SCHEMA_ID
    header = (ROOT / "firmware/generated/pd_schema.h").read_text()
    assert f"#define PD_SCHEMA_ID 0x{result.schema_id:08X}UL" in header


def _generate_from(tmp_path: Path, text: str) -> tuple[Path, codegen.Result]:
    """Everything generated from ``text`` as protoduino.proto (the rest of proto/ as is)."""
    d = tmp_path / str(abs(hash(text)))
    (d / "proto").mkdir(parents=True)
    (d / "proto" / codegen.PROTO_NAME).write_text(text)
    for name in (codegen.OPTIONS_NAME, codegen.OPTIONS_PROTO):
        (d / "proto" / name).write_text((ROOT / "proto" / name).read_text())
    return d / "out", codegen.generate(d / "out", proto_dir=d / "proto")


def test_schema_id_ignores_comments_but_not_fields(tmp_path: Path) -> None:
    source = (ROOT / "proto" / codegen.PROTO_NAME).read_text()
    commented = "// an extra comment\n" + source.replace("\n\n", "\n\n// more\n", 3)
    assert _generate_from(tmp_path, commented)[1].schema_id == protoduino.SCHEMA_ID
    changed = source.replace("bool safe_level = 2;", "bool safe_level = 3;")
    assert changed != source
    assert _generate_from(tmp_path, changed)[1].schema_id != protoduino.SCHEMA_ID


def test_a_declaration_changes_both_tables_and_the_schema_id(tmp_path: Path) -> None:
    """Options are not on the wire, but a command's declaration is part of the schema both
    sides must share: Heartbeat made not idempotent changes SCHEMA_ID and both tables."""
    source = (ROOT / "proto" / codegen.PROTO_NAME).read_text()
    old = "Heartbeat heartbeat = 8 [(command).idempotent = true];"
    assert source.count(old) == 1
    out, result = _generate_from(tmp_path, source.replace(old, "Heartbeat heartbeat = 8;"))
    assert result.schema_id != protoduino.SCHEMA_ID
    header = (out / "firmware/generated/pd_tables.h").read_text()
    assert "X(heartbeat, 1, 0, 0)" in header
    assert (
        "X(heartbeat, 1, PD_CMD_IDEMPOTENT, 0)"
        in (ROOT / "firmware/generated/pd_tables.h").read_text()
    )
    table = (out / "host/protoduino/_generated/tables.py").read_text()
    assert "CommandRow('heartbeat', False," in table
    # The wire is the same: the nanopb code and the Python messages do not change.
    for rel in ("firmware/generated/protoduino.pb.c",):
        assert (out / rel).read_bytes() == (ROOT / rel).read_bytes()


#: The callback fields: the device's encoder writes them from the board's table and the
#: outputs' (pd_encode.h).
CALLBACK_FIELDS = ("DeviceInfo.pins", "DeviceInfo.timers", "OutputStates.servos")


def test_nanopb_bounds_every_variable_field() -> None:
    """Every bytes, string and repeated field has a bound; the only callback fields are the
    pin table's and ReadOutputs' servos, bounded too (max_size), and every message nanopb
    could not size for them has its size with them at their bound (codegen.sized_callbacks)."""
    header = (ROOT / "firmware/generated/protoduino.pb.h").read_text()
    assert header.count("pb_callback_t") == len(CALLBACK_FIELDS)
    assert "depends on runtime parameters" not in header
    assert "#define protoduino_DeviceInfo_size" in header
    variable = [
        f"{m.name}.{f.name}"
        for m in pb.DESCRIPTOR.message_types_by_name.values()
        for f in m.fields
        if f.type in (f.TYPE_BYTES, f.TYPE_STRING) or f.is_repeated
    ]
    assert variable  # the schema has some, and each is bounded in .options
    options = (ROOT / "proto" / codegen.OPTIONS_NAME).read_text()
    for name in variable:
        assert f"protoduino.{name} " in options, name
    for name in CALLBACK_FIELDS:
        assert re.search(rf"^protoduino\.{name}\s+type:FT_CALLBACK max_size:\d+$", options, re.M)


def _protocol_macros() -> dict[str, int]:
    text = (ROOT / "firmware/generated/pd_protocol.h").read_text()
    found = re.findall(r"^#define (PD_\w+) (0x[0-9A-Fa-f]+|\d+)U?L?$", text, re.MULTILINE)
    return {name: int(value, 0) for name, value in found}


def test_pd_protocol_h_carries_constants_py_values() -> None:
    """Read back from the committed header: every listed constant and enum member, in C units."""
    macros = _protocol_macros()
    expected: dict[str, int] = {}
    for name in constants.FIRMWARE_CONSTANTS:
        value = getattr(constants, name)
        if isinstance(value, float):  # seconds on the host, milliseconds on the device
            expected[f"PD_{name}_MS"] = round(value * 1000)
        else:
            expected[f"PD_{name}"] = value
    for prefix, enum in constants.FIRMWARE_ENUMS.items():
        expected.update({f"PD_{prefix}_{m.name}": m.value for m in enum})
    assert macros == expected
    assert macros["PD_FAILSAFE_TIMEOUT_MS"] == 10_000


def test_pd_protocol_h_carries_only_what_the_firmware_uses() -> None:
    """A constant the C code never uses belongs to the host alone: it stays out of the header."""
    sources = [
        p
        for folder in ("firmware/core", "firmware/avr", "firmware/posix")
        for p in sorted((ROOT / folder).glob("*.[ch]"))
    ]
    text = "\n".join(p.read_text() for p in sources)
    unused = [name for name in _protocol_macros() if not re.search(rf"\b{name}\b", text)]
    assert unused == [], f"not used by the firmware: {unused} (drop them from FIRMWARE_*)"
