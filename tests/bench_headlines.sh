#!/usr/bin/env bash
# Every bench/ program runs on a tiny workload and ends with its headline figure, as the house
# rule says: the last line is `<metric>: <value> <unit>` (a finite number), so that anyone can
# compare runs by that line. The figures themselves are not checked: speed targets are met in
# bench/ programs that print figures, not in timed tests. bench/distributed has its own test
# (test_bench_distributed_commands_only).
# Usage: bench_headlines.sh BENCH_DIR POSEFOREST_BINARY
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
(( $# == 2 )) || { echo "usage: bench_headlines.sh BENCH_DIR POSEFOREST_BINARY" >&2; exit 2; }
# Absolute, since the checks run in a temporary folder.
bench_dir=$(cd "$1" && pwd) || { echo "FAIL: no folder $1" >&2; exit 2; }
poseforest=$(cd "$(dirname "$2")" && pwd)/$(basename "$2") || { echo "FAIL: no folder for $2" >&2; exit 2; }
[[ -x $poseforest ]] || { echo "FAIL: $poseforest is not a program" >&2; exit 2; }
failed=0

# The headline's form. Checked on known lines first, so that the checker itself can fail.
headline_re='^[A-Za-z][A-Za-z0-9 /_.()-]*: -?[0-9]+(\.[0-9]+)?(e[+-]?[0-9]+)? [^ ].*$'
for good in "frames/s: 155.9 frames/s" "evaluations/s/core: 1.259e+08 evaluations/s/core" \
            "accuracy cost: 0.000 percentage points" "images/s/core: 184.5 images/s/core"; do
  [[ $good =~ $headline_re ]] || { echo "FAIL: the checker rejects a good headline: $good"; exit 1; }
done
for bad in "frames/s: nan frames/s" "frames/s: 12.5" "done" "frames/s: inf frames/s" ": 3 s" \
            "frames/s 12 frames/s"; do
  [[ $bad =~ $headline_re ]] && { echo "FAIL: the checker accepts a bad headline: $bad"; exit 1; }
done

work=$(mktemp -d /tmp/pf-bench-headlines.XXXXXX)
trap 'rm -rf "$work"' EXIT
cd "$work" || exit 1
# A tiny forest of the paper's 31 parts (rendered people), for the benches that need one.
# shellcheck source=tests/support/tiny_forest.sh
source "$here/support/tiny_forest.sh"
train_tiny_forest "$poseforest" forest.pff || { echo "FAIL: training the tiny forest"; exit 1; }

run() {  # NAME ARGS...: runs bench/NAME, checks its exit status and its last line
  local name=$1
  shift
  local out rc last
  out=$(timeout 300 "$bench_dir/$name" "$@" 2>&1)
  rc=$?
  last=$(tail -n 1 <<< "$out")
  if [ $rc -ne 0 ]; then
    echo "$out" | tail -n 20
    echo "FAIL: bench/$name $*: exit status $rc"
    failed=1
  elif [[ ! $last =~ $headline_re ]]; then
    echo "$out" | tail -n 5
    echo "FAIL: bench/$name $*: the last line is not '<metric>: <value> <unit>': $last"
    failed=1
  else
    echo "ok   bench/$name: $last"
  fi
  REPLY=$out
}

# Command lines (bench_cli.h, CLI11): --help, and a bad value or an unknown option is a usage
# error (exit status 2) that names it, before any work; "--name=" is an empty value.
usage() {  # NAME EXPECTED_STATUS PATTERN ARGS...: bench/NAME ARGS exits EXPECTED_STATUS, output matches PATTERN
  local name=$1 want=$2 pattern=$3
  shift 3
  local out rc
  out=$(timeout 60 "$bench_dir/$name" "$@" 2>&1)
  rc=$?
  if [ $rc -ne "$want" ] || ! grep -q -- "$pattern" <<< "$out"; then
    echo "$out" | tail -n 5
    echo "FAIL: bench/$name $*: exit status $rc (want $want), output should match '$pattern'"
    failed=1
  fi
}
for name in classify segment live pipeline render train leaf_encoding distributed; do
  usage "$name" 0 "^Usage: bench/$name" --help
  # (bench/pipeline's --forest is required: given, so that --bogus is the error)
  required=()
  [ "$name" = pipeline ] && required=(--forest forest.pff)
  usage "$name" 2 "^bench/$name: The following argument was not expected: --bogus" "${required[@]}" --bogus
done
usage live 2 "^bench/live: --threads: Value abc not in range 1 to 1024" --threads abc
usage live 2 "^bench/live: --seconds: 1 required" --forest forest.pff --seconds
usage live 2 "^bench/live: --forest must be a file or folder name, not empty" --forest= --seconds 1
usage live 2 "^bench/live: --fit: best not in {kinematic,greedy}" --fit best
usage segment 2 "^bench/segment: --frames: Value 0 not in range" --frames 0
usage classify 2 "^bench/classify: SECONDS: Value abc not in range" abc
usage render 2 "^bench/render: --people: Value 9 not in range 1 to 8" --people 9
usage train 2 "^bench/train: --compare: maybe not in {auto,sklearn,none}" --compare maybe
usage distributed 2 "^bench/distributed: --workers: Value 20 not in range 1 to 16" --workers 1,20
# A comma list is one argument: the job after it is the job, not a third count.
usage distributed 1 "^bench/distributed: cannot read $work/none.textproto" --workers 1,2 "$work/none.textproto"
usage pipeline 2 "^bench/pipeline: --bodies: robots not in {procedural,makehuman,all}" --forest forest.pff --bodies robots

run classify 0.05
run segment --frames 3 --seconds 0.2
run live --forest forest.pff --frames 3 --seconds 0.3
# bench/live also says what else the machine did, beside the frame rate.
grep -q "^machine: .*% of the CPUs' time stolen by the hypervisor meanwhile; load average" <<< "$REPLY" ||
  { echo "FAIL: bench/live: no steal / load line"; failed=1; }
grep -q "^machine: reference work before the frames: [0-9.]* ns per dependent multiply-add, [0-9.]* ns" <<< "$REPLY" ||
  { echo "FAIL: bench/live: no reference work line"; failed=1; }
run pipeline --forest forest.pff --frames 2
run render --frames 2
run train --images 4 --pixels 200 --candidates 20 --depth 6 --compare none
run leaf_encoding job.textproto

[ $failed -eq 0 ] && echo "PASS" || exit 1
