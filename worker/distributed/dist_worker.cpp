#include "worker/distributed/dist_worker.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>

#include "poseforest/v1/job.pb.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/message_gate.h"
#include "runtime/core/body_parts.h"
#include "worker/candidates.h"
#include "worker/distributed/dist_common.h"
#include "worker/histogram_builder.h"
#include "worker/image_source.h"
#include "worker/job_spec.h"
#include "worker/sample_set.h"

namespace poseforest::dist {

using core::ErrorCode;
using core::Status;
using dds::Topic;

namespace {
struct FrameData {
  core::DepthImage depth;
  std::vector<worker::PixelSample> picked;
};

v1::RendererKind RendererOf(const worker::TrainParams& p) {
  switch (p.source.kind) {
    case worker::SourceKind::kRendered:
      return v1::RENDERER_KIND_EGL;
    case worker::SourceKind::kDataset:
      return v1::RENDERER_KIND_DATASET;
    case worker::SourceKind::kProcedural:
      return v1::RENDERER_KIND_PROCEDURAL;
  }
  return v1::RENDERER_KIND_PROCEDURAL;
}
}  // namespace

struct DistWorker::Impl {
  WorkerOptions& opt;
  std::atomic<bool>& stop;
  std::unique_ptr<dds::DdsNode> node;

  std::mutex send_mu;  // guards stamper + job identity used by the heartbeat thread
  dds::EnvelopeStamper stamper;
  std::atomic<bool> has_job{false}, assigned_any{false}, busy{false};
  std::atomic<uint64_t> newest_epoch{0}, frames_rendered{0}, shard_epoch{0};
  std::atomic<v1::RendererKind> renderer{v1::RENDERER_KIND_PROCEDURAL};

  dds::MessageGate job_gate;
  std::unique_ptr<dds::MessageGate> gate;
  std::string job_id, coordinator_id;
  worker::TrainParams params;

  int tree = -1;
  bool have_shard = false;
  std::map<uint64_t, FrameData> cache;  // tree-local frame index -> frame
  worker::SampleSet samples;
  std::unique_ptr<worker::HistogramBuilder> builder;
  int applied_levels = 0;

  Impl(WorkerOptions& o, std::atomic<bool>& s)
      : opt(o),
        stop(s),
        stamper("", o.worker_id, v1::SENDER_KIND_WORKER),
        job_gate(dds::GateConfig{o.worker_id, "", 16, o.log}) {}

  void Log(const std::string& m) { opt.log(m); }

  Status Publish(Topic topic, v1::Envelope& env) {
    std::string bytes;
    {
      std::lock_guard<std::mutex> lock(send_mu);
      bytes = stamper.Seal(topic, env);
    }
    return node->Publish(topic, bytes);
  }

  v1::WorkerCapacity Capacity() const {
    v1::WorkerCapacity c;
    c.set_threads(uint32_t(std::max(1, opt.threads)));
    c.set_memory_mb(1024);
    c.set_renderer(renderer);
    return c;
  }

  void HeartbeatLoop() {
    while (!stop) {
      if (has_job) {
        v1::Envelope env;
        if (!assigned_any) {
          auto* h = env.mutable_hello();
          *h->mutable_capacity() = Capacity();
          char host[256] = {};
          ::gethostname(host, sizeof host - 1);
          h->set_hostname(host);
          h->set_pid(uint32_t(::getpid()));
          h->set_build_version("poseforest-dist-1");
        } else {
          auto* h = env.mutable_heartbeat();
          *h->mutable_capacity() = Capacity();
          h->set_busy_threads(busy ? uint32_t(std::max(1, opt.threads)) : 0);
          h->set_epoch(newest_epoch);
          h->set_frames_rendered(frames_rendered);
          HeartbeatExt ext;
          ext.set_shard_epoch(shard_epoch);
          AttachExt(ext, h);
        }
        (void)Publish(Topic::kPresence, env);
      }
      std::this_thread::sleep_for(opt.heartbeat_period);
    }
  }

