#!/usr/bin/env bash
# Fig. 6 of Shotton et al. 2011 at this machine's scale: average per-class accuracy on held-out
# mocap clips versus (a) training images per tree, (b) tree depth, (c) maximum probe offset.
# Results, scale and discussion: docs/training/fig6.md.
#
# usage: docs/training/fig6.sh [POSEFOREST] [OUT_DIR]
#   POSEFOREST  the program (default build/bin/poseforest; poseforest-poselib must sit next to it
#               unless POSELIB names a library)
#   OUT_DIR     job files, forests and logs (default /tmp/poseforest-fig6)
# Writes docs/training/fig6a_images.csv, fig6b_depth.csv, fig6c_offset.csv (CSV_DIR) and, with
# Debian's /usr/bin/python3 + matplotlib, the PNGs (docs/training/plot_fig6.py).
#
# Frames: the paper's setting, the mocap/MakeHuman rendered source (README main job): poses of
# the train clips of a pose library built from $POSEFOREST_DATA_DIR/mocap on procedural and
# MakeHuman bodies with Kinect noise; the test set renders poses of the held-out clips (clip-level
# split, test_fraction 0.2, split_seed 1), other seed. "Train" accuracy is measured on the first
# TRAIN_EVAL frames of tree 0's own training frames.
#
# Environment (defaults = the run in fig6.md, ~1 h on 2 shared cores):
#   TREES=1 CANDIDATES=500 THRESHOLDS=50 PIXELS=2000 TEST=50 TRAIN_EVAL=50 THREADS=0
#   IMAGE_STEPS="25 50 100 200 400 800"      (a) at depth 20, offset 129
#   DEPTH_IMAGES="50 400"                    (b) at offset 129: the first count at depths
#   DEPTH_STEPS_FIRST="4 6 8 10 12 14 16 18 20", the others at DEPTH_STEPS="4 8 12 16 20"
#   OFFSET_IMAGES=100 OFFSET_STEPS="10 20 40 65 129 200"          (c) depth 20
#   POSELIB (a .pfposes; default: built into OUT_DIR), POSEFOREST_DATA_DIR (default ../shared/data)
#   CSV_DIR (default docs/training), RESUME=1 reuses the forests and
#   accuracies already in OUT_DIR (a run that was stopped goes on where it was), PLOT=0 skips PNGs.
# A configuration shared by two experiments (e.g. 400 images at depth 20) is trained once.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
PF=${1:-$root/build/bin/poseforest}
OUT=${2:-/tmp/poseforest-fig6}
TREES=${TREES:-1}
CANDIDATES=${CANDIDATES:-500}
THRESHOLDS=${THRESHOLDS:-50}
PIXELS=${PIXELS:-2000}
TEST=${TEST:-50}
TRAIN_EVAL=${TRAIN_EVAL:-50}
THREADS=${THREADS:-0}
IMAGE_STEPS=${IMAGE_STEPS-"25 50 100 200 400 800"}
DEPTH_IMAGES=${DEPTH_IMAGES-"50 400"}
DEPTH_STEPS_FIRST=${DEPTH_STEPS_FIRST-"4 6 8 10 12 14 16 18 20"}
DEPTH_STEPS=${DEPTH_STEPS-"4 8 12 16 20"}
OFFSET_IMAGES=${OFFSET_IMAGES:-100}
OFFSET_STEPS=${OFFSET_STEPS-"10 20 40 65 129 200"}
CSV_DIR=${CSV_DIR:-$root/docs/training}
RESUME=${RESUME:-0}
PLOT=${PLOT:-1}
data=$(cd "${POSEFOREST_DATA_DIR:-$root/../shared/data}" 2>/dev/null && pwd) ||
  { echo "fig6: no shared data at ${POSEFOREST_DATA_DIR:-$root/../shared/data} (set POSEFOREST_DATA_DIR)" >&2; exit 1; }
[ -x "$PF" ] || { echo "fig6: $PF is not an executable (build poseforest first)" >&2; exit 1; }
PF=$(realpath "$PF")
mkdir -p "$OUT" "$CSV_DIR"
OUT=$(cd "$OUT" && pwd)
kit=$data/meshes/makehuman_hm08_kit
start=$(date +%s)

if [ -n "${POSELIB:-}" ]; then
  lib=$(realpath "$POSELIB")
else
  lib=$OUT/mocap.pfposes
  "$(dirname "$PF")/poseforest-poselib" build --out "$lib" "$data/mocap" > "$OUT/poselib.log" 2>&1 ||
    { echo "fig6: building the pose library failed, see $OUT/poselib.log" >&2; exit 1; }
fi

eval_help=$("$PF" eval --help)
eval_flags=()
if grep -q -- '--quiet' <<<"$eval_help"; then eval_flags+=(--quiet); fi
if grep -q -- '--method' <<<"$eval_help"; then eval_flags+=(--method none); fi  # accuracy only

rendered() {  # $1 = seed, $2 = clip set
  cat <<SRC
rendered {
      seed: $1
      rotation_range_deg: 120
      pose_library: "$lib"
      clips: $2
      test_fraction: 0.2
      split_seed: 1
      makehuman_kit: "$kit"
    }
SRC
}

