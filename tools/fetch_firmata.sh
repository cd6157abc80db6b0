#!/usr/bin/env bash
# Fetch StandardFirmata's prebuilt Uno hex, the peer of the bench's race (bench/race.py), into an
# ignored folder: .deps/firmata/StandardFirmata.cpp.hex.
#
# The hex ships inside the npm package avrgirl-arduino 5.0.1 (junk/hex/uno/); it is the
# StandardFirmata 2.4 that the race measures unmodified. The tarball is pinned by version and
# sha256 (tools/fetch_npm.sh refuses a changed upload rather than measure it). Nothing is fetched
# when the bench runs: `python -m bench` only reads the cached file.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
exec "$root/tools/fetch_npm.sh" fetch_firmata avrgirl-arduino@5.0.1 \
    4b49db8316e2f38dcebf1b0de87eecd7ff4cc277e32501ccfc6edc2bc5755015 \
    "$root/.deps/firmata" \
    package/junk/hex/uno/StandardFirmata.cpp.hex