  void OnJob(const v1::Envelope& env) {
    const auto& job = env.job();
    if (!opt.job_id.empty() && env.job_id() != opt.job_id) return;
    if (has_job && env.job_id() == job_id && job.coordinator_id() == coordinator_id) return;
    auto p = worker::ParamsFromConfig(job.config(), "job " + env.job_id());
    if (!p.ok()) {
      Log("job " + env.job_id() + " refused: " + p.status().ToString());
      return;
    }
    if (job.num_parts() != uint32_t(core::kNumParts)) {
      Log("job " + env.job_id() + " refused: " + std::to_string(job.num_parts()) + " parts, this build has " +
          std::to_string(core::kNumParts));
      return;
    }
    // A new job, or a restarted coordinator: start from scratch.
    params = std::move(*p);
    params.threads = std::max(1, opt.threads);
    job_id = env.job_id();
    coordinator_id = job.coordinator_id();
    gate = std::make_unique<dds::MessageGate>(dds::GateConfig{opt.worker_id, job_id, 16, opt.log});
    gate->set_coordinator_id(coordinator_id);
    gate->set_num_parts(uint32_t(core::kNumParts));
    builder = std::make_unique<worker::HistogramBuilder>(params.constants, params.threads);
    tree = -1;
    have_shard = false;
    cache.clear();
    samples = worker::SampleSet{};
    renderer = RendererOf(params);
    {
      std::lock_guard<std::mutex> lock(send_mu);
      stamper.set_job_id(job_id);
    }
    assigned_any = false;
    has_job = true;
    Log("joined job " + job_id + " of " + coordinator_id + ": " + worker::DescribeParams(params));
  }

  Status LoadShard(const v1::ShardAssignment& s) {
    const uint64_t ipt = uint64_t(params.images_per_tree);
    if (s.tree() >= uint32_t(params.num_trees))
      return Status(ErrorCode::kInvalidArgument, "tree out of range");
    if (s.pixels_per_image() != uint32_t(params.pixels_per_image))
      return Status(ErrorCode::kInvalidArgument, "pixels_per_image differs from the job's");
    std::vector<uint64_t> wanted;
    for (const auto& r : s.ranges()) {
      if (r.seed() != params.source.seed)
        return Status(ErrorCode::kInvalidArgument, "image range of another seed");
      for (uint64_t g = r.first_index(); g < r.first_index() + r.count(); ++g) {
        if (g < uint64_t(s.tree()) * ipt || g >= uint64_t(s.tree() + 1) * ipt)
          return Status(ErrorCode::kInvalidArgument, "frame " + std::to_string(g) + " is not one of tree " +
                                                         std::to_string(s.tree()) + "'s");
        wanted.push_back(g - uint64_t(s.tree()) * ipt);
      }
    }
    std::sort(wanted.begin(), wanted.end());
    wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
    if (int(s.tree()) != tree) cache.clear();
    tree = int(s.tree());
    have_shard = false;
    for (auto it = cache.begin(); it != cache.end();)
      it = std::binary_search(wanted.begin(), wanted.end(), it->first) ? std::next(it) : cache.erase(it);
    std::vector<uint64_t> missing;
    for (uint64_t i : wanted)
      if (!cache.count(i)) missing.push_back(i);
    // Frames in parallel, one ImageSource per thread (a renderer's context is per thread).
    const int threads = std::max(1, std::min<int>(params.threads, int(missing.size())));
    std::vector<FrameData> loaded(missing.size());
    std::vector<Status> errors(static_cast<size_t>(threads));
    std::vector<std::thread> pool;
    for (int tid = 0; tid < threads; ++tid) {
      pool.emplace_back([&, tid] {
        try {
          auto source = worker::MakeImageSource(params.source);
          if (!source.ok()) {
            errors[size_t(tid)] = source.status();
            return;
          }
          for (size_t j = size_t(tid); j < missing.size(); j += size_t(threads)) {
            const uint64_t index = uint64_t(tree) * ipt + missing[j];
            auto frame = (*source)->Frame(index);
            if (!frame.ok()) {
              errors[size_t(tid)] = frame.status();
              return;
            }
            loaded[j].picked = worker::SamplePixels(
                *frame, params.pixels_per_image, params.part_balance,
                core::CounterRng(params.seed, uint64_t(tree), index, worker::kSamplingStream));
            loaded[j].depth = std::move(frame->depth);
          }
        } catch (const std::exception& e) {
          errors[size_t(tid)] = Status(ErrorCode::kInternal, std::string("loading frames: ") + e.what());
        }
      });
    }
    for (auto& t : pool) t.join();
    for (const Status& e : errors)
      if (!e.ok()) return e;
    for (size_t j = 0; j < missing.size(); ++j) cache[missing[j]] = std::move(loaded[j]);
    frames_rendered += missing.size();
    samples = worker::SampleSet{};
    for (const auto& [i, f] : cache) {
      if (f.picked.empty()) continue;  // no body in view (as LocalTrainer)
      samples.AddFrame(i, f.depth, f.picked, params.constants);
    }
    samples.StartTree(0);
    have_shard = true;
    applied_levels = 0;
    assigned_any = true;
    Log("tree " + std::to_string(tree) + ": shard of " + std::to_string(wanted.size()) + " frames (" +
        std::to_string(missing.size()) + " new), " + std::to_string(samples.num_samples()) + " samples");
    return Status::Ok();
  }

