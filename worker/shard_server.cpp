#include "worker/shard_server.h"

#include <algorithm>
#include <string>

#include "engine/candidates.h"
#include "engine/wire_codec.h"
#include "runtime/core/body_parts.h"

namespace poseforest::worker {

using core::ErrorCode;
using core::Status;

void ShardServer::StartJob() {
  builder_ = std::make_unique<engine::HistogramBuilder>(ctx_.params.constants, ctx_.params.threads);
  tree_ = -1;
  have_shard_ = false;
  frames_.clear();
  samples_ = engine::SampleSet{};
}

Status ShardServer::Load(const v1::ShardAssignment& s) {
  const engine::TrainParams& params = ctx_.params;
  WorkerCpu& cpu = ctx_.cpu;
  CpuTimer timer(&cpu.shard);
  const uint64_t ipt = uint64_t(params.images_per_tree);
  if (s.tree() >= uint32_t(params.num_trees)) return Status(ErrorCode::kInvalidArgument, "tree out of range");
  if (s.pixels_per_image() != uint32_t(params.pixels_per_image))
    return Status(ErrorCode::kInvalidArgument, "pixels_per_image differs from the job's");
  std::vector<uint64_t> wanted;
  for (const auto& r : s.ranges()) {
    if (r.seed() != params.source.seed) return Status(ErrorCode::kInvalidArgument, "image range of another seed");
    for (uint64_t g = r.first_index(); g < r.first_index() + r.count(); ++g) {
      if (g < uint64_t(s.tree()) * ipt || g >= uint64_t(s.tree() + 1) * ipt)
        return Status(ErrorCode::kInvalidArgument,
                      "frame " + std::to_string(g) + " is not one of tree " + std::to_string(s.tree()) + "'s");
      wanted.push_back(g - uint64_t(s.tree()) * ipt);
    }
  }
  std::sort(wanted.begin(), wanted.end());
  wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
  ++cpu.shard_loads;
  if (ctx_.opt.hold_in_shard_load) ctx_.opt.hold_in_shard_load();
  if (int(s.tree()) != tree_) frames_.clear();
  tree_ = int(s.tree());
  have_shard_ = false;
  for (auto it = frames_.begin(); it != frames_.end();)
    it = std::binary_search(wanted.begin(), wanted.end(), it->first) ? std::next(it) : frames_.erase(it);
  std::vector<uint64_t> missing;
  for (uint64_t i : wanted)
    if (!frames_.count(i)) missing.push_back(i);
  std::vector<engine::ShardFrame> loaded;
  const double t_render = proto::dds::NowSeconds();
  POSEFOREST_RETURN_IF_ERROR(engine::LoadFrames(params, tree_, missing, params.threads, &loaded, &cpu.shard));
  const double render_s = proto::dds::NowSeconds() - t_render;
  render_unreported_s_ += render_s;
  ctx_.live.shard_render_us += uint64_t(render_s * 1e6);
  for (size_t j = 0; j < missing.size(); ++j) frames_[missing[j]] = std::move(loaded[j]);
  ctx_.frames_rendered += missing.size();
  ctx_.live.shard_rendered += missing.size();
  ctx_.live.shard_hits += wanted.size() - missing.size();
  cpu.shard_frames += missing.size();
  samples_ = engine::SampleSet{};
  for (const auto& [i, f] : frames_) {
    if (f.picked.empty()) continue;  // no body in view (as LocalTrainer)
    samples_.AddFrame(i, f.frame, f.picked, params.constants);
  }
  samples_.StartTree(0);
  have_shard_ = true;
  applied_levels_ = 0;
  ctx_.assigned_any = true;
  ctx_.Log("tree " + std::to_string(tree_) + ": shard of " + std::to_string(wanted.size()) + " frames (" +
           std::to_string(missing.size()) + " new), " + std::to_string(samples_.num_samples()) + " samples");
  return Status::Ok();
}

Status ShardServer::Apply(const v1::SplitDecisions& d) {
  CpuTimer timer(&ctx_.cpu.decisions);
  std::vector<engine::SampleSet::Split> splits;
  for (const auto& n : d.nodes()) {
    if (n.kind_case() != v1::NodeDecision::kSplit) continue;
    engine::SampleSet::Split s;
    s.node = n.node_id();
    POSEFOREST_RETURN_IF_ERROR(engine::GetFeatureSplit(n.split(), &s.offsets, &s.cut));
    s.left_child = n.split().left_child();
    splits.push_back(s);
  }
  shard().ApplySplits(splits, ctx_.params.threads);
  ++applied_levels_;
  return Status::Ok();
}

Status ShardServer::PlansOf(const v1::LevelRequest& req, std::vector<engine::NodePlan>* plans) const {
  const engine::TrainParams& params = ctx_.params;
  const int n = req.node_ids_size(), k = params.candidate_features, t = params.thresholds_per_feature;
  plans->assign(static_cast<size_t>(n), {});
  for (int i = 0; i < n; ++i) {
    const v1::NodeSpec& spec = req.nodes(i);
    engine::NodePlan& plan = (*plans)[size_t(i)];
    plan.node = req.node_ids(i);
    plan.position = spec.position();
    plan.num_samples = spec.num_samples();
    if (req.phase() == v1::PHASE_RANGES || req.phase() == v1::PHASE_HISTOGRAMS)
      plan.features = engine::DrawFeatures(params, tree_, plan.position);
    if (req.phase() != v1::PHASE_HISTOGRAMS) continue;
    if (spec.part_counts_size() != core::kNumParts || spec.range_lo_size() != k || spec.range_hi_size() != k)
      return Status(ErrorCode::kInvalidArgument, "node spec of node " + std::to_string(plan.node) + " malformed");
    const std::vector<uint64_t> parts(spec.part_counts().begin(), spec.part_counts().end());
    plan.SetShape(parts, t);
    std::vector<engine::ResponseRange> ranges(static_cast<size_t>(k));
    for (int c = 0; c < k; ++c) ranges[size_t(c)] = {spec.range_lo(c), spec.range_hi(c)};
    plan.cuts = engine::DrawCuts(params, tree_, plan.position, ranges);
  }
  return Status::Ok();
}

namespace {
/// A node of the reply without a histogram: its id and zero part counts.
void AddEmptyNode(uint32_t node, v1::HistogramReply* reply) {
  auto* nh = reply->add_nodes();
  nh->set_node_id(node);
  nh->set_samples(0);
  for (int p = 0; p < core::kNumParts; ++p) nh->add_part_counts(0);
}
}  // namespace

uint64_t ShardServer::AnswerRanges(std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply) {
  // Nodes held entirely here with a whole-node reference: one fused pass (LocalTrainer's
  // BuildFused), histogram and cuts sent now; the others: ranges. A fused node's shape comes
  // from its samples here, which are all of them.
  const engine::Shard one = shard();
  for (engine::NodePlan& plan : plans)
    if (one.CanFuse(plan)) plan.SetShape(one.CountParts(plan.node), ctx_.params.thresholds_per_feature);
  engine::FirstPass pass;
  {
    CpuTimer timer(&ctx_.cpu.level_compute);
    engine::RunFirstPass(std::span<const engine::Shard>(&one, 1), tree_, plans, &pass);
  }
  uint64_t fused = 0;
  for (size_t i = 0; i < plans.size(); ++i) {
    const engine::NodePlan& plan = plans[i];
    auto* r = reply->add_ranges();
    if (!pass.fused[i]) {
      AddEmptyNode(plan.node, reply);
      for (const auto& rr : pass.ranges[i]) {
        r->add_lo(rr.lo);
        r->add_hi(rr.hi);
      }
      continue;
    }
    ++fused;
    auto* nh = reply->add_nodes();
    nh->set_node_id(plan.node);
    nh->set_samples(plan.num_samples);
    for (uint64_t c : one.CountParts(plan.node)) nh->add_part_counts(c);
    engine::EncodeWireRuns(pass.hists[i], plan, core::kNumParts, nh->mutable_runs());
    r->set_fused(true);
    engine::EncodeCuts(plan, r);
  }
  return fused;
}

uint64_t ShardServer::AnswerHistograms(std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply) {
  const engine::Shard one = shard();
  std::vector<engine::NodeHistogram> hists;
  {
    CpuTimer timer(&ctx_.cpu.level_compute);
    one.Histograms(plans, &hists);
  }
  for (size_t i = 0; i < plans.size(); ++i) {
    const engine::NodePlan& plan = plans[i];
    auto* nh = reply->add_nodes();
    nh->set_node_id(plan.node);
    const engine::NodeRange r = samples_.RangeOf(plan.node);
    nh->set_samples(r.end - r.begin);
    for (uint64_t c : one.CountParts(plan.node)) nh->add_part_counts(c);
    engine::EncodeWireRuns(hists[i], plan, core::kNumParts, nh->mutable_runs());
  }
  return plans.size();
}

void ShardServer::AnswerFrames(const std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply) {
  for (const engine::NodePlan& plan : plans) {
    AddEmptyNode(plan.node, reply);
    engine::EncodeNodeFrames(samples_, samples_.RangeOf(plan.node), reply->add_ranges());
  }
}

void ShardServer::AnswerCounts(const std::vector<engine::NodePlan>& plans, v1::HistogramReply* reply) {
  const engine::Shard one = shard();
  for (const engine::NodePlan& plan : plans) {
    AddEmptyNode(plan.node, reply);
    auto* rr = reply->add_ranges();
    for (uint64_t c : one.CountParts(plan.node)) rr->add_part_counts(c);
  }
}

Status ShardServer::Answer(const v1::LevelRequest& req) {
  const engine::TrainParams& params = ctx_.params;
  const int k = params.candidate_features, t = params.thresholds_per_feature;
  if (req.nodes_size() != req.node_ids_size())
    return Status(ErrorCode::kInvalidArgument, "node specs do not match node ids");
  if (req.num_candidates() != uint32_t(k) || req.num_thresholds() != uint32_t(t + 1) ||
      req.num_parts() != uint32_t(core::kNumParts))
    return Status(ErrorCode::kInvalidArgument, "request dimensions differ from the job's");
  if (req.phase() < v1::PHASE_RANGES || req.phase() > v1::PHASE_FRAMES)
    return Status(ErrorCode::kInvalidArgument, "unknown phase");
  WorkerCpu& cpu = ctx_.cpu;
  const double t0 = proto::dds::NowSeconds();
  const double cpu0 = ThreadCpu(), compute0 = cpu.level_compute;
  ctx_.busy = true;
  std::vector<engine::NodePlan> plans;
  if (Status st = PlansOf(req, &plans); !st.ok()) {
    ctx_.busy = false;
    return st;
  }
  v1::Envelope env;
  v1::HistogramReply* reply = env.mutable_histogram();
  reply->set_tree(req.tree());
  reply->set_level(req.level());
  reply->set_epoch(req.epoch());
  reply->set_num_candidates(uint32_t(k));
  reply->set_num_bins(uint32_t(t + 1));
  reply->set_num_parts(uint32_t(core::kNumParts));
  reply->set_phase(req.phase());
  uint64_t histograms_built = 0;  // node histograms in the reply (Stats())
  if (req.phase() == v1::PHASE_RANGES)
    histograms_built = AnswerRanges(plans, reply);
  else if (req.phase() == v1::PHASE_FRAMES)
    AnswerFrames(plans, reply);
  else if (req.phase() == v1::PHASE_COUNTS)
    AnswerCounts(plans, reply);
  else
    histograms_built = AnswerHistograms(plans, reply);
  cpu.level_encode += ThreadCpu() - cpu0 - (cpu.level_compute - compute0);
  reply->set_compute_micros(uint64_t((proto::dds::NowSeconds() - t0) * 1e6));
  if (ctx_.dispatch_received_s > 0 && t0 > ctx_.dispatch_received_s)
    reply->set_queued_micros(uint64_t((t0 - ctx_.dispatch_received_s) * 1e6));
  reply->set_render_micros(uint64_t(render_unreported_s_ * 1e6));
  render_unreported_s_ = 0;
  uint64_t binned = 0;  // samples in the histograms (fused or pass 2), as the coordinator counts
  for (const auto& nh : reply->nodes()) binned += nh.samples();
  ctx_.evaluations += binned * uint64_t(k);
  ctx_.live.evaluations += binned * uint64_t(k);
  ctx_.busy = false;
  Status sent = ctx_.Reply(env);
  if (sent.ok()) {
    ++ctx_.live.rounds[size_t(req.phase()) - 1];  // PHASE_RANGES (1) .. PHASE_FRAMES (4), checked above
    ctx_.live.histograms += histograms_built;
  }
  return sent;
}

}  // namespace poseforest::worker
