#!/usr/bin/env bash
# scripts/accuracy-recipe.sh refuses bad arguments and settings before any work, with a message
# naming what is wrong, and writes nothing. (A whole run trains for 45-85 minutes: the README's and
# the results' figures are its test.)
# Usage: accuracy_recipe_script.sh REPO_ROOT BIN_DIR
set -uo pipefail
root=$1
bin=$2
work=$(mktemp -d /tmp/pf-recipe.XXXXXX)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
# The script runs the programs of its own checkout's build/bin: a checkout of the two scripts
# whose build/bin is this build's.
mkdir -p "$work/repo/scripts" "$work/repo/build"
cp "$root/scripts/accuracy-recipe.sh" "$root/scripts/default-job.sh" "$work/repo/scripts/"
ln -s "$(cd "$bin" && pwd)" "$work/repo/build/bin"
export POSEFOREST_OUT=$work/out POSEFOREST_DATA_DIR=${POSEFOREST_DATA_DIR:-$root/../shared/data}
script=$work/repo/scripts/accuracy-recipe.sh

expect_error() {  # PATTERN ENV... -- ARGS...: the script must exit 2 and say PATTERN
  local pattern=$1 env=() out rc
  shift
  while [[ $# -gt 0 && $1 != -- ]]; do env+=("$1"); shift; done
  shift
  out=$(env "${env[@]}" bash "$script" "$@" 2>&1)
  rc=$?
  [[ $rc == 2 ]] || { echo "$out"; fail "${env[*]} accuracy-recipe.sh $*: exit status $rc, expected 2"; }
  grep -qF -- "$pattern" <<< "$out" || { echo "$out"; fail "${env[*]} accuracy-recipe.sh $*: no '$pattern' in its message"; }
  echo "ok   ${env[*]} accuracy-recipe.sh $*: $out"
}
expect_error "IMAGES_PER_TREE must be a positive integer, got 'many'" -- many
expect_error "CANDIDATE_FEATURES must be a positive integer, got '0'" -- 8000 0
expect_error "POSEFOREST_HEADINGS must be a whole number of degrees, 1-180, got '200'" POSEFOREST_HEADINGS=200 -- 8000
expect_error "POSEFOREST_PROBE_EDGE must be background or clamp, got 'mirror'" POSEFOREST_PROBE_EDGE=mirror -- 8000
for share in 1.5 -0.1 half 0.5x 2; do
  expect_error "POSEFOREST_PIXEL_PROBE_SHARE must be a number in 0..1, got '$share'" \
    "POSEFOREST_PIXEL_PROBE_SHARE=$share" -- 8000
done
[[ ! -e "$work/out" ]] || fail "bad input wrote $work/out"
echo "accuracy-recipe.sh: bad input refused before any work"
