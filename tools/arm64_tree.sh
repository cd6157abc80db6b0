#!/usr/bin/env bash
# An arm64 Debian tree like Raspberry Pi OS, from Debian's registry:
#
#   tools/arm64_tree.sh run [SUITE]   .deps/arm64/run-SUITE-<key>: Python and venv, nothing
#                                     else (what tests/e2e/test_pi.py installs a wheel into,
#                                     under qemu); SUITE bookworm (Debian 12, Raspberry Pi OS
#                                     12, Python 3.11; the default) or trixie (13, Python 3.13)
#   tools/arm64_tree.sh build         .deps/arm64/build-bookworm-<key>: the headers and
#                                     libraries the wheel's native parts link, the sysroot of
#                                     tools/build_wheels.sh
#
# ARCH=armhf in the environment makes the 32-bit tree (Raspberry Pi OS 32-bit) instead,
# as .deps/arm64/armhf-...; tools/build_wheels.sh uses its build tree for the armv7l wheel.
#
# Prints the tree's path. debootstrap --foreign fetches the packages and their dependencies;
# they are unpacked with dpkg -x, never configured (no maintainer script runs, no root needed
# beyond debootstrap's own), which takes about half a minute. A tree is cached under .deps/,
# keyed on its package list; an older one is removed.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
kind=${1:?usage: $0 run|build [SUITE]}
SUITE=${2:-bookworm}
ARCH=${ARCH:-arm64}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}

case "$kind" in
    run) PACKAGES=(python3 python3-venv) ;;
    build)
        [ "$SUITE" = bookworm ] || { echo "$0: the build tree is bookworm's (Python 3.11, glibc 2.36)" >&2; exit 2; }
        PACKAGES=(libc6-dev libpython3.11-dev libjansson-dev libsimavr-dev libelf-dev zlib1g-dev) ;;
    *) echo "usage: $0 run|build [SUITE]" >&2; exit 2 ;;
esac

key=$(printf '%s\n' "$ARCH" "$SUITE" "$MIRROR" "${PACKAGES[@]}" | sha256sum | cut -c1-12)
base="$root/.deps/arm64"
name=$kind-$SUITE
[ "$ARCH" = arm64 ] || name=$ARCH-$name
tree="$base/$name-$key"
if [ -f "$tree/.complete" ]; then
    echo "$tree"
    exit 0
fi
for tool in debootstrap dpkg; do
    command -v "$tool" >/dev/null || { echo "$0: needs $tool (Debian package $tool)" >&2; exit 1; }
done
mkdir -p "$base"
rm -rf "$base/$name"-* "$tree.tmp"
include=$(IFS=,; echo "${PACKAGES[*]}")
debootstrap --arch="$ARCH" --foreign --variant=minbase --include="$include" \
    "$SUITE" "$tree.tmp" "$MIRROR" >"$base/$name.log" 2>&1 ||
    { tail -20 "$base/$name.log" >&2; exit 1; }
for deb in "$tree.tmp"/var/cache/apt/archives/*.deb; do
    dpkg -x "$deb" "$tree.tmp"
done
rm -rf "$tree.tmp"/var/cache/apt/archives/*.deb "$tree.tmp/debootstrap"
touch "$tree.tmp/.complete"
mv "$tree.tmp" "$tree"
echo "$tree"
