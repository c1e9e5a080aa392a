// poseforest live: depth frames in, per-person skeletons out - JSON Lines, pictures with bones,
// a live page in the browser (apps/live/, cpp-httplib, when found at configure time) and, in builds
// with Fast DDS, ROS 2-readable topics (apps/ros2/).
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "runtime/core/forest_format.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "runtime/skeleton_pipeline.h"
#include "runtime/visualize.h"
#ifdef POSEFOREST_HAS_HTTPLIB
#include "apps/live/live_page.h"
#endif
#ifdef POSEFOREST_HAS_SKELETON_DDS
#include "apps/ros2/skeleton_publisher.h"
#endif

namespace poseforest::apps::commands {
namespace {

namespace fs = std::filesystem;

std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop.store(true); }

int UsageError(const std::string& msg) {
  std::fprintf(stderr, "poseforest live: %s\n", msg.c_str());
  return 2;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t k = std::min(v.size() - 1, size_t(std::ceil(q * double(v.size())) - 1 + (q == 0)));
  return v[k];
}

// The command line as given: every option of `live`, declared once by DeclareLiveOptions.
struct LiveFlags {
  std::vector<std::string> sources;
  std::optional<std::string> source, jsonl, png_dir, http, dds_topic, dds_frame_id;
  std::string forest, method = "meanshift", fit;
  FrameSourceFlags frames;
  SegmentationFlags segmentation;
  // Default 2 for live video (docs/runtime/live.md, "Pixel stride"): bench/live's goals
  // (>= 200 frames/s, p99 <= 10 ms on 2 cores) are met there, not at 1 (about 105 frames/s).
  int pixel_stride = 2, threads = 0;
  std::optional<int> dds_domain, dds_wait;
  std::optional<int64_t> max_frames;
  std::optional<double> min_confidence, track_probability, seen_probability, min_support,
      max_match;  ///< default: SkeletonOptions'
  std::optional<double> smooth_min_cutoff, smooth_beta, smooth_d_cutoff;
  bool smooth = false, loop = false, quiet = false, dds = false, no_votes = false, no_tracking_model = false,
       no_seen_model = false;
};

void DeclareLiveOptions(CLI::App& app, LiveFlags* f) {
  app.add_option("SOURCE", f->sources, "depth frames: the sources of `poseforest frames` (docs/runtime/frames.md)");
  app.add_option("--source", f->source,
                 "FILE | FOLDER | 'PATTERN' | - (raw frames on stdin) | freenect:N | openni2:[URI]")
      ->type_name("SOURCE");
  app.add_option("--forest", f->forest, "forest file (.pff)")->type_name("FILE")->required();
  app.add_flag("--loop", f->loop, "replay a finite source forever (until SIGINT / SIGTERM or --max-frames)");
  app.add_option("--max-frames", f->max_frames, "stop after N frames")->type_name("N")->check(IntIn(1, 1LL << 40));
  app.add_option("--threads", f->threads, "OpenMP threads (0: all cores)")->type_name("N")->check(IntIn(0, 1024));
  app.add_flag("--quiet", f->quiet, "no progress line (the summary still goes to stderr)");
  const char* outputs = "outputs (any together; docs/runtime/live.md has the schema)";
  app.add_option("--jsonl", f->jsonl, "JSON Lines, one object per frame (- = stdout)")->type_name("FILE|-")->group(outputs);
  app.add_option("--png-dir", f->png_dir, "DIR/frame-NNNNNN.png per frame: depth | parts | skeletons (bones drawn)")
      ->type_name("DIR")
      ->group(outputs);
  app.add_option("--http", f->http,
                 "a live page at http://ADDR/ (HOST:PORT, or PORT for 127.0.0.1): depth | parts |\n"
                 "skeletons at the camera's rate (server-sent events: /events, one JSON Lines record per\n"
                 "frame); /skeletons.json (the latest), /frame.png (the latest picture, made while a page\n"
                 "is open)")
      ->type_name("ADDR")
      ->group(outputs);
  app.add_flag("--dds", f->dds,
               "ROS 2-readable DDS topics (Fast DDS, rmw_fastrtps naming; builds with Fast DDS):\n"
               "rt/PREFIX/skeletons (poseforest_msgs/msg/Skeletons, msg/*.msg in the source) and\n"
               "rt/PREFIX/markers (visualization_msgs/msg/MarkerArray: joints and bones per person, for\n"
               "RViz); reliable, transient-local, keep-last 100")
      ->group(outputs);
  app.add_option("--dds-domain", f->dds_domain, "DDS domain (ROS_DOMAIN_ID; default 0)")
      ->type_name("N")
      ->check(IntIn(0, 232))
      ->group(outputs);
  app.add_option("--dds-topic", f->dds_topic, "ROS topics /PREFIX/skeletons and /PREFIX/markers (default poseforest)")
      ->type_name("PREFIX")
      ->group(outputs);
  app.add_option("--dds-frame-id", f->dds_frame_id, "header.frame_id (default camera_depth_optical_frame)")
      ->type_name("ID")
      ->group(outputs);
  app.add_option("--dds-wait", f->dds_wait, "before the first frame, wait up to 10 s for N subscribers (default 0)")
      ->type_name("N")
      ->check(IntIn(0, 1000))
      ->group(outputs);
  AddFrameSourceOptions(app, &f->frames);
  AddSegmentationOptions(app, &f->segmentation);
  const char* sk = "skeletons";
  app.add_option("--method", f->method, "joint proposals: meanshift or fast")
      ->type_name("M")
      ->check(OneOf({"meanshift", "fast"}))
      ->group(sk);
  app.add_option("--pixel-stride", f->pixel_stride,
                 "classify and propose from every N-th pixel in x and y only (2: one pixel in 2x2, as\n"
                 "Kinect's tracker ran at 320x240; 2.1x the frames/s of 1 for 0.003 mAP:\n"
                 "docs/runtime/live.md; 1: every pixel)")
      ->type_name("N")
      ->check(IntIn(1, 16))
      ->group(sk);
  app.add_option("--fit", f->fit,
                 "greedy: each joint's most confident proposal on the person; kinematic: one fit per\n"
                 "person choosing among each joint's proposals with bone lengths (runtime/skeleton.h)\n"
                 "(default: the fit the forest's tracking decision was learned on, kinematic without one)")
      ->type_name("F")
      ->check(SkeletonFitValidator())
      ->group(sk);
  app.add_flag("--no-votes", f->no_votes,
               "ignore the forest's offset votes (format 1.5, `learn-votes`); by default a forest with\n"
               "votes gives every joint vote candidates too")
      ->group(sk);
  app.add_flag("--no-tracking-model", f->no_tracking_model,
               "the hand-set tracking rules (--min-confidence, --min-support, the image border, bone\n"
               "lengths, a tracked parent) instead of the forest's learned tracking decision (format\n"
               "1.6, `learn-votes`), which tracks a joint when its P(within 0.1 m) >= --track-probability")
      ->group(sk);
  app.add_flag("--no-seen-model", f->no_seen_model,
               "with the learned decision: track a joint when its P(within 0.1 m) >= --track-probability\n"
               "instead of when the decision's seen model (format 1.8) gives P(seen) >= --seen-probability\n"
               "(a found joint likely hidden is inferred)")
      ->group(sk);
  app.add_option("--min-confidence", f->min_confidence,
                 "without a tracking model: tracked only with a confidence >= C (default 0.3)")
      ->type_name("C")
      ->check(NumberIn(0.0, 1.0))
      ->group(sk);
  app.add_option("--track-probability", f->track_probability,
                 "the learned tracking decision's threshold on P(within 0.1 m) without the seen model\n"
                 "(--no-seen-model, forests before 1.8) (default 0.5)")
      ->type_name("P")
      ->check(NumberIn(0.0, 1.0))
      ->group(sk);
  app.add_option("--seen-probability", f->seen_probability,
                 "with the seen model: tracked when P(seen) >= P (default 0.2: a joint is reported not\n"
                 "seen only when P(hidden) >= 0.8)")
      ->type_name("P")
      ->check(NumberIn(0.0, 1.0))
      ->group(sk);
  app.add_option("--min-support", f->min_support, "... and a proposal support >= S m^2 (default 0.0001)")
      ->type_name("S")
      ->check(NumberIn(0.0, 10.0))
      ->group(sk);
  app.add_option("--max-match", f->max_match, "a person moving more than M metres between frames gets a new id (default 0.5)")
      ->type_name("M")
      ->check(NumberIn(0.0, 100.0))
      ->group(sk);
  app.add_flag("--smooth", f->smooth, "One Euro filter on tracked joints (Casiez et al. 2012)")->group(sk);
  app.add_option("--smooth-min-cutoff", f->smooth_min_cutoff, "--smooth: cutoff at rest (default 1)")
      ->type_name("HZ")
      ->check(NumberIn(1e-6, 1000.0))
      ->group(sk);
  app.add_option("--smooth-beta", f->smooth_beta, "--smooth: speed coefficient (default 0.5)")
      ->type_name("B")
      ->check(NumberIn(0.0, 1000.0))
      ->group(sk);
  app.add_option("--smooth-d-cutoff", f->smooth_d_cutoff, "--smooth: cutoff of the speed (default 1)")
      ->type_name("HZ")
      ->check(NumberIn(1e-6, 1000.0))
      ->group(sk);
}

// What the command line asks for (the outputs aside).
struct LiveOptions {
  std::vector<std::string> specs;
  std::string forest_path;
  runtime::FrameSourceOptions source;
  runtime::SkeletonPipelineOptions pipeline;
  int64_t max_frames = -1;
  bool quiet = false, loop = false;
};

// The options of the pipeline, the sources and the loop; on a usage error, the exit code (the
// message printed).
std::optional<int> ParseLiveOptions(const LiveFlags& f, LiveOptions* out) {
  out->specs = f.sources;
  if (f.source) out->specs.insert(out->specs.begin(), *f.source);
  // The first DDS option given, for the messages.
  const char* dds_option = f.dds_domain ? "dds-domain" : f.dds_topic ? "dds-topic" : f.dds_frame_id ? "dds-frame-id"
                           : f.dds_wait ? "dds-wait" : nullptr;
#ifndef POSEFOREST_HAS_SKELETON_DDS
  if (f.dds || dds_option)
    return UsageError(
        std::string("--") + (f.dds ? "dds" : dds_option) +
        ": this program was built without Fast DDS (the DDS output is built with the training side, "
        "-DPOSEFOREST_TRAINING=ON)");
#endif
  if (!f.dds && dds_option) return UsageError(std::string("--") + dds_option + " needs --dds");
  out->forest_path = f.forest;
  if (out->specs.empty()) return UsageError("no source given: --source SOURCE (see --help)");

  auto source = FrameSourceFromFlags(f.frames);
  if (!source.ok()) return UsageError(source.status().message());
  out->source = *source;
  runtime::SkeletonPipelineOptions& options = out->pipeline;
  options.segment = f.segmentation.segment == "on"    ? runtime::SegmentMode::kOn
                    : f.segmentation.segment == "off" ? runtime::SegmentMode::kOff
                                                      : runtime::SegmentMode::kAuto;
  if (core::Status st = SegmentationFromFlags(f.segmentation, &options.segmentation); !st.ok())
    return UsageError(st.message());
  options.method =
      f.method == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  auto& sk = options.skeleton;
  if (!f.fit.empty()) sk.fit = *runtime::SkeletonFitFromName(f.fit);
  options.votes = !f.no_votes;
  sk.use_tracking_model = !f.no_tracking_model;
  sk.use_seen_model = !f.no_seen_model;
  if (f.min_confidence) sk.min_confidence = float(*f.min_confidence);
  if (f.min_support) sk.min_support_m2 = float(*f.min_support);
  if (f.track_probability) sk.track_probability = float(*f.track_probability);
  if (f.seen_probability) sk.seen_probability = float(*f.seen_probability);
  if (f.max_match) sk.max_match_distance_m = float(*f.max_match);
  sk.smooth = f.smooth;
  if (f.smooth_min_cutoff) sk.min_cutoff_hz = *f.smooth_min_cutoff;
  if (f.smooth_beta) sk.beta = *f.smooth_beta;
  if (f.smooth_d_cutoff) sk.d_cutoff_hz = *f.smooth_d_cutoff;
  if (!sk.smooth && (f.smooth_min_cutoff || f.smooth_beta || f.smooth_d_cutoff))
    return UsageError("--smooth-min-cutoff / --smooth-beta / --smooth-d-cutoff need --smooth");
  options.pixel_stride = f.pixel_stride;
  out->max_frames = f.max_frames.value_or(-1);
  options.num_threads = f.threads;
  out->quiet = f.quiet, out->loop = f.loop;
  return std::nullopt;
}

// Where the skeletons go.
struct LiveOutputs {
  FILE* jsonl = nullptr;  // --jsonl: stdout or jsonl_file
  std::unique_ptr<FILE, int (*)(FILE*)> jsonl_file{nullptr, &std::fclose};
  std::optional<std::string> png_dir;
#ifdef POSEFOREST_HAS_HTTPLIB
  live::LivePage page;
#endif
#ifdef POSEFOREST_HAS_SKELETON_DDS
  std::unique_ptr<ros2::SkeletonPublisher> dds;
#endif
};

// --jsonl and --png-dir; on failure, the exit code (the message printed).
std::optional<int> OpenFileOutputs(const LiveFlags& f, LiveOutputs* out) {
  if (const auto& j = f.jsonl) {
    if (*j == "-") {
      out->jsonl = stdout;
    } else {
      out->jsonl_file.reset(std::fopen(j->c_str(), "w"));
      if (!out->jsonl_file) {
        std::fprintf(stderr, "poseforest live: %s: cannot write: %s\n", j->c_str(), std::strerror(errno));
        return 1;
      }
      out->jsonl = out->jsonl_file.get();
    }
  }
  out->png_dir = f.png_dir;
  if (out->png_dir) {
    std::error_code ec;
    fs::create_directories(*out->png_dir, ec);
    if (ec) {
      std::fprintf(stderr, "poseforest live: %s: cannot create folder: %s\n", out->png_dir->c_str(),
                   ec.message().c_str());
      return 1;
    }
  }
  return std::nullopt;
}

// --http: the live page; on failure, the exit code (the message printed).
std::optional<int> StartLivePage(const LiveFlags& f, LiveOutputs* out) {
#ifdef POSEFOREST_HAS_HTTPLIB
  if (const auto& addr = f.http) {
    const auto address = live::ParseAddress(*addr);
    if (!address) return UsageError("--http must be HOST:PORT or PORT (got '" + *addr + "')");
    const int bound = out->page.Start(*address);
    if (bound < 0) {
      std::fprintf(stderr, "poseforest live: --http %s: cannot listen there\n", addr->c_str());
      return 1;
    }
    std::fprintf(stderr, "poseforest live: the live page is at http://%s:%d/\n", address->host.c_str(),
                 bound);
  }
#else
  (void)out;
  if (f.http)
    return UsageError(
        "--http: this program was built without cpp-httplib (Debian libcpp-httplib-dev, found at configure "
        "time)");
#endif
  return std::nullopt;
}

// --dds: the ROS 2 topics; on failure, the exit code (the message printed).
std::optional<int> StartDds(const LiveFlags& f, LiveOutputs* out) {
#ifdef POSEFOREST_HAS_SKELETON_DDS
  if (f.dds) {
    ros2::DdsOptions o;
    o.domain = f.dds_domain.value_or(0);
    if (f.dds_topic) o.topic_prefix = *f.dds_topic;
    if (f.dds_frame_id) o.frame_id = *f.dds_frame_id;
    auto p = ros2::SkeletonPublisher::Create(o);
    if (!p.ok()) {
      std::fprintf(stderr, "poseforest live: %s\n", p.status().ToString().c_str());
      return p.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
    }
    out->dds = std::move(*p);
    std::fprintf(stderr, "poseforest live: publishing on %s\n", out->dds->Describe().c_str());
    if (const int wait = f.dds_wait.value_or(0); wait > 0 && !out->dds->WaitForSubscribers(wait, 10.0))
      std::fprintf(stderr, "poseforest live: DDS: fewer than %d subscribers after 10 s; publishing anyway\n",
                   wait);
  }
#else
  (void)f, (void)out;
#endif
  return std::nullopt;
}

// SIGINT / SIGTERM set g_stop; the loop stops after the current frame.
void InstallStopHandlers() {
  struct sigaction sa {};
  sa.sa_handler = OnStopSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: a read blocked on stdin or a device returns
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

// What the loop counted, for the summary.
struct LiveStats {
  std::vector<double> latencies;
  runtime::StageTimes stage_sum;
  double output_ms_sum = 0;
  int64_t frames = 0, bad = 0, write_errors = 0, people_frames = 0;
  int64_t jsonl_errors = 0;  ///< of write_errors, the JSON Lines output's
  int loops = 0;
  bool stopped_by_signal = false;
};

// One frame's skeletons to every output; the errors counted in `stats`.
void WriteFrame(const runtime::Frame& frame, const runtime::SkeletonFrame& result, const std::string& line,
                LiveOutputs* out, LiveStats* stats) {
  if (out->jsonl) {
    const bool ok = std::fputs(line.c_str(), out->jsonl) >= 0 && std::fputc('\n', out->jsonl) != EOF &&
                    std::fflush(out->jsonl) == 0;
    if (!ok) {
      // A full disk, a closed pipe: said once (the summary counts every frame it cost).
      if (stats->jsonl_errors++ == 0)
        std::fprintf(stderr, "poseforest live: --jsonl: a write failed at frame %lld: %s\n",
                     static_cast<long long>(frame.index), std::strerror(errno));
      ++stats->write_errors;
      std::clearerr(out->jsonl);
    }
  }
#ifdef POSEFOREST_HAS_SKELETON_DDS
  if (out->dds && !out->dds->Publish(frame.index, frame.timestamp_s, frame.source, result.skeletons)) {
    std::fprintf(stderr, "poseforest live: DDS: a write failed at frame %lld\n",
                 static_cast<long long>(frame.index));
    ++stats->write_errors;
  }
#else
  (void)frame, (void)result, (void)stats;
#endif
}

// The picture (--png-dir, and the live page while a page is open) and the page's record.
void WritePictures(const runtime::Frame& frame, const runtime::SkeletonFrame& result, const std::string& line,
                   LiveOutputs* out, LiveStats* stats) {
  // The picture is made for --png-dir and while a page is open (its event stream connected):
  // encoding it costs about as much as classifying.
  bool page_open = false;
#ifdef POSEFOREST_HAS_HTTPLIB
  page_open = out->page.page_open();
#endif
  runtime::RgbImage fig;
  if (out->png_dir || page_open)
    fig = runtime::SkeletonFigure(*result.depth, result.classification.labels, result.skeletons, 1);
  if (out->png_dir) {
    char name[40];
    std::snprintf(name, sizeof name, "frame-%06lld.png", static_cast<long long>(frame.index));
    const auto st =
        runtime::WriteRgbPng((fs::path(*out->png_dir) / name).string(), fig.width, fig.height, fig.rgb);
    if (!st.ok()) std::fprintf(stderr, "poseforest live: %s\n", st.ToString().c_str()), ++stats->write_errors;
  }
#ifdef POSEFOREST_HAS_HTTPLIB
  if (out->page.running()) {
    std::optional<std::vector<uint8_t>> png;
    if (page_open) png = runtime::EncodePng8(fig.width, fig.height, 3, fig.rgb);
    out->page.Publish(line, std::move(png));
  }
#else
  (void)line;
#endif
}

// Frames from `source` through `pipeline` to the outputs until the source ends, --max-frames,
// too many bad frames in a row, or a signal.
LiveStats RunLoop(const LiveOptions& o, runtime::SkeletonPipeline* pipeline,
                  std::unique_ptr<runtime::FrameSource>* source, LiveOutputs* out) {
  LiveStats stats;
  const bool tty = isatty(STDERR_FILENO);
  runtime::Frame frame;
  runtime::SkeletonFrame result;
  int bad_in_a_row = 0;
  int64_t frames_at_replay = 0;
  std::string rescale_said;
  auto last_progress = std::chrono::steady_clock::now();
  int64_t frames_at_progress = 0;
  while (o.max_frames < 0 || stats.frames < o.max_frames) {
    if (g_stop.load()) {
      stats.stopped_by_signal = true;
      break;
    }
    auto next = (*source)->Next(&frame);
    if (g_stop.load()) {
      stats.stopped_by_signal = true;
      break;
    }
    if (!next.ok()) {
      std::fprintf(stderr, "%sposeforest live: %s\n", tty && !o.quiet ? "\n" : "",
                   next.status().ToString().c_str());
      ++stats.bad;
      if (++bad_in_a_row >= runtime::kMaxConsecutiveBadFrames) {
        std::fprintf(stderr, "poseforest live: %s: giving up after %d bad frames in a row\n",
                     (*source)->Describe().c_str(), bad_in_a_row);
        break;
      }
      continue;
    }
    bad_in_a_row = 0;
    if (!*next) {
      // A replay that gave nothing (stdin at its end, a device gone) ends the loop.
      if (!o.loop || stats.frames == frames_at_replay) break;
      frames_at_replay = stats.frames;
      auto again = runtime::OpenFrameSources(o.specs, o.source);
      if (!again.ok()) {
        std::fprintf(stderr, "poseforest live: %s\n", again.status().ToString().c_str());
        break;
      }
      *source = std::move(*again);
      ++stats.loops;
      continue;
    }
    const auto t_in = std::chrono::steady_clock::now();
    // With --loop, frame indices and times keep counting over the replays.
    frame.index = stats.frames;
    pipeline->Process(frame, &result);
    if (!pipeline->rescale_note().empty() && rescale_said != pipeline->rescale_note()) {
      rescale_said = pipeline->rescale_note();
      std::fprintf(stderr, "poseforest live: camera %s: %s\n", frame.camera.Describe().c_str(),
                   rescale_said.c_str());
    }
    const auto t_out = std::chrono::steady_clock::now();
    const std::string line =
        runtime::SkeletonsJsonLine(frame.index, frame.timestamp_s, frame.source, result.skeletons);
    WriteFrame(frame, result, line, out, &stats);
    const double latency_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_in).count();
    WritePictures(frame, result, line, out, &stats);
    stats.output_ms_sum +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_out).count();
    ++stats.frames;
    stats.latencies.push_back(latency_ms);
    stats.stage_sum.segment_ms += result.times.segment_ms;
    stats.stage_sum.classify_ms += result.times.classify_ms;
    stats.stage_sum.proposals_ms += result.times.proposals_ms;
    stats.stage_sum.skeletons_ms += result.times.skeletons_ms;
    stats.stage_sum.votes_ms += result.times.votes_ms;
    stats.people_frames += int64_t(result.skeletons.size());

    const auto now = std::chrono::steady_clock::now();
    const double since = std::chrono::duration<double>(now - last_progress).count();
    if (!o.quiet && since >= (tty ? 0.25 : 5.0)) {
      const double fps = double(stats.frames - frames_at_progress) / since;
      int tracked = 0;
      for (const auto& s : result.skeletons) tracked += s.tracked_joints();
      std::fprintf(stderr, "%sframe %lld: %.1f frames/s, latency %.1f ms, %zu people (%d joints tracked)%s",
                   tty ? "\r" : "", static_cast<long long>(frame.index), fps, latency_ms,
                   result.skeletons.size(), tracked, tty ? "   " : "\n");
      last_progress = now;
      frames_at_progress = stats.frames;
    }
  }
  return stats;
}

