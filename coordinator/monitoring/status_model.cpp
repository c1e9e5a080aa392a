#include "coordinator/monitoring/status_model.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "proto/http/prometheus_text.h"

namespace poseforest::coordinator::monitoring {

namespace {
double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

constexpr double kWorkerWindowS = 10;  // per-worker throughput window
}  // namespace

double UnixSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

double Finite(double v) { return std::isfinite(v) ? v : 0; }

std::string ValidUtf8(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  const size_t n = s.size();
  for (size_t i = 0; i < n;) {
    const unsigned char c = p[i];
    // Copy a well-formed UTF-8 sequence; replace anything else with U+FFFD.
    const int len = c < 0x80                 ? 1
                    : c >= 0xF0 && c <= 0xF4 ? 4
                    : c >= 0xE0 && c < 0xF0  ? 3
                    : c >= 0xC2 && c < 0xE0  ? 2
                                             : 0;
    bool ok = len > 0 && i + size_t(len) <= n;
    for (int k = 1; ok && k < len; ++k) ok = (p[i + size_t(k)] & 0xC0) == 0x80;
    if (ok && len >= 3) {  // no overlong forms, surrogates or code points past U+10FFFF
      const unsigned char c1 = p[i + 1];
      ok = !(c == 0xE0 && c1 < 0xA0) && !(c == 0xED && c1 > 0x9F) && !(c == 0xF0 && c1 < 0x90) &&
           !(c == 0xF4 && c1 > 0x8F);
    }
    if (ok) {
      out.append(s, i, size_t(len));
      i += size_t(len);
    } else {
      out += "\xef\xbf\xbd";
      ++i;
    }
  }
  return out;
}

std::string MessageJson(const google::protobuf::Message& m, bool every_field) {
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;  // job_id, not jobId: the names users have always read
  o.always_print_primitive_fields = every_field;
  std::string out;
  // Cannot fail for our messages (no Any, no invalid UTF-8: callers pass strings through ValidUtf8).
  const auto st = google::protobuf::util::MessageToJsonString(m, &out, o);
  return st.ok() ? out : "{}";
}

std::string StatusKindName(v1::StatusKind kind) {
  std::string name = v1::StatusKind_Name(kind);
  const std::string prefix = "STATUS_KIND_";
  if (name.rfind(prefix, 0) == 0) name = name.substr(prefix.size());
  return name.empty() ? "UNKNOWN" : name;
}

StatusModel::StatusModel(JobInfo info) : info_(std::move(info)) {
  start_unix_ = UnixSeconds();
  start_steady_ = SteadySeconds();
}

void StatusModel::SetUrl(const std::string& url) {
  std::lock_guard<std::mutex> lock(mu_);
  url_ = url;
}

void StatusModel::OnStatus(const v1::StatusEvent& e) {
  std::lock_guard<std::mutex> lock(mu_);
  Event ev;
  ev.unix_s = UnixSeconds();
  ev.kind = StatusKindName(e.kind());
  ev.worker = e.worker_id();
  ev.message = e.message();
  ev.tree = int(e.tree());
  ev.level = int(e.level());
  events_.push_back(ev);
  while (events_.size() > kMaxEvents) events_.pop_front();
  switch (e.kind()) {
    case v1::STATUS_KIND_WORKER_JOINED: {
      Worker& w = workers_[e.worker_id()];
      w = Worker{};
      w.joined = ev.unix_s;
      w.last_seen = SteadySeconds();
      break;
    }
    case v1::STATUS_KIND_WORKER_LOST:
    case v1::STATUS_KIND_WORKER_EVICTED: {
      Worker& w = workers_[e.worker_id()];
      w.state = e.kind() == v1::STATUS_KIND_WORKER_LOST ? "lost" : "evicted";
      w.frames = 0;
      w.recent.clear();
      (e.kind() == v1::STATUS_KIND_WORKER_LOST ? workers_lost_ : workers_evicted_)++;
      break;
    }
    case v1::STATUS_KIND_WORKER_REFUSED: {  // not admitted: the message says why
      Worker& w = workers_[e.worker_id()];
      w = Worker{};
      w.state = "refused";
      break;
    }
    case v1::STATUS_KIND_TREE_DONE:
      trees_done_ = std::max(trees_done_, int(e.tree()) + 1);
      levels_done_in_tree_ = 0;
      nodes_finished_trees_ += nodes_current_tree_;
      nodes_current_tree_ = 1;
      break;
    case v1::STATUS_KIND_JOB_DONE:
      state_ = "done";
      trees_done_ = info_.num_trees;
      if (end_steady_ < 0) end_steady_ = SteadySeconds();
      for (auto& [id, w] : workers_)
        if (w.state == "training" || w.state == "joined") w.state = "done";
      break;
    case v1::STATUS_KIND_ERROR:
      message_ = e.message();
      break;
    default:
      break;
  }
}

void StatusModel::OnLevelStart(int tree, int level, size_t nodes, uint64_t samples) {
  std::lock_guard<std::mutex> lock(mu_);
  state_ = "training";
  if (train_start_steady_ < 0) train_start_steady_ = SteadySeconds();
  if (tree != tree_) {
    levels_done_in_tree_ = 0;
    nodes_current_tree_ = nodes;  // a resumed tree: at least its frontier
  }
  tree_ = tree;
  level_ = level;
  trees_done_ = std::max(trees_done_, tree);
  levels_done_in_tree_ = std::max(levels_done_in_tree_, level);
  nodes_done_ = 0;
  nodes_total_ = nodes;
  level_samples_ = samples;
  for (auto& [id, w] : workers_)
    if (w.state == "training" && w.tree != tree) w.state = "joined", w.frames = 0;
}

void StatusModel::OnNodesDecided(size_t done, size_t total) {
  std::lock_guard<std::mutex> lock(mu_);
  nodes_done_ = done;
  nodes_total_ = total;
}

void StatusModel::OnLevelDone(const DistLevelStats& s) {
  std::lock_guard<std::mutex> lock(mu_);
  levels_.push_back(s);
  if (levels_.size() > kMaxLevels) levels_.erase(levels_.begin());
  nodes_done_ = nodes_total_ = s.frontier_nodes;
  nodes_current_tree_ += 2 * uint64_t(s.split_nodes);
  levels_done_in_tree_ = s.level + 1;
  total_samples_ += s.samples;
  total_evaluations_ += s.evaluations;
  total_bytes_received_ += s.bytes_received;
  total_bytes_sent_ += s.bytes_sent;
  total_retries_ += uint64_t(s.retries);
  total_level_s_ += s.level_seconds;
  ++total_levels_;
  // Throughput over the last few levels (one level can be a few milliseconds).
  double secs = 0, samples = 0, evals = 0;
  // A tree's last level (every node a leaf) costs nothing: it would inflate samples/s.
  int counted = 0;
  for (size_t i = levels_.size(); i-- > 0 && counted < 5;) {
    if (levels_[i].evaluations == 0) continue;
    ++counted;
    secs += levels_[i].level_seconds;
    samples += double(levels_[i].samples);
    evals += double(levels_[i].evaluations);
  }
  samples_per_s_ = secs > 0 ? samples / secs : 0;
  evaluations_per_s_ = secs > 0 ? evals / secs : 0;
}

void StatusModel::OnWorkerSeen(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = workers_.find(id);
  if (it == workers_.end()) return;  // WORKER_JOINED comes first; ignore strays
  it->second.last_seen = SteadySeconds();
}

void StatusModel::OnWorkerAssigned(const std::string& id, int tree, uint64_t frames) {
  std::lock_guard<std::mutex> lock(mu_);
  Worker& w = workers_[id];
  if (w.joined == 0) w.joined = UnixSeconds();
  w.state = "training";
  w.tree = tree;
  w.frames = frames;
}

void StatusModel::OnWorkerReply(const std::string& id, uint64_t bytes, const v1::HistogramReply& reply) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = workers_.find(id);
  if (it == workers_.end()) return;
  Worker& w = it->second;
  uint64_t samples = 0;
  for (const auto& n : reply.nodes()) samples += n.samples();
  const uint64_t evals = samples * uint64_t(reply.num_candidates());
  const double now = SteadySeconds();
  w.last_seen = now;
  ++w.replies;
  w.samples += samples;
  w.evaluations += evals;
  w.bytes += bytes;
  w.compute_s += double(reply.compute_micros()) * 1e-6;
  w.recent.emplace_back(now, evals);
  while (!w.recent.empty() && now - w.recent.front().first > kWorkerWindowS) w.recent.pop_front();
}

