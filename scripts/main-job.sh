#!/usr/bin/env bash
# README command one: install what is missing, build (Release), and run the main job on its
# embedded default (the job below):
#   1. mocap -> pose library: the shared BVH clips retargeted onto the canonical skeleton and
#      subsampled so no two poses are closer than 5 cm (section 2.2), split by clip into
#      train and test clips;
#   2. train a forest with the distributed service - a coordinator and 2 local worker processes
#      over Fast DDS (`train --local-workers 2`), each worker rendering its shard of frames on
#      the fly (headless EGL): mocap poses from the train clips on procedural and MakeHuman
#      bodies, random camera, Kinect-like noise; export the forest from the job's checkpoint
#      (`poseforest export`) and check it equals the coordinator's file; then train a small job
#      both ways and check the service writes the single-process engine's forest, byte for byte;
#   3. learn the joint-proposal parameters (b, lambda, zeta per joint) on validation renders of
#      the train clips and store them in the forest, and its offset votes (learn-votes: per leaf,
#      the offsets to the joints, from the training frames); report joint AP / mAP (mean shift, fast,
#      the ground-truth-parts upper bound, also with two people per frame) and the average
#      per-class accuracy on held-out renders of the test clips (section 4), with PR curves;
#      and the skeletons on the hand-labelled real Kinect frames (eval --real-labels);
#   4. run the runtime on a held-out render and on a real Kinect v1 frame: body parts and
#      3D joint proposals (JSON + picture); and PCL's independently trained trees on that frame.
# Outputs go to ./out (POSEFOREST_OUT); POSEFOREST_DATA_DIR points at the shared data.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
# shellcheck source=scripts/default-job.sh
source "$root/scripts/default-job.sh"
data=$(cd "${POSEFOREST_DATA_DIR:-$root/../shared/data}" 2>/dev/null && pwd) ||
  { echo "main-job: no shared data at ${POSEFOREST_DATA_DIR:-$root/../shared/data} (set POSEFOREST_DATA_DIR)" >&2; exit 1; }
out=${POSEFOREST_OUT:-$root/out}
mkdir -p "$out"
out=$(cd "$out" && pwd)
bin=$root/build/bin
start=$(date +%s)

scripts/setup.sh
echo "== build (Release)"
scripts/build.sh

echo "== 1. pose library from $data/mocap"
"$bin/poseforest-poselib" build --out "$out/mocap.pfposes" "$data/mocap"

# The embedded default job (proto/poseforest/v1/job.proto). Sized to train in about 14 minutes
# on two cores; the paper used 300k images per tree. 4,000 images per tree with 250 candidate
# features per node track more joints right than 1,000 images with 1,000 candidates, on
# validation renders and on the real frames, for 11 % more training time in one process (34 %
# through the service) (docs/training/realism.md, "Fewer candidates, more images").
main_images=4000
candidate_features=250
write_default_job "$out/job.textproto" "$main_images" 200 "$out/mocap.pfposes" "$data"
# the clips the job tests on are in $out/job.textproto; job_facing.textproto (step 3b) differs in
# the test people's yaw range only

echo "== 2. training ($out/job.textproto): coordinator + 2 local worker processes over Fast DDS"
rm -rf "$out/checkpoint" "$out/small_checkpoint"
"$bin/poseforest" train "$out/job.textproto" --out "$out/forest.pff" --local-workers 2 \
  --checkpoint "$out/checkpoint" --event-log "$out/events.jsonl"
"$bin/poseforest" export --checkpoint "$out/checkpoint" --out "$out/exported.pff"
cmp "$out/forest.pff" "$out/exported.pff"
echo "exported from the checkpoint == the coordinator's forest, byte for byte"
"$bin/poseforest" inspect "$out/forest.pff"

echo "== 2b. the distributed service (coordinator + 2 local workers over Fast DDS) on a small job"
small="$root/docs/training/smoke_job.textproto"
"$bin/poseforest" train "$small" --out "$out/small_single.pff" --quiet
"$bin/poseforest" coordinator "$small" --out "$out/small_distributed.pff" --local-workers 2 --checkpoint "$out/small_checkpoint"
cmp "$out/small_single.pff" "$out/small_distributed.pff"
echo "distributed forest == single-process forest, byte for byte"

echo "== 3. joint proposals: learn b, lambda, zeta per joint, for mean shift and for the fast clustering, on validation renders (train clips, unseen frames)"
"$bin/poseforest" tune-joints --forest "$out/forest.pff" --validation "$out/job.textproto" --frames 60 --out "$out/forest.pff"
echo "== 3'. offset votes: per leaf, the offsets to the joints its training pixels agree on (the skeleton's second source of joint candidates)"
"$bin/poseforest" learn-votes --forest "$out/forest.pff" --job "$out/job.textproto" --out "$out/forest.pff" --quiet
echo "== 3b. joint AP / mAP and per-class accuracy on held-out renders (test clips)"
"$bin/poseforest" eval --forest "$out/forest.pff" --test-set "$out/job.textproto" --png "$out/confusion.png" \
  --pr-png "$out/pr" --quiet | tee "$out/eval.txt"
echo "== 3b, facing. the same test clips with the people facing the camera (+-60 degrees, as the training people)"
write_default_job "$out/job_facing.textproto" "$main_images" 200 "$out/mocap.pfposes" "$data" "" "$classic_test_fields" 60
"$bin/poseforest" eval --forest "$out/forest.pff" --test-set "$out/job_facing.textproto" --method meanshift --quiet |
  tee "$out/eval_facing.txt" | grep -E '^eval: mAP|^mean over joints'
echo "== 3b'. real Kinect v1 frames, joints labelled by hand: the skeleton live gives, scored (pictures: $out/real/)"
"$bin/poseforest" eval --forest "$out/forest.pff" --real-labels "$data/real/skeltrack_kinect_depth/joint_labels.json" \
  --png-dir "$out/real" --quiet | tee "$out/real.txt"
echo "== 3c. two people per frame: proposals counted against each person's joints"
"$bin/poseforest" eval --forest "$out/forest.pff" --test-set "$out/job.textproto" --images 50 --people 2 \
  --method meanshift --quiet | sed -n '/^joint average precision/,$p'

echo "== 4. runtime: body parts and joint proposals"
"$bin/poseforest" render --out "$out/heldout" --count 4 --seed 4242 --poses "$out/mocap.pfposes" --clips test \
  --test-fraction 0.2 --split-seed 1 --bodies all --data "$data" --montage "$out/heldout/montage.png" >/dev/null
frame=$(ls "$data"/real/skeltrack_kinect_depth/depth-data-* | head -n 1)
"$bin/poseforest" infer --forest "$out/forest.pff" --joints --out-dir "$out/infer" "$out/heldout/depth_000000.png" "$frame"
"$bin/poseforest" import-pcl --out "$out/pcl_people.pff" "$data"/pretrained/pcl_people_trees/forest{1,2,3}_tree_20.txt.bz2
"$bin/poseforest" infer --forest "$out/pcl_people.pff" --out-dir "$out/pcl" "$frame"

echo "== done in $(( $(date +%s) - start )) s. In $out: forest.pff, confusion.png, infer/*.parts.png,"
echo "   infer/*.pose.png (depth | parts | joints; front/side/top views), infer/*.joints.json, pcl/,"
echo "   pr/pr_joints.png + pr/pr_mean.png (precision-recall curves)"
tail -n 1 "$out/eval.txt"
echo "people facing the camera: $(tail -n 1 "$out/eval_facing.txt")"
tail -n 1 "$out/real.txt"
