#include "worker/dist_worker.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <list>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "engine/candidates.h"
#include "engine/histogram_builder.h"
#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "engine/sample_set.h"
#include "engine/subtree_trainer.h"
#include "engine/wire_codec.h"
#include "poseforest/v1/job.pb.h"
#include "proto/dds/histogram_codec.h"
#include "proto/dds/message_gate.h"
#include "proto/dds/node_config.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/crc32.h"

namespace poseforest::worker {

using core::ErrorCode;
using core::Status;
using proto::dds::Topic;

namespace {
double ThreadCpu() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

double ProcessCpu() {
  timespec ts{};
  ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

/// Adds the calling thread's CPU time from construction to destruction to `*into`.
class CpuTimer {
 public:
  explicit CpuTimer(double* into) : into_(into), t0_(ThreadCpu()) {}
  ~CpuTimer() { *into_ += ThreadCpu() - t0_; }
  CpuTimer(const CpuTimer&) = delete;
  CpuTimer& operator=(const CpuTimer&) = delete;

 private:
  double* into_;
  double t0_;
};

/// A frame as kept for training: what features can read of its depth (no labels: its sampled
/// pixels carry their parts).
struct FrameData {
  engine::CompactFrame frame;
  std::vector<engine::PixelSample> picked;
  uint64_t Bytes() const { return frame.Bytes() + picked.size() * sizeof(engine::PixelSample); }
};

/// Frames of one tree rendered for SubtreeTasks, least recently used dropped first to stay
/// within `cap_bytes` (a frame larger than the cap is not kept).
struct TaskFrameCache {
  uint64_t cap_bytes = 0;
  int tree = -1;
  uint64_t bytes = 0, peak_bytes = 0, evictions = 0;

  void Clear(int new_tree) {
    tree = new_tree;
    frames_.clear();
    lru_.clear();
    bytes = 0;
  }
  bool Has(uint64_t i) const { return frames_.count(i) > 0; }
  /// The frame (marked as used now), or nullptr.
  const FrameData* Find(uint64_t i) {
    auto it = frames_.find(i);
    if (it == frames_.end()) return nullptr;
    lru_.splice(lru_.begin(), lru_, it->second.second);
    return &it->second.first;
  }
  void Put(uint64_t i, FrameData f) {
    if (Has(i)) return;
    const uint64_t b = f.Bytes();
    if (b > cap_bytes) {
      ++evictions;
      return;
    }
    while (bytes + b > cap_bytes && !lru_.empty()) {
      auto it = frames_.find(lru_.back());
      bytes -= it->second.first.Bytes();
      frames_.erase(it);
      lru_.pop_back();
      ++evictions;
    }
    lru_.push_front(i);
    frames_.emplace(i, std::make_pair(std::move(f), lru_.begin()));
    bytes += b;
    peak_bytes = std::max(peak_bytes, bytes);
  }

 private:
  std::map<uint64_t, std::pair<FrameData, std::list<uint64_t>::iterator>> frames_;
  std::list<uint64_t> lru_;  ///< most recently used first
};

v1::RendererKind RendererOf(const engine::TrainParams& p) {
  switch (p.source.kind) {
    case engine::SourceKind::kRendered:
      return v1::RENDERER_KIND_EGL;
    case engine::SourceKind::kDataset:
      return v1::RENDERER_KIND_DATASET;
    case engine::SourceKind::kProcedural:
      return v1::RENDERER_KIND_PROCEDURAL;
  }
  return v1::RENDERER_KIND_PROCEDURAL;
}
}  // namespace

struct DistWorker::Live {
  std::atomic<bool> stopped{false};  ///< Run() returned
  std::atomic<bool> busy{false};  ///< Impl::busy
  std::array<std::atomic<uint64_t>, 4> rounds{};
  std::atomic<uint64_t> histograms{0}, subtrees{0}, subtree_nodes{0}, evaluations{0};
  std::atomic<uint64_t> shard_rendered{0}, shard_render_us{0}, shard_hits{0};
  std::atomic<uint64_t> task_rendered{0}, task_render_us{0}, task_hits{0};
  std::atomic<uint64_t> cache_evictions{0}, cache_bytes{0}, cache_capacity{0};
  std::array<std::atomic<uint64_t>, proto::dds::kNumTopics> sent{}, sent_bytes{}, received{};
  std::atomic<uint64_t> rejected{0}, stale{0}, inbox_bytes{0};
  mutable std::mutex mu;  ///< guards the job's ids and `cpu`
  std::string job_id, coordinator_id;
  WorkerCpu cpu;  ///< Impl::cpu as of the last message handled
};

struct DistWorker::Impl {
  WorkerOptions& opt;
  std::atomic<bool>& stop;
  DistWorker::Live& live;  ///< what Stats() reads (the /metrics of `worker --http`)
  std::unique_ptr<proto::dds::DdsNode> node;
  WorkerCpu cpu;  ///< written by the receiving (Run's) thread only

  std::mutex send_mu;  // guards stamper + job identity used by the heartbeat thread
  proto::dds::EnvelopeStamper stamper;
  std::atomic<bool> has_job{false}, assigned_any{false};
  std::atomic<bool>& busy;  ///< live.busy: heartbeats and Stats() say how many threads are busy
  /// Marks the worker busy (its heartbeats say so) while a subtree task or batch runs.
  struct BusyScope {
    explicit BusyScope(std::atomic<bool>& f) : flag(f) { flag = true; }
    ~BusyScope() { flag = false; }
    std::atomic<bool>& flag;
  };
  std::atomic<uint64_t> newest_epoch{0}, frames_rendered{0}, shard_epoch{0}, received_shard_epoch{0};
  /// Decisions and level requests below this epoch belong to a skipped assignment (Dispatch).
  uint64_t skip_below_epoch = 0;
  std::string control_writer;  ///< the coordinator's control writer (GUID), once heard
  std::atomic<v1::RendererKind> renderer{v1::RENDERER_KIND_PROCEDURAL};
  std::atomic<uint64_t> evaluations{0};  ///< sample x candidate evaluations binned (heartbeats)

  proto::dds::MessageGate job_gate;
  std::unique_ptr<proto::dds::MessageGate> gate;
  std::string job_id, coordinator_id;
  engine::TrainParams params;

  int tree = -1;
  int subtree_log_tree = -1;  ///< progress lines of subtree tasks: tree, count, nodes, seconds
  uint64_t subtree_done = 0, subtree_nodes_done = 0;
  double subtree_s = 0;       ///< wall seconds of subtree work of tree subtree_log_tree
  double subtree_mark = 0;    ///< when the last SubtreeResult was built (SendResult)
  bool have_shard = false;
  std::map<uint64_t, FrameData> cache;  // tree-local frame index -> frame
  // Frames of other shards rendered for SubtreeTasks, kept for the tree's later tasks within
  // WorkerOptions::task_cache_bytes.
  TaskFrameCache task_cache;
  /// Task frames of tree task_tree (read by the heartbeat thread for /metrics).
  std::atomic<uint32_t> task_tree{0};
  std::atomic<uint64_t> tree_task_rendered{0}, tree_task_cached{0}, tree_task_evictions{0};
  uint64_t tree_evictions_at_start = 0;
  uint64_t evictions_counted = 0;  ///< task_cache.evictions already in live.cache_evictions
  /// The frames batches of SubtreeTasks of tree `task_set_tree` trained on, each copied into
  /// the set's probe buffer once (not once per batch); its samples are a batch's. Dropped and
  /// started again when the tree changes or its frames would pass task_cache_bytes.
  engine::SampleSet task_set;
  int task_set_tree = -1;
  std::map<uint64_t, uint32_t> task_set_frames;  ///< frame -> local id in task_set
  // Renders the few frames a SubtreeTask lacks on the receiving thread (Run's), created once
  // per job: creating a source (renderer context, pose library, bodies) costs seconds.
  std::unique_ptr<engine::ImageSource> task_source;
  int corrupt_left = 0;
  engine::SampleSet samples;
  std::unique_ptr<engine::HistogramBuilder> builder;
  /// Subtree tasks' own builder: a round answered in the middle of a batch (ServeRounds) uses
  /// `builder` while the batch's TrainSubtrees counts its evaluations on this one.
  std::unique_ptr<engine::HistogramBuilder> subtree_builder;
  int applied_levels = 0;

  Impl(WorkerOptions& o, std::atomic<bool>& s, DistWorker::Live& l)
      : opt(o),
        stop(s),
        live(l),
        stamper("", o.worker_id, v1::SENDER_KIND_WORKER),
        busy(l.busy),
        job_gate(proto::dds::GateConfig{o.worker_id, "", 16, o.log}) {}

  void Log(const std::string& m) { opt.log(m); }