void StatusModel::OnWorkerHeartbeat(const std::string& id, const v1::Heartbeat& hb) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = workers_.find(id);
  if (it == workers_.end()) return;
  // The gate has checked the figures (finite, 0..1e13); a restarted worker counts from 0 again.
  it->second.reported_evaluations = hb.evaluations();
  it->second.reported_rate = hb.evaluations_per_s();
  if (hb.task_frames_rendered() + hb.task_frames_cached() > 0) {
    it->second.task_tree = int(hb.task_tree());
    it->second.task_rendered = hb.task_frames_rendered();
    it->second.task_cached = hb.task_frames_cached();
    it->second.task_evicted = hb.task_cache_evictions();
  }
}

void StatusModel::FillStatus(v1::StatusEvent* e) {
  std::lock_guard<std::mutex> lock(mu_);
  const double now = SteadySeconds();
  const double end = end_steady_ >= 0 ? end_steady_ : now;
  // Within what the gate accepts (ValidateStatus), so that a reader never drops our own event.
  constexpr double kMaxRate = 1e13, kMaxSeconds = 1e9;
  auto bounded = [](double v, double hi) { return std::isfinite(v) ? std::clamp(v, 0.0, hi) : 0.0; };
  if (e->kind() == v1::STATUS_KIND_PROGRESS) {
    e->set_tree(uint32_t(std::max(0, tree_)));
    e->set_level(uint32_t(std::max(0, level_)));
    e->set_progress(std::clamp(Progress(), 0.0, 1.0));
  }
  e->set_samples_per_s(bounded(samples_per_s_, kMaxRate));
  e->set_evaluations_per_s(bounded(evaluations_per_s_, kMaxRate));
  const double eta = Eta();
  if (eta >= 0 && std::isfinite(eta))
    e->set_eta_s(std::min(eta, kMaxSeconds));
  else
    e->clear_eta_s();
  e->set_elapsed_s(bounded(end - start_steady_, kMaxSeconds));
  e->set_trees_done(uint32_t(std::max(0, trees_done_)));
  e->set_level_nodes_total(uint32_t(std::min<size_t>(nodes_total_, UINT32_MAX)));
  e->set_level_nodes_done(uint32_t(std::min(nodes_done_, std::min<size_t>(nodes_total_, UINT32_MAX))));
  e->set_forest_nodes(nodes_finished_trees_ + nodes_current_tree_);
  e->set_evaluations(total_evaluations_);
  e->set_bytes_received(total_bytes_received_);
  e->set_retries(total_retries_);
  e->clear_levels();
  for (size_t i = levels_.size() > size_t(kMaxStatusLevels) ? levels_.size() - kMaxStatusLevels : 0;
       i < levels_.size(); ++i) {
    const DistLevelStats& s = levels_[i];
    v1::LevelStatus* l = e->add_levels();
    l->set_tree(uint32_t(std::max(0, s.tree)));
    l->set_level(uint32_t(std::clamp(s.level, 0, 64)));
    l->set_nodes(s.frontier_nodes);
    l->set_split(std::min(s.split_nodes, s.frontier_nodes));
    l->set_samples(s.samples);
    l->set_entropy(bounded(s.mean_entropy, 64));
    l->set_gain(bounded(s.mean_gain, 64));
    l->set_evaluations(s.evaluations);
    l->set_evaluations_per_s(bounded(s.evaluations_per_s, kMaxRate));
    l->set_seconds(bounded(s.level_seconds, kMaxSeconds));
    l->set_workers(uint32_t(std::max(0, s.workers_alive)));
  }
  e->clear_workers();
  for (const auto& [id, w] : workers_) {
    if (e->workers_size() >= kMaxStatusWorkers) break;
    if (id.empty() || id.size() > 256) continue;  // the gate accepts 1..256 bytes
    v1::WorkerStatus* ws = e->add_workers();
    ws->set_id(id);
    ws->set_state(w.state == "training"  ? v1::WORKER_STATE_TRAINING
                  : w.state == "lost"    ? v1::WORKER_STATE_LOST
                  : w.state == "evicted" ? v1::WORKER_STATE_EVICTED
                  : w.state == "done"    ? v1::WORKER_STATE_DONE
                  : w.state == "refused" ? v1::WORKER_STATE_REFUSED
                                         : v1::WORKER_STATE_JOINED);
    ws->set_frames(w.frames);
    ws->set_replies(w.replies);
    ws->set_evaluations(w.reported_evaluations);
    ws->set_evaluations_per_s(w.state == "training" ? bounded(w.reported_rate, kMaxRate) : 0);
    ws->set_last_seen_s(w.last_seen > 0 ? std::min(now - w.last_seen, kMaxSeconds) : -1);
  }
}

