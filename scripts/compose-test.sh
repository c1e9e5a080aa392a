#!/bin/bash
# The compose cluster end to end (not part of ctest: it needs a running container engine and
# the images; docs/distributed/compose.md says how to get both on Debian 12):
#
#   scripts/compose-test.sh [N]          # N workers (default 3)
#
# Trains a small job with the engine on this machine (`poseforest train JOB --out ref.pff`, the
# reference), then on deploy/compose.yaml with N workers (scripts/compose-train.sh), and checks:
# the cluster's forest is byte-identical to the reference; the coordinator counted N workers and
# lost none; Prometheus scraped the coordinator and N workers (each target's `up` reached 1).
# Prints the figures and "N passed, M failed"; exit 0 when all passed.
# POSEFOREST_BIN: the poseforest program for the reference (default build/bin/poseforest);
# POSEFOREST_COMPOSE_JOB: another job file (default: docs/distributed/bench_3tree_job.textproto,
# procedural, about 7 s: long enough for Prometheus, every 2 s, to scrape the coordinator).
set -euo pipefail
n=${1:-3}
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=${POSEFOREST_BIN:-$repo/build/bin/poseforest}
work=$(mktemp -d /tmp/pf-compose-test.XXXXXX)
trap 'rm -rf "$work"' EXIT
passed=0 failed=0
check() {  # check NAME COMMAND...
  if "${@:2}"; then echo "PASS $1"; passed=$((passed + 1)); else echo "FAIL $1"; failed=$((failed + 1)); fi
}

job=${POSEFOREST_COMPOSE_JOB:-$repo/docs/distributed/bench_3tree_job.textproto}
cp "$job" "$work/job.textproto"
t0=$(date +%s.%N)
"$bin" train "$work/job.textproto" --out "$work/ref.pff" --quiet
t1=$(date +%s.%N)
echo "reference: poseforest train, $(stat -c %s "$work/ref.pff") bytes, $(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.1f", b - a }') s"

if "$repo/scripts/compose-train.sh" "$work/job.textproto" "$work/out" "$n"; then
  check "compose-train.sh exits 0" true
else
  check "compose-train.sh exits 0" false
fi
forest=$work/out/forest.pff
check "the cluster's forest is byte-identical to poseforest train's" cmp "$forest" "$work/ref.pff"
check "the coordinator counted $n workers" grep -q "$n workers alive" "$work/out/coordinator.log"
check "no worker lost" grep -q " 0 workers lost" "$work/out/coordinator.log"
up_targets() {  # up_targets JOB: how many targets of a scrape job reached up == 1
  grep -c "job=\"$1\".* => 1 @" "$work/out/prometheus-up.txt" || true
}
check "Prometheus scraped the coordinator" test "$(up_targets poseforest-coordinator)" -eq 1
check "Prometheus scraped $n workers" test "$(up_targets poseforest-worker)" -eq "$n"
echo "figures: $(tr '\n' ' ' < "$work/out/times.txt")"
echo "$passed passed, $failed failed"
((failed == 0))
