#!/usr/bin/env bash
# scripts/validate.sh, the four validation sets the docs' comparisons are chosen on: its job files
# render the main job's training clips at seed 5005 (never the test clips), it prints one row per
# forest with a cell per set and the real frames, reuses an eval only while the forest is the
# same (and the shared data unchanged), and refuses bad input with a clear message. A tiny forest and 2 frames per set keep it
# short; the figures themselves are not checked.
# Usage: validate_script.sh REPO_ROOT BIN_DIR
set -uo pipefail
root=$1
bin=$2
script=$root/scripts/validate.sh
work=$(mktemp -d /tmp/pf-validate.XXXXXX)
trap 'rm -rf "$work"' EXIT
cd "$work" || exit 1
export POSEFOREST_OUT=$work/out POSEFOREST_BIN_DIR=$bin
fail() { echo "FAIL: $*"; exit 1; }
# The shared data as links in a folder of the test's own (the mocap clips one by one), so that
# the test can add a file to it without touching the shared data.
shared=$(cd "${POSEFOREST_DATA_DIR:-$root/../shared/data}" && pwd) || fail "no shared data"
mkdir -p "$work/data/mocap"
for f in "$shared"/*; do [[ $(basename "$f") == mocap ]] || ln -s "$f" "$work/data/"; done
for f in "$shared"/mocap/*; do ln -s "$f" "$work/data/mocap/"; done
export POSEFOREST_DATA_DIR=$work/data

# Bad input: exit status and message, before any work.
expect_error() {  # STATUS PATTERN ARGS...: validate.sh ARGS must exit STATUS and say PATTERN
  local status=$1 pattern=$2 out rc
  shift 2
  out=$(bash "$script" "$@" 2>&1)
  rc=$?
  [[ $rc == "$status" ]] || { echo "$out"; fail "validate.sh $*: exit status $rc, expected $status"; }
  grep -qE -- "$pattern" <<< "$out" || { echo "$out"; fail "validate.sh $*: no '$pattern' in its message"; }
  echo "ok   validate.sh $*: $(head -n 1 <<< "$out")"
}
expect_error 2 '^usage: scripts/validate.sh'
expect_error 1 "no forest file 'missing.pff'" missing.pff
expect_error 2 "--images must be a positive integer, got '0'" --images 0 missing.pff
expect_error 2 "unknown set 'classic-90'" --sets realism-60,classic-90 missing.pff
expect_error 2 "unknown option '--frames'" --frames 3 missing.pff
[[ ! -e "$work/out" ]] || fail "bad input wrote $work/out"

# A tiny forest of the paper's 31 parts.
# shellcheck source=tests/support/tiny_forest.sh
source "$root/tests/support/tiny_forest.sh"
train_tiny_forest "$bin/poseforest" tiny.pff || fail "training the tiny forest"

out=$(bash "$script" --images 2 tiny.pff 2>err.log) || { cat err.log; echo "$out"; fail "validate.sh --images 2 tiny.pff"; }
echo "$out"
num='[0-9]+\.[0-9]{3}'
cell="$num / $num / $num / $num"
grep -qE "^\| tiny.pff \| $cell \| $cell \| $cell \| $cell \| [0-9]+ of 90 \(arms [0-9]+ of 54\) \|$" <<< "$out" ||
  fail "no row of four set cells and the real frames' cell for tiny.pff"
grep -qF '| forest | realism +-60 | realism +-120 | classic +-120 | classic +-60 | real frames within 0.10 m |' \
  <<< "$out" || fail "the header does not name the four sets in the docs' order"
[[ $(grep -c '^validate: tiny.pff on ' err.log) == 5 ]] || { cat err.log; fail "expected 5 evals (4 sets, real)"; }

# The job files: the training clips at seed 5005, the set's rotation and render style.
v=$work/out/validation
for s in realism-60 realism-120 classic-120 classic-60; do
  f=$v/$s.textproto
  [[ -s $f ]] || fail "no $f"
  test_set=$(sed -n '/^test_set {/,$p' "$f")
  grep -q '^      seed: 5005$' <<< "$test_set" || fail "$s: the test set's seed is not 5005"
  grep -q 'clips: CLIP_SET_TRAIN' <<< "$test_set" || fail "$s: the set does not render the training clips"
  grep -q 'CLIP_SET_TEST' "$f" && fail "$s: the held-out test clips are in the validation set"
  grep -q "rotation_range_deg: ${s#*-}\$" <<< "$test_set" || fail "$s: rotation is not ${s#*-}"
  if [[ $s == classic-* ]]; then
    grep -q 'upper_body_share: 0 arm_pose_share: 0' <<< "$test_set" || fail "$s: not the classic renders"
  else
    grep -q 'upper_body_share' <<< "$test_set" && fail "$s: not the realism defaults"
  fi
done
echo "ok   the four job files: training clips, seed 5005, rotations and render styles"

# Reused while the forest is the same; scored again for another forest or with --rescore.
again=$(bash "$script" --images 2 tiny.pff 2>err2.log) || fail "second run"
[[ "$again" == "$out" ]] || fail "the second run printed another table"
grep -q '^validate: tiny.pff on ' err2.log && fail "the second run scored again instead of reusing"
bash "$script" --images 2 --sets classic-60 --no-real --rescore tiny.pff > rescore.txt 2>err3.log || fail "--rescore"
[[ $(grep -c '^validate: tiny.pff on classic-60' err3.log) == 1 ]] || fail "--rescore did not score again"
grep -q 'real frames' rescore.txt && fail "--no-real still scored the real frames"
# Another data file: every eval is scored again; another clip: the pose library is built again.
echo "a note" > "$work/data/NOTE.txt"
bash "$script" --images 2 --sets classic-60 --no-real tiny.pff > /dev/null 2>err4.log || fail "after a data change"
[[ $(grep -c '^validate: tiny.pff on classic-60' err4.log) == 1 ]] || { cat err4.log; fail "a changed data set reused an eval"; }
grep -q 'pose library' err4.log && fail "the pose library was built again although the clips did not change"
clip=$(find -L "$shared/mocap" -name '*.bvh' -print -quit)
[[ -n $clip ]] || fail "no .bvh clip under $shared/mocap"
ln -s "$clip" "$work/data/mocap/zz_again.bvh"
bash "$script" --images 2 --sets classic-60 --no-real tiny.pff > /dev/null 2>err5.log || fail "after a clip change"
grep -q '^validate: pose library from ' err5.log || { cat err5.log; fail "a new clip did not rebuild the pose library"; }
cp tiny.pff other.pff
printf 'x' >> other.pff  # another file: its evals are its own; a corrupt forest is a clear error
out2=$(bash "$script" --images 2 --sets realism-60 --no-real other.pff 2>&1)
rc=$?
[[ $rc == 1 ]] || { echo "$out2"; fail "a corrupt forest: exit status $rc, expected 1"; }
grep -q 'poseforest eval failed on other.pff, realism-60' <<< "$out2" || { echo "$out2"; fail "a corrupt forest: no clear error"; }
echo "ok   reuse, --rescore, --no-real, a changed data set, a new clip, a corrupt forest"
echo "all validate.sh checks passed"
