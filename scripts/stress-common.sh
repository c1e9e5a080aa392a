# Shared by scripts/stress-*.sh (sourced, not run). stress_setup (below) makes the work folder;
# stress_chains runs PARALLEL chains of TRIALS calls of the caller's `trial DOMAIN N` (0 passed,
# 1 failed, 2 not counted), one DDS domain per chain from FIRST_DOMAIN, beside BUSY busy loops.
# Needs $trials, $parallel, $busy, $dir and $bin set.
#
#   stress_chains FIRST_DOMAIN WHAT NOT_COUNTED
#
# Prints one line per chain ("domain D: F of N WHAT failed (K NOT_COUNTED)") and leaves the sums
# in $failed and $total, and in $forests the number of distinct $dir/forest_*.pff.

# stress_setup DIR_NAME: checks $profile (shm, udp, default) and the numbers $trials, $parallel
# and $busy, then makes $dir ($POSEFOREST_STRESS_DIR, default $root/out/DIR_NAME) afresh with a
# copy of the program ($POSEFOREST_BIN, default the build's), so a rebuild while this runs does not
# change the program under test; $bin names the copy.
stress_setup() {
  case "$profile" in shm | udp | default) ;; *) echo "stress: PROFILE must be shm, udp or default" >&2; exit 2 ;; esac
  local n
  for n in "$trials" "$parallel" "$busy"; do
    [[ "$n" =~ ^[0-9]+$ ]] || { echo "stress: TRIALS, PARALLEL and BUSY are whole numbers, not '$n'" >&2; exit 2; }
  done
  bin=${POSEFOREST_BIN:-$root/build/bin/poseforest}
  [ -x "$bin" ] || { echo "stress: no $bin (build first: README command one)" >&2; exit 1; }
  dir=${POSEFOREST_STRESS_DIR:-$root/out/$1}
  rm -rf "$dir"
  mkdir -p "$dir"
  cp "$bin" "$dir/poseforest"
  bin="$dir/poseforest"
}

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
