"""InputReport decoding (messages.input_values): masks and packed values, for any report."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from protoduino.errors import ProtocolError
from protoduino.messages import ArduinoOut, input_values, parse_out, pin_set

PINS = st.sets(st.integers(0, 31), max_size=8)


@given(
    digital=PINS,
    high=PINS,
    analog=st.dictionaries(st.integers(0, 31), st.integers(0, 1023), max_size=6),
    counts=st.dictionaries(st.integers(0, 31), st.integers(0, 2**32 - 1), max_size=4),
    time_ms=st.integers(0, 2**32 - 1),
)
def test_every_value_comes_back_by_kind_and_pin(
    digital: set[int], high: set[int], analog: dict[int, int], counts: dict[int, int], time_ms: int
) -> None:
    out = ArduinoOut()
    rep = out.input_report
    rep.time_ms = time_ms
    rep.digital_pins = pin_set(sum(1 << pin for pin in digital))
    rep.digital_levels = pin_set(sum(1 << pin for pin in high & digital))
    rep.analog_pins = pin_set(sum(1 << pin for pin in analog))
    rep.analog_values.extend(analog[pin] for pin in sorted(analog))
    rep.counter_pins = pin_set(sum(1 << pin for pin in counts))
    rep.counter_counts.extend(counts[pin] for pin in sorted(counts))
    wire = parse_out(out.SerializeToString()).input_report  # through the wire format
    found = input_values(wire)
    assert [(p, v) for k, p, v in found if k == "digital"] == [
        (p, p in high) for p in sorted(digital)
    ]
    assert {p: v for k, p, v in found if k == "analog"} == analog
    assert {p: v for k, p, v in found if k == "counter"} == counts
    assert all(isinstance(v, bool) for k, _, v in found if k == "digital")


@pytest.mark.parametrize("field", ["analog", "counter"])
def test_a_mask_that_disagrees_with_its_values_is_refused(field: str) -> None:
    out = ArduinoOut()
    rep = out.input_report
    if field == "analog":
        rep.analog_pins = pin_set(0b11 << 14)
        rep.analog_values.append(5)
    else:
        rep.counter_pins = pin_set(1 << 2)
        rep.counter_counts.extend([1, 2])
    with pytest.raises(ProtocolError, match=f"2 {field} pins|1 {field} pins"):
        input_values(rep)