job() {  # $1 = images, $2 = depth, $3 = offset, $4 = test source block, $5 = test images
  cat <<JOB
seed: 1
num_trees: $TREES
max_depth: $2
images_per_tree: $1
pixels_per_image: $PIXELS
candidate_features: $CANDIDATES
thresholds_per_feature: $THRESHOLDS
max_probe_offset_pixel_m: $3
threads: $THREADS
source {
  $(rendered 1 CLIP_SET_TRAIN)
}
test_set {
  source {
    $4
  }
  num_images: $5
}
JOB
}

accuracy() {  # $1 = forest, $2 = job -> "avg_class pixel"
  local log
  log=$("$PF" eval --forest "$1" --test-set "$2" --threads "$THREADS" "${eval_flags[@]}")
  echo "$log" > "${2%.textproto}.eval.log"
  local avg pix
  avg=$(echo "$log" | sed -n 's/^average per-class accuracy: \([0-9.]*\)%.*/\1/p')
  pix=$(echo "$log" | sed -n 's/^average per-class accuracy: .*(pixel accuracy \([0-9.]*\)%).*/\1/p')
  [ -n "$avg" ] || { echo "fig6: no accuracy in the output of eval on $2" >&2; exit 1; }
  echo "$avg ${pix:-NA}"
}

declare -A done_rows
point() {  # $1 = images, $2 = depth, $3 = offset -> ROW="test,pixel,train,seconds,nodes"
  local key="i$1_d$2_o$3"
  if [ -n "${done_rows[$key]:-}" ]; then ROW=${done_rows[$key]}; return; fi
  local base=$OUT/$key
  if [ "$RESUME" = 1 ] && [ -s "$base.row" ]; then ROW=$(cat "$base.row"); done_rows[$key]=$ROW; return; fi
  job "$1" "$2" "$3" "$(rendered 2 CLIP_SET_TEST)" "$TEST" > "$base.textproto"
  local train_n=$(( TRAIN_EVAL < $1 ? TRAIN_EVAL : $1 ))
  job "$1" "$2" "$3" "$(rendered 1 CLIP_SET_TRAIN)" "$train_n" > "$base.train.textproto"
  local t0 secs
  t0=$(date +%s)
  if [ "$RESUME" = 1 ] && [ -s "$base.pff" ] && [ -s "$base.seconds" ]; then
    secs=$(cat "$base.seconds")
  else
    "$PF" train "$base.textproto" --out "$base.pff" > "$base.train.log" 2>&1 ||
      { echo "fig6: training $base.textproto failed, see $base.train.log" >&2; exit 1; }
    secs=$(( $(date +%s) - t0 ))
    echo "$secs" > "$base.seconds"
  fi
  local nodes test train
  nodes=$("$PF" inspect "$base.pff" | sed -n 's/.*, nodes \([0-9][0-9]*\)$/\1/p' | tail -n 1)
  test=$(accuracy "$base.pff" "$base.textproto")
  train=$(accuracy "$base.pff" "$base.train.textproto")
  ROW="${test% *},${test#* },${train% *},$secs,${nodes:-NA}"
  done_rows[$key]=$ROW
  echo "$ROW" > "$base.row"
}

header="test_avg_class_acc,test_pixel_acc,train_avg_class_acc,train_wall_s,nodes"
a=$CSV_DIR/fig6a_images.csv b=$CSV_DIR/fig6b_depth.csv c=$CSV_DIR/fig6c_offset.csv
echo "images_per_tree,max_depth,max_offset,$header" > "$a.tmp"
echo "images_per_tree,max_depth,max_offset,$header" > "$b.tmp"
echo "images_per_tree,max_depth,max_offset,$header" > "$c.tmp"
echo "fig6: $TREES tree(s), $CANDIDATES candidates x $THRESHOLDS thresholds, $PIXELS px/image," \
  "$TEST test frames (held-out clips), forests in $OUT"
for n in $IMAGE_STEPS; do                                   # Fig. 6(a)
  point "$n" 20 129; row="$n,20,129,$ROW"; echo "(a) $row"; echo "$row" >> "$a.tmp"
done
first=1
for n in $DEPTH_IMAGES; do                                  # Fig. 6(b)
  steps=$DEPTH_STEPS; [ "$first" = 1 ] && steps=$DEPTH_STEPS_FIRST; first=0
  for d in $steps; do
    point "$n" "$d" 129; row="$n,$d,129,$ROW"; echo "(b) $row"; echo "$row" >> "$b.tmp"
  done
done
for o in $OFFSET_STEPS; do                                  # Fig. 6(c)
  point "$OFFSET_IMAGES" 20 "$o"; row="$OFFSET_IMAGES,20,$o,$ROW"; echo "(c) $row"; echo "$row" >> "$c.tmp"
done
mv "$a.tmp" "$a"; mv "$b.tmp" "$b"; mv "$c.tmp" "$c"
echo "fig6: wrote $a $b $c in $(( $(date +%s) - start )) s"
if [ "$PLOT" = 1 ]; then /usr/bin/python3 "$root/docs/training/plot_fig6.py" "$CSV_DIR"; fi
