#!/usr/bin/env bash
# Fetch StandardFirmata's prebuilt Uno hex, the peer of the bench's race (bench/race.py), into an
# ignored folder: .deps/firmata/StandardFirmata.cpp.hex.
#
# The hex ships inside the npm package avrgirl-arduino 5.0.1 (junk/hex/uno/); it is the
# StandardFirmata 2.4 that the race measures unmodified. The tarball is pinned by version and
# sha256, so a changed upload is refused rather than measured. Nothing is fetched when the bench
# runs: `python -m bench` only reads the cached file. Needs `npm`: Debian's npm package, which
# tools/dev.sh declares beside every other Debian package (APT_COMMANDS) and installs, when no
# npm is on the PATH, before this runs.
set -euo pipefail

PACKAGE=avrgirl-arduino@5.0.1
SHA256=4b49db8316e2f38dcebf1b0de87eecd7ff4cc277e32501ccfc6edc2bc5755015
MEMBER=package/junk/hex/uno/StandardFirmata.cpp.hex

root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/firmata"
if [ -f "$dest/StandardFirmata.cpp.hex" ] && [ "$(cat "$dest/.sha256" 2>/dev/null)" = "$SHA256" ]; then
    exit 0
fi

if ! command -v npm >/dev/null 2>&1; then
    echo "fetch_firmata: npm is missing: tools/dev.sh setup installs it (Debian's npm)" >&2
    exit 1
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# npm pack only downloads the tarball: no install scripts run, nothing lands in node_modules.
(cd "$tmp" && npm pack --silent --cache "$tmp/npm-cache" "$PACKAGE" >/dev/null)
tarball=$(ls "$tmp"/avrgirl-arduino-*.tgz)
got=$(sha256sum "$tarball" | cut -d' ' -f1)
if [ "$got" != "$SHA256" ]; then
    echo "fetch_firmata: $PACKAGE tarball has sha256 $got, expected $SHA256: refusing it" >&2
    exit 1
fi
tar -xzf "$tarball" -C "$tmp" "$MEMBER"
mkdir -p "$dest"
cp "$tmp/$MEMBER" "$dest/StandardFirmata.cpp.hex"
echo "$SHA256" >"$dest/.sha256"
echo "fetch_firmata: StandardFirmata's Uno hex from $PACKAGE in $dest"
