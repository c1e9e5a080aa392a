#!/usr/bin/env bash
# The runtime on 64-bit ARM Linux boards (aarch64: Raspberry Pi 4/5, Jetson, Rockchip), built on
# an x86-64 Debian 12 machine with Debian's cross toolchain and tested there under qemu-user:
#   scripts/cross-arm64.sh            all three steps below
#   scripts/cross-arm64.sh --build    install what is missing (apt-get), build build-arm64/: the
#                                     runtime-only configuration (library, C/C++ API, `poseforest`
#                                     inference commands, tests) for aarch64-linux-gnu
#   scripts/cross-arm64.sh --test     build, then run its tests: ctest, every program under
#                                     qemu-aarch64 (cmake/toolchains/aarch64-linux-gnu.cmake)
#   scripts/cross-arm64.sh --compare  build, then run `poseforest infer --labels --joints` of the
#                                     aarch64 and the x86-64 runtime on the same frames and forests
#                                     (a real Kinect frame, a render) and check the outputs agree
# No Python module: it needs the target's Python headers and NumPy (Debian's arm64 multiarch
# packages, i.e. dpkg --add-architecture arm64 on the build machine).
# Environment: POSEFOREST_ARM64_BUILD_DIR (default build-arm64), POSEFOREST_X86_BUILD_DIR (the
# x86-64 build to compare with; default build-runtime-only, configured if missing, else brought
# up to date in its own configuration),
# POSEFOREST_RENDER_BIN (a full build's `poseforest` that renders the compared frame; default
# build/bin/poseforest when it has `render`, else the tests' synthetic figure stands in),
# POSEFOREST_DATA_DIR, POSEFOREST_JOBS.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
step=${1:-all}
case $step in
all | --build | --test | --compare) ;;
*)
  sed -n '2,20p' "$0" >&2
  exit 2
  ;;
esac
arm=${POSEFOREST_ARM64_BUILD_DIR:-$root/build-arm64}
jobs=${POSEFOREST_JOBS:-$(nproc)}
toolchain=$root/cmake/toolchains/aarch64-linux-gnu.cmake
sysroot=/usr/aarch64-linux-gnu
emulator=(qemu-aarch64 -L "$sysroot" -E "LD_LIBRARY_PATH=$arm/deps/usr/lib/aarch64-linux-gnu:$arm/deps/lib/aarch64-linux-gnu")

# --- what it needs: the host's runtime packages (CMake, Eigen, Catch2), the cross g++ (with its
# libgomp and libstdc++ for arm64) and qemu-user; apt-get only when something is missing.
scripts/setup.sh --runtime
pkgs=(g++-aarch64-linux-gnu qemu-user)
missing=()
installed=$(dpkg-query -W -f='${db:Status-Status} ${Package}\n' "${pkgs[@]}" 2>/dev/null || true)
for p in "${pkgs[@]}"; do
  grep -qx "installed $p" <<<"$installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "cross-arm64: installing ${missing[*]}"
  SUDO=""
  if [[ $(id -u) -ne 0 ]]; then SUDO=sudo; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

