#!/usr/bin/env bash
# The installed runtime consumed from outside, as an application uses it (ctest runs each step
# as a test; tests/runtime/CMakeLists.txt sets the PF_* variables):
#   install    cmake --install into a fresh prefix; check what is there; write the inputs; run
#              the installed `poseforest infer` on them (the reference outputs)
#   symbols    the shared library exports exactly the functions poseforest.h declares (pf_*),
#              its SONAME, the installed headers include nothing internal
#   cmake      examples/ built by an out-of-tree CMake project (find_package), C, C++ and C++
#              static; the find_package version rule
#   pkgconfig  examples/ built by a plain Makefile with pkg-config, C and C++
#   python     the Python module imported from the prefix: examples/classify.py and
#              tests/runtime/python_api_check.py (results equal the CLI's byte for byte)
# A cross build (cmake/toolchains/) also sets PF_EMULATOR (e.g. "qemu-aarch64 -L SYSROOT": the
# built programs run through it), PF_NM (the target's nm), PF_TOOLCHAIN_FILE (for the
# examples' CMake project) and PF_CROSS_DEPS (where the toolchain finds the target's libspng and zlib).
set -euo pipefail
step=${1:?usage: consumers.sh install|symbols|cmake|pkgconfig|python}
for v in PF_CMAKE PF_BUILD_DIR PF_SOURCE_DIR PF_WORK PF_VERSION PF_SOVERSION PF_LIBDIR PF_BINDIR PF_INCLUDEDIR \
  PF_DOCDIR PF_PYDIR; do
  [[ -n ${!v:-} ]] || { echo "consumers.sh: $v is not set (run through ctest)" >&2; exit 2; }
done
prefix=$PF_WORK/prefix
inputs=$PF_WORK/inputs
lib=$prefix/$PF_LIBDIR

