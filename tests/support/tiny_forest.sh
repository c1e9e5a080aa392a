# shellcheck shell=bash
# Sourced by the shell tests that need a forest file but not its accuracy.
#   train_tiny_forest POSEFOREST_BINARY OUT.pff
# Trains a tiny forest of the paper's 31 parts on rendered people (1 tree of depth 6, 4 images) in
# about a second, in the current folder (job.textproto, train.log beside it); on failure prints
# the training log and returns 1.
train_tiny_forest() {
  cat > job.textproto <<'JOB'
seed: 3 num_trees: 1 max_depth: 6 images_per_tree: 4 pixels_per_image: 200
candidate_features: 20 thresholds_per_feature: 5
source { rendered { seed: 1 } }
test_set { source { rendered { seed: 99 } } num_images: 2 }
JOB
  "$1" train job.textproto --out "$2" --quiet > train.log 2>&1 || { cat train.log; return 1; }
}
