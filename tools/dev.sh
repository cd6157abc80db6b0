#!/usr/bin/env bash
# One entry point for a fresh Debian 12 machine (README "Quick start"):
#
#   ./tools/dev.sh demo    set up what the demo needs, then run it against the simulated board
#   ./tools/dev.sh test    set up everything, then run the whole test suite (what CI runs)
#   ./tools/dev.sh setup   set up everything, run nothing
#
# Setup is idempotent. The demo's (setup_demo) is what the native simulated board and the
# package need: the Debian packages that build it (DEMO_APT_PACKAGES), a virtual environment
# in .venv with the package and the development tools (dev/, the protoduino_dev package,
# which builds the board from the checkout), and the nanopb C runtime from Debian's source
# package (.deps/nanopb). The full one (setup) adds what the suite needs beyond that: the
# other Debian packages (the Uno's toolchain, simavr, clang, ...), the pinned dev extras,
# the bench's peers, StandardFirmata's Uno hex from the npm registry for the bench's race
# (.deps/firmata), uPlot from the npm registry for the live console's plots
# (.deps/uplot), and a real ROS 2 node's client library in a venv of its own
# (.deps/ros2-venv: ROS 2's rclpy and rmw_fastrtps_cpp wheels, pinned in constraints.txt, for
# tests/e2e/test_ros2_real.py).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
venv="$root/.venv"

#: What the demo needs: the native simulated board and the package.
DEMO_APT_PACKAGES=(
    build-essential python3-venv           # native builds, virtual environment
    python3-dev                            # headers for the C accelerator protoduino._speedups
    libjansson-dev                         # JSON of the simulated boards' control socket
)
#: What the whole suite needs beyond the demo's.
APT_PACKAGES=(
    gcc-avr binutils-avr avr-libc          # the Uno firmware
    arduino-core-avr                       # Optiboot sources for the flashing test
    arduino-builder                        # the Arduino IDE 1.8's builder: the user-service sketch's test
    simavr libsimavr-dev                   # the emulated Uno
    avrdude                                # flashing
    clang libclang-rt-14-dev               # libFuzzer + sanitizers for the C core
    ser2net                                # the RFC 2217 server of the remote-board test
    chromium chromium-driver               # the live console's browser tests (Selenium)
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

# setup_apt PACKAGE... [-- PACKAGE:COMMAND...]: install the packages that are missing.
setup_apt() {
    local missing=() commands=false
    for arg in "$@"; do
        if [ "$arg" = "--" ]; then
            commands=true
        elif $commands; then
            command -v "${arg#*:}" >/dev/null 2>&1 || missing+=("${arg%%:*}")
        else
            dpkg-query -W -f='${Status}' "$arg" 2>/dev/null | grep -q "ok installed" || missing+=("$arg")
        fi
    done
    if [ ${#missing[@]} -gt 0 ]; then
        log "installing Debian packages: ${missing[*]}"
        as_root apt-get update -q
        as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
    fi
}

# setup_venv demo|full: the package and the development tools (demo), plus the pinned dev
# extras and the bench's peers (full). Reinstalled only when the dependency declarations
# changed; a full install serves the demo too.
setup_venv() {
    local profile=$1
    if [ ! -x "$venv/bin/python" ]; then
        log "creating $venv"
        python3 -m venv "$venv"
    fi
    local full_stamp="$venv/.protoduino-deps" demo_stamp="$venv/.protoduino-deps-demo"
    local want
    # setup.py's sources too: the editable install compiles protoduino._speedups from them.
    want=$(cat pyproject.toml dev/pyproject.toml constraints.txt tools/bench_setup.sh setup.py host/protoduino/_speedups.c \
        firmware/core/pd_cobs.[ch] firmware/core/pd_crc.[ch] firmware/generated/pd_protocol.h |
        sha256sum | cut -d' ' -f1)
    if [ "$(cat "$full_stamp" 2>/dev/null)" = "$want" ]; then
        return
    fi
    local pip=("$venv/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt)
    if [ "$profile" = demo ]; then
        if [ "$(cat "$demo_stamp" 2>/dev/null)" != "$want" ]; then
            log "installing protoduino and the development tools into $venv"
            "${pip[@]}" pip setuptools
            "${pip[@]}" -e . -e ./dev
            echo "$want" >"$demo_stamp"
        fi
        return
    fi
    log "installing protoduino and its pinned dev dependencies into $venv"
    "${pip[@]}" pip setuptools
    "${pip[@]}" -e ".[dev]" -e ./dev
    # The libraries the benchmarks compare against, so their smoke tests run too.
    VENV="$venv" "$root/tools/bench_setup.sh" >/dev/null
    echo "$want" >"$full_stamp"
}

#: The ROS 2 wheels of the real node (tests/e2e/test_ros2_real.py); versions in constraints.txt.
ROS2_PACKAGES=(
    ros-rclpy ros-rmw-fastrtps-cpp                                   # ROS 2's client, its default RMW
    ros-std-msgs ros-geometry-msgs ros-sensor-msgs ros-diagnostic-msgs ros-std-srvs  # the bridge's types
    ros-nav-msgs                                                     # its odometry (bench part 8)
)

# setup_ros2_venv: ROS 2's Python client on Fast DDS in .deps/ros2-venv, apart from .venv (its
# wheels bring their own rosidl/numpy stack and about 260 MB). Reinstalled when the pins change.
setup_ros2_venv() {
    local ros2_venv="$root/.deps/ros2-venv" want
    want=$(printf '%s\n' "${ROS2_PACKAGES[@]}" | cat - constraints.txt | sha256sum | cut -d' ' -f1)
    if [ "$(cat "$ros2_venv/.protoduino-deps" 2>/dev/null)" = "$want" ]; then
        return
    fi
    log "installing ROS 2's rclpy and rmw_fastrtps_cpp into $ros2_venv"
    [ -x "$ros2_venv/bin/python" ] || python3 -m venv "$ros2_venv"
    "$ros2_venv/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt \
        "${ROS2_PACKAGES[@]}"
    echo "$want" >"$ros2_venv/.protoduino-deps"
}

# What the demo needs, and no more: the native simulated board and the package.
setup_demo() {
    setup_apt "${DEMO_APT_PACKAGES[@]}"
    setup_venv demo
    "$root/tools/fetch_nanopb.sh"
}

# Everything the suite needs (CI: .ci/run -> ./tools/dev.sh test).
setup() {
    setup_apt "${DEMO_APT_PACKAGES[@]}" "${APT_PACKAGES[@]}" -- "${APT_COMMANDS[@]}"
    setup_venv full
    "$root/tools/fetch_nanopb.sh"
    "$root/tools/fetch_firmata.sh"  # the bench race's peer (bench/race.py), from npm, pinned
    setup_ros2_venv
    "$root/tools/fetch_uplot.sh"    # the live console's plots (protoduino console), from npm, pinned
}

cmd=${1:-}
shift || true
case "$cmd" in
    setup)
        setup
        ;;
    demo)
        setup_demo
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
