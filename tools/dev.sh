#!/usr/bin/env bash
# One entry point for a fresh Debian 12 machine (README "Quick start"):
#
#   ./tools/dev.sh demo    set up, then run the demo against the simulated board
#   ./tools/dev.sh test    set up, then run the whole test suite (what CI runs)
#   ./tools/dev.sh setup   set up only
#
# Setup is idempotent: Debian packages (installed only when missing), a
# virtual environment in .venv with the package, its pinned dev extras and the
# development tools (dev/, the protoduino_dev package),
# the nanopb C runtime from Debian's source package (.deps/nanopb), and StandardFirmata's
# Uno hex from the npm registry for the bench's race (.deps/firmata).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
venv="$root/.venv"

APT_PACKAGES=(
    build-essential python3-venv           # native builds, virtual environment
    python3-dev                            # headers for the C accelerator protoduino._speedups
    gcc-avr binutils-avr avr-libc          # the Uno firmware
    arduino-core-avr                       # Optiboot sources for the flashing test
    arduino-builder                        # the Arduino IDE 1.8's builder: the user-service sketch's test
    simavr libsimavr-dev                   # the emulated Uno
    libjansson-dev                         # JSON of the simulated boards' control socket
    avrdude                                # flashing
    clang libclang-rt-14-dev               # libFuzzer + sanitizers for the C core
    ser2net                                # the RFC 2217 server of the remote-board test
    gcc-aarch64-linux-gnu debootstrap      # the aarch64 wheel (tools/build_wheels.sh) and its
    qemu-user-static binfmt-support        # arm64 tree, run under qemu (tests/e2e/test_pi.py)
    gcc-arm-linux-gnueabihf                # the armv7l wheel (32-bit Raspberry Pi OS)
)
#: Debian packages wanted for one command each, as package:command: missing only when the
#: command is too (NodeSource's nodejs, for one, ships its own npm and conflicts with Debian's).
APT_COMMANDS=(
    npm:npm                                # fetches StandardFirmata's hex (tools/fetch_firmata.sh)
)

log() { printf '\033[1m==> %s\033[0m\n' "$*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

setup_apt() {
    local missing=()
    for pkg in "${APT_PACKAGES[@]}"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "ok installed" || missing+=("$pkg")
    done
    for entry in "${APT_COMMANDS[@]}"; do
        command -v "${entry#*:}" >/dev/null 2>&1 || missing+=("${entry%%:*}")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        log "installing Debian packages: ${missing[*]}"
        as_root apt-get update -q
        as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
    fi
}

setup_venv() {
    if [ ! -x "$venv/bin/python" ]; then
        log "creating $venv"
        python3 -m venv "$venv"
    fi
    # Reinstall only when the dependency declarations changed.
    local stamp="$venv/.protoduino-deps"
    local want
    # setup.py's sources too: the editable install compiles protoduino._speedups from them.
    want=$(cat pyproject.toml dev/pyproject.toml constraints.txt tools/bench_setup.sh setup.py host/protoduino/_speedups.c \
        firmware/core/pd_cobs.[ch] firmware/core/pd_crc.[ch] firmware/generated/pd_protocol.h |
        sha256sum | cut -d' ' -f1)
    if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
        log "installing protoduino and its pinned dev dependencies into $venv"
        "$venv/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt pip setuptools
        "$venv/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[dev]" -e ./dev
        # The libraries the benchmarks compare against, so their smoke tests run too.
        VENV="$venv" "$root/tools/bench_setup.sh" >/dev/null
        echo "$want" >"$stamp"
    fi
}

setup() {
    setup_apt
    setup_venv
    "$root/tools/fetch_nanopb.sh"
    "$root/tools/fetch_firmata.sh"  # the bench race's peer (bench/race.py), from npm, pinned
}

cmd=${1:-}
shift || true
case "$cmd" in
    setup)
        setup
        ;;
    demo)
        setup
        exec "$venv/bin/protoduino" demo "$@"
        ;;
    test)
        setup
        export PATH="$venv/bin:$PATH"
        log "ruff"
        ruff check .
        ruff format --check .
        log "mypy (strict)"
        mypy
        log "pytest"
        exec pytest "$@"
        ;;
    *)
        echo "usage: $0 setup|demo|test [args...]" >&2
        exit 2
        ;;
esac
