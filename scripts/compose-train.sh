#!/bin/bash
# Trains one job on the compose cluster (deploy/compose.yaml) and collects the forest:
#
#   scripts/compose-train.sh JOB.textproto OUT_DIR [N]     # N workers (default 2)
#
# Builds the images when they are missing (scripts/compose-build.sh), clears the cluster's
# previous state (`down -v`: an old checkpoint of another job would be refused), brings up the
# discovery server, N workers (`--scale worker=N`) and Prometheus, then (once Prometheus scrapes
# every worker) the coordinator, waits for it to finish, then writes to OUT_DIR:
#   forest.pff       the forest (the coordinator's /var/lib/poseforest/forest.pff)
#   events.jsonl     the coordinator's event log
#   job.textproto    the job as trained
#   coordinator.log, workers.log, prometheus-up.txt (each target's `up`, highest over the job),
#   times.txt        seconds: cluster up (workers and Prometheus running, every worker scraped),
#                    job (coordinator started -> exited, with its 10 s HTTP linger), train (the
#                    coordinator's own "trees in S s"), total
# and takes the cluster down (POSEFOREST_COMPOSE_KEEP=1 leaves it up; the dashboard and
# Prometheus URLs are printed). Exit 0 when the coordinator exited 0 and the forest is in OUT_DIR.
#
# Environment: COMPOSE ("docker compose", "docker-compose", "podman-compose"; default: the first
# that works), ENGINE (docker or podman, for wait/cp/inspect; default: podman for
# podman-compose), COMPOSE_PROJECT_NAME (default poseforest), POSEFOREST_WORKER_THREADS (default
# 1), POSEFOREST_COMPOSE_TIMEOUT_S (default 3600: give up on the job after that),
# POSEFOREST_COMPOSE_KEEP=1. The job must be procedural or name files the containers have
# (deploy/compose.yaml mounts only the job file). docs/distributed/compose.md.
set -euo pipefail

