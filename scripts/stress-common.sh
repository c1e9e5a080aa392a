# Shared by scripts/stress-*.sh (sourced, not run): PARALLEL chains of TRIALS calls of the caller's
# `trial DOMAIN N` (0 passed, 1 failed, 2 not counted), one DDS domain per chain from FIRST_DOMAIN,
# beside BUSY busy loops. Needs $trials, $parallel, $busy, $dir and $bin set.
#
#   stress_chains FIRST_DOMAIN WHAT NOT_COUNTED
#
# Prints one line per chain ("domain D: F of N WHAT failed (K NOT_COUNTED)") and leaves the sums
# in $failed and $total, and in $forests the number of distinct $dir/forest_*.pff.

stress_chain() {
  local d=$1 what=$2 not_counted=$3 chain_failed=0 done=0 n rc
  for n in $(seq 1 "$trials"); do
    rc=0
    trial "$d" "$n" || rc=$?
    [ "$rc" = 2 ] && continue
    done=$((done + 1))
    [ "$rc" = 0 ] || chain_failed=$((chain_failed + 1))
  done
  echo "$chain_failed $done" >"$dir/failed_$d"
  echo "domain $d: $chain_failed of $done $what failed ($((trials - done)) $not_counted)"
}

stress_chains() {
  local first=$1 what=$2 not_counted=$3 c f n
  loads=()
  for _ in $(seq 1 "$busy"); do
    (while :; do :; done) &
    loads+=($!)
  done
  chains=()
  stress_cleanup() {
    kill "${loads[@]}" "${chains[@]}" 2>/dev/null || true
    pkill -f "^$bin " 2>/dev/null || true
  }
  trap stress_cleanup EXIT
  trap 'exit 130' INT TERM
  for c in $(seq 0 $((parallel - 1))); do
    stress_chain $((first + c)) "$what" "$not_counted" &
    chains+=($!)
  done
  wait "${chains[@]}"
  failed=0
  total=0
  for c in $(seq 0 $((parallel - 1))); do
    read -r f n <"$dir/failed_$((first + c))"
    failed=$((failed + f))
    total=$((total + n))
  done
  forests=$(find "$dir" -maxdepth 1 -name 'forest_*.pff' -exec md5sum {} + | awk '{print $1}' | sort -u | wc -l)
}
