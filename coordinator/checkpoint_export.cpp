#include "coordinator/checkpoint_export.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "engine/job_spec.h"
#include "engine/tree_assembler.h"
#include "poseforest/v1/checkpoint.pb.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {
constexpr int kParts = core::kNumParts;
constexpr size_t kMaxNodes = size_t(1) << 26;  // far above a depth-30 tree's real size

/// Replays decisions into a TreeAssembler, checking first everything the assembler would
/// CHECK (it trusts its caller): node ids in range and undecided, the breadth-first child
/// numbering, offsets in int16, thresholds exact in float, part count lengths.
class SafeReplay {
 public:
  SafeReplay(std::string where, int max_depth) : where_(std::move(where)), max_depth_(max_depth), a_(kParts) {
    decided_.push_back(0);
    depth_.push_back(0);
  }

  Status Apply(const v1::LoggedDecision& d) {
    const uint32_t n = d.node();
    if (n >= decided_.size() || decided_[n])
      return Bad("node " + std::to_string(n) +
                 (n >= decided_.size() ? " does not exist yet" : " decided twice"));
    if (d.split()) {
      if (d.left_child() != decided_.size())
        return Bad("node " + std::to_string(n) + ": left child " + std::to_string(d.left_child()) +
                   ", the layout gives " + std::to_string(decided_.size()));
      for (int32_t v : {d.ux(), d.uy(), d.vx(), d.vy()})
        if (v < -32768 || v > 32767)
          return Bad("node " + std::to_string(n) + ": offset " + std::to_string(v));
      if (d.cut() <= -(1 << 22) || d.cut() >= (1 << 22))
        return Bad("node " + std::to_string(n) + ": threshold " + std::to_string(d.cut()));
      if (int(depth_[n]) >= max_depth_) return Bad("node " + std::to_string(n) + ": split below max_depth");
      if (decided_.size() + 2 > kMaxNodes) return Bad("too many nodes");
      a_.MakeSplit(n, {int16_t(d.ux()), int16_t(d.uy()), int16_t(d.vx()), int16_t(d.vy())}, d.cut());
      decided_[n] = 1;
      for (int i = 0; i < 2; ++i) decided_.push_back(0), depth_.push_back(depth_[n] + 1);
    } else {
      if (d.part_counts_size() != kParts)
        return Bad("leaf " + std::to_string(n) + ": " + std::to_string(d.part_counts_size()) +
                   " part counts, expected " + std::to_string(kParts));
      return Leaf(n, std::vector<uint64_t>(d.part_counts().begin(), d.part_counts().end()));
    }
    return Status::Ok();
  }

  Status Leaf(uint32_t n, const std::vector<uint64_t>& parts) {
    if (n >= decided_.size() || decided_[n])
      return Bad("node " + std::to_string(n) +
                 (n >= decided_.size() ? " does not exist yet" : " decided twice"));
    if (parts.size() != size_t(kParts)) return Bad("leaf " + std::to_string(n) + ": part counts");
    a_.MakeLeaf(n, parts);
    decided_[n] = 1;
    return Status::Ok();
  }

  /// Undecided node ids in order.
  std::vector<uint32_t> Open() const {
    std::vector<uint32_t> out;
    for (size_t i = 0; i < decided_.size(); ++i)
      if (!decided_[i]) out.push_back(uint32_t(i));
    return out;
  }

  Result<core::Tree> Finish() {
    if (auto open = Open(); !open.empty())
      return Bad(std::to_string(open.size()) + " nodes left undecided (first: " + std::to_string(open[0]) +
                 ")");
    return a_.Finish();
  }

  Status Bad(const std::string& what) const { return Status(ErrorCode::kDataLoss, where_ + ": " + what); }

 private:
  std::string where_;
  int max_depth_;
  engine::TreeAssembler a_;
  std::vector<uint8_t> decided_;
  std::vector<uint32_t> depth_;
};
}  // namespace

namespace {
constexpr char kSealMagic[4] = {'P', 'F', 'C', 'K'};
constexpr size_t kSealSize = 8;
}  // namespace

std::string SealCheckpoint(const std::string& message) {
  const uint32_t crc = core::Crc32(reinterpret_cast<const uint8_t*>(message.data()), message.size());
  std::string out = message;
  out.append(kSealMagic, sizeof kSealMagic);
  for (int i = 0; i < 4; ++i) out.push_back(char(uint8_t(crc >> (8 * i))));
  return out;
}

Result<std::string> UnsealCheckpoint(const std::string& bytes, const std::string& file, bool* sealed) {
  if (sealed) *sealed = false;
  if (bytes.size() < kSealSize || bytes.compare(bytes.size() - kSealSize, 4, kSealMagic, 4) != 0)
    return bytes;  // before the trailer, or cut short (the caller checks the format)
  const size_t n = bytes.size() - kSealSize;
  uint32_t stored = 0;
  for (int i = 0; i < 4; ++i) stored |= uint32_t(uint8_t(bytes[n + 4 + size_t(i)])) << (8 * i);
  if (core::Crc32(reinterpret_cast<const uint8_t*>(bytes.data()), n) != stored)
    return Status(ErrorCode::kDataLoss, file + ": checksum mismatch: the checkpoint is corrupt");
  if (sealed) *sealed = true;
  return bytes.substr(0, n);
}

