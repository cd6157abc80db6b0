#!/usr/bin/env bash
# Fetch the nanopb C runtime (pb_encode.c, pb_decode.c, pb_common.c and headers)
# from Debian's nanopb *source* package into an ignored folder.
#
# Why this dance: no PyPI wheel and no Debian binary package ships the runtime
# sources, and the runtime must match the generator version pinned in
# pyproject.toml (nanopb==0.4.7). We never copy third-party source into the
# repository; we point a private apt instance at a deb-src list derived from
# the machine's own Debian sources and leave the system's apt config alone.
set -euo pipefail

NANOPB_VERSION=0.4.7
root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/nanopb"
if [ -f "$dest/pb_decode.c" ] && [ "$(cat "$dest/.version" 2>/dev/null)" = "$NANOPB_VERSION" ]; then
    exit 0
fi

work="$root/.deps/apt"
mkdir -p "$work/lists/partial" "$work/cache/archives/partial" "$work/sources.list.d" "$work/dl"

# Derive a deb-src entry from the machine's Debian entry (deb822 or one-line form).
src="$work/sources.list.d/protoduino-src.sources"
if ls /etc/apt/sources.list.d/*.sources >/dev/null 2>&1 && \
   grep -l -E '^URIs:.*debian' /etc/apt/sources.list.d/*.sources >/dev/null 2>&1; then
    main_src=$(grep -l -E '^URIs:.*debian/?$' /etc/apt/sources.list.d/*.sources | head -n1)
    # keep only the first stanza (the main archive), turn it into deb-src
    awk 'BEGIN{RS=""; ORS="\n\n"} NR==1' "$main_src" | sed -e 's/^Types:.*/Types: deb-src/' >"$src"
else
    line=$(grep -hE '^deb\s' /etc/apt/sources.list 2>/dev/null | grep -v security | head -n1)
    if [ -z "$line" ]; then
        echo "fetch_nanopb: no Debian apt source found in /etc/apt" >&2
        exit 1
    fi
    echo "deb-src${line#deb}" >"$work/sources.list.d/protoduino-src.list"
    src="$work/sources.list.d/protoduino-src.list"
fi

opts=(-o "Dir::State::Lists=$work/lists" -o "Dir::Cache=$work/cache"
      -o "Dir::Etc::SourceList=/dev/null" -o "Dir::Etc::SourceParts=$work/sources.list.d"
      -o "Debug::NoLocking=1" -o "APT::Sandbox::User=root" -q)
apt-get "${opts[@]}" update >/dev/null
(cd "$work/dl" && apt-get "${opts[@]}" source --download-only nanopb >/dev/null)

tarball=$(ls "$work"/dl/nanopb_"$NANOPB_VERSION"*.orig.tar.* | head -n1)
tmp=$(mktemp -d)
tar -xf "$tarball" -C "$tmp"
srcdir=$(find "$tmp" -maxdepth 2 -name pb_decode.c -printf '%h\n' | head -n1)
rm -rf "$dest"
mkdir -p "$dest"
cp "$srcdir"/pb.h "$srcdir"/pb_common.[ch] "$srcdir"/pb_encode.[ch] "$srcdir"/pb_decode.[ch] "$srcdir"/LICENSE.txt "$dest"/
echo "$NANOPB_VERSION" >"$dest/.version"
rm -rf "$tmp"
echo "fetch_nanopb: nanopb $NANOPB_VERSION runtime in $dest"