void StatusModel::Finish(bool ok, const std::string& message) {
  std::lock_guard<std::mutex> lock(mu_);
  state_ = ok ? "done" : "failed";
  message_ = message;
  if (end_steady_ < 0) end_steady_ = SteadySeconds();
  if (ok) trees_done_ = info_.num_trees;
  for (auto& [id, w] : workers_)
    if (w.state == "training" || w.state == "joined") w.state = "done";
}

double StatusModel::Progress() const {
  if (state_ == "done") return 1;
  if (info_.num_trees <= 0) return 0;
  const double in_tree =
      std::min(1.0, double(levels_done_in_tree_) / double(std::max(1, info_.max_depth + 1)));
  return std::clamp(
      (double(trees_done_) + (trees_done_ < info_.num_trees ? in_tree : 0)) / double(info_.num_trees), 0.0,
      1.0);
}

double StatusModel::Eta() const {
  if (state_ == "done") return 0;
  if (state_ != "training" || train_start_steady_ < 0) return -1;
  const double p = Progress();
  if (p <= 0) return -1;
  return (SteadySeconds() - train_start_steady_) * (1 - p) / p;
}

double StatusModel::WorkerRate(const Worker& w, double now) const {
  if (w.state != "training") return 0;
  uint64_t evals = 0;
  for (const auto& [t, e] : w.recent)
    if (now - t <= kWorkerWindowS) evals += e;
  const double span = std::min(kWorkerWindowS, std::max(1.0, now - start_steady_));
  return double(evals) / span;
}

