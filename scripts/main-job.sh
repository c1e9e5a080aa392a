#!/usr/bin/env bash
# README command one: install what is missing, build (Release), and run the main job on its
# embedded default. Outputs go to ./out (POSEFOREST_OUT to change).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
data=${POSEFOREST_DATA_DIR:-$root/../shared/data}
out=${POSEFOREST_OUT:-$root/out}
bin=$root/build/bin/poseforest
mkdir -p "$out"

scripts/setup.sh
echo "== build (Release)"
scripts/build.sh

echo "== runtime on real data: PCL's trained people trees on real Kinect v1 frames"
if [[ -d "$data/pretrained/pcl_people_trees" && -d "$data/real/skeltrack_kinect_depth" ]]; then
  "$bin" import-pcl --out "$out/pcl_people.pff" "$data"/pretrained/pcl_people_trees/forest{1,2,3}_tree_20.txt.bz2
  "$bin" infer --forest "$out/pcl_people.pff" --out-dir "$out/real" "$data"/real/skeltrack_kinect_depth/depth-data-*
else
  echo "(skipped: no shared data at $data; set POSEFOREST_DATA_DIR)"
fi
echo "== done: outputs in $out"
