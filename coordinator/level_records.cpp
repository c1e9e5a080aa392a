#include "coordinator/level_records.h"

#include <algorithm>
#include <string>

#include "engine/candidates.h"
#include "engine/split_search.h"
#include "engine/wire_codec.h"
#include "runtime/core/body_parts.h"

namespace poseforest::coordinator {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {
constexpr int kParts = core::kNumParts;
}  // namespace

engine::SubtreeNode FromProto(const v1::SubtreeNode& n) {
  engine::SubtreeNode o;
  o.position = n.position();
  o.split = n.split();
  o.offsets = {int16_t(n.ux()), int16_t(n.uy()), int16_t(n.vx()), int16_t(n.vy())};
  o.cut = n.cut();
  o.gain = n.gain();
  o.parts.assign(n.part_counts().begin(), n.part_counts().end());
  return o;
}

void ToProto(const engine::SubtreeNode& n, v1::SubtreeNode* o) {
  o->set_position(n.position);
  o->set_split(n.split);
  if (n.split) {
    o->set_ux(n.offsets.ux), o->set_uy(n.offsets.uy), o->set_vx(n.offsets.vx), o->set_vy(n.offsets.vy);
    o->set_cut(n.cut);
    o->set_gain(n.gain);
  }
  for (uint64_t c : n.parts) o->add_part_counts(c);
}

Status ReplayLoggedTree(const v1::LoggedTree& log, engine::TreeAssembler* assembler) {
  for (const v1::LoggedLevel& level : log.levels())
    for (const v1::LoggedDecision& d : level.decisions()) {
      if (d.split()) {
        core::FeatureOffsets f{int16_t(d.ux()), int16_t(d.uy()), int16_t(d.vx()), int16_t(d.vy())};
        if (assembler->MakeSplit(d.node(), f, d.cut()) != d.left_child())
          return Status(ErrorCode::kDataLoss, "checkpoint: node layout does not replay");
      } else {
        if (d.part_counts_size() != kParts) return Status(ErrorCode::kDataLoss, "checkpoint: leaf part counts");
        std::vector<uint64_t> parts(d.part_counts().begin(), d.part_counts().end());
        assembler->MakeLeaf(d.node(), parts);
      }
    }
  return Status::Ok();
}

void LevelRecords::RestoreDecisions(int tree, const v1::LoggedTree& log) {
  tree_decisions_.clear();
  // Replays of a resumed tree's levels: rebuild the decisions from the log.
  for (const v1::LoggedLevel& lv : log.levels()) {
    v1::SplitDecisions d;
    d.set_tree(uint32_t(tree));
    d.set_level(uint32_t(tree_decisions_.size()));
    for (const v1::LoggedDecision& ld : lv.decisions()) {
      auto* nd = d.add_nodes();
      nd->set_node_id(ld.node());
      if (ld.delegated())
        nd->set_delegated(true);
      else if (ld.split())
        engine::SetFeatureSplit({int16_t(ld.ux()), int16_t(ld.uy()), int16_t(ld.vx()), int16_t(ld.vy())}, ld.cut(),
                                ld.left_child(), 0, nd->mutable_split());
      else
        for (uint64_t c : ld.part_counts()) nd->mutable_leaf()->add_part_counts(c);
    }
    tree_decisions_.push_back(std::move(d));
  }
}

Status LevelRecords::BeginTree(const v1::Checkpoint& ckpt) {
  assembler_ = std::make_unique<engine::TreeAssembler>(kParts);
  POSEFOREST_RETURN_IF_ERROR(ReplayLoggedTree(ckpt.current(), assembler_.get()));
  split_of_.clear();
  delegated_.clear();
  for (const v1::LoggedLevel& lv : ckpt.current().levels())
    for (const v1::LoggedDecision& d : lv.decisions())
      if (d.split())
        split_of_[d.position()] = {{int16_t(d.ux()), int16_t(d.uy()), int16_t(d.vx()), int16_t(d.vy())}, d.cut()};
  for (const v1::SubtreeNode& n : ckpt.subtree_nodes()) delegated_[n.position()] = FromProto(n);
  return Status::Ok();
}

core::Tree LevelRecords::FinishTree() { return assembler_->Finish(); }

void LevelRecords::BeginLevel(int tree, int level, v1::LoggedLevel* logged) {
  // Children in node order (breadth-first layout), decisions to the workers, the log.
  env_.Clear();
  v1::SplitDecisions* dec = env_.mutable_decisions();
  dec->set_tree(uint32_t(tree));
  dec->set_level(uint32_t(level));
  logged_ = logged;
}

const LevelRecords::SplitAt* LevelRecords::SplitAtPosition(uint64_t position) const {
  const auto it = split_of_.find(position);
  return it == split_of_.end() ? nullptr : &it->second;
}

Result<uint32_t> LevelRecords::Place(const engine::OpenNode& f, engine::NodeDecision& d, LevelFigures* figures) {
  engine::TreeAssembler& assembler = *assembler_;
  // One tree: a node's sample-node id is its breadth-first index, the assembler's.
  POSEFOREST_CHECK(f.node == f.local);
  if (d.tried) figures->evaluations += d.evaluations;
  figures->entropy_sum += engine::Entropy(f.parts) * double(f.total());
  auto* nd = env_.mutable_decisions()->add_nodes();
  nd->set_node_id(f.node);
  v1::LoggedDecision* ld = logged_->add_decisions();
  ld->set_node(f.node);
  ld->set_position(f.position);
  if (auto it = delegated_.find(f.position); it != delegated_.end()) {
    ld->set_delegated(true);
    // Decided by a worker that holds the whole subtree; the other workers drop their
    // samples of it (a delegated decision routes nothing).
    ++figures->from_subtrees;
    nd->set_delegated(true);
    const engine::SubtreeNode s = std::move(it->second);
    delegated_.erase(it);
    if (!std::equal(s.parts.begin(), s.parts.end(), f.parts.begin(), f.parts.end()))
      return Status(ErrorCode::kInternal, "subtree node " + std::to_string(f.position) + ": part counts");
    if (!s.split) {
      assembler.MakeLeaf(f.node, f.parts);
      for (uint64_t c : f.parts) ld->add_part_counts(c);
      return uint32_t(0);
    }
    figures->gain_sum += s.gain;
    const uint32_t left = assembler.MakeSplit(f.node, s.offsets, s.cut);
    ld->set_split(true);
    ld->set_ux(s.offsets.ux), ld->set_uy(s.offsets.uy), ld->set_vx(s.offsets.vx), ld->set_vy(s.offsets.vy);
    ld->set_cut(s.cut);
    ld->set_left_child(left);
    split_of_[f.position] = {s.offsets, s.cut};
    // The loop follows the worker's decision: children with the subtree's counts.
    d.split = true;
    d.offsets = s.offsets;
    d.choice.cut = s.cut;
    d.choice.left_parts = delegated_.at(engine::LeftChildPosition(f.position)).parts;
    d.choice.right_parts = delegated_.at(engine::RightChildPosition(f.position)).parts;
    return left;
  }
  if (!d.split) {
    assembler.MakeLeaf(f.node, f.parts);
    for (uint64_t c : f.parts) {
      nd->mutable_leaf()->add_part_counts(c);
      ld->add_part_counts(c);
    }
    return uint32_t(0);
  }
  const engine::SplitChoice& c = d.choice;
  figures->gain_sum += c.gain;
  const uint32_t left = assembler.MakeSplit(f.node, d.offsets, c.cut);
  engine::SetFeatureSplit(d.offsets, c.cut, left, uint32_t(c.candidate), nd->mutable_split());
  ld->set_split(true);
  ld->set_ux(d.offsets.ux), ld->set_uy(d.offsets.uy), ld->set_vx(d.offsets.vx), ld->set_vy(d.offsets.vy);
  ld->set_cut(c.cut);
  ld->set_left_child(left);
  split_of_[f.position] = {d.offsets, c.cut};
  return left;
}

}  // namespace poseforest::coordinator