  /// Copies `cpu` for Stats() (called between messages, when no phase timer is open).
  void SaveCpu() {
    std::lock_guard<std::mutex> lock(live.mu);
    live.cpu = cpu;
  }

  /// Counts a message the gate dropped (Stats()).
  void CountDropped(const proto::dds::MessageGate::Outcome& out) {
    if (out.verdict == proto::dds::MessageGate::Verdict::kRejected)
      ++live.rejected;
    else if (out.verdict == proto::dds::MessageGate::Verdict::kStale)
      ++live.stale;
  }

  // DDS intake: a thread of its own takes every sample off the DDS readers as it
  // arrives and queues it here, whatever the training thread is doing. A worker deep in a long
  // batch of subtree tasks thus never leaves the coordinator's keep-all control history full
  // (which made the coordinator's writes fail). Bounded in bytes against a flood: past
  // kInboxMaxBytes the intake pauses and DDS flow control applies again.
  static constexpr uint64_t kInboxMaxBytes = uint64_t(1) << 30;
  std::mutex inbox_mu;
  std::condition_variable inbox_cv;
  std::deque<proto::dds::ReceivedSample> inbox;
  uint64_t inbox_bytes = 0;
  double intake_cpu = 0;  ///< the intake thread's CPU (added to cpu.receive after Run)

  void IntakeLoop() {
    CpuTimer timer(&intake_cpu);
    while (!stop) {
      {
        std::unique_lock<std::mutex> lock(inbox_mu);
        if (inbox_bytes > kInboxMaxBytes) {
          inbox_cv.wait_for(lock, std::chrono::milliseconds(20));
          continue;
        }
      }
      std::optional<proto::dds::ReceivedSample> s = node->Receive(std::chrono::milliseconds(50));
      if (!s) continue;
      s->received_s = proto::dds::NowSeconds();
      ++live.received[size_t(s->topic)];
      std::lock_guard<std::mutex> lock(inbox_mu);
      inbox_bytes += s->bytes.size();
      live.inbox_bytes = inbox_bytes;
      inbox.push_back(std::move(*s));
      inbox_cv.notify_all();
    }
  }

  /// The next sample the intake thread queued, waiting up to `timeout`.
  std::optional<proto::dds::ReceivedSample> Take(std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(inbox_mu);
    if (!inbox_cv.wait_for(lock, timeout, [&] { return !inbox.empty() || stop; }) || inbox.empty())
      return std::nullopt;
    proto::dds::ReceivedSample s = std::move(inbox.front());
    inbox.pop_front();
    inbox_bytes -= s.bytes.size();
    live.inbox_bytes = inbox_bytes;
    inbox_cv.notify_all();
    return s;
  }

  /// Seals and writes `env`; `timed`: counted in cpu.publish (the receiving thread's sends).
  Status Publish(Topic topic, v1::Envelope& env, bool timed = true) {
    std::optional<CpuTimer> timer;
    if (timed) timer.emplace(&cpu.publish);
    {
      std::lock_guard<std::mutex> lock(send_mu);
      stamper.Stamp(topic, env);
    }
    // Serialized outside the lock: a reply of tens of MiB took the heartbeat thread's lock long
    // enough, on a loaded machine, for the coordinator to take the worker for lost.
    const std::string bytes = env.SerializeAsString();
    Status st = node->Publish(topic, bytes);
    if (st.ok()) {
      ++live.sent[size_t(topic)];
      live.sent_bytes[size_t(topic)] += bytes.size();
    }
    return st;
  }

  v1::WorkerCapacity Capacity() const {
    v1::WorkerCapacity c;
    c.set_threads(uint32_t(std::max(1, opt.threads)));
    c.set_memory_mb(1024);
    c.set_renderer(renderer);
    return c;
  }

