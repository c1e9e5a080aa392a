#!/usr/bin/env bash
# Configures and builds poseforest in Release into ./build (or $POSEFOREST_BUILD_DIR).
# Extra arguments go to cmake's configure step, e.g. -DPOSEFOREST_TRAINING=OFF.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${POSEFOREST_BUILD_DIR:-$root/build}
jobs=${POSEFOREST_JOBS:-$(nproc)}
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$build" -j"$jobs"
