#!/usr/bin/env bash
# scripts/realism-ablation.sh prints the table to choose on first: every variant on the four
# validation sets of scripts/validate.sh (the training clips at seed 5005), and only then the
# held-out test clips and the real frames, for the record. One variant ("classic"), 2 images per
# tree and 2 frames per set keep it short; the figures themselves are not checked.
# Usage: realism_ablation_script.sh REPO_ROOT BIN_DIR
set -uo pipefail
root=$1
bin=$2
work=$(mktemp -d /tmp/pf-ablation.XXXXXX)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
# The script runs the programs of build/bin under the repository it is in: a copy of the scripts
# beside a link to the programs under test.
mkdir -p "$work/repo/build"
cp -r "$root/scripts" "$work/repo/"
ln -s "$bin" "$work/repo/build/bin"
data=$(cd "${POSEFOREST_DATA_DIR:-$root/../shared/data}" && pwd) || fail "no shared data"
export POSEFOREST_OUT=$work/out POSEFOREST_DATA_DIR=$data
script=$work/repo/scripts/realism-ablation.sh

out=$(POSEFOREST_ABLATION_ONLY=nothing-matches bash "$script" 2 2 2>&1)
rc=$?
[[ $rc == 2 ]] || { echo "$out"; fail "no matching variant: exit status $rc, expected 2"; }
grep -q "no variant matches 'nothing-matches'" <<< "$out" || { echo "$out"; fail "no matching variant: no message"; }
echo "ok   no matching variant: $(tail -n 1 <<< "$out")"

out=$(POSEFOREST_ABLATION_ONLY=classic bash "$script" 2 2 2>&1)
rc=$?
echo "$out" | tail -n 14
[[ $rc == 0 ]] || fail "realism-ablation.sh 2 2: exit status $rc"
forest=$POSEFOREST_OUT/ablation-2/classic/forest.pff
[[ -s "$forest" ]] || fail "no forest at $forest"
first=$(grep -n '^== 1\. choose on these: the validation sets' <<< "$out" | cut -d: -f1)
second=$(grep -n '^== 2\. for the record' <<< "$out" | cut -d: -f1)
[[ -n "$first" && -n "$second" && $first -lt $second ]] || fail "the validation table does not come first"
# The validation table: a row for the variant's forest with one cell per set (4), no real frames.
row=$(sed -n "${first},${second}p" <<< "$out" | grep -F "| $forest |")
[[ -n "$row" ]] || fail "no validation row for $forest"
cells=$(tr -cd '|' <<< "$row" | wc -c)
[[ $cells == 6 ]] || fail "the validation row has $((cells - 1)) cells, expected 5 (the forest and 4 sets): $row"
grep -q 'never the test clips' <<< "$out" || fail "no validation header"
# Then the test clips and the real frames: the variant's row after the second heading.
sed -n "${second},\$p" <<< "$out" | grep -qE '^\| classic +\| [0-9.]+ \| [0-9.]+ \|' ||
  fail "no test-set row for the variant after the validation table"
echo "PASS"
