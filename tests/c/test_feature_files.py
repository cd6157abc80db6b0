"""Each pin mode's file is behind its feature switch (issue 36, item 5): built without the
feature (``make -C firmware avr FEATURES=...`` leaves ``PD_FEATURE_<NAME>`` 0), the file
compiles to nothing, and built with it, it defines its mode's functions.

Its callers test the same switch (the pin-mode table in ``pd_outputs.c``, the command table
in ``pd_dispatch.c``, the inputs' poll in ``pd_inputs.c``), so a build without the feature
links without the file's code; the subset builds that prove it: tests/c/test_footprint.py and
the e2e tests' ``FEATURES=`` builds. Here each file alone, compiled natively with the
project's warnings.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "firmware" / "core"
INCLUDES = ("-I", str(CORE), "-I", str(ROOT / "firmware" / "generated"))
NANOPB = ROOT / ".deps" / "nanopb"

#: Each pin mode's file, its feature switch and a function it defines when built.
MODE_FILES = (
    ("pd_servo.c", "PD_FEATURE_SERVO", "pd_servo_safe"),
    ("pd_digital.c", "PD_FEATURE_DIGITAL_OUTPUT", "pd_digital_safe"),
    ("pd_pwm.c", "PD_FEATURE_PWM", "pd_pwm_safe"),
    ("pd_digital_input.c", "PD_FEATURE_DIGITAL_INPUT", "pd_inputs_digital_init"),
    ("pd_analog_input.c", "PD_FEATURE_ANALOG_INPUT", "pd_inputs_analog_init"),
    ("pd_counter.c", "PD_FEATURE_COUNTER", "pd_inputs_counter_init"),
)


def defined_symbols(source: Path, tmp_path: Path, feature: str, on: bool) -> set[str]:
    """The symbols the object of `source` defines, built with `feature` on or off."""
    obj = tmp_path / f"{source.stem}_{int(on)}.o"
    subprocess.run(
        [
            "gcc", "-std=c99", "-Os", "-Wall", "-Wextra", "-Werror", "-c",
            *INCLUDES, "-I", str(NANOPB), f"-D{feature}={int(on)}",
            str(source), "-o", str(obj),
        ],
        check=True,
        capture_output=True,
        text=True,
    )  # fmt: skip
    listing = subprocess.run(
        ["nm", "--defined-only", str(obj)], check=True, capture_output=True, text=True
    ).stdout
    return {line.split()[-1] for line in listing.splitlines() if line.strip()}


@pytest.mark.parametrize(("name", "feature", "function"), MODE_FILES)
def test_a_modes_file_compiles_to_nothing_without_its_feature(
    tmp_path: Path, name: str, feature: str, function: str
) -> None:
    for tool in ("gcc", "nm"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed (Debian packages gcc, binutils)")
    if not (NANOPB / "pb.h").exists():
        pytest.skip("the nanopb runtime is not fetched (./tools/dev.sh setup)")
    assert function in defined_symbols(CORE / name, tmp_path, feature, on=True)
    assert defined_symbols(CORE / name, tmp_path, feature, on=False) == set()