  void HeartbeatLoop() {
    // (time, evaluations): the rate over the last ~10 s, from the start (work done before the
    // first heartbeat counts).
    std::deque<std::pair<double, uint64_t>> recent{{proto::dds::NowSeconds(), evaluations.load()}};
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
          h->set_shard_epoch(shard_epoch);
          h->set_received_shard_epoch(received_shard_epoch);
          const double now = proto::dds::NowSeconds();
          const uint64_t e = evaluations;
          recent.emplace_back(now, e);
          while (recent.size() > 2 && now - recent[1].first >= 10) recent.pop_front();
          const double span = now - recent.front().first;
          h->set_evaluations(e);
          h->set_evaluations_per_s(span > 0 ? double(e - recent.front().second) / span : 0);
          h->set_task_tree(task_tree);
          h->set_task_frames_rendered(tree_task_rendered);
          h->set_task_frames_cached(tree_task_cached);
          h->set_task_cache_evictions(tree_task_evictions);
        }
        (void)Publish(Topic::kPresence, env, /*timed=*/false);
      }
      std::this_thread::sleep_for(opt.heartbeat_period);
    }
  }

  void OnJob(const v1::Envelope& env) {
    const auto& job = env.job();
    if (!opt.job_id.empty() && env.job_id() != opt.job_id) return;
    if (has_job && env.job_id() == job_id && job.coordinator_id() == coordinator_id) return;
    auto p = engine::ParamsFromConfig(job.config(), "job " + env.job_id());
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
    gate =
        std::make_unique<proto::dds::MessageGate>(proto::dds::GateConfig{opt.worker_id, job_id, 16, opt.log});
    gate->set_coordinator_id(coordinator_id);
    gate->set_num_parts(uint32_t(core::kNumParts));
    builder = std::make_unique<engine::HistogramBuilder>(params.constants, params.threads);
    subtree_builder = std::make_unique<engine::HistogramBuilder>(params.constants, params.threads);
    tree = -1;
    have_shard = false;
    cache.clear();
    task_cache.Clear(-1);
    task_cache.cap_bytes = opt.task_cache_bytes > 0
                               ? opt.task_cache_bytes
                               : TaskCacheBytesFor(params, uint64_t(::sysconf(_SC_PHYS_PAGES)) *
                                                               uint64_t(::sysconf(_SC_PAGE_SIZE)));
    Log("task frame cache: " + std::to_string(task_cache.cap_bytes >> 20) + " MiB" +
        (opt.task_cache_bytes > 0 ? "" : " (auto: a tree's frames; --task-cache-mb to set)"));
    task_set = engine::SampleSet{};
    task_set_tree = -1;
    task_set_frames.clear();
    task_source.reset();
    corrupt_left = opt.corrupt_subtree_results;
    samples = engine::SampleSet{};
    renderer = RendererOf(params);
    {
      std::lock_guard<std::mutex> lock(send_mu);
      stamper.set_job_id(job_id);
    }
    {
      std::lock_guard<std::mutex> lock(live.mu);
      live.job_id = job_id;
      live.coordinator_id = coordinator_id;
    }
    live.cache_capacity = task_cache.cap_bytes;
    live.cache_bytes = 0;
    assigned_any = false;
    shard_epoch = 0;
    received_shard_epoch = 0;
    skip_below_epoch = 0;
    control_writer.clear();
    has_job = true;
    Log("joined job " + job_id + " of " + coordinator_id + ": " + engine::DescribeParams(params));
  }

  Status LoadShard(const v1::ShardAssignment& s) {
    CpuTimer timer(&cpu.shard);
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
    ++cpu.shard_loads;
    if (opt.hold_in_shard_load) opt.hold_in_shard_load();
    if (int(s.tree()) != tree) cache.clear();
    tree = int(s.tree());
    have_shard = false;
    for (auto it = cache.begin(); it != cache.end();)
      it = std::binary_search(wanted.begin(), wanted.end(), it->first) ? std::next(it) : cache.erase(it);
    std::vector<uint64_t> missing;
    for (uint64_t i : wanted)
      if (!cache.count(i)) missing.push_back(i);
    std::vector<FrameData> loaded;
    const double t_render = proto::dds::NowSeconds();
    POSEFOREST_RETURN_IF_ERROR(LoadFrames(missing, &loaded, &cpu.shard));
    const double render_s = proto::dds::NowSeconds() - t_render;
    shard_render_unreported_s += render_s;
    live.shard_render_us += uint64_t(render_s * 1e6);
    for (size_t j = 0; j < missing.size(); ++j) cache[missing[j]] = std::move(loaded[j]);
    frames_rendered += missing.size();
    live.shard_rendered += missing.size();
    live.shard_hits += wanted.size() - missing.size();
    cpu.shard_frames += missing.size();
    samples = engine::SampleSet{};
    for (const auto& [i, f] : cache) {
      if (f.picked.empty()) continue;  // no body in view (as LocalTrainer)
      samples.AddFrame(i, f.frame, f.picked, params.constants);
    }
    samples.StartTree(0);
    have_shard = true;
    applied_levels = 0;
    assigned_any = true;
    Log("tree " + std::to_string(tree) + ": shard of " + std::to_string(wanted.size()) + " frames (" +
        std::to_string(missing.size()) + " new), " + std::to_string(samples.num_samples()) + " samples");
    return Status::Ok();
  }

  /// Renders/loads tree-local frames `missing` of tree `tree` and samples their pixels; the CPU
  /// time of the loading threads is added to `*pool_cpu`.
  Status LoadFrames(const std::vector<uint64_t>& missing, std::vector<FrameData>* out, double* pool_cpu) {
    const uint64_t ipt = uint64_t(params.images_per_tree);
    std::vector<FrameData>& loaded = *out;
    loaded.assign(missing.size(), FrameData{});
    if (missing.empty()) return Status::Ok();
    // Frames in parallel, one ImageSource per thread (a renderer's context is per thread).
    const int threads = std::max(1, std::min<int>(params.threads, int(missing.size())));
    std::vector<Status> errors(static_cast<size_t>(threads));
    std::vector<double> thread_cpu(static_cast<size_t>(threads), 0.0);
    std::vector<std::thread> pool;
    for (int tid = 0; tid < threads; ++tid) {
      pool.emplace_back([&, tid] {
        CpuTimer timer(&thread_cpu[size_t(tid)]);
        try {
          auto source = engine::MakeImageSource(params.source);
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
            loaded[j].picked = engine::SamplePixels(
                *frame, params.pixels_per_image, params.part_balance,
                core::CounterRng(params.seed, uint64_t(tree), index, engine::kSamplingStream));
            loaded[j].frame = engine::CompactFrame::Of(frame->depth, params.constants.background_mm);
          }
        } catch (const std::exception& e) {
          errors[size_t(tid)] = Status(ErrorCode::kInternal, std::string("loading frames: ") + e.what());
        }
      });
    }
    for (auto& t : pool) t.join();
    for (double c : thread_cpu) *pool_cpu += c;
    for (const Status& e : errors)
      if (!e.ok()) return e;
    return Status::Ok();
  }

  Status ApplyDecisions(const v1::SplitDecisions& d) {
    CpuTimer timer(&cpu.decisions);
    std::vector<engine::SampleSet::Split> splits;
    for (const auto& n : d.nodes()) {
      if (n.kind_case() != v1::NodeDecision::kSplit) continue;
      engine::SampleSet::Split s;
      s.node = n.node_id();
      POSEFOREST_RETURN_IF_ERROR(engine::GetFeatureSplit(n.split(), &s.offsets, &s.cut));
      s.left_child = n.split().left_child();
      splits.push_back(s);
    }
    samples.ApplySplits(splits, params.constants, params.threads);
    ++applied_levels;
    return Status::Ok();
  }

  Status Answer(const v1::LevelRequest& req) {
    const int n = req.node_ids_size();
    const int k = params.candidate_features;
    const int t = params.thresholds_per_feature;
    if (req.nodes_size() != n) return Status(ErrorCode::kInvalidArgument, "node specs do not match node ids");
    if (req.num_candidates() != uint32_t(k) || req.num_thresholds() != uint32_t(t + 1) ||
        req.num_parts() != uint32_t(core::kNumParts))
      return Status(ErrorCode::kInvalidArgument, "request dimensions differ from the job's");
    const double t0 = proto::dds::NowSeconds();
    const double cpu0 = ThreadCpu(), compute0 = cpu.level_compute;
    busy = true;
    std::vector<engine::NodePlan> plans(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
      const v1::NodeSpec& spec = req.nodes(i);
      engine::NodePlan& plan = plans[size_t(i)];
      plan.node = req.node_ids(i);
      plan.position = spec.position();
      plan.num_samples = spec.num_samples();
      if (req.phase() == v1::PHASE_RANGES || req.phase() == v1::PHASE_HISTOGRAMS)
        plan.features = engine::DrawFeatures(params, tree, plan.position);
      if (req.phase() == v1::PHASE_HISTOGRAMS) {
        if (spec.part_counts_size() != core::kNumParts || spec.range_lo_size() != k ||
            spec.range_hi_size() != k) {
          busy = false;
          return Status(ErrorCode::kInvalidArgument,
                        "node spec of node " + std::to_string(plan.node) + " malformed");
        }
        std::vector<uint64_t> parts(spec.part_counts().begin(), spec.part_counts().end());
        plan.SetParts(parts);
        plan.sample_bins = engine::UseSampleBins(plan.num_samples, t, plan.num_slots);
        plan.cut_stride = engine::CutStride(t);
        std::vector<engine::ResponseRange> ranges(static_cast<size_t>(k));
        for (int c = 0; c < k; ++c) ranges[size_t(c)] = {spec.range_lo(c), spec.range_hi(c)};
        plan.cuts = engine::DrawCuts(params, tree, plan.position, ranges);
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
    reply->set_phase(req.phase());
    uint64_t histograms_built = 0;  // node histograms in the reply (Stats())
    // A node of the reply without a histogram: its id and zero part counts.
    auto add_empty_node = [reply](uint32_t node) {
      auto* nh = reply->add_nodes();
      nh->set_node_id(node);
      nh->set_samples(0);
      for (int p = 0; p < core::kNumParts; ++p) nh->add_part_counts(0);
    };
    if (req.phase() == v1::PHASE_RANGES) {
      // Nodes held entirely here with a whole-node reference: one fused pass (LocalTrainer's
      // BuildFused), histogram and cuts sent now; the others: ranges.
      std::vector<engine::NodePlan> normal, fused;
      std::vector<std::pair<bool, size_t>> where(static_cast<size_t>(n));
      for (int i = 0; i < n; ++i) {
        engine::NodePlan& plan = plans[size_t(i)];
        if (engine::HistogramBuilder::CanFuse(samples, params, plan)) {
          std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
          samples.CountParts(samples.RangeOf(plan.node), core::kNumParts, parts.data());
          plan.SetParts(parts);
          plan.sample_bins = engine::UseSampleBins(plan.num_samples, t, plan.num_slots);
          plan.cut_stride = engine::CutStride(t);
          where[size_t(i)] = {true, fused.size()};
          fused.push_back(std::move(plan));
        } else {
          where[size_t(i)] = {false, normal.size()};
          normal.push_back(std::move(plan));
        }
      }
      std::vector<std::vector<engine::ResponseRange>> ranges;
      std::vector<engine::NodeHistogram> fused_hists;
      {
        CpuTimer timer(&cpu.level_compute);
        if (!normal.empty()) builder->ComputeRanges(samples, params, tree, normal, &ranges);
        if (!fused.empty()) builder->BuildFused(samples, params, tree, fused, &fused_hists);
      }
      histograms_built = fused.size();
      for (int i = 0; i < n; ++i) {
        const auto [is_fused, j] = where[size_t(i)];
        auto* nh = reply->add_nodes();
        auto* r = reply->add_ranges();
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
        const engine::NodePlan& plan = fused[j];
        nh->set_node_id(plan.node);
        nh->set_samples(plan.num_samples);
        std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
        samples.CountParts(samples.RangeOf(plan.node), core::kNumParts, parts.data());
        for (uint64_t c : parts) nh->add_part_counts(c);
        engine::EncodeWireRuns(fused_hists[j], plan, core::kNumParts, nh->mutable_runs());
        r->set_fused(true);
        for (int c = 0; c < k; ++c) {
          uint32_t count = 0;
          int32_t prev = 0;
          for (int e = 0; e < plan.cut_stride; ++e) {
            const int32_t cut = plan.cuts[size_t(c) * size_t(plan.cut_stride) + size_t(e)];
            if (cut == engine::kNoCut) break;
            r->add_cut_deltas(count == 0 ? cut : cut - prev);
            prev = cut;
            ++count;
          }
          r->add_cut_counts(count);
        }
      }
    } else if (req.phase() == v1::PHASE_FRAMES) {
      for (int i = 0; i < n; ++i) {
        add_empty_node(plans[size_t(i)].node);
        auto* rr = reply->add_ranges();
        const engine::NodeRange r = samples.RangeOf(plans[size_t(i)].node);
        rr->set_num_samples(r.end - r.begin);
        // Samples of a node are ordered by (frame, pixel): distinct frames are runs. The pixel
        // indices go along, so that a SubtreeTask needs no routing.
        uint32_t prev_pixel = 0;
        for (uint64_t j = r.begin; j < r.end; ++j) {
          const uint64_t f = samples.frame_index(j);
          const uint32_t pixel =
              uint32_t(samples.y()[j]) * uint32_t(samples.frames()[samples.frame()[j]].width) +
              uint32_t(samples.x()[j]);
          if (rr->frames_size() == 0 || rr->frames(rr->frames_size() - 1) != uint32_t(f)) {
            rr->add_frames(uint32_t(f));
            rr->add_frame_samples(0);
            prev_pixel = 0;
          }
          rr->set_frame_samples(rr->frames_size() - 1, rr->frame_samples(rr->frames_size() - 1) + 1);
          rr->add_pixel_deltas(pixel - prev_pixel);
          prev_pixel = pixel;
        }
      }
    } else if (req.phase() == v1::PHASE_COUNTS) {
      for (int i = 0; i < n; ++i) {
        add_empty_node(plans[size_t(i)].node);
        std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
        const engine::NodeRange r = samples.RangeOf(plans[size_t(i)].node);
        if (r.end > r.begin) samples.CountParts(r, core::kNumParts, parts.data());
        auto* rr = reply->add_ranges();
        for (uint64_t c : parts) rr->add_part_counts(c);
      }
    } else if (req.phase() == v1::PHASE_HISTOGRAMS) {
      std::vector<engine::NodeHistogram> hists;
      {
        CpuTimer timer(&cpu.level_compute);
        builder->Build(samples, plans, t, &hists);
      }
      histograms_built = uint64_t(n);
      for (int i = 0; i < n; ++i) {
        const engine::NodePlan& plan = plans[size_t(i)];
        auto* nh = reply->add_nodes();
        nh->set_node_id(plan.node);
        const engine::NodeRange r = samples.RangeOf(plan.node);
        nh->set_samples(r.end - r.begin);
        std::vector<uint64_t> parts(static_cast<size_t>(core::kNumParts), 0);
        if (r.end > r.begin) samples.CountParts(r, core::kNumParts, parts.data());
        for (uint64_t c : parts) nh->add_part_counts(c);
        engine::EncodeWireRuns(hists[size_t(i)], plan, core::kNumParts, nh->mutable_runs());
      }
    } else {
      busy = false;
      return Status(ErrorCode::kInvalidArgument, "unknown phase");
    }
    cpu.level_encode += ThreadCpu() - cpu0 - (cpu.level_compute - compute0);
    reply->set_compute_micros(uint64_t((proto::dds::NowSeconds() - t0) * 1e6));
    if (dispatch_received_s > 0 && t0 > dispatch_received_s)
      reply->set_queued_micros(uint64_t((t0 - dispatch_received_s) * 1e6));
    reply->set_render_micros(uint64_t(shard_render_unreported_s * 1e6));
    shard_render_unreported_s = 0;
    uint64_t binned = 0;  // samples in the histograms (fused or pass 2), as the coordinator counts
    for (const auto& nh : reply->nodes()) binned += nh.samples();
    evaluations += binned * uint64_t(k);
    live.evaluations += binned * uint64_t(k);
    busy = false;
    // A volatile writer drops what it writes before the coordinator's reader matched.
    (void)node->WaitForMatch(Topic::kReplies, 1, std::chrono::milliseconds(5000));
    Status sent = Publish(Topic::kReplies, env);
    if (sent.ok()) {
      ++live.rounds[size_t(req.phase()) - 1];  // PHASE_RANGES (1) .. PHASE_FRAMES (4), checked above
      live.histograms += histograms_built;
    }
    return sent;
  }

  /// Frames `missing` of tree `t` rendered on this thread by task_source (few frames: no
  /// thread pool, and the source is made once per job). Same frames and samples as LoadFrames.
  Status RenderHere(int t, const std::vector<uint64_t>& missing, std::vector<FrameData>* out) {
    out->assign(missing.size(), FrameData{});
    if (missing.empty()) return Status::Ok();
    try {
      if (!task_source) {
        auto source = engine::MakeImageSource(params.source);
        if (!source.ok()) return source.status();
        task_source = std::move(*source);
      }
      for (size_t j = 0; j < missing.size(); ++j) {
        const uint64_t index = uint64_t(t) * uint64_t(params.images_per_tree) + missing[j];
        auto frame = task_source->Frame(index);
        if (!frame.ok()) return frame.status();
        (*out)[j].picked =
            engine::SamplePixels(*frame, params.pixels_per_image, params.part_balance,
                                 core::CounterRng(params.seed, uint64_t(t), index, engine::kSamplingStream));
        (*out)[j].frame = engine::CompactFrame::Of(frame->depth, params.constants.background_mm);
      }
    } catch (const std::exception& e) {
      return Status(ErrorCode::kInternal, std::string("rendering frames: ") + e.what());
    }
    return Status::Ok();
  }

  /// Trains the subtree of a SubtreeTask and sends the SubtreeResult: the node's frames (from
  /// the shard's cache or the task cache, else rendered and then kept in the task cache), the
  /// node's samples (listed in the task, else every sample of the frames routed along the
  /// task's path), then TrainSubtree (the engine's own loop and keys).
  /// Checks a SubtreeTask; `*wanted`: the tree-local frames it needs (its sample frames when it
  /// lists its samples, else its ranges' frames), ascending.
  Status CheckTask(const v1::SubtreeTask& task, std::vector<uint64_t>* wanted_out) {
    const uint64_t ipt = uint64_t(params.images_per_tree);
    const int t = int(task.tree());
    std::vector<uint64_t>& wanted = *wanted_out;
    wanted.clear();
    if (task.tree() >= uint32_t(params.num_trees))
      return Status(ErrorCode::kInvalidArgument, "tree out of range");
    if (task.part_counts_size() != core::kNumParts)
      return Status(ErrorCode::kInvalidArgument, "part counts of the wrong length");
    if (task.position() >= (uint64_t(1) << 31) ||
        engine::PositionDepth(task.position()) != int(task.depth()) || int(task.depth()) > params.max_depth)
      return Status(ErrorCode::kInvalidArgument, "position " + std::to_string(task.position()) +
                                                     " is not at depth " + std::to_string(task.depth()));
    for (const auto& r : task.ranges()) {
      if (r.seed() != params.source.seed)
        return Status(ErrorCode::kInvalidArgument, "image range of another seed");
      for (uint64_t g = r.first_index(); g < r.first_index() + r.count(); ++g) {
        if (g < uint64_t(t) * ipt || g >= uint64_t(t + 1) * ipt)
          return Status(ErrorCode::kInvalidArgument,
                        "frame " + std::to_string(g) + " is not one of tree " + std::to_string(t) + "'s");
        wanted.push_back(g - uint64_t(t) * ipt);
      }
    }
    std::sort(wanted.begin(), wanted.end());
    wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
    // The node's samples listed by the coordinator (then no routing): their frames replace
    // `wanted`, checked here; each pixel is checked against the frame's sampled pixels below.
    const bool listed = task.sample_frames_size() > 0;
    if (listed) {
      if (task.sample_counts_size() != task.sample_frames_size())
        return Status(ErrorCode::kInvalidArgument, "sample_counts and sample_frames differ in length");
      uint64_t total = 0;
      for (uint32_t c : task.sample_counts()) total += c;
      if (total != uint64_t(task.sample_pixel_deltas_size()) || total != task.expected_samples())
        return Status(ErrorCode::kInvalidArgument,
                      "the task lists " + std::to_string(task.sample_pixel_deltas_size()) +
                          " sample pixels, " + std::to_string(total) + " by its counts, expects " +
                          std::to_string(task.expected_samples()));
      wanted.clear();
      for (int e = 0; e < task.sample_frames_size(); ++e) {
        const uint32_t f = task.sample_frames(e);
        if (f >= ipt || (e > 0 && f <= task.sample_frames(e - 1)))
          return Status(ErrorCode::kInvalidArgument,
                        "sample frame " + std::to_string(f) + " out of range or out of order");
        wanted.push_back(f);
      }
    }
    return Status::Ok();
  }

  /// The frames `wanted` (ascending) of tree `t` for subtree tasks: from the shard's cache or the
  /// task cache, else rendered (into `*loaded`, parallel to `*missing`; the caller puts them in
  /// the task cache once done). `*src`: each wanted frame.
  Status TaskFrames(int t, const std::vector<uint64_t>& wanted, std::vector<uint64_t>* missing,
                    std::vector<FrameData>* loaded, std::vector<const FrameData*>* src) {
    if (task_cache.tree != t) {
      if (task_cache.tree >= 0 && (tree_task_rendered > 0 || tree_task_cached > 0))
        Log("tree " + std::to_string(task_cache.tree) + " subtree frames: " + std::to_string(tree_task_rendered) +
            " rendered again, " + std::to_string(tree_task_cached) + " from the shard or the task cache, " +
            std::to_string(task_cache.evictions - tree_evictions_at_start) + " evicted (cache " +
            std::to_string(task_cache.cap_bytes >> 20) + " MiB)");
      task_cache.Clear(t);
      live.cache_bytes = 0;
      task_tree = uint32_t(t);
      tree_task_rendered = 0;
      tree_task_cached = 0;
      tree_evictions_at_start = task_cache.evictions;
      tree_task_evictions = 0;
    }
    const bool own = t == tree;
    missing->clear();
    for (uint64_t i : wanted)
      if (!(own && cache.count(i)) && !task_cache.Has(i)) missing->push_back(i);
    cpu.task_frames += missing->size();
    cpu.task_frames_cached += wanted.size() - missing->size();
    tree_task_rendered += missing->size();
    tree_task_cached += wanted.size() - missing->size();
    live.task_hits += wanted.size() - missing->size();
    {
      CpuTimer timer(&cpu.subtree_render);
      const double t_render = proto::dds::NowSeconds();
      struct Mark {  // the wall time, however it ends
        double t0;
        double* sum;
        std::atomic<uint64_t>* micros;
        ~Mark() {
          const double s = proto::dds::NowSeconds() - t0;
          *sum += s;
          *micros += uint64_t(s * 1e6);
        }
      } mark{t_render, &task_render_unreported_s, &live.task_render_us};
      Status st;
      if (missing->size() >= 4 * size_t(params.threads) && params.threads > 1) {
        const int saved_tree = tree;
        tree = t;  // LoadFrames keys the frames by `tree`
        st = LoadFrames(*missing, loaded, &cpu.subtree_render);
        tree = saved_tree;
      } else {
        st = RenderHere(t, *missing, loaded);
      }
      if (!st.ok()) return st;
      frames_rendered += missing->size();
      live.task_rendered += missing->size();
    }
    src->assign(wanted.size(), nullptr);
    for (size_t e = 0, next_loaded = 0; e < wanted.size(); ++e) {
      const uint64_t i = wanted[e];
      if (next_loaded < missing->size() && (*missing)[next_loaded] == i)
        (*src)[e] = &(*loaded)[next_loaded++];
      else
        (*src)[e] = own && cache.count(i) ? &cache.at(i) : task_cache.Find(i);
    }
    return Status::Ok();
  }

  /// Rendered task frames into the task cache (within its cap) for the tree's later tasks.
  void KeepTaskFrames(const std::vector<uint64_t>& missing, std::vector<FrameData>& loaded) {
    for (size_t j = 0; j < missing.size(); ++j) task_cache.Put(missing[j], std::move(loaded[j]));
    cpu.task_cache_peak_bytes = std::max(cpu.task_cache_peak_bytes, task_cache.peak_bytes);
    cpu.task_cache_evictions = task_cache.evictions;
    tree_task_evictions = task_cache.evictions - tree_evictions_at_start;
    live.cache_evictions += task_cache.evictions - evictions_counted;
    evictions_counted = task_cache.evictions;
    live.cache_bytes = task_cache.bytes;
  }

  Status RunSubtree(const v1::SubtreeTask& task) {
    const int t = int(task.tree());
    std::vector<uint64_t> wanted;
    POSEFOREST_RETURN_IF_ERROR(CheckTask(task, &wanted));
    const bool listed = Listed(task);
    const double t0 = proto::dds::NowSeconds();
    const BusyScope busy_scope(busy);
    ++cpu.subtree_tasks;
    std::vector<uint64_t> missing;
    std::vector<FrameData> loaded;
    std::vector<const FrameData*> src;
    POSEFOREST_RETURN_IF_ERROR(TaskFrames(t, wanted, &missing, &loaded, &src));
    std::optional<CpuTimer> route_timer(&cpu.subtree_route);
    engine::SampleSet set;
    {
      size_t pixels = 0, picked = 0;
      for (const FrameData* f : src) pixels += f->frame.pixels.size(), picked += f->picked.size();
      set.Reserve(wanted.size(), pixels, listed ? size_t(task.expected_samples()) : picked,
                  wanted.size() * size_t(std::max(0, params.source.height)));
      size_t delta_at = 0;
      std::vector<engine::PixelSample> chosen;
      for (size_t e = 0; e < wanted.size(); ++e) {
        const uint64_t i = wanted[e];
        const FrameData* f = src[e];
        if (!listed) {
          if (!f->picked.empty()) set.AddFrame(i, f->frame, f->picked, params.constants);
          continue;
        }
        const uint32_t count = task.sample_counts(int(e));
        POSEFOREST_RETURN_IF_ERROR(SelectListedSamples(
            f->picked, f->frame.width, i,
            std::span<const uint32_t>(task.sample_pixel_deltas().data() + delta_at, count), &chosen));
        delta_at += count;
        if (!chosen.empty()) set.AddFrame(i, f->frame, chosen, params.constants);
      }
    }
    src.clear();
    KeepTaskFrames(missing, loaded);
    set.StartTree(0);
    // Without a sample list: route along the ancestors' splits; the side not taken is dropped
    // at every step.
    uint32_t at = 0;
    if (!listed)
      for (const auto& step : task.path()) {
        engine::SampleSet::Split sp;
        sp.node = at;
        POSEFOREST_RETURN_IF_ERROR(engine::GetFeatureSplit(step.split(), &sp.offsets, &sp.cut));
        sp.left_child = at + 1;
        set.ApplySplits(std::span<const engine::SampleSet::Split>(&sp, 1), params.constants, params.threads);
        at = step.went_right() ? at + 2 : at + 1;
      }
    std::vector<uint64_t> parts(task.part_counts().begin(), task.part_counts().end());
    const engine::NodeRange routed = set.RangeOf(at);
    route_timer.reset();
    std::optional<CpuTimer> train_timer(&cpu.subtree_train);
    served_in_batch_s = 0;
    auto out = engine::TrainSubtree(set, at, params, t, task.position(), parts, *subtree_builder,
                                    [this] { PauseInSubtrees(); });
    train_timer.reset();
    busy = false;
    if (!out.ok()) return out.status();
    return SendResult(task, *out, t0, routed.end - routed.begin, wanted.size(), missing.size());
  }

  /// Sends the SubtreeResult of `task` (+ the progress lines); t0: when the task started.
  Status SendResult(const v1::SubtreeTask& task, const engine::SubtreeOutput& result, double t0,
                    uint64_t num_samples, size_t num_frames, size_t rendered) {
    const int t = int(task.tree());
    const engine::SubtreeOutput* out = &result;
    std::optional<CpuTimer> encode_timer(&cpu.subtree_encode);
    v1::Envelope env;
    v1::SubtreeResult* res = env.mutable_subtree_result();
    res->set_tree(task.tree());
    res->set_node_id(task.node_id());
    res->set_epoch(task.epoch());
    res->set_nodes(std::string(reinterpret_cast<const char*>(out->tree.nodes.data()),
                               out->tree.nodes.size() * sizeof(core::Node)));
    res->set_leaves(
        std::string(reinterpret_cast<const char*>(out->tree.leaves.data()), out->tree.leaves.size()));
    res->set_num_nodes(uint32_t(out->tree.nodes.size()));
    res->set_num_leaves(out->tree.num_leaves);
    res->set_num_parts(uint32_t(core::kNumParts));
    res->set_position(task.position());
    res->set_evaluations(out->evaluations);
    evaluations += out->evaluations;
    live.evaluations += out->evaluations;
    for (const engine::SubtreeNode& n : out->nodes) {
      v1::SubtreeNode* sn = res->add_subtree_nodes();
      sn->set_position(n.position);
      sn->set_split(n.split);
      if (n.split) {
        sn->set_ux(n.offsets.ux), sn->set_uy(n.offsets.uy), sn->set_vx(n.offsets.vx),
            sn->set_vy(n.offsets.vy);
        sn->set_cut(n.cut);
        sn->set_gain(n.gain);
      }
      for (uint64_t c : n.parts) sn->add_part_counts(c);
    }
    if (corrupt_left > 0) {  // tests: a hostile worker
      if (corrupt_left-- % 2 == 1)
        res->set_position(res->position() + 1), res->mutable_subtree_nodes(0)->set_position(res->position());
      else
        res->mutable_subtree_nodes(0)->set_part_counts(0, res->subtree_nodes(0).part_counts(0) + 1);
    }
    uint32_t crc = core::Crc32(res->nodes().data(), res->nodes().size());
    res->set_crc32(core::Crc32(res->leaves().data(), res->leaves().size(), crc));
    // One line for a tree's first subtree task, then a running total every 100 tasks (a depth-20
    // job hands off hundreds per tree).
    if (t != subtree_log_tree) subtree_log_tree = t, subtree_done = 0, subtree_nodes_done = 0, subtree_s = 0;
    ++subtree_done;
    subtree_nodes_done += out->nodes.size();
    // Wall seconds of subtree work: the tasks of a batch share one stretch of time, so each
    // adds only the time since the previous result (or its start), never the batch's whole.
    const double now = proto::dds::NowSeconds();
    // Rounds answered in the middle of the batch (ServeRounds) are not subtree work.
    const double busy_s = std::max(0.0, now - std::max(t0, subtree_mark) - served_in_batch_s);
    served_in_batch_s = 0;
    subtree_s += busy_s;
    subtree_mark = now;
    res->set_busy_micros(uint64_t(busy_s * 1e6));
    res->set_render_micros(uint64_t(task_render_unreported_s * 1e6));
    task_render_unreported_s = 0;
    if (subtree_done == 1)
      Log("tree " + std::to_string(t) + ": subtree at position " + std::to_string(task.position()) + " (" +
          std::to_string(num_samples) + " samples from " + std::to_string(num_frames) + " frames, " +
          std::to_string(rendered) + " rendered) -> " + std::to_string(out->nodes.size()) + " nodes in " +
          std::to_string(proto::dds::NowSeconds() - t0) + " s");
    else if (subtree_done % 100 == 0)
      Log("tree " + std::to_string(t) + ": " + std::to_string(subtree_done) + " subtrees trained so far (" +
          std::to_string(subtree_nodes_done) + " nodes, " + std::to_string(subtree_s) +
          " s; task frame cache " + std::to_string(task_cache.bytes >> 20) + " of " +
          std::to_string(task_cache.cap_bytes >> 20) + " MiB, " + std::to_string(task_cache.evictions) +
          " evicted; queued rounds answered " + std::to_string(cpu.rounds_in_batches) + " times in between)");
    encode_timer.reset();
    (void)node->WaitForMatch(Topic::kReplies, 1, std::chrono::milliseconds(5000));
    Status sent = Publish(Topic::kReplies, env);
    if (sent.ok()) {
      ++live.subtrees;
      live.subtree_nodes += out->nodes.size();
    }
    return sent;
  }

  /// SubtreeTasks of one tree that all list their samples, trained together: one SampleSet of
  /// the union of their frames (each frame copied once), the node of each task a root of
  /// TrainSubtrees (the same subtrees as one by one), one SubtreeResult each. A task that fails
  /// its checks is dropped (logged); if the batch as a whole fails, the tasks run one by one.
  void RunSubtreeBatch(const std::vector<v1::Envelope>& batch, const std::string& sender) {
    auto drop = [&](const v1::SubtreeTask& task, const Status& st) {
      Log("dropped SubtreeTask (position " + std::to_string(task.position()) + ") from " + sender + ": " +
          st.ToString());
    };
    std::vector<const v1::SubtreeTask*> tasks;
    std::vector<std::vector<uint64_t>> wanted_of;
    for (const v1::Envelope& env : batch) {
      std::vector<uint64_t> w;
      if (Status st = CheckTask(env.subtree_task(), &w); !st.ok()) {
        drop(env.subtree_task(), st);
        continue;
      }
      tasks.push_back(&env.subtree_task());
      wanted_of.push_back(std::move(w));
    }
    if (tasks.empty()) return;
    const int t = int(tasks[0]->tree());
    const double t0 = proto::dds::NowSeconds();
    const BusyScope busy_scope(busy);
    cpu.subtree_tasks += tasks.size();
    ++cpu.subtree_batches;
    // The union of the tasks' frames; per frame, which tasks list samples there and where.
    std::map<uint64_t, std::vector<std::pair<size_t, size_t>>> users;  // frame -> (task, entry)
    for (size_t k = 0; k < tasks.size(); ++k)
      for (size_t e = 0; e < wanted_of[k].size(); ++e) users[wanted_of[k][e]].push_back({k, e});
    std::vector<uint64_t> wanted;
    for (const auto& [frame, u] : users) wanted.push_back(frame);
    std::vector<uint64_t> missing;
    std::vector<FrameData> loaded;
    std::vector<const FrameData*> src;
    auto one_by_one = [&](const Status& why) {
      Log("a batch of " + std::to_string(tasks.size()) + " subtree tasks failed (" + why.ToString() +
          "): one by one");
      cpu.subtree_tasks -= tasks.size();
      --cpu.subtree_batches;
      for (const v1::SubtreeTask* task : tasks)
        if (Status st = RunSubtree(*task); !st.ok()) drop(*task, st);
    };
    if (Status st = TaskFrames(t, wanted, &missing, &loaded, &src); !st.ok()) return one_by_one(st);
    std::optional<CpuTimer> route_timer(&cpu.subtree_route);
    // Where each task's pixel list of each frame starts.
    std::vector<std::vector<size_t>> delta_at(tasks.size());
    for (size_t k = 0; k < tasks.size(); ++k) {
      delta_at[k].resize(size_t(tasks[k]->sample_counts_size()));
      for (size_t e = 0, at = 0; e < delta_at[k].size(); at += tasks[k]->sample_counts(int(e)), ++e)
        delta_at[k][e] = at;
    }
    // The batch's samples go into task_set, whose frames are copied once per tree (frames it
    // lacks are added here); same samples in the same order as a fresh set, so same subtrees.
    size_t new_pixels = 0;
    for (size_t w = 0; w < wanted.size(); ++w)
      if (!task_set_frames.count(wanted[w])) new_pixels += src[w]->frame.pixels.size();
    if (task_set_tree != t ||
        (task_set.probe_pixels() + new_pixels) * sizeof(uint16_t) >
            std::max<uint64_t>(task_cache.cap_bytes, 1) ||
        task_set.probe_pixels() + new_pixels >= (size_t(1) << 30)) {
      task_set = engine::SampleSet{};
      task_set_frames.clear();
      task_set_tree = t;
      new_pixels = 0;
      for (const FrameData* f : src) new_pixels += f->frame.pixels.size();
    }
    task_set.ClearSamples();
    engine::SampleSet& set = task_set;
    std::vector<uint32_t> node_of_sample;
    {
      size_t samples_total = 0;
      for (const v1::SubtreeTask* task : tasks) samples_total += size_t(task->expected_samples());
      set.Reserve(wanted.size(), new_pixels, samples_total);
      for (size_t w = 0; w < wanted.size(); ++w)
        if (!task_set_frames.count(wanted[w]))
          task_set_frames[wanted[w]] = set.AddFrameOnly(wanted[w], src[w]->frame, params.constants);
      node_of_sample.reserve(samples_total);
      std::vector<engine::PixelSample> chosen, merged;
      std::vector<std::pair<uint64_t, uint32_t>> order;  // (pixel index, task) of `merged`
      for (size_t w = 0; w < wanted.size(); ++w) {
        const FrameData* f = src[w];
        merged.clear();
        order.clear();
        for (const auto& [k, e] : users[wanted[w]]) {
          const uint32_t count = tasks[k]->sample_counts(int(e));
          const Status st = SelectListedSamples(
              f->picked, f->frame.width, wanted[w],
              std::span<const uint32_t>(tasks[k]->sample_pixel_deltas().data() + delta_at[k][e], count),
              &chosen);
          if (!st.ok()) {
            route_timer.reset();
            src.clear();
            KeepTaskFrames(missing, loaded);
            return one_by_one(st);
          }
          for (const engine::PixelSample& p : chosen) {
            order.push_back({uint64_t(p.y) * uint64_t(f->frame.width) + uint64_t(p.x), uint32_t(k)});
            merged.push_back(p);
          }
        }
        // One frame's samples in pixel order (as SamplePixels gives them), each tagged with its task.
        std::vector<size_t> idx(merged.size());
        for (size_t j = 0; j < idx.size(); ++j) idx[j] = j;
        std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return order[a] < order[b]; });
        std::vector<engine::PixelSample> sorted;
        sorted.reserve(merged.size());
        for (size_t j : idx) sorted.push_back(merged[j]), node_of_sample.push_back(order[j].second);
        if (!sorted.empty()) set.AddSamples(task_set_frames.at(wanted[w]), sorted, params.constants);
      }
    }
    src.clear();
    KeepTaskFrames(missing, loaded);
    set.StartTree(node_of_sample);
    std::vector<engine::SubtreeRoot> roots(tasks.size());
    for (size_t k = 0; k < tasks.size(); ++k) {
      roots[k].sample_node = uint32_t(k);
      roots[k].position = tasks[k]->position();
      roots[k].parts.assign(tasks[k]->part_counts().begin(), tasks[k]->part_counts().end());
    }
    route_timer.reset();
    std::optional<CpuTimer> train_timer(&cpu.subtree_train);
    served_in_batch_s = 0;
    auto out = engine::TrainSubtrees(set, roots, params, t, *subtree_builder, [this] { PauseInSubtrees(); });
    train_timer.reset();
    if (!out.ok()) return one_by_one(out.status());
    busy = false;
    for (size_t k = 0; k < tasks.size(); ++k) {
      uint64_t n = 0;
      for (uint64_t c : roots[k].parts) n += c;
      if (Status st = SendResult(*tasks[k], (*out)[k], t0, n, wanted_of[k].size(), missing.size()); !st.ok())
        drop(*tasks[k], st);
    }
  }

  /// Called by a subtree batch between its histogram batches and levels: answers the level
  /// requests (and applies the decisions) of this worker's shard that are queued at the front,
  /// so the coordinator's rounds do not wait for the whole batch (in a 2,000-image run,
  /// rounds waited 883 of 1,917 s for workers busy in subtree batches). Only those: the
  /// first other message (an assignment, a task, a job) stops it and waits its turn in `pending`.
  /// The batch uses its own sample set and subtree_builder, so answering from the shard's set
  /// with `builder` is safe here; the answers and the subtrees are what they would be in order.
  void PauseInSubtrees() {
    if (opt.in_subtree_batch) opt.in_subtree_batch();
    ServeRounds();
  }

  void ServeRounds() {
    const double t_serve = proto::dds::NowSeconds(), cpu_serve = ThreadCpu();
    const bool was_busy = busy;
    auto is_round = [&](const v1::Envelope& env) {
      if (!have_shard) return false;
      if (env.body_case() == v1::Envelope::kLevelRequest)
        return int(env.level_request().tree()) == tree && env.level_request().epoch() >= skip_below_epoch;
      if (env.body_case() == v1::Envelope::kDecisions)
        return int(env.decisions().tree()) == tree && env.decisions().epoch() >= skip_below_epoch;
      return false;
    };
    int served = 0;
    for (;;) {
      if (!pending.empty()) {
        if (!pending.front().checked || !is_round(pending.front().env)) break;
        Pending p = std::move(pending.front());
        pending.pop_front();
        dispatch_received_s = p.received_s;
        Dispatch(p.env, p.sender);
        ++served;
        continue;
      }
      std::optional<proto::dds::ReceivedSample> s = Take(std::chrono::milliseconds(0));
      if (!s) break;
      if (s->topic == Topic::kJob || !gate) {
        pending.push_back({false, std::move(*s), {}, {}, 0});
        break;
      }
      auto out = gate->Check(s->topic, s->bytes, s->writer_guid);
      CountDropped(out);
      if (out.verdict != proto::dds::MessageGate::Verdict::kAccepted) continue;
      if (!is_round(out.envelope)) {
        pending.push_back({true, {}, std::move(out.envelope), std::move(out.sender), s->received_s});
        break;
      }
      dispatch_received_s = s->received_s;
      Dispatch(out.envelope, out.sender);
      ++served;
    }
    busy = was_busy;
    if (served == 0) return;
    ++cpu.rounds_in_batches;
    served_in_batch_s += proto::dds::NowSeconds() - t_serve;
    // The subtree_train timer around the batch counts this thread's CPU; the answers counted
    // theirs in their own phases.
    cpu.subtree_train -= ThreadCpu() - cpu_serve;
  }

  void OnSample(const proto::dds::ReceivedSample& s) {
    if (s.topic == Topic::kJob) {
      auto out = job_gate.Check(s.topic, s.bytes, s.writer_guid);
      CountDropped(out);
      if (out.verdict == proto::dds::MessageGate::Verdict::kAccepted) OnJob(out.envelope);
      return;
    }
    if (!gate) return;
    std::optional<CpuTimer> gate_timer(&cpu.receive);
    auto out = gate->Check(s.topic, s.bytes, s.writer_guid);
    gate_timer.reset();
    CountDropped(out);
    if (out.verdict != proto::dds::MessageGate::Verdict::kAccepted) return;
    if (s.topic == Topic::kControl && out.sender == coordinator_id) control_writer = s.writer_guid;
    dispatch_received_s = s.received_s;
    Dispatch(out.envelope, out.sender);
  }

  /// The newest epoch above `epoch` of a ShardAssignment for this worker waiting in the inbox,
  /// written by the coordinator's control writer (the gate checked that writer's earlier
  /// messages; these are only looked at, and pass the gate when their turn comes); 0: none.
  uint64_t NewerQueuedShard(uint64_t epoch) {
    if (control_writer.empty()) return 0;
    uint64_t newest = 0;
    std::lock_guard<std::mutex> lock(inbox_mu);
    for (const proto::dds::ReceivedSample& q : inbox) {
      // Assignments are small (a few ranges); big samples are replies, tasks or decisions.
      if (q.topic != Topic::kControl || q.writer_guid != control_writer || q.bytes.size() > (64u << 10)) continue;
      v1::Envelope peek;
      if (!peek.ParseFromArray(q.bytes.data(), int(q.bytes.size())) || !peek.has_shard()) continue;
      if (peek.recipient_id() == opt.worker_id && peek.job_id() == job_id && peek.shard().epoch() > epoch)
        newest = std::max<uint64_t>(newest, peek.shard().epoch());
    }
    return newest;
  }

  /// Messages taken off DDS while collecting a batch of SubtreeTasks, handled next (in order).
  struct Pending {
    bool checked = false;  ///< passed the gate: env/sender; else a raw sample for OnSample
    proto::dds::ReceivedSample raw;
    v1::Envelope env;
    std::string sender;
    double received_s = 0;  ///< when `env` was taken off DDS (checked ones)
  };
  std::deque<Pending> pending;
  /// When the sample being dispatched was taken off DDS (for HistogramReply.queued_micros).
  double dispatch_received_s = 0;
  /// Wall seconds of rounds answered inside the current subtree batch (ServeRounds).
  double served_in_batch_s = 0;
  /// Wall seconds spent rendering shard frames not yet reported (HistogramReply.render_micros),
  /// and task frames not yet reported (the next SubtreeResult's render_micros).
  double shard_render_unreported_s = 0, task_render_unreported_s = 0;

  static bool Listed(const v1::SubtreeTask& t) { return t.sample_frames_size() > 0; }

  /// After a SubtreeTask with a sample list: the tasks queued right behind it (the coordinator
  /// sends a level's tasks in one burst) of the same tree, also listed, join `batch`; the first
  /// other message is kept in `pending`. False: the test hook says die.
  bool DrainTasks(std::vector<v1::Envelope>* batch) {
    for (;;) {
      std::optional<proto::dds::ReceivedSample> more;
      {
        CpuTimer timer(&cpu.receive);
        more = Take(std::chrono::milliseconds(0));
      }
      if (!more) return true;
      if (more->topic == Topic::kJob) {
        pending.push_back({false, std::move(*more), {}, {}, 0});
        return true;
      }
      std::optional<CpuTimer> gate_timer(&cpu.receive);
      auto out = gate->Check(more->topic, more->bytes, more->writer_guid);
      gate_timer.reset();
      CountDropped(out);
      if (out.verdict != proto::dds::MessageGate::Verdict::kAccepted) continue;
      if (out.envelope.body_case() == v1::Envelope::kSubtreeTask &&
          out.envelope.subtree_task().tree() == batch->front().subtree_task().tree() &&
          Listed(out.envelope.subtree_task())) {
        if (opt.die_on_subtree_task && opt.die_on_subtree_task()) return false;
        batch->push_back(std::move(out.envelope));
        continue;
      }
      if (out.envelope.body_case() == v1::Envelope::kSubtreeTasks &&
          out.envelope.subtree_tasks().tasks(0).tree() == batch->front().subtree_task().tree() &&
          std::all_of(out.envelope.subtree_tasks().tasks().begin(), out.envelope.subtree_tasks().tasks().end(),
                      Listed)) {
        if (opt.die_on_subtree_task && opt.die_on_subtree_task()) return false;
        for (const v1::SubtreeTask& task : out.envelope.subtree_tasks().tasks())
          *batch->emplace_back().mutable_subtree_task() = task;
        continue;
      }
      pending.push_back({true, {}, std::move(out.envelope), std::move(out.sender), more->received_s});
      return true;
    }
  }

  void Dispatch(const v1::Envelope& env, const std::string& sender) {
    Status st;
    switch (env.body_case()) {
      case v1::Envelope::kShard: {
        if (opt.hold_before_shard) opt.hold_before_shard();
        const uint64_t e = env.shard().epoch();
        newest_epoch = std::max<uint64_t>(newest_epoch, e);
        received_shard_epoch = std::max<uint64_t>(received_shard_epoch, e);
        assigned_any = true;  // heartbeats (with the epochs) from now on, also while it loads
        // A newer assignment for us already queued (the coordinator sent it again while we were
        // busy): load that one only. Loading each in turn, slower than the coordinator re-sent
        // them, livelocked a 2,000-image run. The decisions replayed and the
        // level requests between the two are obsolete: the newer one is followed by its own.
        if (const uint64_t newer = NewerQueuedShard(e); newer > 0) {
          skip_below_epoch = std::max(skip_below_epoch, newer);
          ++cpu.shards_skipped;
          Log("assignment of epoch " + std::to_string(e) + " skipped: epoch " + std::to_string(newer) +
              " is queued");
          break;
        }
        st = LoadShard(env.shard());
        if (st.ok()) shard_epoch = e;
        break;
      }
      case v1::Envelope::kDecisions:
        if (env.decisions().epoch() < skip_below_epoch) break;  // replayed for a skipped assignment
        if (have_shard && int(env.decisions().tree()) == tree) st = ApplyDecisions(env.decisions());
        break;
      case v1::Envelope::kLevelRequest:
        newest_epoch = std::max<uint64_t>(newest_epoch, env.level_request().epoch());
        if (env.level_request().epoch() < skip_below_epoch) break;  // asked again after the newer one
        if (have_shard && int(env.level_request().tree()) == tree) st = Answer(env.level_request());
        break;
      case v1::Envelope::kSubtreeTask:
        if (opt.die_on_subtree_task && opt.die_on_subtree_task()) {
          Log("test hook: dying with a subtree task");
          stop = true;
          return;
        }
        if (opt.hold_on_subtree_task) opt.hold_on_subtree_task();
        if (Listed(env.subtree_task())) {
          std::vector<v1::Envelope> batch{env};
          if (!DrainTasks(&batch)) {
            Log("test hook: dying with subtree tasks");
            stop = true;
            return;
          }
          if (batch.size() > 1) {
            RunSubtreeBatch(batch, sender);
            break;
          }
        }
        st = RunSubtree(env.subtree_task());
        break;
      case v1::Envelope::kSubtreeTasks: {
        if (opt.die_on_subtree_task && opt.die_on_subtree_task()) {
          Log("test hook: dying with subtree tasks");
          stop = true;
          return;
        }
        if (opt.hold_on_subtree_task) opt.hold_on_subtree_task();
        // Tasks with sample lists train together (one SampleSet), with any listed tasks queued
        // right behind; a task without a list (the coordinator routes none today) alone.
        std::vector<v1::Envelope> batch;
        for (const v1::SubtreeTask& task : env.subtree_tasks().tasks()) {
          if (Listed(task)) {
            *batch.emplace_back().mutable_subtree_task() = task;
          } else if (Status one = RunSubtree(task); !one.ok()) {
            Log("dropped SubtreeTask (position " + std::to_string(task.position()) + ") from " + sender + ": " +
                one.ToString());
          }
        }
        if (batch.empty()) break;
        if (!DrainTasks(&batch)) {
          Log("test hook: dying with subtree tasks");
          stop = true;
          return;
        }
        if (batch.size() > 1)
          RunSubtreeBatch(batch, sender);
        else
          st = RunSubtree(batch.front().subtree_task());
        break;
      }
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
      Log(std::string("dropped ") + proto::dds::BodyName(env.body_case()) + " from " + sender + ": " +
          st.ToString());
  }
};

