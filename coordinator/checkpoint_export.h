#pragma once
// The runtime forest from a coordinator checkpoint (`poseforest export`): the finished trees are
// rebuilt by replaying their logged decisions, exactly as the coordinator builds them, so the
// file of a finished job equals the coordinator's --out byte for byte. For a stopped job the tree
// in progress is either dropped or finished as leaves: every node of its next frontier becomes a
// leaf holding the node's part counts (which the checkpoint stores), as if training had stopped at
// that depth. Every field of the checkpoint is checked before use (a corrupt file is an error,
// never a crash).

#include <string>

#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

enum class PartialTree {
  kFinishAsLeaves,  ///< the tree in progress, its frontier turned into leaves
  kDrop,            ///< only finished trees
};

struct CheckpointForest {
  core::Forest forest;
  std::string job_id;
  int job_trees = 0;          ///< trees the job asks for
  int finished_trees = 0;     ///< trees the checkpoint holds complete
  bool job_finished = false;  ///< finished_trees == job_trees
  int partial_levels = 0;     ///< decided levels of the tree in progress (0: none)
  size_t partial_leaves = 0;  ///< frontier nodes made leaves (kFinishAsLeaves)
  bool partial_included = false;
};

/// A checkpoint file's bytes: the serialized v1::Checkpoint, then 8 bytes "PFCK" + the CRC-32 of
/// the message (little-endian), since 30 Nov 2026. Protobuf has no checksum of its own: a byte
/// changed on disk could parse as another valid job state and export another forest.
std::string SealCheckpoint(const std::string& message);
/// The message of a checkpoint file: kDataLoss (naming `file`) when its checksum does not match.
/// A file without the trailer is returned whole, unchecked, and `*sealed` (if given) says which:
/// files of format 3 must have it (one cut short loses it), files before 30 Nov 2026 lack it.
core::Result<std::string> UnsealCheckpoint(const std::string& bytes, const std::string& file,
                                           bool* sealed = nullptr);

/// Reads `path` (a checkpoint directory holding checkpoint.pb, or the file itself). Errors:
/// kNotFound (no checkpoint), kDataLoss (not a checkpoint, inconsistent decisions, naming the
/// tree and node), kInvalidArgument (nothing to export: no finished tree and no decided level).
core::Result<CheckpointForest> ForestFromCheckpoint(const std::string& path, PartialTree partial);
/// The same from the checkpoint's bytes; errors name `file`.
core::Result<CheckpointForest> ForestFromCheckpointBytes(const std::string& bytes, const std::string& file,
                                                         PartialTree partial);

}  // namespace poseforest::coordinator
