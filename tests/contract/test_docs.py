"""The docs say what the schema says: every field number they name, and the version.

docs/protocol.md is the normative text (its own first paragraph): a field number there that
is not the .proto's sends a reader of it to another field. So every place a document names a
schema field with its number, in any of the shapes the text uses (`` `Ack.user_reply` (6, ``,
`` `DeviceInfo.rx_buffer` (field 8) ``, `` (`ArduinoIn.pose`, 6) ``, `` `Ack.outputs`
(`OutputStates`, 30) ``), is checked against the generated descriptors, which are the .proto's.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from google.protobuf.descriptor import Descriptor
from protoduino import constants
from protoduino._generated import protoduino_pb2 as pb

ROOT = Path(__file__).resolve().parents[2]
DOCS = [*sorted((ROOT / "docs").glob("*.md")), ROOT / "README.md", ROOT / "firmware/README.md"]

#: `Message.field` then its number: "(6", "(field 8", "(`OutputStates`, 30", ", 6", ", field 8".
#: A number that starts a range ("(1..255)") is a value, not a field number.
FIELD_NUMBER = re.compile(
    r"`(?P<message>[A-Z]\w*)\.(?P<field>[a-z_]\w*)`"
    r"(?:\s*\((?:`\w+`,\s*)?|,\s*)(?:field\s+)?(?P<number>\d+)(?![.\d])"
)


def _messages() -> dict[str, Descriptor]:
    return dict(pb.DESCRIPTOR.message_types_by_name.items())


def field_numbers(text: str) -> list[tuple[str, str, int, int]]:
    """Each (message, field, number, line) ``text`` names, for a message of the schema."""
    messages = _messages()
    return [
        (m["message"], m["field"], int(m["number"]), text.count("\n", 0, m.start()) + 1)
        for m in FIELD_NUMBER.finditer(text)
        if m["message"] in messages
    ]


def test_the_pattern_reads_every_shape_the_text_uses() -> None:
    text = (
        "`Ack.user_reply` (6, in the oneof), `DeviceInfo.rx_buffer` (field 8), "
        "(`ArduinoIn.pose`, 6), `Ack.outputs`\n(`OutputStates`, 30), `Ack.user_code` (1..255),"
        " `Board.open` (2, not the schema's)"
    )
    assert [(m, f, n) for m, f, n, _ in field_numbers(text)] == [
        ("Ack", "user_reply", 6),
        ("DeviceInfo", "rx_buffer", 8),
        ("ArduinoIn", "pose", 6),
        ("Ack", "outputs", 30),
    ]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_field_number_a_doc_names_is_the_schemas(doc: Path) -> None:
    messages = _messages()
    wrong = []
    for message, field, number, line in field_numbers(doc.read_text(encoding="utf-8")):
        descriptor = messages[message].fields_by_name.get(field)
        if descriptor is None:
            wrong.append(f"line {line}: {message}.{field} is not in the schema")
        elif descriptor.number != number:
            wrong.append(
                f"line {line}: {message}.{field} is field {descriptor.number}, not {number}"
            )
    assert not wrong, f"{doc.relative_to(ROOT)}:\n" + "\n".join(wrong)


def test_protocol_md_names_fields_by_number() -> None:
    """The check above reads something: protocol.md names dozens of fields by number."""
    assert len(field_numbers((ROOT / "docs/protocol.md").read_text(encoding="utf-8"))) >= 15


def test_the_schema_and_the_protocol_text_name_the_protocol_version() -> None:
    version = constants.PROTOCOL_VERSION
    first = (ROOT / "proto/protoduino.proto").read_text(encoding="utf-8").splitlines()[0]
    assert f"wire protocol version {version}," in first, first
    title = (ROOT / "docs/protocol.md").read_text(encoding="utf-8").splitlines()[0]
    assert title == f"# The protoduino wire protocol, version {version}"


#: Where SimBoard's docstring and docs/api.md state each of the emulated Uno's trace limits:
#: (the limit's macro in tools/avrsim/pd_pins.h, the words whose quantity is that limit).
TRACE_LIMITS = (
    ("PD_PINS_PWM_STEADY_US", r"had no edge for (\S+ \w+)"),
    ("PD_PINS_MAX_PULSE_US", r"a high of at most (\S+ \w+) is a pulse"),
    ("PD_PINS_MAX_PERIOD_US", r"pulses at most (\S+ \w+) apart are a servo"),
    ("PD_PINS_MAX_PERIOD_US", r"value 0 once (\S+ \w+) passed without one"),
    ("PD_PINS_MAX_PERIOD_US", r"1 then 0 once (\S+ \w+) passed without another"),
    ("PD_PINS_LOW_WAIT_US", r"output low shows 0 once (\S+ \w+) passed"),
    ("PD_PINS_HYST_US", r"a change smaller than (\S+ \w+) does not show"),
)


def _pins_limits() -> dict[str, float]:
    header = (ROOT / "tools/avrsim/pd_pins.h").read_text(encoding="utf-8")
    found = re.findall(r"^#define (PD_PINS_\w+_US) ([\d.]+)U?L?\b", header, re.M)
    return {name: float(value) for name, value in found}


def _quantity(us: float) -> str:
    """A limit as the docs write it: "5 ms", "0.75 us"."""
    return f"{us / 1000:g} ms" if us >= 1000 else f"{us:g} us"


def _trace_limits_stated(text: str) -> dict[str, set[str]]:
    flat = " ".join(text.split())
    stated: dict[str, set[str]] = {}
    for macro, words in TRACE_LIMITS:
        found = re.findall(words, flat)
        assert len(found) == 1, f"{words!r} should be stated once, found {found}"
        stated.setdefault(macro, set()).add(found[0])
    return stated


def test_simboard_states_the_emulated_unos_trace_limits() -> None:
    """A SimBoard user has the docstring and docs/api.md, not tools/avrsim: both state the
    limits the runner's pin measurement has, with its numbers."""
    from protoduino.simboard import SimBoard

    limits = _pins_limits()
    assert set(limits) == {macro for macro, _ in TRACE_LIMITS}, "a limit the docs do not state"
    api = (ROOT / "docs/api.md").read_text(encoding="utf-8")
    for where, text in (("SimBoard's docstring", SimBoard.__doc__ or ""), ("docs/api.md", api)):
        stated = _trace_limits_stated(text)
        for macro, us in limits.items():
            assert stated[macro] == {_quantity(us)}, f"{where}: {macro} is {_quantity(us)}"


def test_a_wrong_limit_in_the_text_is_caught() -> None:
    """The comparison above reads the number the words give, whatever it is."""
    assert _quantity(5000) == "5 ms" and _quantity(0.75) == "0.75 us"
    text = (ROOT / "docs/api.md").read_text(encoding="utf-8")
    wrong = text.replace("had no edge for\n  5 ms", "had no edge for\n  8 ms", 1)
    assert wrong != text
    assert _trace_limits_stated(wrong)["PD_PINS_PWM_STEADY_US"] == {"8 ms"}