Result<CheckpointForest> ForestFromCheckpoint(const std::string& path, PartialTree partial) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const std::string file = fs::is_directory(path, ec) ? (fs::path(path) / "checkpoint.pb").string() : path;
  if (!fs::exists(file, ec))
    return Status(ErrorCode::kNotFound, file + ": no checkpoint (run the coordinator with --checkpoint DIR)");
  auto bytes = core::ReadFileText(file);
  if (!bytes.ok()) return bytes.status();
  return ForestFromCheckpointBytes(*bytes, file, partial);
}

Result<CheckpointForest> ForestFromCheckpointBytes(const std::string& file_bytes, const std::string& file,
                                                   PartialTree partial) {
  bool sealed = false;
  auto message = UnsealCheckpoint(file_bytes, file, &sealed);
  if (!message.ok()) return message.status();
  const std::string& bytes = *message;
  v1::Checkpoint ck;
  if (bytes.empty() || !ck.ParseFromString(bytes))
    return Status(ErrorCode::kDataLoss, file + ": not a coordinator checkpoint (does not parse)");
  // 2 adds heap positions and pending subtree nodes, which export does not need; 3 the file's
  // checksum, which a format-3 file cut short has lost.
  if (ck.format() < 1 || ck.format() > 3)
    return Status(ErrorCode::kDataLoss,
                  file + ": checkpoint format " + std::to_string(ck.format()) + ", expected 1 to 3");
  if (ck.format() >= 3 && !sealed)
    return Status(ErrorCode::kDataLoss, file + ": no checksum at its end: the checkpoint is cut short");
  v1::TrainerConfig config;
  if (!config.ParseFromString(ck.config()))
    return Status(ErrorCode::kDataLoss, file + ": the job config inside does not parse");
  // The frame source may name files of another machine (pose library); it does not affect the
  // forest's header, so a procedural stand-in lets the other fields be checked here.
  v1::TrainerConfig checked = config;
  checked.mutable_source()->Clear();
  checked.mutable_source()->mutable_procedural();
  checked.clear_test_set();
  auto params = engine::ParamsFromConfig(checked, file + " (job config)");
  if (!params.ok()) return Status(ErrorCode::kDataLoss, params.status().message());

  CheckpointForest out;
  out.job_id = ck.job_id();
  out.job_trees = params->num_trees;
  if (ck.finished_size() > params->num_trees)
    return Status(ErrorCode::kDataLoss, file + ": " + std::to_string(ck.finished_size()) +
                                            " finished trees, the job has " +
                                            std::to_string(params->num_trees));
  std::vector<core::Tree> trees;
  for (int t = 0; t < ck.finished_size(); ++t) {
    SafeReplay r(file + ": tree " + std::to_string(t), params->max_depth);
    for (const v1::LoggedLevel& lv : ck.finished(t).levels())
      for (const v1::LoggedDecision& d : lv.decisions()) POSEFOREST_RETURN_IF_ERROR(r.Apply(d));
    auto tree = r.Finish();
    if (!tree.ok()) return tree.status();
    trees.push_back(std::move(*tree));
  }
  out.finished_trees = int(trees.size());
  out.job_finished = out.finished_trees == params->num_trees;
  out.partial_levels = ck.current().levels_size();
  if (!out.job_finished && out.partial_levels > 0 && partial == PartialTree::kFinishAsLeaves) {
    const int t = int(trees.size());
    SafeReplay r(file + ": tree in progress (" + std::to_string(t) + ")", params->max_depth);
    for (const v1::LoggedLevel& lv : ck.current().levels())
      for (const v1::LoggedDecision& d : lv.decisions()) POSEFOREST_RETURN_IF_ERROR(r.Apply(d));
    const std::vector<uint32_t> open = r.Open();
    if (open.size() != size_t(ck.frontier_size()))
      return r.Bad(std::to_string(open.size()) + " open nodes but " + std::to_string(ck.frontier_size()) +
                   " frontier entries");
    for (int i = 0; i < ck.frontier_size(); ++i) {
      const v1::FrontierEntry& fe = ck.frontier(i);
      if (fe.node() != open[size_t(i)])
        return r.Bad("frontier entry " + std::to_string(i) + " is node " + std::to_string(fe.node()) +
                     ", expected " + std::to_string(open[size_t(i)]));
      if (fe.part_counts_size() != kParts)
        return r.Bad("frontier node " + std::to_string(fe.node()) + ": part counts");
      POSEFOREST_RETURN_IF_ERROR(
          r.Leaf(fe.node(), std::vector<uint64_t>(fe.part_counts().begin(), fe.part_counts().end())));
    }
    auto tree = r.Finish();
    if (!tree.ok()) return tree.status();
    trees.push_back(std::move(*tree));
    out.partial_leaves = open.size();
    out.partial_included = true;
  }
  if (trees.empty())
    return Status(ErrorCode::kInvalidArgument,
                  file + ": nothing to export yet (no finished tree" +
                      (out.partial_levels > 0 ? "; the tree in progress is dropped by --partial drop)"
                                              : " and no decided level)"));
  out.forest.constants = params->constants;
  out.forest.num_parts = kParts;
  out.forest.part_names = core::Forest::DefaultPartNames();
  // The training focal length the coordinator recorded (engine::EmptyForest on its machine);
  // checkpoints from before it hold 0: the Kinect v1's, as every forest had then.
  if (ck.training_fx() > 0 && ck.training_fy() > 0) {
    out.forest.training_fx = ck.training_fx();
    out.forest.training_fy = ck.training_fy();
  }
  out.forest.trees = std::move(trees);
  POSEFOREST_RETURN_IF_ERROR(core::ValidateForest(out.forest, file));
  return out;
}

}  // namespace poseforest::coordinator
