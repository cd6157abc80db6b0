#!/usr/bin/env bash
# Fetch uPlot, the live console's plotting library (protoduino console, docs/console.md), into
# an ignored folder: .deps/uplot/ (uPlot.iife.min.js, uPlot.min.css, LICENSE).
#
# uPlot is the npm package uplot 1.6.32 (MIT), pinned by version and sha256 (tools/fetch_npm.sh
# refuses a changed upload). Nothing is fetched when the console runs, and no copy is stored in
# the repository: the wheel's build (setup.py) copies these files into the package data
# (protoduino/console/static/vendor/), and a checkout's console serves them from here.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
exec "$root/tools/fetch_npm.sh" fetch_uplot uplot@1.6.32 \
    4b8a8191e425658e3ea8c8c1314b0fc679c861ee3a1af2b20c7b16ba50b5133d \
    "$root/.deps/uplot" \
    package/dist/uPlot.iife.min.js package/dist/uPlot.min.css package/LICENSE