uint64_t TaskCacheBytesFor(const engine::TrainParams& params, uint64_t physical_bytes) {
  const uint64_t frame = uint64_t(std::max(0, params.source.width)) *
                             uint64_t(std::max(0, params.source.height)) * sizeof(uint16_t) +
                         uint64_t(std::max(0, params.pixels_per_image)) * sizeof(engine::PixelSample);
  const uint64_t tree = frame * uint64_t(std::max(0, params.images_per_tree));
  const uint64_t floor = uint64_t(256) << 20;
  return std::max(floor, std::min(tree, physical_bytes / 8));
}

Status SelectListedSamples(std::span<const engine::PixelSample> picked, int width, uint64_t frame,
                           std::span<const uint32_t> deltas, std::vector<engine::PixelSample>* out) {
  out->clear();
  uint64_t pixel = 0;
  size_t k = 0;
  auto index = [&](size_t j) { return uint64_t(picked[j].y) * uint64_t(width) + uint64_t(picked[j].x); };
  for (size_t c = 0; c < deltas.size(); ++c) {
    if (c > 0 && deltas[c] == 0)
      return Status(ErrorCode::kInvalidArgument,
                    "frame " + std::to_string(frame) + ": pixel " + std::to_string(pixel) + " listed twice");
    pixel += deltas[c];
    while (k < picked.size() && index(k) < pixel) ++k;
    if (k == picked.size() || index(k) != pixel)
      return Status(ErrorCode::kInvalidArgument, "frame " + std::to_string(frame) + ": pixel " +
                                                     std::to_string(pixel) +
                                                     " is not one of its sampled pixels");
    out->push_back(picked[k]);
  }
  return Status::Ok();
}

