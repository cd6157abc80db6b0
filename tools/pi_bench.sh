#!/usr/bin/env bash
# The bench's host-side figures on an emulated Raspberry Pi 4 beside this machine (issue 38):
#
#   tools/pi_bench.sh [OUTDIR]      default build/pi-bench; as root (chroot), after
#                                   ./tools/dev.sh setup
#
# The aarch64 wheel (tools/build_wheels.sh) is pip-installed into a fresh arm64 Debian 12
# tree (tools/arm64_tree.sh run), and there, under qemu-user with a Pi 4's CPU
# (QEMU_CPU=cortex-a72), run: the receive path (bench part 1, bench.receive, at --quick's size:
# 1,000 frames, 5 repetitions; the peers not installed there are left out; run alone, as
# python -m bench needs the development tools) and the host CPU per acked command against
# the simulated board (tools/hostcpu.py native). Then the same two on this machine. Writes
# receive-{aarch64,x86_64}.md and hostcpu-{aarch64,x86_64}.txt into OUTDIR.
#
# The aarch64 figures are EMULATED: qemu translates every arm64 instruction, so they say how
# the two paths compare under the same emulation, not how fast a real Pi is.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
out=$(realpath -m "${1:-$root/build/pi-bench}")
python=${PYTHON:-$root/.venv/bin/python}
log() { printf '\033[1m==> %s\033[0m\n' "$*" >&2; }
mkdir -p "$out"
work=$(mktemp -d "${TMPDIR:-/tmp}/protoduino-pi-bench-XXXXXX")
trap 'rm -rf "$work"' EXIT

log "the aarch64 wheel"
"$root/tools/build_wheels.sh" "$work/dist" aarch64 >/dev/null
wheel=$(echo "$work"/dist/protoduino-*_aarch64.whl)
tree="$work/tree"
cp -a "$("$root/tools/arm64_tree.sh" run)" "$tree"
cp /etc/resolv.conf "$tree/etc/resolv.conf"
mkdir -p "$tree/etc/ssl/certs" "$tree/work/tools" "$root/.deps/arm64/pip-cache-bookworm"
cp /etc/ssl/certs/ca-certificates.crt "$tree/etc/ssl/certs/"
cp "$wheel" "$root/constraints.txt" "$tree/tmp/"
cp -a "$root/bench" "$tree/work/bench"
cp "$root/tools/hostcpu.py" "$tree/work/tools/"
pi() {
    QEMU_CPU=cortex-a72 "$root/tools/arm64_run.sh" "$tree" "$root/.deps/arm64/pip-cache-bookworm" "$@"
}
log "installing it in an arm64 Debian 12 tree (qemu)"
pi python3 -m venv /opt/protoduino
pi pip install -q --disable-pip-version-check --cert /etc/ssl/certs/ca-certificates.crt \
    -c /tmp/constraints.txt "/tmp/$(basename "$wheel")"

cat >"$tree/work/receive_bench.py" <<'PY'
from bench import receive
from bench.core import Context

print(receive.run(Context(reps=5, frames=1000, chart_dir=None, profile=False)).markdown)
PY
log "receive path, emulated cortex-a72"
pi sh -c "cd /work && python receive_bench.py" >"$out/receive-aarch64.md" 2>"$out/receive-aarch64.log"
log "host CPU per command, emulated cortex-a72"
pi sh -c "cd /work && python tools/hostcpu.py native" >"$out/hostcpu-aarch64.txt" 2>&1
log "the same on this machine ($(uname -m))"
(cd "$root" && "$python" "$tree/work/receive_bench.py") >"$out/receive-x86_64.md" 2>"$out/receive-x86_64.log"
(cd "$root" && "$python" tools/hostcpu.py native) >"$out/hostcpu-x86_64.txt" 2>&1
ls "$out"
