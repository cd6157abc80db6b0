#!/usr/bin/env bash
# Fetch files out of one npm package's tarball into an ignored folder, pinned by version and
# sha256: a changed upload is refused. The declarations are the callers' (tools/fetch_firmata.sh,
# tools/fetch_uplot.sh); this is the one way they are fetched.
#
#   fetch_npm.sh NAME PACKAGE@VERSION SHA256 DEST MEMBER...
#
# Each MEMBER (a path inside the tarball, package/...) lands in DEST under its own file name;
# DEST/.sha256 records the tarball's, so a second run with the same pin fetches nothing. npm pack
# only downloads the tarball: no install scripts run, nothing lands in node_modules. Needs `npm`:
# Debian's npm package, which tools/dev.sh declares (APT_COMMANDS) and installs before this runs.
set -euo pipefail

if [ $# -lt 5 ]; then
    echo "usage: fetch_npm.sh NAME PACKAGE@VERSION SHA256 DEST MEMBER..." >&2
    exit 2
fi
name=$1 package=$2 sha256=$3 dest=$4
shift 4
members=("$@")

first=$(basename "${members[0]}")
if [ -f "$dest/$first" ] && [ "$(cat "$dest/.sha256" 2>/dev/null)" = "$sha256" ]; then
    exit 0
fi

if ! command -v npm >/dev/null 2>&1; then
    echo "$name: npm is missing: tools/dev.sh setup installs it (Debian's npm)" >&2
    exit 1
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm pack --silent --cache "$tmp/npm-cache" "$package" >/dev/null)
tarball=$(ls "$tmp"/*.tgz)
got=$(sha256sum "$tarball" | cut -d' ' -f1)
if [ "$got" != "$sha256" ]; then
    echo "$name: $package tarball has sha256 $got, expected $sha256: refusing it" >&2
    exit 1
fi
tar -xzf "$tarball" -C "$tmp" "${members[@]}"
mkdir -p "$dest"
for member in "${members[@]}"; do
    cp "$tmp/$member" "$dest/"
done
echo "$sha256" >"$dest/.sha256"
echo "$name: ${members[*]##*/} from $package in $dest"
