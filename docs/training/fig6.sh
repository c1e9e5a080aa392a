#!/usr/bin/env bash
# Fig. 6 of Shotton et al. 2011 at small scale: average per-class accuracy on held-out frames
# versus (a) training images per tree, (b) tree depth, (c) maximum probe offset.
#
# usage: docs/training/fig6.sh [POSEFOREST] [OUT_DIR]
#   POSEFOREST  the program (default build-train/bin/poseforest)
#   OUT_DIR     job files, forests, logs and fig6.csv (default /tmp/poseforest-fig6)
# Environment: SOURCE=rendered|procedural (default rendered), TREES (default 3),
#   IMAGES (images per tree for (b) and (c), default 200), TEST (test frames, default 50),
#   IMAGE_STEPS, DEPTH_STEPS, OFFSET_STEPS (space-separated values), THREADS (default 0 = all).
# The paper's curves use 3 trees, 2000 features x 50 thresholds and up to 900k images; the
# defaults here take minutes to hours on a workstation, not a cluster day.
set -euo pipefail
PF=${1:-build-train/bin/poseforest}
OUT=${2:-/tmp/poseforest-fig6}
SOURCE=${SOURCE:-rendered}
TREES=${TREES:-3}
IMAGES=${IMAGES:-200}
TEST=${TEST:-50}
THREADS=${THREADS:-0}
IMAGE_STEPS=${IMAGE_STEPS:-"10 30 100 300"}
DEPTH_STEPS=${DEPTH_STEPS:-"4 8 12 16 20"}
OFFSET_STEPS=${OFFSET_STEPS:-"10 30 60 90 129"}
mkdir -p "$OUT"

source_block() {  # $1 = seed
  if [ "$SOURCE" = rendered ]; then echo "rendered { seed: $1 rotation_range_deg: 120 }"
  else echo "procedural { seed: $1 width: 320 height: 240 }"; fi
}

run() {  # $1 = experiment, $2 = value, $3 = images, $4 = depth, $5 = offset
  local name="$1-$2" job="$OUT/$1-$2.textproto"
  cat > "$job" <<JOB
seed: 1
num_trees: $TREES
max_depth: $4
images_per_tree: $3
pixels_per_image: 2000
candidate_features: 2000
thresholds_per_feature: 50
max_probe_offset_pixel_m: $5
threads: $THREADS
source { $(source_block 1) }
test_set { source { $(source_block 2) } num_images: $TEST }
JOB
  "$PF" train "$job" --out "$OUT/$name.pff" --quiet > "$OUT/$name.train.log"
  local acc
  acc=$("$PF" eval --forest "$OUT/$name.pff" --test-set "$job" | sed -n 's/^average per-class accuracy: \([0-9.]*\)%.*/\1/p')
  echo "$1,$2,$acc" | tee -a "$OUT/fig6.csv"
}

echo "experiment,value,average_per_class_accuracy_percent" > "$OUT/fig6.csv"
for n in $IMAGE_STEPS; do run images "$n" "$n" 20 129; done        # Fig. 6(a)
for d in $DEPTH_STEPS; do run depth "$d" "$IMAGES" "$d" 129; done   # Fig. 6(b)
for o in $OFFSET_STEPS; do run offset "$o" "$IMAGES" 20 "$o"; done  # Fig. 6(c)
echo "wrote $OUT/fig6.csv"