// The summary on stderr: frames, rate, latency and stage times, people.
void PrintSummary(const LiveStats& stats, double seconds, const runtime::SkeletonPipeline& pipeline) {
  std::fprintf(
      stderr, "poseforest live: %s: %lld frames in %.2f s (%.1f frames/s%s), %lld bad frames skipped%s\n",
      stats.stopped_by_signal ? "stopped by signal" : "end of source", static_cast<long long>(stats.frames),
      seconds, seconds > 0 ? double(stats.frames) / seconds : 0.0,
      stats.loops ? (", " + std::to_string(stats.loops) + " replays").c_str() : "",
      static_cast<long long>(stats.bad),
      stats.write_errors ? (", " + std::to_string(stats.write_errors) + " write errors").c_str() : "");
  if (stats.frames > 0) {
    const double n = double(stats.frames);
    const runtime::StageTimes& stage_sum = stats.stage_sum;
    std::fprintf(
        stderr,
        "poseforest live: latency p50 %.2f ms, p99 %.2f ms (frame in to JSON line out and "
        "published); per frame: segment "
        "%.2f ms, classify %.2f ms, proposals %.2f ms, votes %.2f ms, skeletons %.2f ms, pictures/page "
        "%.2f ms\n",
        Percentile(stats.latencies, 0.5), Percentile(stats.latencies, 0.99), stage_sum.segment_ms / n,
        stage_sum.classify_ms / n, stage_sum.proposals_ms / n, stage_sum.votes_ms / n,
        stage_sum.skeletons_ms / n, stats.output_ms_sum / n);
    std::fprintf(stderr, "poseforest live: %d people seen (ids 1..%d), %.2f people per frame\n",
                 pipeline.tracker().people_seen(), pipeline.tracker().people_seen(),
                 double(stats.people_frames) / n);
  }
}