  Status ApplyDecisions(const v1::SplitDecisions& d) {
    std::vector<worker::SampleSet::Split> splits;
    for (const auto& n : d.nodes()) {
      if (n.kind_case() != v1::NodeDecision::kSplit) continue;
      worker::SampleSet::Split s;
      s.node = n.node_id();
      POSEFOREST_RETURN_IF_ERROR(GetFeatureSplit(n.split(), &s.offsets, &s.cut));
      s.left_child = n.split().left_child();
      splits.push_back(s);
    }
    samples.ApplySplits(splits, params.constants, params.threads);
    ++applied_levels;
    return Status::Ok();
  }

  Status Answer(const v1::LevelRequest& req) {
    LevelRequestExt ext;
    POSEFOREST_RETURN_IF_ERROR(ReadExt(req, &ext, "LevelRequest"));
    const int n = req.node_ids_size();
    const int k = params.candidate_features;
    const int t = params.thresholds_per_feature;
    if (ext.nodes_size() != n) return Status(ErrorCode::kInvalidArgument, "node specs do not match node ids");
    if (req.num_candidates() != uint32_t(k) || req.num_thresholds() != uint32_t(t + 1) ||
        req.num_parts() != uint32_t(core::kNumParts))
      return Status(ErrorCode::kInvalidArgument, "request dimensions differ from the job's");
    const double t0 = NowSeconds();
    busy = true;
    std::vector<worker::NodePlan> plans(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
      const NodeSpec& spec = ext.nodes(i);
      worker::NodePlan& plan = plans[size_t(i)];
      plan.node = req.node_ids(i);
      plan.num_samples = spec.num_samples();
      if (ext.phase() != PHASE_COUNTS) plan.features = worker::DrawFeatures(params, tree, plan.node);
      if (ext.phase() == PHASE_HISTOGRAMS) {
        if (spec.part_counts_size() != core::kNumParts || spec.range_lo_size() != k ||
            spec.range_hi_size() != k) {
          busy = false;
          return Status(ErrorCode::kInvalidArgument,
                        "node spec of node " + std::to_string(plan.node) + " malformed");
        }
        std::vector<uint64_t> parts(spec.part_counts().begin(), spec.part_counts().end());
        plan.SetParts(parts);
        plan.sample_bins = worker::UseSampleBins(plan.num_samples, t, plan.num_slots);
        plan.cut_stride = worker::CutStride(t);
        std::vector<worker::ResponseRange> ranges(static_cast<size_t>(k));
        for (int c = 0; c < k; ++c) ranges[size_t(c)] = {spec.range_lo(c), spec.range_hi(c)};
        plan.cuts = worker::DrawCuts(params, tree, plan.node, ranges);
      }
    }
    v1::Envelope env;
    v1::HistogramReply* reply = env.mutable_histogram();
    reply->set_tree(req.tree());
    reply->set_level(req.level());
    reply->set_epoch(req.epoch());
    reply->set_num_candidates(uint32_t(k));
    reply->set_num_bins(uint32_t(t + 1));
    reply->set_num_parts(uint32_t(core::kNumParts));
    HistogramReplyExt rext;
    rext.set_phase(ext.phase());
    if (ext.phase() == PHASE_RANGES) {
      // Nodes held entirely here with a whole-node reference: one fused pass (LocalTrainer's
      // BuildFused), histogram and cuts sent now; the others: ranges.
      std::vector<worker::NodePlan> normal, fused;
      std::vector<std::pair<bool, size_t>> where(static_cast<size_t>(n));
      for (int i = 0; i < n; ++i) {
        worker::NodePlan& plan = plans[size_t(i)];
        if (worker::HistogramBuilder::CanFuse(samples, params, plan)) {
          std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
          samples.CountParts(samples.RangeOf(plan.node), core::kNumParts, parts.data());
          plan.SetParts(parts);
          plan.sample_bins = worker::UseSampleBins(plan.num_samples, t, plan.num_slots);
          plan.cut_stride = worker::CutStride(t);
          where[size_t(i)] = {true, fused.size()};
          fused.push_back(std::move(plan));
        } else {
          where[size_t(i)] = {false, normal.size()};
          normal.push_back(std::move(plan));
        }
      }
      std::vector<std::vector<worker::ResponseRange>> ranges;
      if (!normal.empty()) builder->ComputeRanges(samples, params, tree, normal, &ranges);
      std::vector<worker::NodeHistogram> fused_hists;
      if (!fused.empty()) builder->BuildFused(samples, params, tree, fused, &fused_hists);
      for (int i = 0; i < n; ++i) {
        const auto [is_fused, j] = where[size_t(i)];
        auto* nh = reply->add_nodes();
        auto* r = rext.add_ranges();
        if (!is_fused) {
          nh->set_node_id(normal[j].node);
          nh->set_samples(0);
          for (int p = 0; p < core::kNumParts; ++p) nh->add_part_counts(0);
          for (const auto& rr : ranges[j]) {
            r->add_lo(rr.lo);
            r->add_hi(rr.hi);
          }
          continue;
        }
        const worker::NodePlan& plan = fused[j];
        nh->set_node_id(plan.node);
        nh->set_samples(plan.num_samples);
        std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
        samples.CountParts(samples.RangeOf(plan.node), core::kNumParts, parts.data());
        for (uint64_t c : parts) nh->add_part_counts(c);
        EncodeWireRuns(fused_hists[j], plan, core::kNumParts, nh->mutable_runs());
        r->set_fused(true);
        for (int c = 0; c < k; ++c) {
          uint32_t count = 0;
          int32_t prev = 0;
          for (int e = 0; e < plan.cut_stride; ++e) {
            const int32_t cut = plan.cuts[size_t(c) * size_t(plan.cut_stride) + size_t(e)];
            if (cut == worker::kNoCut) break;
            r->add_cut_deltas(count == 0 ? cut : cut - prev);
            prev = cut;
            ++count;
          }
          r->add_cut_counts(count);
        }
      }
    } else if (ext.phase() == PHASE_COUNTS) {
      for (int i = 0; i < n; ++i) {
        auto* nh = reply->add_nodes();
        nh->set_node_id(plans[size_t(i)].node);
        nh->set_samples(0);
        for (int p = 0; p < core::kNumParts; ++p) nh->add_part_counts(0);
        std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
        const worker::NodeRange r = samples.RangeOf(plans[size_t(i)].node);
        if (r.end > r.begin) samples.CountParts(r, core::kNumParts, parts.data());
        auto* rr = rext.add_ranges();
        for (uint64_t c : parts) rr->add_part_counts(c);
      }
    } else if (ext.phase() == PHASE_HISTOGRAMS) {
      std::vector<worker::NodeHistogram> hists;
      builder->Build(samples, plans, t, &hists);
      for (int i = 0; i < n; ++i) {
        const worker::NodePlan& plan = plans[size_t(i)];
        auto* nh = reply->add_nodes();
        nh->set_node_id(plan.node);
        const worker::NodeRange r = samples.RangeOf(plan.node);
        nh->set_samples(r.end - r.begin);
        std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
        if (r.end > r.begin) samples.CountParts(r, core::kNumParts, parts.data());
        for (uint64_t c : parts) nh->add_part_counts(c);
        EncodeWireRuns(hists[size_t(i)], plan, core::kNumParts, nh->mutable_runs());
      }
    } else {
      busy = false;
      return Status(ErrorCode::kInvalidArgument, "unknown phase");
    }
    AttachExt(rext, reply);
    reply->set_compute_micros(uint64_t((NowSeconds() - t0) * 1e6));
    busy = false;
    // A volatile writer drops what it writes before the coordinator's reader matched.
    (void)node->WaitForMatch(Topic::kReplies, 1, std::chrono::milliseconds(5000));
    return Publish(Topic::kReplies, env);
  }

