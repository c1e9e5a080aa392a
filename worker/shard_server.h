#pragma once
// A worker's shard: the frames the coordinator assigns it (ShardAssignment) and their samples,
// one engine::Shard, through which it answers the coordinator's rounds (LevelRequests: census,
// ranges and fused nodes, histograms, frame lists; replies in the wire codec's form,
// engine/wire_codec.h) and routes its samples down the decided splits (SplitDecisions).

#include <cstdint>
#include <map>
#include <memory>
#include <vector>

#include "engine/histogram_builder.h"
#include "engine/sample_set.h"
#include "engine/shard.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/core/result.h"
#include "worker/context.h"

namespace poseforest::worker {

class ShardServer {
 public:
  explicit ShardServer(Context& ctx) : ctx_(ctx) {}

  /// A new job (ctx.params set): no shard, no frames, a new histogram builder.
  void StartJob();

  /// Loads an assignment: its frames (kept from the tree's last assignment, else rendered or
  /// loaded) and their samples, all at the root.
  core::Status Load(const v1::ShardAssignment& s);
  /// Routes the samples down the splits of `d`.
  core::Status Apply(const v1::SplitDecisions& d);
  /// Answers a LevelRequest with a HistogramReply.
  core::Status Answer(const v1::LevelRequest& req);

  bool have_shard() const { return have_shard_; }
  int tree() const { return tree_; }
  /// The shard's frames when it holds tree `t` (a subtree task's frames may be here), else null.
  const std::map<uint64_t, engine::ShardFrame>* FramesOf(int t) const { return t == tree_ ? &frames_ : nullptr; }

 private:
  /// The request's nodes as plans: features drawn (ranges, histograms), and for histograms the
  /// shape and cuts from the coordinator's part counts and merged ranges.
  core::Status PlansOf(const v1::LevelRequest& req, std::vector<engine::NodePlan>* plans) const;
  /// The phases' replies; each returns how many node histograms it put in the reply.
  uint64_t AnswerRanges(std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply);
  uint64_t AnswerHistograms(std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply);
  void AnswerFrames(const std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply);
  void AnswerCounts(const std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply);
  engine::Shard shard() { return engine::Shard(samples_, ctx_.params, *builder_); }

  Context& ctx_;
  int tree_ = -1;
  bool have_shard_ = false;
  std::map<uint64_t, engine::ShardFrame> frames_;  // tree-local frame index -> frame
  engine::SampleSet samples_;
  std::unique_ptr<engine::HistogramBuilder> builder_;
  int applied_levels_ = 0;
  /// Wall seconds spent rendering shard frames not yet reported (HistogramReply.render_micros).
  double render_unreported_s_ = 0;
};

}  // namespace poseforest::worker
