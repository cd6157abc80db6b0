#!/bin/sh
# Run a command in an arm64 tree (tools/arm64_tree.sh) under qemu-user, as root:
#
#   tools/arm64_run.sh TREE PIP_CACHE COMMAND [ARG...]
#
# In a private mount namespace (nothing stays mounted however it ends): the host's /dev (the
# boards' pseudo-terminals are the host's, by the same path) and a /proc, PIP_CACHE as the
# tree's pip cache; then chroot with a clean environment (PATH: /opt/protoduino/bin first),
# exec'd all the way so that a signal reaches the command. QEMU_CPU (e.g. cortex-a72, a Pi
# 4's CPU) passes through to qemu. binfmt_misc must run aarch64 programs (tests/e2e/test_pi.py
# mounts and enables it).
set -eu
[ $# -ge 3 ] || { echo "usage: $0 TREE PIP_CACHE COMMAND [ARG...]" >&2; exit 2; }
exec unshare --mount sh -c '
    mount --rbind /dev "$0/dev" && mount -t proc proc "$0/proc" &&
    mkdir -p "$0/root/.cache/pip" && mount --bind "$1" "$0/root/.cache/pip" && shift &&
    exec chroot "$0" /usr/bin/env -i PATH=/opt/protoduino/bin:/usr/bin:/bin HOME=/root "$@"
' "$@"