v1::JobStatus StatusModel::Snapshot() const {
  std::lock_guard<std::mutex> lock(mu_);
  const double now = SteadySeconds();
  const double end = end_steady_ >= 0 ? end_steady_ : now;
  const double eta = Eta();
  v1::JobStatus j;
  j.set_job_id(ValidUtf8(info_.job_id));
  j.set_state(state_);
  j.set_message(ValidUtf8(message_));
  j.set_url(ValidUtf8(url_));
  j.set_domain(info_.domain);
  j.set_profile(ValidUtf8(info_.profile));
  j.set_out(ValidUtf8(info_.out_path));
  j.set_started_unix(Finite(start_unix_));
  j.set_now_unix(Finite(UnixSeconds()));
  j.set_elapsed_s(Finite(end - start_steady_));
  v1::JobStatus::Config* c = j.mutable_config();
  c->set_num_trees(info_.num_trees);
  c->set_max_depth(info_.max_depth);
  c->set_images_per_tree(info_.images_per_tree);
  c->set_pixels_per_image(info_.pixels_per_image);
  c->set_candidate_features(info_.candidate_features);
  c->set_thresholds_per_feature(info_.thresholds_per_feature);
  j.set_tree(tree_);
  j.set_level(level_);
  j.set_trees_done(trees_done_);
  j.set_level_nodes_done(uint32_t(std::min<size_t>(nodes_done_, UINT32_MAX)));
  j.set_level_nodes_total(uint32_t(std::min<size_t>(nodes_total_, UINT32_MAX)));
  j.set_level_samples(double(level_samples_));
  j.set_forest_nodes(double(nodes_finished_trees_ + nodes_current_tree_));
  j.set_progress(Finite(Progress()));
  if (eta >= 0 && std::isfinite(eta)) j.set_eta_s(eta);
  j.set_samples_per_s(Finite(samples_per_s_));
  j.set_evaluations_per_s(Finite(evaluations_per_s_));
  v1::JobStatus::Totals* t = j.mutable_totals();
  t->set_levels(uint32_t(total_levels_));
  t->set_samples(double(total_samples_));
  t->set_evaluations(double(total_evaluations_));
  t->set_bytes_received(double(total_bytes_received_));
  t->set_bytes_sent(double(total_bytes_sent_));
  t->set_retries(uint32_t(total_retries_));
  t->set_workers_lost(uint32_t(workers_lost_));
  t->set_workers_evicted(uint32_t(workers_evicted_));
  t->set_level_seconds(Finite(total_level_s_));
  for (const DistLevelStats& s : levels_) {
    v1::JobStatus::Level* l = j.add_levels();
    l->set_tree(s.tree);
    l->set_level(s.level);
    l->set_nodes(uint32_t(std::min<size_t>(s.frontier_nodes, UINT32_MAX)));
    l->set_split(uint32_t(std::min<size_t>(s.split_nodes, UINT32_MAX)));
    l->set_samples(double(s.samples));
    l->set_entropy(Finite(s.mean_entropy));
    l->set_gain(Finite(s.mean_gain));
    l->set_evaluations(double(s.evaluations));
    l->set_evaluations_per_s(Finite(s.evaluations_per_s));
    l->set_samples_per_s(Finite(s.level_seconds > 0 ? double(s.samples) / s.level_seconds : 0));
    l->set_seconds(Finite(s.level_seconds));
    l->set_elapsed_s(Finite(s.elapsed_s));
    l->set_workers(s.workers_alive);
    l->set_bytes_received(double(s.bytes_received));
    l->set_retries(s.retries);
  }
  for (const auto& [id, w] : workers_) {
    v1::JobStatus::Worker* ws = j.add_workers();
    ws->set_id(ValidUtf8(id));
    ws->set_state(w.state);
    ws->set_frames(double(w.frames));
    ws->set_replies(double(w.replies));
    ws->set_samples(double(w.samples));
    ws->set_evaluations(double(w.evaluations));
    ws->set_evaluations_per_s(Finite(WorkerRate(w, now)));
    ws->set_compute_evaluations_per_s(Finite(w.compute_s > 0 ? double(w.evaluations) / w.compute_s : 0));
    ws->set_reported_evaluations(double(w.reported_evaluations));
    ws->set_reported_evaluations_per_s(Finite(w.state == "training" ? w.reported_rate : 0));
    ws->set_bytes_received(double(w.bytes));
    ws->set_joined_unix(Finite(w.joined));
    ws->set_last_seen_s(Finite(w.last_seen > 0 ? now - w.last_seen : -1));
  }
  for (const Event& e : events_) {
    v1::JobEvent* ev = j.add_events();
    ev->set_unix(Finite(e.unix_s));
    ev->set_event(e.kind);
    ev->set_tree(e.tree);
    ev->set_level(e.level);
    ev->set_worker(ValidUtf8(e.worker));
    ev->set_message(ValidUtf8(e.message));
  }
  return j;
}

