#!/usr/bin/env bash
# bench/distributed --commands-only on its small default job: both commands run, the forests are
# the same, the per-level table is there and its service split adds up (rounds = the critical
# worker's computing + its request queued + traffic, to the table's rounding), the last line is
# the bench's metric. Usage: bench_commands_only.sh BENCH
set -uo pipefail
bench=$1
out=$("$bench" --commands-only --domain 77 2>&1); rc=$?
echo "$out"
fail() { echo "FAIL: $*"; exit 1; }
[ $rc -eq 0 ] || fail "exit status $rc"
grep -q "^pair 1 (engine first): forests identical; wall service / engine [0-9.]*, per CPU-second [0-9.]*$" <<< "$out" ||
  fail "no 'forests identical' pair line"
grep -q "^wall, service / engine: median [0-9.]* over 1 pair(s)" <<< "$out" || fail "no wall ratio line"
[[ $(tail -1 <<< "$out") =~ ^distributed/engine\ per\ core:\ [0-9.]+\ ratio$ ]] || fail "last line: $(tail -1 <<< "$out")"
# Rows: tree level engine service ratio rounds computing queued traffic merge wait other MiB subtree render
rows=$(awk '$1 ~ /^[0-9]+$/ && NF == 15' <<< "$out")
[ "$(wc -l <<< "$rows")" -ge 5 ] || fail "fewer than 5 level rows"
awk '{ if ($6 - ($7 + $8 + $9) > 0.03 || ($7 + $8 + $9) - $6 > 0.03) { print "row does not add up: " $0; bad = 1 } }
     END { exit bad }' <<< "$rows" || fail "split does not add up"
awk '$2 == 0 && $4 > 0 && $7 > 0 { ok = 1 } END { exit !ok }' <<< "$rows" || fail "level 0 has no service time or computing"
awk '$1 == "all" && $3 > 0 && $4 > 0 { ok = 1 } END { exit !ok }' <<< "$out" || fail "no 'all' row"
echo "PASS"