DistWorker::DistWorker(WorkerOptions options)
    : options_(std::move(options)), live_(std::make_unique<Live>()) {
  if (options_.worker_id.empty()) options_.worker_id = proto::dds::DefaultWorkerId();
  if (!options_.log) {
    const std::string id = options_.worker_id;
    options_.log = [id](const std::string& m) { std::fprintf(stderr, "[%s] %s\n", id.c_str(), m.c_str()); };
  }
  options_.threads = std::max(1, options_.threads);
}

DistWorker::~DistWorker() = default;

Status DistWorker::Run() {
  const double process0 = ProcessCpu();
  live_->busy = false;
  live_->stopped = false;
  struct Stopped {
    std::atomic<bool>& stopped;
    ~Stopped() { stopped = true; }
  } stopped_at_return{live_->stopped};
  Impl impl(options_, stop_, *live_);
  impl.cpu.process_at_start = process0;
  std::optional<CpuTimer> participant_timer(&impl.cpu.participant);
  proto::dds::NodeConfig node_config = proto::dds::MakeNodeConfig(
      options_.domain, options_.transport, false, options_.worker_id, options_.lease, options_.udp_peers,
      options_.udp_interfaces, options_.transport_extras);
  node_config.log = options_.log;
  auto node = proto::dds::DdsNode::Create(node_config);
  if (!node.ok()) return node.status();
  impl.node = std::move(*node);
  participant_timer.reset();
  std::thread heartbeat([&] { impl.HeartbeatLoop(); });
  std::thread intake([&] { impl.IntakeLoop(); });
  while (!stop_) {
    if (!impl.pending.empty()) {  // taken off DDS while a batch of subtree tasks was collected
      Impl::Pending p = std::move(impl.pending.front());
      impl.pending.pop_front();
      if (p.checked) {
        impl.dispatch_received_s = p.received_s;
        impl.Dispatch(p.env, p.sender);
      }
      else
        impl.OnSample(p.raw);
      continue;
    }
    std::optional<proto::dds::ReceivedSample> s;
    {
      CpuTimer timer(&impl.cpu.receive);
      s = impl.Take(std::chrono::milliseconds(50));
    }
    if (s) impl.OnSample(*s);
    impl.SaveCpu();
  }
  heartbeat.join();
  impl.inbox_cv.notify_all();
  intake.join();
  impl.cpu.receive += impl.intake_cpu;
  // Let the last replies reach the coordinator before the participant goes away.
  {
    CpuTimer timer(&impl.cpu.publish);
    (void)impl.node->WaitForAcknowledgments(Topic::kReplies, std::chrono::milliseconds(500));
  }
  impl.cpu.run_total = ProcessCpu() - process0;
  cpu_ = impl.cpu;
  impl.SaveCpu();
  return Status::Ok();
}