  void OnSample(const dds::ReceivedSample& s) {
    if (s.topic == Topic::kJob) {
      auto out = job_gate.Check(s.topic, s.bytes, s.writer_guid);
      if (out.verdict == dds::MessageGate::Verdict::kAccepted) OnJob(out.envelope);
      return;
    }
    if (!gate) return;
    auto out = gate->Check(s.topic, s.bytes, s.writer_guid);
    if (out.verdict != dds::MessageGate::Verdict::kAccepted) return;
    const v1::Envelope& env = out.envelope;
    Status st;
    switch (env.body_case()) {
      case v1::Envelope::kShard:
        newest_epoch = std::max<uint64_t>(newest_epoch, env.shard().epoch());
        st = LoadShard(env.shard());
        if (st.ok()) shard_epoch = env.shard().epoch();
        break;
      case v1::Envelope::kDecisions:
        if (have_shard && int(env.decisions().tree()) == tree) st = ApplyDecisions(env.decisions());
        break;
      case v1::Envelope::kLevelRequest:
        newest_epoch = std::max<uint64_t>(newest_epoch, env.level_request().epoch());
        if (have_shard && int(env.level_request().tree()) == tree) st = Answer(env.level_request());
        break;
      case v1::Envelope::kStatus:
        if (env.status().kind() == v1::STATUS_KIND_JOB_DONE && opt.exit_when_done) {
          Log("job " + job_id + " done");
          stop = true;
        }
        break;
      default:
        break;
    }
    if (!st.ok())
      Log(std::string("dropped ") + dds::BodyName(env.body_case()) + " from " + out.sender + ": " +
          st.ToString());
  }
};

DistWorker::DistWorker(WorkerOptions options) : options_(std::move(options)) {
  if (options_.worker_id.empty()) {
    char host[256] = {};
    ::gethostname(host, sizeof host - 1);
    options_.worker_id = "worker-" + std::string(host) + "-" + std::to_string(::getpid());
  }
  if (!options_.log) {
    const std::string id = options_.worker_id;
    options_.log = [id](const std::string& m) { std::fprintf(stderr, "[%s] %s\n", id.c_str(), m.c_str()); };
  }
  options_.threads = std::max(1, options_.threads);
}

DistWorker::~DistWorker() = default;

Status DistWorker::Run() {
  Impl impl(options_, stop_);
  auto node =
      dds::DdsNode::Create(MakeNodeConfig(options_.domain, options_.transport, false, options_.worker_id,
                                          options_.lease, options_.udp_peers, options_.udp_interfaces));
  if (!node.ok()) return node.status();
  impl.node = std::move(*node);
  std::thread heartbeat([&] { impl.HeartbeatLoop(); });
  while (!stop_) {
    auto s = impl.node->Receive(std::chrono::milliseconds(50));
    if (s) impl.OnSample(*s);
  }
  heartbeat.join();
  // Let the last replies reach the coordinator before the participant goes away.
  (void)impl.node->WaitForAcknowledgments(Topic::kReplies, std::chrono::milliseconds(500));
  return Status::Ok();
}

}  // namespace poseforest::dist