fail() {
  echo "FAIL: $*" >&2
  exit 1
}
# run PROGRAM ARGS...: a program built for the target (through PF_EMULATOR in a cross build).
read -r -a emulator <<<"${PF_EMULATOR:-}"
run() { "${emulator[@]}" "$@"; }
# libs PROGRAM: the shared libraries it loads, as ldd lists them (the target's loader, asked
# through the emulator, in a cross build).
libs() {
  if ((${#emulator[@]})); then run -E LD_TRACE_LOADED_OBJECTS=1 "$1"; else ldd "$1"; fi
}
# same FILE_A FILE_B WHAT: byte-identical files
same() {
  cmp "$1" "$2" || fail "$3: $1 and $2 differ"
  echo "ok: $3 ($(stat -c %s "$1") bytes identical)"
}
# The CLI's P(part | pixel): the .npy payload after its 128-byte header.
cli_probs() { tail -c +129 "$inputs/cli/person.probs.npy"; }

case $step in
install)
  rm -rf "$PF_WORK"
  mkdir -p "$PF_WORK"
  "$PF_CMAKE" --install "$PF_BUILD_DIR" --prefix "$prefix" >"$PF_WORK/install.log"
  for f in "$lib/libposeforest.so" "$lib/libposeforest.so.$PF_SOVERSION" "$lib/libposeforest.so.$PF_VERSION" \
    "$lib/libposeforest.a" "$prefix/$PF_INCLUDEDIR/poseforest/poseforest.h" \
    "$prefix/$PF_INCLUDEDIR/poseforest/poseforest.hpp" "$prefix/$PF_INCLUDEDIR/poseforest/version.h" \
    "$lib/cmake/poseforest/poseforestConfig.cmake" "$lib/cmake/poseforest/poseforestConfigVersion.cmake" \
    "$lib/cmake/poseforest/poseforestTargets.cmake" "$lib/pkgconfig/poseforest.pc" "$prefix/$PF_BINDIR/poseforest" \
    "$prefix/$PF_DOCDIR/README.md" "$prefix/$PF_DOCDIR/api.md" "$prefix/$PF_DOCDIR/FORMAT.md" \
    "$prefix/$PF_DOCDIR/examples/classify.c"; do
    [[ -e $f ]] || fail "cmake --install did not install $f"
  done
  if [[ ${PF_WITH_PYTHON:-OFF} == ON ]]; then
    compgen -G "$prefix/$PF_PYDIR/poseforest/_poseforest*.so" >/dev/null || fail "no Python module in $prefix/$PF_PYDIR"
  fi
  run "$prefix/$PF_BINDIR/poseforest" --version | grep -qx "poseforest $PF_VERSION" || fail "installed poseforest --version"
  run "$PF_MAKE_INPUTS" "$inputs"
  run "$prefix/$PF_BINDIR/poseforest" infer --quiet --labels --distributions --joints --forest "$inputs/forest.pff" \
    --out-dir "$inputs/cli" "$inputs/person.raw"
  echo "ok: installed $(find "$prefix" -type f | wc -l) files into $prefix"
  ;;

symbols)
  so=$lib/libposeforest.so.$PF_VERSION
  exported=$("${PF_NM:-nm}" -D --defined-only "$so" | awk '{print $NF}' | sort)
  [[ -n $exported ]] || fail "nm found no exported symbols in $so"
  outside=$(grep -v '^pf_' <<<"$exported" || true)
  [[ -z $outside ]] || fail "$so exports symbols outside the public API (pf_*): $(tr '\n' ' ' <<<"$outside")"
  header=$prefix/$PF_INCLUDEDIR/poseforest/poseforest.h
  declared=$(grep -oE 'PF_API[^;(]*\bpf_[a-z_]+' "$header" | grep -oE 'pf_[a-z_]+$' | sort)
  if [[ $exported != "$declared" ]]; then
    diff <(echo "$declared") <(echo "$exported") >&2 || true
    fail "exported symbols (>) differ from the functions poseforest.h declares (<)"
  fi
  echo "ok: $(wc -l <<<"$exported") exported symbols, all declared in poseforest.h: $(tr '\n' ' ' <<<"$exported")"
  soname=$(readelf -d "$so" | sed -n 's/.*Library soname: \[\(.*\)\]/\1/p')
  [[ $soname == "libposeforest.so.$PF_SOVERSION" ]] || fail "SONAME is '$soname', want libposeforest.so.$PF_SOVERSION"
  echo "ok: SONAME $soname"
  # The public headers stand alone: standard headers and each other only (no Eigen, no internals).
  bad=$(grep -hE '^\s*#\s*include' "$prefix/$PF_INCLUDEDIR"/poseforest/*.h* |
    grep -vE '<(stddef|stdint)\.h>|<(cstddef|cstdint|stdexcept|string|utility|vector)>|"poseforest/(poseforest|version)\.h"' || true)
  [[ -z $bad ]] || fail "installed headers include more than the standard library and each other: $bad"
  echo "ok: the installed headers include only standard headers and each other"
  # ... and compile cleanly as strict C99 and C++17.
  echo '#include <poseforest/poseforest.h>' >"$PF_WORK/strict.c"
  "$PF_CC" -std=c99 -pedantic-errors -Wall -Wextra -Werror -I"$prefix/$PF_INCLUDEDIR" -c "$PF_WORK/strict.c" \
    -o "$PF_WORK/strict_c.o" || fail "poseforest.h is not clean C99"
  echo '#include <poseforest/poseforest.hpp>' >"$PF_WORK/strict.cpp"
  "$PF_CXX" -std=c++17 -pedantic-errors -Wall -Wextra -Wshadow -Werror -I"$prefix/$PF_INCLUDEDIR" \
    -c "$PF_WORK/strict.cpp" -o "$PF_WORK/strict_cpp.o" || fail "poseforest.hpp is not clean C++17"
  echo "ok: poseforest.h compiles as strict C99, poseforest.hpp as strict C++17"
  ;;

cmake)
  build=$PF_WORK/cmake-build
  rm -rf "$build"
  "$PF_CMAKE" -S "$PF_SOURCE_DIR/examples" -B "$build" -DCMAKE_PREFIX_PATH="$prefix" -DEXAMPLES_STATIC=ON \
    -DCMAKE_C_COMPILER="$PF_CC" -DCMAKE_CXX_COMPILER="$PF_CXX" -DCMAKE_BUILD_TYPE=Release \
    ${PF_TOOLCHAIN_FILE:+-DCMAKE_TOOLCHAIN_FILE="$PF_TOOLCHAIN_FILE"} \
    ${PF_CROSS_DEPS:+-DPOSEFOREST_CROSS_DEPS="$PF_CROSS_DEPS"} >"$PF_WORK/cmake-configure.log"
  "$PF_CMAKE" --build "$build" -j1
  run "$build/classify_c" "$inputs/forest.pff" "$inputs/person.raw" "$build/c.labels" | tee "$build/c.out"
  same "$build/c.labels" "$inputs/person.labels" "C program (CMake) labels = runtime's"
  grep -q "poseforest $PF_VERSION (headers $PF_VERSION)" "$build/c.out" || fail "C program: version line"
  run "$build/classify_cpp" "$inputs/forest.pff" "$inputs/person.raw" "$build/cpp.labels" "$build/cpp.probs"
  same "$build/cpp.labels" "$inputs/person.labels" "C++ program (CMake) labels = runtime's"
  same "$build/cpp.probs" <(cli_probs) "C++ program (CMake) distributions = poseforest infer --distributions"
  run "$build/classify_cpp_static" "$inputs/forest.pff" "$inputs/person.raw" "$build/static.labels"
  same "$build/static.labels" "$inputs/person.labels" "C++ program (CMake, static) labels = runtime's"
  ! libs "$build/classify_cpp_static" | grep -q libposeforest || fail "classify_cpp_static loads libposeforest.so"
  # Compare real paths: CMake may record the prefix through a resolved symlink (CI's /check/work).
  resolved=$(libs "$build/classify_c" | awk -v so="libposeforest.so.$PF_SOVERSION" '$1 == so { print $3 }')
  [[ -n $resolved && $(realpath "$resolved") == "$(realpath "$lib")"/* ]] ||
    fail "classify_c: not linked to $lib: ldd says '$(libs "$build/classify_c" | grep poseforest)'," \
      "RUNPATH '$(readelf -d "$build/classify_c" | grep -E 'R(UN)?PATH')'"
  echo "ok: classify_c loads $resolved"
  # find_package's version rule: same major.minor (0.x), any patch; not another minor.
  probe=$PF_WORK/version-probe
  mkdir -p "$probe"
  cat >"$probe/CMakeLists.txt" <<EOF
cmake_minimum_required(VERSION 3.16)
project(probe NONE)
find_package(poseforest \${WANT} QUIET)
if(poseforest_FOUND)
  message(STATUS "found=1 version=\${poseforest_VERSION}")
else()
  message(STATUS "found=0")
endif()
EOF
  IFS=. read -r major minor _ <<<"$PF_VERSION"
  for want in "$major.$minor" "$PF_VERSION" "$major.$((minor + 1))" "$major.$((minor - 1))"; do
    rm -rf "$probe/b"
    found=$("$PF_CMAKE" -S "$probe" -B "$probe/b" -DCMAKE_PREFIX_PATH="$prefix" -DWANT="$want" | grep -o 'found=[01]')
    expect=found=1
    if [[ $major == 0 && $want != "$major.$minor" && $want != "$PF_VERSION" ]]; then expect=found=0; fi
    [[ $found == "$expect" ]] || fail "find_package(poseforest $want): $found, want $expect"
    echo "ok: find_package(poseforest $want): $found"
  done
  ;;

pkgconfig)
  build=$PF_WORK/make-build
  rm -rf "$build"
  mkdir -p "$build"
  export PKG_CONFIG_PATH=$lib/pkgconfig
  [[ $(pkg-config --modversion poseforest) == "$PF_VERSION" ]] || fail "pkg-config --modversion poseforest"
  (cd "$build" && make -f "$PF_SOURCE_DIR/examples/Makefile" CC="$PF_CC" CXX="$PF_CXX")
  run "$build/classify_c" "$inputs/forest.pff" "$inputs/person.raw" "$build/c.labels"
  same "$build/c.labels" "$inputs/person.labels" "C program (Makefile + pkg-config) labels = runtime's"
  run "$build/classify_cpp" "$inputs/forest.pff" "$inputs/person.raw" "$build/cpp.labels" "$build/cpp.probs"
  same "$build/cpp.labels" "$inputs/person.labels" "C++ program (Makefile + pkg-config) labels = runtime's"
  same "$build/cpp.probs" <(cli_probs) "C++ program (Makefile + pkg-config) distributions = poseforest infer"
  # A corrupt forest: the example reports the library's message, which is the CLI's.
  if run "$build/classify_c" "$inputs/corrupt.pff" "$inputs/person.raw" 2>"$build/corrupt.err"; then
    fail "classify_c accepted a corrupt forest"
  fi
  cli_err=$(run "$prefix/$PF_BINDIR/poseforest" infer --quiet --forest "$inputs/corrupt.pff" "$inputs/person.raw" 2>&1 || true)
  [[ "classify_c: load: ${cli_err#poseforest infer: }" == "$(cat "$build/corrupt.err")" ]] ||
    fail "corrupt forest: C program said '$(cat "$build/corrupt.err")', the CLI '$cli_err'"
  echo "ok: corrupt forest: $(cat "$build/corrupt.err")"
  ;;

python)
  [[ -n ${PF_PYTHON:-} ]] || fail "PF_PYTHON is not set"
  export PYTHONPATH=$prefix/$PF_PYDIR
  where=$(cd "$PF_WORK" && "$PF_PYTHON" -c 'import poseforest, os; print(os.path.realpath(poseforest._poseforest.__file__))')
  [[ $where == "$(realpath "$prefix")"/* ]] || fail "poseforest imported from $where, not from $prefix"
  echo "ok: import poseforest from $where"
  "$PF_PYTHON" "$PF_SOURCE_DIR/examples/classify.py" "$inputs/forest.pff" "$inputs/person.raw" "$PF_WORK/py.labels"
  same "$PF_WORK/py.labels" "$inputs/person.labels" "Python example labels = runtime's"
  "$PF_PYTHON" "$PF_SOURCE_DIR/tests/runtime/python_api_check.py" "$inputs" "$prefix/$PF_BINDIR/poseforest" "$PF_VERSION"
  ;;

*)
  fail "unknown step $step"
  ;;
esac
