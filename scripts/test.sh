#!/usr/bin/env bash
# README command two: installs what is missing, builds, and runs the whole test suite (ctest),
# then proves the runtime builds and passes its tests alone (-DPOSEFOREST_TRAINING=OFF).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
start=$(date +%s)
scripts/setup.sh
echo "== build (Release, full)"
scripts/build.sh
echo "== tests"
(cd build && ctest --output-on-failure -j"${POSEFOREST_JOBS:-$(nproc)}" --timeout 900)
echo "== runtime-only build (compiler + Eigen + OpenMP; no optional device back ends)"
POSEFOREST_BUILD_DIR="$root/build-runtime-only" scripts/build.sh -DPOSEFOREST_TRAINING=OFF -DPOSEFOREST_BENCH=OFF -DPOSEFOREST_DEVICES=OFF
(cd build-runtime-only && ctest --output-on-failure -j"${POSEFOREST_JOBS:-$(nproc)}" --timeout 900)
echo "== all tests passed in $(( $(date +%s) - start )) s"
