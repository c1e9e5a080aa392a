#pragma once
// The coordinator's checkpoint (checkpoint_dir/checkpoint.pb): the job, every finished tree's
// logged decisions, the levels of the tree in progress, its open frontier and the decided nodes
// of its delegated subtrees, and the epoch. Written atomically after every level and every
// tree, so a restarted coordinator (--resume) continues where it stopped and trains the same
// forest. `poseforest export` reads it too (checkpoint_export.h).

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "engine/frontier_loop.h"
#include "engine/subtree_trainer.h"
#include "poseforest/v1/checkpoint.pb.h"
#include "runtime/core/forest.h"
#include "runtime/core/result.h"

namespace poseforest::coordinator {

/// 2: frontier entries, logged decisions and subtree nodes carry heap positions (the random
/// draws are keyed by them since subtree hand-off); format 1 checkpoints cannot resume.
/// 3 (30 Nov 2026): format 2 with the file's checksum trailer (SealCheckpoint), which a format-3
/// file must have: a file cut short loses it. Format 2 files (no trailer) still resume.
inline constexpr uint32_t kCheckpointFormat = 3;

/// Where a resumed job goes on (Checkpoint::Start); nothing for a fresh one.
struct ResumePoint {
  bool resumed = false;
  std::vector<core::Tree> trees;            ///< the finished trees, replayed
  std::vector<engine::OpenNode> frontier;   ///< of the tree in progress (empty: from its root)
  int first_level = 0;                      ///< its next level
  uint64_t epoch = 0;                       ///< the epoch saved
};

class Checkpoint {
 public:
  /// `dir` empty: nothing is written or read.
  explicit Checkpoint(std::string dir);

  /// Starts the record of job `job_id` (`config_bytes`: its serialized config; the forest
  /// header's training focal length, which `poseforest export` writes). With `resume` and a
  /// checkpoint in the directory, continues that one instead: errors if it is not a
  /// checkpoint, of another format or written by another build (`build_id`, proto/dds/build_id.h;
  /// kVersionMismatch), or of another job.
  core::Result<ResumePoint> Start(const std::string& job_id, const std::string& config_bytes,
                                  const std::string& build_id, float training_fx, float training_fy,
                                  bool resume);

  /// The record (the tree in progress: current()).
  const v1::Checkpoint& record() const { return ckpt_; }
  /// A new level's log in the tree in progress.
  v1::LoggedLevel* AddLevel() { return ckpt_.mutable_current()->add_levels(); }

  /// A level is done: the next frontier and the delegated subtrees' remaining nodes recorded,
  /// then saved under `epoch`.
  core::Status LevelDone(std::span<const engine::OpenNode> next,
                         const std::map<uint64_t, engine::SubtreeNode>& delegated, uint64_t epoch);
  /// Tree `tree` is done: filed as finished, saved under `epoch`.
  core::Status TreeDone(int tree, uint64_t epoch);

 private:
  core::Status Save(uint64_t epoch);

  std::string dir_;
  v1::Checkpoint ckpt_;
};

}  // namespace poseforest::coordinator
