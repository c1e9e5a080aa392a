#!/usr/bin/env bash
# README command two: installs what is missing, builds, and runs the whole test suite (ctest),
# then proves the runtime builds and passes its tests alone (-DPOSEFOREST_TRAINING=OFF), and
# for 64-bit ARM (scripts/cross-arm64.sh: cross-built, tested under qemu-user, compared).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
start=$(date +%s)
scripts/setup.sh
echo "== build (Release, full)"
scripts/build.sh
echo "== tests"
(cd build && ctest --output-on-failure -j"${POSEFOREST_JOBS:-$(nproc)}" --timeout 900)
echo "== runtime-only build (compiler + Eigen + OpenMP + libspng; no optional device back ends)"
POSEFOREST_BUILD_DIR="$root/build-runtime-only" scripts/build.sh -DPOSEFOREST_TRAINING=OFF -DPOSEFOREST_BENCH=OFF -DPOSEFOREST_DEVICES=OFF
(cd build-runtime-only && ctest --output-on-failure -j"${POSEFOREST_JOBS:-$(nproc)}" --timeout 900)
echo "== aarch64 (64-bit ARM boards): cross build, its tests under qemu-user, same outputs as x86-64"
scripts/cross-arm64.sh
echo "== all tests passed in $(( $(date +%s) - start )) s"