class LiveCommand final : public Command {
 public:
  LiveCommand()
      : Command("live",
                "Per-person skeletons from depth frames, as they come: people segmentation, body parts (the\n"
                "forest), joint proposals (section 3.4 of Shotton et al.), then per person one position per\n"
                "joint with a confidence in 0..1, a tracked / not-tracked state and an id that stays with the\n"
                "person over the sequence. Progress (frames/s, latency, people) goes to stderr on one line;\n"
                "SIGINT / SIGTERM (Ctrl-C) stop cleanly after the current frame with a summary.\n"
                "The confidence is the forest's calibration (`tune-joints`: the precision proposals of that\n"
                "support had on validation renders); forests without one get a documented fallback (the\n"
                "summary says which).") {
    DeclareLiveOptions(app_, &f_);
  }
  int Run() override;

 private:
  LiveFlags f_;
};

int LiveCommand::Run() {
  LiveOptions o;
  if (auto failed = ParseLiveOptions(f_, &o)) return *failed;
  LiveOutputs out;
  if (auto failed = OpenFileOutputs(f_, &out)) return *failed;

  auto forest = core::LoadForest(o.forest_path);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest live: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  auto pipeline = runtime::SkeletonPipeline::Create(*forest, o.pipeline);
  if (!pipeline.ok()) {
    std::fprintf(stderr, "poseforest live: %s: %s\n", o.forest_path.c_str(),
                 pipeline.status().message().c_str());
    return 1;
  }
  auto source = runtime::OpenFrameSources(o.specs, o.source);
  if (!source.ok()) {
    std::fprintf(stderr, "poseforest live: %s\n", source.status().ToString().c_str());
    return 1;
  }
  if (auto failed = StartLivePage(f_, &out)) return *failed;
  if (auto failed = StartDds(f_, &out)) return *failed;
  InstallStopHandlers();

  const bool tty = isatty(STDERR_FILENO);
  std::fprintf(stderr, "poseforest live: %s on %s; confidence: %s; proposal parameters: %s\n",
               o.forest_path.c_str(), (*source)->Describe().c_str(),
               runtime::DescribeConfidence((*pipeline)->calibration()).c_str(),
               core::DescribeProposalParamsSource((*pipeline)->params_source()));
  {
    const auto& model = forest->tracking_model;
    const bool learned = model && o.pipeline.skeleton.use_tracking_model;
    std::fprintf(stderr, "poseforest live: skeleton fit %s (%s); tracked: %s\n",
                 std::string(runtime::SkeletonFitName(
                                 runtime::ResolveSkeletonFit(o.pipeline.skeleton, learned ? &*model : nullptr)))
                     .c_str(),
                 o.pipeline.skeleton.fit ? "--fit"
                 : learned               ? "the one the forest's tracking decision was learned on"
                                         : "the default",
                 !learned                                          ? "the hand-set rules"
                 : model->seen && o.pipeline.skeleton.use_seen_model ? "the forest's learned decision, when likely seen"
                                                                     : "the forest's learned decision");
  }
  if (o.pipeline.pixel_stride > 1)
    std::fprintf(stderr,
                 "poseforest live: pixel stride %d: one pixel in %dx%d classified (--pixel-stride 1: all)\n",
                 o.pipeline.pixel_stride, o.pipeline.pixel_stride, o.pipeline.pixel_stride);

  const auto start = std::chrono::steady_clock::now();
  const LiveStats stats = RunLoop(o, (*pipeline).get(), &*source, &out);
#ifdef POSEFOREST_HAS_HTTPLIB
  out.page.Stop();
#endif
#ifdef POSEFOREST_HAS_SKELETON_DDS
  // Let matched subscribers receive what was published before the writers go away.
  if (out.dds && !out.dds->Flush(3.0))
    std::fprintf(stderr, "poseforest live: DDS: not every subscriber acknowledged within 3 s\n");
  out.dds.reset();
#endif
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (tty && !o.quiet) std::fputc('\n', stderr);
  PrintSummary(stats, seconds, **pipeline);
  return stats.bad == 0 && stats.write_errors == 0 ? 0 : 1;
}

}  // namespace

std::unique_ptr<Command> MakeLiveCommand() { return std::make_unique<LiveCommand>(); }

}  // namespace poseforest::apps::commands