std::string StatusModel::Json() const { return MessageJson(Snapshot(), /*every_field=*/true) + "\n"; }

std::string StatusModel::Prometheus() const {
  std::lock_guard<std::mutex> lock(mu_);
  const double now = SteadySeconds();
  // Prometheus attaches its own `job` label (the scrape job) to every sample; a target's own
  // `job` label would clash with it (renamed exported_job, or overriding it with honor_labels), so
  // ours is exported_job from the start.
  const std::string job = "exported_job=\"" + proto::http::PromLabelValue(info_.job_id) + "\"";
  std::string m =
      "# HELP poseforest_build_info The poseforest build serving these metrics (always 1).\n"
      "# TYPE poseforest_build_info gauge\n"
      "poseforest_build_info{version=\"" POSEFOREST_BUILD_VERSION "\"} 1\n";
  auto metric = [&](const std::string& name, const std::string& type, const std::string& help,
                    const std::vector<std::pair<std::string, double>>& samples) {
    m += "# HELP " + name + " " + help + "\n# TYPE " + name + " " + type + "\n";
    for (const auto& [labels, v] : samples)
      m += name + "{" + job + (labels.empty() ? "" : "," + labels) + "} " + proto::http::PromNumber(v) + "\n";
  };
  const double eta = Eta();
  std::vector<std::pair<std::string, double>> states;
  for (const char* s : {"waiting", "training", "done", "failed"})
    states.push_back({"state=\"" + std::string(s) + "\"", state_ == s ? 1 : 0});
  metric("poseforest_job_state", "gauge", "1 for the job's current state.", states);
  metric("poseforest_job_progress_ratio", "gauge", "Estimated fraction of the job done (0..1).",
         {{"", Progress()}});
  metric("poseforest_job_eta_seconds", "gauge", "Estimated seconds left (NaN: unknown).",
         {{"", eta >= 0 ? eta : std::nan("")}});
  metric("poseforest_job_trees", "gauge", "Trees of the job.", {{"", double(info_.num_trees)}});
  metric("poseforest_trees_done", "gauge", "Trees finished.", {{"", double(trees_done_)}});
  metric("poseforest_current_tree", "gauge", "Tree in training (0-based).", {{"", double(tree_)}});
  metric("poseforest_current_level", "gauge", "Level in training (0 = root).", {{"", double(level_)}});
  metric("poseforest_level_nodes_done", "gauge", "Frontier nodes of the current level decided.",
         {{"", double(nodes_done_)}});
  metric("poseforest_level_nodes", "gauge", "Frontier nodes of the current level.",
         {{"", double(nodes_total_)}});
  metric("poseforest_forest_nodes", "gauge", "Nodes in the forest so far.",
         {{"", double(nodes_finished_trees_ + nodes_current_tree_)}});
  metric("poseforest_samples_per_second", "gauge", "Frontier samples per second over the last levels.",
         {{"", samples_per_s_}});
  metric("poseforest_evaluations_per_second", "gauge",
         "Sample x candidate evaluations per second over the last levels.", {{"", evaluations_per_s_}});
  const double gain = levels_.empty() ? 0 : levels_.back().mean_gain;
  const double entropy = levels_.empty() ? 0 : levels_.back().mean_entropy;
  metric("poseforest_level_mean_information_gain", "gauge",
         "Mean information gain of the last level's splits (bits; not in the name: promtool's lint reads "
         "bits as data).",
         {{"", gain}});
  metric("poseforest_level_mean_part_entropy", "gauge",
         "Sample-weighted part entropy of the last level's frontier (bits).", {{"", entropy}});
  metric("poseforest_levels_total", "counter", "Levels finished.", {{"", double(total_levels_)}});
  metric("poseforest_samples_total", "counter", "Frontier samples over all finished levels.",
         {{"", double(total_samples_)}});
  metric("poseforest_evaluations_total", "counter", "Sample x candidate evaluations binned.",
         {{"", double(total_evaluations_)}});
  metric("poseforest_received_bytes_total", "counter", "Reply payload bytes received.",
         {{"", double(total_bytes_received_)}});
  metric("poseforest_sent_bytes_total", "counter", "Control payload bytes sent.",
         {{"", double(total_bytes_sent_)}});
  metric("poseforest_round_retries_total", "counter", "Rounds asked again after a worker loss.",
         {{"", double(total_retries_)}});
  metric("poseforest_workers_lost_total", "counter", "Workers lost.", {{"", double(workers_lost_)}});
  metric("poseforest_workers_evicted_total", "counter", "Workers evicted.", {{"", double(workers_evicted_)}});
  std::map<std::string, int> by_state;
  for (const char* s : {"joined", "training", "lost", "evicted", "refused", "done"}) by_state[s] = 0;
  for (const auto& [id, w] : workers_) ++by_state[w.state];
  std::vector<std::pair<std::string, double>> ws;
  for (const auto& [s, n] : by_state)
    ws.push_back({"state=\"" + proto::http::PromLabelValue(s) + "\"", double(n)});
  metric("poseforest_workers", "gauge", "Workers by state.", ws);
  std::vector<std::pair<std::string, double>> up, rate, evals, bytes, seen;
  for (const auto& [id, w] : workers_) {
    const std::string l = "worker=\"" + proto::http::PromLabelValue(id) + "\"";
    up.push_back({l, w.state == "training" || w.state == "joined" ? 1 : 0});
    rate.push_back({l, WorkerRate(w, now)});
    evals.push_back({l, double(w.evaluations)});
    bytes.push_back({l, double(w.bytes)});
    seen.push_back({l, w.last_seen > 0 ? now - w.last_seen : std::nan("")});
  }
  std::vector<std::pair<std::string, double>> task_rendered, task_cached, task_evicted;
  for (const auto& [id, w] : workers_) {
    if (w.task_tree < 0) continue;
    const std::string l =
        "worker=\"" + proto::http::PromLabelValue(id) + "\",tree=\"" + std::to_string(w.task_tree) + "\"";
    task_rendered.push_back({l, double(w.task_rendered)});
    task_cached.push_back({l, double(w.task_cached)});
    task_evicted.push_back({l, double(w.task_evicted)});
  }
  metric("poseforest_worker_up", "gauge", "1 while the worker is alive.", up);
  if (!task_rendered.empty()) {
    metric("poseforest_worker_task_frames_rendered", "gauge",
           "Frames of other shards rendered again for subtree tasks, this tree.", task_rendered);
    metric("poseforest_worker_task_frames_cached", "gauge",
           "Subtree-task frames found in the shard or the task-frame cache, this tree.", task_cached);
    metric("poseforest_worker_task_cache_evictions", "gauge",
           "Frames dropped from the task-frame cache to stay under its cap, this tree.", task_evicted);
  }
  metric("poseforest_worker_evaluations_per_second", "gauge", "Evaluations per second over the last 10 s.",
         rate);
  metric("poseforest_worker_evaluations_total", "counter", "Evaluations in the worker's histograms.", evals);
  metric("poseforest_worker_received_bytes_total", "counter", "Reply bytes received from the worker.", bytes);
  metric("poseforest_worker_last_seen_seconds", "gauge", "Seconds since the worker's last message.", seen);
  return m;
}

}  // namespace poseforest::coordinator::monitoring