if [[ $# -lt 2 || $# -gt 3 ]]; then
  sed -n '2,4p' "$0" >&2
  exit 2
fi
job=$1
out=$2
n=${3:-2}
[[ -f "$job" ]] || { echo "compose-train.sh: no job file $job" >&2; exit 2; }
[[ "$n" =~ ^[1-9][0-9]*$ ]] || { echo "compose-train.sh: N must be a positive integer, got '$n'" >&2; exit 2; }

repo=$(cd "$(dirname "$0")/.." && pwd)
compose_file=$repo/deploy/compose.yaml
project=${COMPOSE_PROJECT_NAME:-poseforest}
timeout_s=${POSEFOREST_COMPOSE_TIMEOUT_S:-3600}

if [[ -z "${COMPOSE:-}" ]]; then
  if docker compose version >/dev/null 2>&1; then COMPOSE="docker compose"
  elif command -v docker-compose >/dev/null; then COMPOSE=docker-compose
  elif command -v podman-compose >/dev/null; then COMPOSE=podman-compose
  else echo "compose-train.sh: no compose CLI (docker compose, docker-compose or podman-compose)" >&2; exit 2
  fi
fi
if [[ -z "${ENGINE:-}" ]]; then
  if [[ "$COMPOSE" == podman-compose ]]; then ENGINE=podman; else ENGINE=docker; fi
fi
read -r -a compose <<<"$COMPOSE"
compose+=(-p "$project" -f "$compose_file")

for image in poseforest-discovery poseforest-coordinator poseforest-worker poseforest-prometheus; do
  if ! "$ENGINE" image inspect "$image" >/dev/null 2>&1; then
    echo "compose-train.sh: image $image missing: scripts/compose-build.sh"
    ENGINE=$ENGINE "$repo/scripts/compose-build.sh"
    break
  fi
done

mkdir -p "$out"
out=$(cd "$out" && pwd)
# The coordinator runs as uid 65534: the mounted job must be readable by others.
cp "$job" "$out/job.textproto"
chmod 0644 "$out/job.textproto"
export POSEFOREST_JOB=$out/job.textproto POSEFOREST_WORKERS=$n

seconds() {  # seconds FROM TO: TO - FROM, one decimal
  awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'
}
address() {  # address CONTAINER: its IPv4 address on the compose network
  "$ENGINE" inspect -f '{{range .NetworkSettings.Networks}}{{.IPAddress}} {{end}}' "$1" | awk '{print $1}'
}

promql() {  # promql EXPR: the value of a one-series PromQL query on the cluster's Prometheus, or ""
  "$ENGINE" exec "$prometheus" promtool query instant http://localhost:9090 "$1" 2>/dev/null |
    awk '/=>/ { print $(NF - 1) ; exit }'
}

"${compose[@]}" down -v --remove-orphans >/dev/null 2>&1 || true
start=$(date +%s.%N)
# The workers and Prometheus first: the coordinator starts once Prometheus scrapes all N workers
# (at most 60 s), so a short job's metrics are in Prometheus from its first level on.
"${compose[@]}" up -d --no-build --scale "worker=$n" discovery worker prometheus
prometheus=$("${compose[@]}" ps -q prometheus)
for _ in $(seq 120); do
  [[ "$(promql 'count(up{job="poseforest-worker"} == 1)')" == "$n" ]] && break
  sleep 0.5
done
scraped=$(promql 'count(up{job="poseforest-worker"} == 1)')
[[ "$scraped" == "$n" ]] || echo "compose-train.sh: Prometheus scrapes ${scraped:-0} of $n workers after 60 s; going on" >&2
up=$(date +%s.%N)
"${compose[@]}" up -d --no-build --scale "worker=$n" coordinator
coordinator=$("${compose[@]}" ps -q coordinator)
echo "compose-train.sh: cluster up in $(seconds "$start" "$up") s ($n workers, ${scraped:-0} scraped by Prometheus);" \
  "dashboard http://$(address "$coordinator"):8080/, Prometheus http://$(address "$prometheus"):9090/"

# Wait for the coordinator to exit 0 (restart: on-failure restarts it from its checkpoint).
restarts_seen=0
while :; do
  read -r status code restarts < <("$ENGINE" inspect -f '{{.State.Status}} {{.State.ExitCode}} {{.RestartCount}}' \
    "$coordinator")
  if [[ "$status" == exited && "$code" == 0 ]]; then break; fi
  if [[ "$restarts" != "$restarts_seen" ]]; then
    echo "compose-train.sh: the coordinator restarted ($restarts): it resumes from its checkpoint" >&2
    restarts_seen=$restarts
  fi
  if (($(date +%s) - ${start%.*} > timeout_s)); then
    echo "compose-train.sh: no forest after $timeout_s s (coordinator $status, exit $code)" >&2
    "$ENGINE" logs --tail 30 "$coordinator" >&2 || true
    exit 1
  fi
  sleep 0.5
done
done_at=$(date +%s.%N)

rm -f "$out/forest.pff" "$out/events.jsonl"
"$ENGINE" cp "$coordinator:/var/lib/poseforest/forest.pff" "$out/forest.pff"
"$ENGINE" cp "$coordinator:/var/lib/poseforest/events.jsonl" "$out/events.jsonl" || true
"$ENGINE" logs "$coordinator" > "$out/coordinator.log" 2>&1
"${compose[@]}" logs --no-color worker > "$out/workers.log" 2>&1 || true
# What Prometheus scraped: every target's `up`, highest over the job (1: scraped at least once).
"$ENGINE" exec "$prometheus" promtool query instant http://localhost:9090 "max_over_time(up[1h])" \
  > "$out/prometheus-up.txt" 2>&1 || true

{
  echo "cluster_up_s $(seconds "$start" "$up")"
  echo "job_s $(seconds "$up" "$done_at")"
  # The coordinator's own figure: training alone (without start-up and the HTTP linger).
  echo "train_s $(sed -n 's/^wrote .*: [0-9]* trees in \([0-9.]*\) s,.*/\1/p' "$out/coordinator.log" | tail -1)"
  echo "total_s $(seconds "$start" "$done_at")"
  echo "workers $n"
} > "$out/times.txt"
echo "compose-train.sh: forest $out/forest.pff ($(stat -c %s "$out/forest.pff") bytes);" \
  "$(tr '\n' ' ' < "$out/times.txt")"
grep -h "workers alive\|workers lost\|rejected" "$out/coordinator.log" | tail -3 || true
echo "compose-train.sh: Prometheus targets (max_over_time(up[1h])):"
sed 's/^/  /' "$out/prometheus-up.txt"

if [[ "${POSEFOREST_COMPOSE_KEEP:-0}" == 1 ]]; then
  echo "compose-train.sh: cluster left up; take it down with: ${compose[*]} down -v"
else
  "${compose[@]}" down -v >/dev/null 2>&1
fi