# --- libspng and zlib for aarch64 (the runtime links them): Debian's arm64 packages, fetched by
# apt-get with a state folder of its own (no `dpkg --add-architecture` on this machine) and
# unpacked into $arm/deps, where the toolchain file looks (pkg-config, libraries, and qemu's
# LD_LIBRARY_PATH). Same versions as the host's.
deps=$arm/deps
if [[ ! -f $deps/usr/lib/aarch64-linux-gnu/pkgconfig/spng.pc ]]; then
  echo "== aarch64 libspng + zlib (Debian arm64 packages) into $deps"
  apt_dir=$arm/apt
  rm -rf "$deps" "$apt_dir"
  mkdir -p "$apt_dir/lists/partial" "$apt_dir/cache/archives/partial" "$apt_dir/debs" "$deps"
  apt_opts=(-q -o Dir::State::Lists="$apt_dir/lists" -o Dir::Cache="$apt_dir/cache" -o APT::Architecture=arm64
    -o APT::Architectures::=arm64 -o Debug::NoLocking=1)
  apt-get "${apt_opts[@]}" update >/dev/null
  debs=()
  for p in libspng0 libspng-dev zlib1g zlib1g-dev; do
    debs+=("$p:arm64=$(dpkg-query -W -f='${Version}' "$p")")
  done
  (cd "$apt_dir/debs" && apt-get "${apt_opts[@]}" download "${debs[@]}" 2>/dev/null)
  for d in "$apt_dir"/debs/*.deb; do dpkg-deb -x "$d" "$deps"; done
  # Paths inside the unpacked tree: .pc prefixes, and libz.so's absolute link.
  sed -i "s|^prefix=/usr|prefix=$deps/usr|" "$deps"/usr/lib/aarch64-linux-gnu/pkgconfig/{spng,zlib}.pc
  ln -sf ../../../lib/aarch64-linux-gnu/libz.so.1 "$deps/usr/lib/aarch64-linux-gnu/libz.so"
  rm -rf "$apt_dir"
fi

# --- build
echo "== aarch64 cross build (runtime only) into $arm"
t0=$(date +%s)
cmake -S "$root" -B "$arm" -DCMAKE_TOOLCHAIN_FILE="$toolchain" -DCMAKE_BUILD_TYPE=Release -DPOSEFOREST_CROSS_DEPS="$deps" \
  -DPOSEFOREST_TRAINING=OFF -DPOSEFOREST_BENCH=OFF -DPOSEFOREST_DEVICES=OFF -DPOSEFOREST_PYTHON=OFF >/dev/null
cmake --build "$arm" -j"$jobs"
readelf -h "$arm/bin/poseforest" | grep -q 'Machine: *AArch64' || {
  echo "cross-arm64: $arm/bin/poseforest is not an aarch64 program" >&2
  exit 1
}
echo "== aarch64 build: $(($(date +%s) - t0)) s"

# --- tests under qemu-aarch64
if [[ $step == all || $step == --test ]]; then
  echo "== aarch64 tests under $(qemu-aarch64 --version | head -1)"
  t0=$(date +%s)
  (cd "$arm" && ctest --output-on-failure -j"$jobs" --timeout 1800)
  echo "== aarch64 tests (emulated): $(($(date +%s) - t0)) s"
fi

# --- the same inference on both architectures
if [[ $step == all || $step == --compare ]]; then
  x86=${POSEFOREST_X86_BUILD_DIR:-$root/build-runtime-only}
  if [[ -f $x86/CMakeCache.txt ]]; then
    cmake --build "$x86" -j"$jobs" >/dev/null  # up to date with the sources, in its own configuration
  else
    echo "== x86-64 runtime-only build into $x86 (to compare with)"
    POSEFOREST_BUILD_DIR="$x86" scripts/build.sh -DPOSEFOREST_TRAINING=OFF -DPOSEFOREST_BENCH=OFF -DPOSEFOREST_DEVICES=OFF
  fi
  data=${POSEFOREST_DATA_DIR:-$root/../shared/data}
  work=$arm/compare
  rm -rf "$work"
  mkdir -p "$work/in"
  echo "== compare: aarch64 (qemu) and x86-64 ($x86) runtimes"
  # Forests: the tests' random 31-part forest (labels and joints), and PCL's three trained
  # depth-20 trees converted (labels: 25 parts, no joints).
  "$x86/bin/make_api_inputs" "$work/in" >/dev/null
  "$x86/bin/poseforest" import-pcl --out "$work/in/pcl.pff" \
    "$data"/pretrained/pcl_people_trees/forest{1,2,3}_tree_20.txt.bz2 >/dev/null 2>&1
  # Frames: a real Kinect v1 frame, and a render (a full build's EGL renderer; else the tests'
  # synthetic figure, ray-cast by make_api_inputs).
  real=$data/real/skeltrack_kinect_depth/depth-data-1028894671
  render_bin=${POSEFOREST_RENDER_BIN:-$root/build/bin/poseforest}
  if [[ -x $render_bin ]] && "$render_bin" help 2>&1 | grep -qw render; then
    "$render_bin" render --out "$work/render" --count 1 --seed 25 --threads 2 >/dev/null
    rendered=$work/render/depth_000000.png
  else
    echo "compare: no renderer (POSEFOREST_RENDER_BIN or build/bin/poseforest with \`render\`): the synthetic figure stands in"
    rendered=$work/in/person.raw
  fi
  cases=("forest.pff $real" "forest.pff $rendered" "pcl.pff $real" "pcl.pff $rendered")
  for arch in x86-64 aarch64; do
    for c in "${cases[@]}"; do
      read -r forest frame <<<"$c"
      out=$work/$arch/${forest%.pff}
      mkdir -p "$out"
      joints=()
      [[ $forest == forest.pff ]] && joints=(--joints)
      if [[ $arch == x86-64 ]]; then run=("$x86/bin/poseforest"); else run=("${emulator[@]}" "$arm/bin/poseforest"); fi
      t0=$EPOCHREALTIME
      "${run[@]}" infer --quiet --labels "${joints[@]}" --forest "$work/in/$forest" --out-dir "$out" "$frame"
      printf 'compare: %-7s infer %-10s %-24s %6.2f s\n' "$arch" "$forest" "$(basename "$frame")" \
        "$(awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN { print b - a }')"
    done
  done
  python3 "$root/scripts/compare-infer.py" "$work/x86-64" "$work/aarch64"
fi
