#!/usr/bin/env bash
# Fetch uPlot, the live console's plotting library (protoduino console, docs/console.md), into
# an ignored folder: .deps/uplot/ (uPlot.iife.min.js, uPlot.min.css, LICENSE).
#
# uPlot is the npm package uplot 1.6.32 (MIT), pinned by version and sha256: a changed upload
# is refused. Nothing is fetched when the console runs, and no copy is stored in the
# repository: the wheel's build (setup.py) copies these files into the package data
# (protoduino/console/static/vendor/), and a checkout's console serves them from here.
# Needs `npm`, which tools/dev.sh installs (Debian's npm) before this runs.
set -euo pipefail

PACKAGE=uplot@1.6.32
SHA256=4b8a8191e425658e3ea8c8c1314b0fc679c861ee3a1af2b20c7b16ba50b5133d
MEMBERS=(package/dist/uPlot.iife.min.js package/dist/uPlot.min.css package/LICENSE)

root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/uplot"
if [ -f "$dest/uPlot.iife.min.js" ] && [ "$(cat "$dest/.sha256" 2>/dev/null)" = "$SHA256" ]; then
    exit 0
fi

if ! command -v npm >/dev/null 2>&1; then
    echo "fetch_uplot: npm is missing: tools/dev.sh setup installs it (Debian's npm)" >&2
    exit 1
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# npm pack only downloads the tarball: no install scripts run, nothing lands in node_modules.
(cd "$tmp" && npm pack --silent --cache "$tmp/npm-cache" "$PACKAGE" >/dev/null)
tarball=$(ls "$tmp"/uplot-*.tgz)
got=$(sha256sum "$tarball" | cut -d' ' -f1)
if [ "$got" != "$SHA256" ]; then
    echo "fetch_uplot: $PACKAGE tarball has sha256 $got, expected $SHA256: refusing it" >&2
    exit 1
fi
tar -xzf "$tarball" -C "$tmp" "${MEMBERS[@]}"
mkdir -p "$dest"
for member in "${MEMBERS[@]}"; do
    cp "$tmp/$member" "$dest/"
done
echo "$SHA256" >"$dest/.sha256"
echo "fetch_uplot: uPlot from $PACKAGE in $dest"