WorkerStats DistWorker::Stats() const {
  const Live& l = *live_;
  WorkerStats s;
  s.worker_id = options_.worker_id;
  s.stopped = l.stopped;
  s.threads = options_.threads;
  s.busy_threads = l.busy ? options_.threads : 0;
  for (size_t i = 0; i < s.rounds.size(); ++i) s.rounds[i] = l.rounds[i];
  s.histograms = l.histograms;
  s.subtrees = l.subtrees;
  s.subtree_nodes = l.subtree_nodes;
  s.evaluations = l.evaluations;
  s.shard_frames = {l.shard_rendered, double(l.shard_render_us) * 1e-6, l.shard_hits};
  s.task_frames = {l.task_rendered, double(l.task_render_us) * 1e-6, l.task_hits};
  s.frame_cache_evictions = l.cache_evictions;
  s.frame_cache_bytes = l.cache_bytes;
  s.frame_cache_capacity_bytes = l.cache_capacity;
  for (size_t t = 0; t < size_t(proto::dds::kNumTopics); ++t) {
    s.messages_sent[t] = l.sent[t];
    s.bytes_sent[t] = l.sent_bytes[t];
    s.messages_received[t] = l.received[t];
  }
  s.messages_rejected = l.rejected;
  s.messages_stale = l.stale;
  s.inbox_bytes = l.inbox_bytes;
  std::lock_guard<std::mutex> lock(l.mu);
  s.job_id = l.job_id;
  s.coordinator_id = l.coordinator_id;
  s.cpu = l.cpu;
  return s;
}

}  // namespace poseforest::worker
