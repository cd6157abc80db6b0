"""The committed generated code must be exactly what the schema generates."""

from __future__ import annotations

from pathlib import Path

import protoduino
import pytest
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


def test_schema_id_ignores_comments_but_not_fields(tmp_path: Path) -> None:
    source = (ROOT / "proto" / codegen.PROTO_NAME).read_text()
    options = (ROOT / "proto" / codegen.OPTIONS_NAME).read_text()

    def schema_id_of(text: str) -> int:
        d = tmp_path / str(abs(hash(text)))
        (d / "proto").mkdir(parents=True)
        (d / "proto" / codegen.PROTO_NAME).write_text(text)
        (d / "proto" / codegen.OPTIONS_NAME).write_text(options)
        return codegen.generate(d / "out", proto_dir=d / "proto").schema_id

    commented = "// an extra comment\n" + source.replace("\n\n", "\n\n// more\n", 3)
    assert schema_id_of(commented) == protoduino.SCHEMA_ID
    changed = source.replace("bool safe_level = 2;", "bool safe_level = 3;")
    assert changed != source
    assert schema_id_of(changed) != protoduino.SCHEMA_ID


def test_nanopb_bounds_every_variable_field() -> None:
    """No callback fields: every bytes, string and repeated field has a bound."""
    header = (ROOT / "firmware/generated/protoduino.pb.h").read_text()
    assert "pb_callback_t" not in header
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
