#!/usr/bin/env bash
# Stress check of a coordinator SIGKILLed mid-job (after tree 0's level 1) and restarted at once
# with --resume (what a supervisor such as `restart: on-failure` does), with 2 worker processes
# on one host.
#
#   scripts/stress-coordinator-restart.sh [TRIALS] [PARALLEL] [BUSY] [PROFILE]
#
# Runs PARALLEL chains of TRIALS restarts each (default 40 x 3), each chain on a DDS domain of
# its own (150, 151, ...), beside BUSY busy loops (default 2) that load the CPUs, on the DDS
# profile PROFILE (default shm, the commands' default; or udp, default). A trial passes when
# the restarted coordinator writes a forest within 60 s; the forests must all be
# byte-identical (same job, same seed). A trial whose first coordinator finished before the kill
# (a loaded machine) is not counted. A failed trial keeps its logs, with the shared-memory
# segments each process has mapped (a "(deleted)" one is a port another process replaced), in
# $POSEFOREST_STRESS_DIR (default ./out/stress-restart) as fail_<domain>_<trial>/.
# Needs build/bin/poseforest (README command one builds it; POSEFOREST_BIN names another build,
# to compare). Prints one line per chain and, last, "restarts failed: N of M".
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
trials=${1:-40}
parallel=${2:-3}
busy=${3:-2}
profile=${4:-shm}
# shellcheck source=scripts/stress-common.sh
. "$root/scripts/stress-common.sh"
stress_setup stress-restart
cat >"$dir/job.textproto" <<'EOF'
seed: 5
num_trees: 3
max_depth: 8
images_per_tree: 12
pixels_per_image: 150
candidate_features: 40
thresholds_per_feature: 12
max_probe_offset_pixel_m: 60
threshold_reference_pixels: 200
source { procedural { seed: 9 width: 96 height: 72 } }
EOF

# One trial on domain $1, number $2: 0 when the restarted coordinator wrote its forest.
trial() {
  local d=$1 n=$2 t="$dir/run$1"
  rm -rf "$t"
  mkdir -p "$t"
  local common=(--domain "$d" --profile "$profile")
  "$bin" worker "${common[@]}" --job "stress$d" --id a >"$t/w0.log" 2>&1 &
  local w0=$!
  "$bin" worker "${common[@]}" --job "stress$d" --id b >"$t/w1.log" 2>&1 &
  local w1=$!
  local args=(coordinator "$dir/job.textproto" --out "$t/forest.pff" "${common[@]}" --job-id "stress$d"
    --min-workers 2 --checkpoint "$t/ckpt" --http off)
  # Line-buffered, so that the level line reaches the log file as soon as it is printed.
  stdbuf -oL -eL "$bin" "${args[@]}" >"$t/c1.log" 2>&1 &
  local c1=$! i
  for i in $(seq 1 4500); do grep -qs "tree 0 level 1:" "$t/c1.log" && break; sleep 0.02; done
  kill -9 "$c1" 2>/dev/null || true
  wait "$c1" 2>/dev/null || true
  stdbuf -oL -eL "$bin" "${args[@]}" --resume --worker-wait-s 45 >"$t/c2.log" 2>&1 &
  local c2=$! rc=0
  # The last levels can take milliseconds: when the first coordinator had finished the job
  # before the kill (the restarted one resumes "at tree 3 level 0", after the last tree), the
  # workers may have left on its JOB_DONE, and there is no restart to test.
  for i in $(seq 1 100); do grep -qs "resuming" "$t/c2.log" && break; sleep 0.1; done
  if grep -q "resuming .* at tree 3 level 0" "$t/c2.log"; then
    kill "$c2" "$w0" "$w1" 2>/dev/null || true
    wait 2>/dev/null || true
    return 2
  fi
  for i in $(seq 1 600); do kill -0 "$c2" 2>/dev/null || break; sleep 0.1; done
  if kill -0 "$c2" 2>/dev/null || ! wait "$c2"; then
    rc=1
    for p in "$w0" "$w1" "$c2"; do
      echo "== pid $p"
      grep fastrtps "/proc/$p/maps" 2>/dev/null | awk '{print $6, $7}' | sort | uniq -c || true
    done >"$t/maps.txt"
    rm -rf "$dir/fail_${d}_$n"
    cp -r "$t" "$dir/fail_${d}_$n"
  else
    cp "$t/forest.pff" "$dir/forest_${d}_$n.pff"
  fi
  kill "$c2" "$w0" "$w1" 2>/dev/null || true
  wait 2>/dev/null || true
  return $rc
}

stress_chains 150 restarts "jobs ended before the kill"
echo "distinct forests among the passed restarts: $forests (1 expected)"
echo "restarts failed: $failed of $total"
