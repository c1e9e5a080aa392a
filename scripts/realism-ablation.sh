#!/usr/bin/env bash
# The ablation behind the rendering realism defaults (job.proto RenderedSource fields 14-19,
# docs/training/realism.md): the main job's job, one variant per line of VARIANTS below, each
# trained at the same images per tree and tuned on validation renders of its own training source.
# Prints two tables:
#   1. to choose on: every variant on the four validation sets of scripts/validate.sh (the main
#      job's training clips at another seed, never the test clips; --no-real);
#   2. for the record, after the choice: the held-out classic renders (mAP, average per-class
#      accuracy), the same test clips rendered with the realism defaults (mAP), and the
#      hand-labelled real Kinect frames (eval --real-labels).
# Choosing on table 2 would tune the defaults to the test set and to the 9 real frames.
#
#   scripts/realism-ablation.sh [IMAGES_PER_TREE [TEST_IMAGES]]   (default 300 and 200)
#
# Needs a build (scripts/build.sh) and the shared data (POSEFOREST_DATA_DIR, default
# ../shared/data). Outputs in $POSEFOREST_OUT/ablation-N (default ./out/ablation-N), one folder per
# variant; a variant already trained (tune.log) is not trained again, and a score file that exists
# is kept (delete it to score again; delete the folder to train again).
# ~7 minutes per variant at 300 images per tree on two cores, and ~4 more for its validation sets
# (scores already made are reused, as scripts/validate.sh reuses them).
# POSEFOREST_ABLATION_ONLY='A|B' trains and scores only the variants whose name contains A or B.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
# shellcheck source=scripts/default-job.sh
source "$root/scripts/default-job.sh"
per_tree=${1:-300}
test_images=${2:-200}
[[ "$per_tree" =~ ^[1-9][0-9]*$ && "$test_images" =~ ^[1-9][0-9]*$ ]] ||
  { echo "realism-ablation: IMAGES_PER_TREE and TEST_IMAGES must be positive integers" >&2; exit 2; }
data=$(cd "${POSEFOREST_DATA_DIR:-$root/../shared/data}" 2>/dev/null && pwd) ||
  { echo "realism-ablation: no shared data at ${POSEFOREST_DATA_DIR:-$root/../shared/data} (set POSEFOREST_DATA_DIR)" >&2; exit 1; }
bin=$root/build/bin
[[ -x "$bin/poseforest" ]] || { echo "realism-ablation: $bin/poseforest not built (run scripts/build.sh)" >&2; exit 1; }
out=${POSEFOREST_OUT:-$root/out}/ablation-$per_tree
mkdir -p "$out"
out=$(cd "$out" && pwd)
labels=$data/real/skeltrack_kinect_depth/joint_labels.json

# name | training source fields (on top of the defaults: everything on)
VARIANTS=(
  "classic|upper_body_share: 0 arm_pose_share: 0 projector_shadow: false min_range_m: 0"
  "defaults (upper-body share 0.25)|"
  "upper-body share 0.5|upper_body_share: 0.5"
  "share 0.5, no arm re-posing|upper_body_share: 0.5 arm_pose_share: 0"
  "share 0.5, no shadow, no near limit|upper_body_share: 0.5 projector_shadow: false min_range_m: 0"
  "no upper-body framing|upper_body_share: 0"
  "arms only|upper_body_share: 0 projector_shadow: false min_range_m: 0"
  "defaults + flying pixels 0.3|flying_pixels: 0.3"
  "defaults + range and grazing holes|range_holes: 0.2 grazing_holes: 0.5"
  "defaults + 50 sampled bodies|makehuman_sampled_bodies: 50"
  "defaults + clothes and hair 0.5|makehuman_clothed_share: 0.5"
  "defaults + sampled bodies, clothes|makehuman_sampled_bodies: 50 makehuman_clothed_share: 0.5"
  "defaults + sitting 0.25, leaning 0.25|sitting_share: 0.25 leaning_share: 0.25"
)
[[ -n "${POSEFOREST_ABLATION_ONLY:-}" ]] && echo "(only variants matching '$POSEFOREST_ABLATION_ONLY')"

