#!/usr/bin/env bash
# Stress check of a worker SIGKILLed mid-job and started again (what a supervisor does), with 3
# worker processes and a coordinator on one host: the case CI's test_distributed_processes "SIGKILL
# of one of 3 worker processes" failed on now and then before 29 Nov 2026 (the new worker never
# heard the coordinator: Fast DDS 2.9 had given it the dead one's shared-memory ports).
#
#   scripts/stress-worker-restart.sh [TRIALS] [PARALLEL] [BUSY] [PROFILE]
#
# Runs PARALLEL chains of TRIALS trials each (default 40 x 3), each chain on a DDS domain of its
# own (160, 161, ...), beside BUSY busy loops (default 2), on the DDS profile PROFILE (default
# shm, the commands' default; or udp, default). In a trial, worker b is SIGKILLed after tree 0's
# level 1; when the coordinator, done, waits for its lost worker, a new b is started. The trial
# passes when the coordinator writes its forest and the new b hears the job end (prints "done"
# and exits 0) within 20 s; the forests must all be byte-identical. How often the coordinator
# saw the new b before it left ("1 of 1 lost worker(s) came back") is printed too: b may hear
# JOB_DONE (the status topic replays it) and leave before its first heartbeat is heard.
# Failed trials keep their logs in $POSEFOREST_STRESS_DIR (default ./out/stress-worker) as
# fail_<domain>_<trial>/. Needs build/bin/poseforest (POSEFOREST_BIN names another build, to
# compare). Prints one line per chain and, last, "worker restarts failed: N of M".
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
trials=${1:-40}
parallel=${2:-3}
busy=${3:-2}
profile=${4:-shm}
# shellcheck source=scripts/stress-common.sh
. "$root/scripts/stress-common.sh"
stress_setup stress-worker
cat >"$dir/job.textproto" <<'JOB'
seed: 5
num_trees: 2
max_depth: 8
images_per_tree: 30
pixels_per_image: 300
candidate_features: 100
thresholds_per_feature: 12
max_probe_offset_pixel_m: 60
threshold_reference_pixels: 200
source { procedural { seed: 9 width: 96 height: 72 } }
JOB

# Waits up to $3 steps of $4 seconds for the text $2 in the file $1.
wait_for() {
  local i
  for i in $(seq 1 "$3"); do grep -qs -- "$2" "$1" && return 0; sleep "$4"; done
  return 1
}

# One trial on domain $1, number $2: 0 passed, 1 failed, 2 not counted (the job ended before
# the kill, or the coordinator never waited for the lost worker).
trial() {
  local d=$1 n=$2 t="$dir/run$1" rc=0
  rm -rf "$t"
  mkdir -p "$t"
  local common=(--domain "$d" --profile "$profile" --job "stress$d")
  "$bin" worker "${common[@]}" --id a >"$t/wa.log" 2>&1 &
  local wa=$!
  "$bin" worker "${common[@]}" --id b >"$t/wb.log" 2>&1 &
  local wb=$!
  "$bin" worker "${common[@]}" --id c >"$t/wc.log" 2>&1 &
  local wc=$!
  stdbuf -oL -eL "$bin" coordinator "$dir/job.textproto" --out "$t/forest.pff" --domain "$d" --profile "$profile" \
    --job-id "stress$d" --min-workers 3 --http off >"$t/coord.log" 2>&1 &
  local co=$! again=
  if ! wait_for "$t/coord.log" "tree 0 level 1:" 3000 0.02; then
    rc=1
  else
    kill -9 "$wb" 2>/dev/null || true
    wait "$wb" 2>/dev/null || true
    local i lost=
    for i in $(seq 1 600); do
      if grep -qs "lost worker(s) to come back" "$t/coord.log"; then lost=1; break; fi
      kill -0 "$co" 2>/dev/null || break
      sleep 0.1
    done
    if [ -z "$lost" ]; then
      # Done without missing b (the kill came after its last work): not counted; or stuck: failed.
      if ! kill -0 "$co" 2>/dev/null && grep -qs "^wrote " "$t/coord.log"; then rc=2; else rc=1; fi
    else
      "$bin" worker "${common[@]}" --id b >"$t/wb-again.log" 2>&1 &
      again=$!
      for i in $(seq 1 300); do kill -0 "$co" 2>/dev/null || break; sleep 0.1; done
      if kill -0 "$co" 2>/dev/null || ! wait "$co"; then
        rc=1
      else
        for i in $(seq 1 200); do kill -0 "$again" 2>/dev/null || break; sleep 0.1; done
        if kill -0 "$again" 2>/dev/null || ! wait "$again" || ! grep -q "done" "$t/wb-again.log"; then rc=1; fi
        # Informative: the coordinator saw it before it left (it may hear JOB_DONE first and go).
        if grep -q "1 of 1 lost worker(s) came back" "$t/coord.log"; then echo >>"$dir/seen_back_$d"; fi
      fi
    fi
  fi
  if [ "$rc" = 1 ]; then
    rm -rf "$dir/fail_${d}_$n"
    cp -r "$t" "$dir/fail_${d}_$n"
  elif [ "$rc" = 0 ]; then
    cp "$t/forest.pff" "$dir/forest_${d}_$n.pff"
  fi
  kill "$co" "$wa" "$wc" $again 2>/dev/null || true
  wait 2>/dev/null || true
  return $rc
}

stress_chains 160 "worker restarts" "trials not counted: no worker was lost"
echo "distinct forests among the passed trials: $forests (1 expected)"
seen=$(cat "$dir"/seen_back_* 2>/dev/null | wc -l)
echo "the coordinator saw the new worker before it left: $seen of $total"
echo "worker restarts failed: $failed of $total"
