"""The Arduino library's user-service example, built the way the IDE builds it, then run.

``make -C firmware arduino-zip`` puts the blinker of examples/blinker in the library as the
sketch ``ProtoduinoService`` (its handlers and what ``protoduino gen`` wrote). The test
installs the zip as "Add .ZIP Library" would, switches the service on and a pin mode the
sketch does not use (counters, analog inputs) off in the installed library's ``src/pd_config.h`` as
docs/services.md says, and compiles the sketch with Debian's
``arduino-builder`` (the Arduino IDE 1.8's own builder) and the Arduino core; then the ELF it
made runs on the emulated Uno and answers the service's generated client.
"""

from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import protoduino
import protoduino.cli.main
import pytest
from protoduino.simboard import SimBoard
from simfixtures import wait_for_pin
from test_arduino_lib import BOARDS, arduino_build, flash_size

pytestmark = pytest.mark.avr

ROOT = Path(__file__).resolve().parents[2]
HARDWARE = Path("/usr/share/arduino/hardware")


def _missing() -> str | None:
    for tool in ("make", "gcc", "avr-gcc", "arduino-builder"):
        if shutil.which(tool) is None:
            return tool
    if not (HARDWARE / "arduino" / "avr" / "cores" / "arduino" / "Arduino.h").exists():
        return "arduino-core-avr (the Arduino core)"
    return None


def test_the_service_sketch_builds_with_arduino_builder_and_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    missing = _missing()
    if missing is not None:
        pytest.skip(f"{missing} is not installed")
    made = subprocess.run(
        ["make", "-s", "-C", str(ROOT / "firmware"), "arduino-zip"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert made.returncode == 0, made.stderr
    libraries = tmp_path / "libraries"
    with zipfile.ZipFile(ROOT / "build" / "arduino" / "Protoduino.zip") as z:
        z.extractall(libraries)
    config = libraries / "protoduino" / "src" / "pd_config.h"
    text = config.read_text()
    off = ("#define PD_FEATURE_COUNTER 1", "#define PD_FEATURE_ANALOG_INPUT 1")
    assert "#define PD_FEATURE_USER 0" in text and all(line in text for line in off)
    # The service on, and two pin modes the sketch does not use off (docs/services.md): with
    # every pin mode the IDE's build of the blinker is past the Uno's 32,256 B.
    text = text.replace("#define PD_FEATURE_USER 0", "#define PD_FEATURE_USER 1")
    for line in off:
        text = text.replace(line, line[:-1] + "0")
    config.write_text(text)
    sketch = tmp_path / "ProtoduinoService"
    shutil.copytree(libraries / "protoduino" / "examples" / "ProtoduinoService", sketch)
    elf = arduino_build(
        sketch / "ProtoduinoService.ino", libraries, tmp_path / "build", BOARDS["uno"].fqbn
    )
    assert flash_size(elf) <= BOARDS["uno"].max_size

    # The sketch's firmware on the emulated Uno, called through the generated client.
    gen = tmp_path / "gen"
    assert (
        protoduino.cli.main.main(
            ["gen", str(ROOT / "examples/blinker/blinker.proto"), "--out", str(gen)]
        )
        == 0
    )
    monkeypatch.syspath_prepend(str(gen))
    for module in ("blinker_client", "blinker_pb2"):
        sys.modules.pop(module, None)
    client = importlib.import_module("blinker_client")
    with SimBoard("avr", trace=tmp_path / "trace.jsonl", firmware=elf) as sim:
        sim.start()
        with protoduino.Board.open(sim.port) as board:
            blinker = client.Blinker(board)
            reply = blinker.start_blink(client.pb.Blink(pin=13, period_ms=40))
            assert reply.half_ms == 20
            assert wait_for_pin(sim, 13, lambda v: len(v) >= 4)[:4] == [1, 0, 1, 0]
            board.stop()
            wait_for_pin(sim, 13, lambda v: v[-1] == 0)
            assert not blinker.count(client.pb.Empty()).on