[[ -f "$out/mocap.pfposes" ]] || "$bin/poseforest-poselib" build --out "$out/mocap.pfposes" "$data/mocap"
rows=() forests=()
for v in "${VARIANTS[@]}"; do
  name=${v%%|*}
  fields=${v#*|}
  if [[ -n "${POSEFOREST_ABLATION_ONLY:-}" ]]; then  # 'a|b|c': variants whose name contains any
    IFS='|' read -r -a only <<<"$POSEFOREST_ABLATION_ONLY"
    keep=0
    for o in "${only[@]}"; do [[ -n "$o" && "$name" == *"$o"* ]] && keep=1; done
    ((keep)) || continue
  fi
  dir=$out/$(echo "$name" | tr -c 'a-zA-Z0-9\n' '-' | tr -s '-')
  mkdir -p "$dir"
  if [[ ! -s "$dir/tune.log" ]]; then
    echo "== $name: training ($dir)"
    write_default_job "$dir/job.textproto" "$per_tree" "$test_images" "$out/mocap.pfposes" "$data" "$fields"
    t0=$(date +%s)
    "$bin/poseforest" train "$dir/job.textproto" --out "$dir/forest.pff" --quiet
    echo "train: $(( $(date +%s) - t0 )) s" > "$dir/time.txt"
    "$bin/poseforest" tune-joints --forest "$dir/forest.pff" --validation "$dir/job.textproto" --frames 60 \
      --out "$dir/forest.pff" > "$dir/tune.log" 2>&1
  fi
  # Scores (delete them to score again, e.g. after a change to the runtime).
  [[ -s "$dir/eval.txt" ]] || "$bin/poseforest" eval --forest "$dir/forest.pff" --test-set "$dir/job.textproto" \
    --method meanshift --quiet > "$dir/eval.txt"
  [[ -s "$dir/real.txt" ]] || "$bin/poseforest" eval --forest "$dir/forest.pff" --real-labels "$labels" \
    --png-dir "$dir/real" --quiet > "$dir/real.txt"
  if [[ ! -s "$dir/eval_realistic.txt" ]]; then
    # The same held-out test clips rendered with the realism defaults (upper-body framings, arms,
    # projector shadow): the job without its test-set pins.
    write_default_job "$dir/job_realistic_test.textproto" "$per_tree" "$test_images" "$out/mocap.pfposes" "$data" \
      "$fields" ""
    "$bin/poseforest" eval --forest "$dir/forest.pff" --test-set "$dir/job_realistic_test.textproto" --method meanshift \
      --quiet > "$dir/eval_realistic.txt"
  fi
  map=$(grep '^eval: mAP' "$dir/eval.txt" | sed -E 's/.*mAP ([0-9.]+).*accuracy ([0-9.]+)%.*/\1 \2/')
  map_r=$(grep '^eval: mAP' "$dir/eval_realistic.txt" | sed -E 's/.*mAP ([0-9.]+).*/\1/')
  real=$(grep '^eval: real frames' "$dir/real.txt" | sed -E 's/.*\(([0-9.]+)\), found within ([0-9.]+), any within 0.10 m ([0-9.]+)/\1 \2 \3/')
  arms=$(grep '^elbows, wrists, hands' "$dir/real.txt" | sed -E 's/.* [0-9]+ +[0-9]+ +[0-9]+ \(([0-9.]+)\).*/\1/')
  forests+=("$dir/forest.pff")
  # shellcheck disable=SC2086  # map and real hold two and three words, one cell each
  rows+=("$(printf '| %-36s | %s | %s | %s | %s | %s | %s | %s |' "$name" ${map:-- -} "${map_r:--}" ${real:-- - -} "${arms:--}")")
done
(( ${#forests[@]} )) || { echo "realism-ablation: no variant matches '${POSEFOREST_ABLATION_ONLY:-}'" >&2; exit 2; }
echo
echo "== 1. choose on these: the validation sets (scripts/validate.sh --images $test_images --no-real)"
POSEFOREST_OUT=${POSEFOREST_OUT:-$root/out} POSEFOREST_DATA_DIR=$data POSEFOREST_BIN_DIR=$bin \
  bash "$root/scripts/validate.sh" --images "$test_images" --no-real "${forests[@]}"
echo
echo "== 2. for the record, after the choice: the held-out test clips and the real frames"
echo "images per tree: $per_tree; mAP and accuracy on $test_images held-out classic renders; real: 9 frames, 90 joints"
echo "| variant | mAP, classic renders | per-class accuracy %, classic | mAP, realistic renders | real: tracked within 0.10 m | real: found within | real: any within 0.10 m | real: elbows, wrists, hands tracked within |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|"
printf '%s\n' "${rows[@]}"
