#include "coordinator/checkpoint.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include "coordinator/checkpoint_export.h"
#include "coordinator/level_records.h"
#include "engine/candidates.h"
#include "engine/tree_assembler.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/forest_format.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {
constexpr int kParts = core::kNumParts;
}  // namespace

Checkpoint::Checkpoint(std::string dir) : dir_(std::move(dir)) {}

Result<ResumePoint> Checkpoint::Start(const std::string& job_id, const std::string& config_bytes,
                                      const std::string& build_id, float training_fx, float training_fy,
                                      bool resume) {
  ResumePoint at;
  ckpt_.Clear();
  ckpt_.set_format(kCheckpointFormat);
  ckpt_.set_job_id(job_id);
  ckpt_.set_config(config_bytes);
  ckpt_.set_build_id(build_id);
  ckpt_.set_training_fx(training_fx);
  ckpt_.set_training_fy(training_fy);
  const std::string ckpt_path = dir_.empty() ? "" : (std::filesystem::path(dir_) / "checkpoint.pb").string();
  if (!(resume && !ckpt_path.empty() && std::filesystem::exists(ckpt_path))) return at;
  auto file_bytes = core::ReadFileText(ckpt_path);
  if (!file_bytes.ok()) return file_bytes.status();
  bool sealed = false;
  auto bytes = UnsealCheckpoint(*file_bytes, ckpt_path, &sealed);
  if (!bytes.ok()) return bytes.status();
  v1::Checkpoint saved;
  if (!saved.ParseFromString(*bytes) || saved.format() == 0)
    return Status(ErrorCode::kDataLoss, ckpt_path + ": not a checkpoint");
  if (saved.format() != 2 && saved.format() != kCheckpointFormat)
    return Status(ErrorCode::kVersionMismatch,
                  ckpt_path + ": checkpoint format " + std::to_string(saved.format()) +
                      ", this coordinator reads 2 and " + std::to_string(kCheckpointFormat));
  if (saved.format() >= 3 && !sealed)
    return Status(ErrorCode::kDataLoss, ckpt_path + ": no checksum at its end: the checkpoint is cut short");
  if (saved.config() != config_bytes || saved.job_id() != job_id)
    return Status(ErrorCode::kInvalidArgument, ckpt_path + ": checkpoint of another job");
  // The rest of the job must be trained by the build that trained its start, for the forest to
  // be the one an uninterrupted run gives (checkpoints before 30 Nov 2026 do not say).
  if (!saved.build_id().empty() && saved.build_id() != build_id)
    return Status(ErrorCode::kVersionMismatch,
                  ckpt_path + ": written by build \"" + saved.build_id() + "\", this coordinator is \"" +
                      build_id +
                      "\": resume with the build that started the job (or set POSEFOREST_BUILD_ID to \"" +
                      saved.build_id() + "\" if the builds are known to train alike)");
  for (const v1::LoggedTree& lt : saved.finished()) {
    engine::TreeAssembler a(kParts);
    POSEFOREST_RETURN_IF_ERROR(ReplayLoggedTree(lt, &a));
    at.trees.push_back(a.Finish());
  }
  for (const v1::FrontierEntry& fe : saved.frontier()) {
    if (fe.part_counts_size() != kParts) return Status(ErrorCode::kDataLoss, ckpt_path + ": frontier");
    // Every frontier node sits at depth first_level; node ids are breadth-first indices.
    at.frontier.push_back({fe.node(), fe.position(), engine::PositionDepth(fe.position()),
                           std::vector<uint64_t>(fe.part_counts().begin(), fe.part_counts().end()), 0, fe.node()});
  }
  at.first_level = saved.current().levels_size();
  at.epoch = saved.epoch();
  at.resumed = true;
  ckpt_ = saved;
  ckpt_.set_build_id(build_id);
  if (ckpt_.training_fx() == 0) ckpt_.set_training_fx(training_fx), ckpt_.set_training_fy(training_fy);
  return at;
}

Status Checkpoint::Save(uint64_t epoch) {
  if (dir_.empty()) return Status::Ok();
  ckpt_.set_epoch(epoch);
  ckpt_.set_format(kCheckpointFormat);
  const std::string bytes = SealCheckpoint(ckpt_.SerializeAsString());
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  return core::WriteFileAtomic(
      (std::filesystem::path(dir_) / "checkpoint.pb").string(),
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()));
}

Status Checkpoint::LevelDone(std::span<const engine::OpenNode> next,
                             const std::map<uint64_t, engine::SubtreeNode>& delegated, uint64_t epoch) {
  ckpt_.clear_frontier();
  for (const engine::OpenNode& f : next) {
    auto* fe = ckpt_.add_frontier();
    fe->set_node(f.node);
    fe->set_position(f.position);
    for (uint64_t c : f.parts) fe->add_part_counts(c);
  }
  // Every task of this level is in, so the subtrees' remaining decisions are all known.
  ckpt_.clear_subtree_nodes();
  for (const auto& [pos, n] : delegated) ToProto(n, ckpt_.add_subtree_nodes());
  return Save(epoch);
}

Status Checkpoint::TreeDone(int tree, uint64_t epoch) {
  *ckpt_.add_finished() = ckpt_.current();
  ckpt_.clear_current();
  ckpt_.clear_subtree_nodes();
  ckpt_.clear_frontier();
  ckpt_.set_tree(uint32_t(tree + 1));
  return Save(epoch);
}

}  // namespace poseforest::coordinator
