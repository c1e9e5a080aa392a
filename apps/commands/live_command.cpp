// poseforest live: depth frames in, per-person skeletons out - JSON Lines, pictures with bones,
// a live page in the browser (apps/live/, cpp-httplib, when found at configure time) and, in builds
// with Fast DDS, ROS 2-readable topics (apps/ros2/).
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "apps/commands/args.h"
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

constexpr const char* kUsage = R"(usage: poseforest live --forest FOREST.pff --source SOURCE [options]

Per-person skeletons from depth frames, as they come: people segmentation, body parts (the
forest), joint proposals (section 3.4 of Shotton et al.), then per person one position per joint
with a confidence in 0..1, a tracked / not-tracked state and an id that stays with the person
over the sequence. Outputs (any together; docs/runtime/live.md has the schema):
  --jsonl FILE|-       JSON Lines, one object per frame (- = stdout)
  --png-dir DIR        DIR/frame-NNNNNN.png per frame: depth | parts | skeletons (bones drawn)
  --http ADDR          a live page at http://ADDR/ (HOST:PORT, or PORT for 127.0.0.1): depth | parts
                       | skeletons at the camera's rate (server-sent events: /events, one JSON Lines
                       record per frame); /skeletons.json (the latest), /frame.png (the
                       latest picture, made while a page is open)
  --dds                ROS 2-readable DDS topics (Fast DDS, rmw_fastrtps naming; builds with Fast DDS):
                       rt/PREFIX/skeletons (poseforest_msgs/msg/Skeletons, msg/*.msg in the source)
                       and rt/PREFIX/markers (visualization_msgs/msg/MarkerArray: joints and bones
                       per person, for RViz); reliable, transient-local, keep-last 100
  --dds-domain N       DDS domain (ROS_DOMAIN_ID; default 0)
  --dds-topic PREFIX   ROS topics /PREFIX/skeletons and /PREFIX/markers (default poseforest)
  --dds-frame-id ID    header.frame_id (default camera_depth_optical_frame)
  --dds-wait N         before the first frame, wait up to 10 s for N subscribers (default 0)
Progress (frames/s, latency, people) goes to stderr on one line; SIGINT / SIGTERM (Ctrl-C) stop
cleanly after the current frame with a summary.

SOURCE (also positional; the sources of `poseforest frames`, docs/runtime/frames.md):
  FILE | FOLDER | 'PATTERN' | - (raw frames on stdin) | freenect:N | openni2:[URI]
camera: --camera PRESET, --fx F --fy F --cx C --cy C, --depth-scale S, --raw-size WxH,
        --fps N (deliver at most N frames/s: a folder played at the camera's rate)
segmentation: --segment auto|on|off, --floor A,B,C,D, --near M, --far M (as `infer`)

skeletons:
  --method M           joint proposals: meanshift (default) or fast
  --pixel-stride N     classify and propose from every N-th pixel in x and y only (default 2:
                       one pixel in 2x2, as Kinect's tracker ran at 320x240; 2.1x the frames/s
                       of 1 for 0.003 mAP: docs/runtime/live.md; 1: every pixel)
  --fit F              greedy (default): each joint's most confident proposal on the person;
                       kinematic: one fit per person choosing among each joint's proposals with
                       bone lengths (runtime/skeleton.h)
  --no-votes           ignore the forest's offset votes (format 1.5, `learn-votes`); by default
                       a forest with votes gives every joint vote candidates too
  --no-tracking-model  the hand-set tracking rules (--min-confidence, --min-support, the image
                       border, bone lengths, a tracked parent) instead of the forest's learned
                       tracking decision (format 1.6, `learn-votes`), which tracks a joint when
                       its P(within 0.1 m) >= --track-probability (default 0.5)
  --min-confidence C   without a tracking model: tracked only with a confidence >= C (default 0.3)
  --min-support S      ... and a proposal support >= S m^2 (default 0.0001)
  --max-match M        a person moving more than M metres between frames gets a new id (0.5)
  --smooth             One Euro filter on tracked joints (Casiez et al. 2012), with
  --smooth-min-cutoff HZ (default 1), --smooth-beta B (0.5), --smooth-d-cutoff HZ (1)
  The confidence is the forest's calibration (`tune-joints`: the precision proposals of that
  support had on validation renders); forests without one get a documented fallback (the
  summary says which).

options:
  --forest FILE        forest file (.pff), required
  --loop               replay a finite source forever (until SIGINT / SIGTERM or --max-frames)
  --max-frames N       stop after N frames
  --threads N          OpenMP threads (default: all cores)
  --quiet              no progress line (the summary still goes to stderr)
  --help               this text
)";

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
std::optional<int> ParseLiveOptions(const Args& args, LiveOptions* out) {
  out->specs = args.positional();
  if (auto src = args.Get("source")) out->specs.insert(out->specs.begin(), *src);
#ifndef POSEFOREST_HAS_SKELETON_DDS
  for (const char* o : {"dds", "dds-domain", "dds-topic", "dds-frame-id", "dds-wait"})
    if (args.Has(o))
      return UsageError(
          std::string("--") + o +
          ": this program was built without Fast DDS (the DDS output is built with the training side, "
          "-DPOSEFOREST_TRAINING=ON)");
#endif
  if (!args.Has("dds"))
    for (const char* o : {"dds-domain", "dds-topic", "dds-frame-id", "dds-wait"})
      if (args.Has(o)) return UsageError(std::string("--") + o + " needs --dds");
  const auto forest_path = args.Get("forest");
  if (!forest_path) return UsageError("--forest is required (see --help)");
  out->forest_path = *forest_path;
  if (out->specs.empty()) return UsageError("no source given: --source SOURCE (see --help)");

  if (auto st = ParseFrameSourceOptions(args, &out->source); !st.ok()) return UsageError(st.message());
  runtime::SkeletonPipelineOptions& options = out->pipeline;
  const std::string segment = args.GetOr("segment", "auto");
  if (segment == "auto")
    options.segment = runtime::SegmentMode::kAuto;
  else if (segment == "on")
    options.segment = runtime::SegmentMode::kOn;
  else if (segment == "off")
    options.segment = runtime::SegmentMode::kOff;
  else
    return UsageError("--segment must be auto, on or off (got '" + segment + "')");
  if (auto fl = args.Get("floor")) {
    double a, b, c, d;
    if (std::sscanf(fl->c_str(), "%lf,%lf,%lf,%lf", &a, &b, &c, &d) != 4 || std::hypot(a, b, c) < 1e-9)
      return UsageError("--floor must be A,B,C,D with (A,B,C) != 0 (got '" + *fl + "')");
    const double n = std::hypot(a, b, c);
    options.segmentation.floor_plane = Eigen::Vector4d(a / n, b / n, c / n, d / n);
  }
  {
    auto near = GetDouble(args, "near", options.segmentation.near_m, 0.0, 60.0);
    auto far = GetDouble(args, "far", options.segmentation.far_m, 0.0, 65.0);
    if (!near.ok()) return UsageError(near.status().message());
    if (!far.ok()) return UsageError(far.status().message());
    if (*near >= *far) return UsageError("--near must be less than --far");
    options.segmentation.near_m = *near, options.segmentation.far_m = *far;
  }
  const std::string method = args.GetOr("method", "meanshift");
  if (method != "meanshift" && method != "fast")
    return UsageError("--method must be meanshift or fast (got '" + method + "')");
  options.method =
      method == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  auto& sk = options.skeleton;
  {
    const std::string fit = args.GetOr("fit", "greedy");
    const auto parsed = runtime::SkeletonFitFromName(fit);
    if (!parsed) return UsageError("--fit must be kinematic or greedy (got '" + fit + "')");
    sk.fit = *parsed;
  }
  options.votes = !args.Has("no-votes");
  sk.use_tracking_model = !args.Has("no-tracking-model");
  {
    auto min_conf = GetDouble(args, "min-confidence", sk.min_confidence, 0.0, 1.0);
    auto track_p = GetDouble(args, "track-probability", sk.track_probability, 0.0, 1.0);
    auto min_support = GetDouble(args, "min-support", sk.min_support_m2, 0.0, 10.0);
    auto max_match = GetDouble(args, "max-match", sk.max_match_distance_m, 0.0, 100.0);
    auto min_cutoff = GetDouble(args, "smooth-min-cutoff", sk.min_cutoff_hz, 1e-6, 1000.0);
    auto beta = GetDouble(args, "smooth-beta", sk.beta, 0.0, 1000.0);
    auto d_cutoff = GetDouble(args, "smooth-d-cutoff", sk.d_cutoff_hz, 1e-6, 1000.0);
    for (const auto* r : {&min_conf, &track_p, &min_support, &max_match, &min_cutoff, &beta, &d_cutoff})
      if (!r->ok()) return UsageError(r->status().message());
    sk.min_confidence = float(*min_conf), sk.min_support_m2 = float(*min_support);
    sk.track_probability = float(*track_p);
    sk.max_match_distance_m = float(*max_match);
    sk.smooth = args.Has("smooth");
    sk.min_cutoff_hz = *min_cutoff, sk.beta = *beta, sk.d_cutoff_hz = *d_cutoff;
    if (!sk.smooth &&
        (args.Has("smooth-min-cutoff") || args.Has("smooth-beta") || args.Has("smooth-d-cutoff")))
      return UsageError("--smooth-min-cutoff / --smooth-beta / --smooth-d-cutoff need --smooth");
  }
  auto threads = args.GetInt("threads", 0, 0, 1024);
  auto max_frames = args.GetInt("max-frames", -1, 1, 1L << 40);
  // Default 2 for live video (docs/runtime/live.md, "Pixel stride"): bench/live's goals
  // (>= 200 frames/s, p99 <= 10 ms on 2 cores) are met there, not at 1 (about 105 frames/s).
  auto pixel_stride = args.GetInt("pixel-stride", 2, 1, 16);
  if (!threads.ok()) return UsageError(threads.status().message());
  if (!pixel_stride.ok()) return UsageError(pixel_stride.status().message());
  options.pixel_stride = int(*pixel_stride);
  if (!max_frames.ok()) return UsageError(max_frames.status().message());
  out->max_frames = *max_frames;
  options.num_threads = int(*threads);
  out->quiet = args.Has("quiet"), out->loop = args.Has("loop");
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
std::optional<int> OpenFileOutputs(const Args& args, LiveOutputs* out) {
  if (auto j = args.Get("jsonl")) {
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
  out->png_dir = args.Get("png-dir");
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
std::optional<int> StartLivePage(const Args& args, LiveOutputs* out) {
#ifdef POSEFOREST_HAS_HTTPLIB
  if (auto addr = args.Get("http")) {
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
  if (args.Has("http"))
    return UsageError(
        "--http: this program was built without cpp-httplib (Debian libcpp-httplib-dev, found at configure "
        "time)");
#endif
  return std::nullopt;
}

// --dds: the ROS 2 topics; on failure, the exit code (the message printed).
std::optional<int> StartDds(const Args& args, LiveOutputs* out) {
#ifdef POSEFOREST_HAS_SKELETON_DDS
  if (args.Has("dds")) {
    ros2::DdsOptions o;
    auto domain = args.GetInt("dds-domain", 0, 0, 232);
    auto wait = args.GetInt("dds-wait", 0, 0, 1000);
    if (!domain.ok()) return UsageError(domain.status().message());
    if (!wait.ok()) return UsageError(wait.status().message());
    o.domain = int(*domain);
    o.topic_prefix = args.GetOr("dds-topic", o.topic_prefix);
    o.frame_id = args.GetOr("dds-frame-id", o.frame_id);
    auto p = ros2::SkeletonPublisher::Create(o);
    if (!p.ok()) {
      std::fprintf(stderr, "poseforest live: %s\n", p.status().ToString().c_str());
      return p.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
    }
    out->dds = std::move(*p);
    std::fprintf(stderr, "poseforest live: publishing on %s\n", out->dds->Describe().c_str());
    if (*wait > 0 && !out->dds->WaitForSubscribers(int(*wait), 10.0))
      std::fprintf(stderr, "poseforest live: DDS: fewer than %ld subscribers after 10 s; publishing anyway\n",
                   *wait);
  }
#else
  (void)args, (void)out;
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
  int loops = 0;
  bool stopped_by_signal = false;
};

// One frame's skeletons to every output; the errors counted in `stats`.
void WriteFrame(const runtime::Frame& frame, const runtime::SkeletonFrame& result, const std::string& line,
                LiveOutputs* out, LiveStats* stats) {
  if (out->jsonl) {
    std::fputs(line.c_str(), out->jsonl);
    std::fputc('\n', out->jsonl);
    std::fflush(out->jsonl);
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

}  // namespace

int LiveMain(int argc, char** argv) {
  std::set<std::string> value_options = {"forest",         "source",
                                         "jsonl",          "png-dir",
                                         "http",           "method",
                                         "min-confidence", "track-probability", "min-support",
                                         "max-match",      "smooth-min-cutoff",
                                         "smooth-beta",    "smooth-d-cutoff",
                                         "max-frames",     "threads",
                                         "segment",        "floor",
                                         "near",           "far",
                                         "dds-domain",     "dds-topic",
                                         "dds-frame-id",   "dds-wait",
                                         "pixel-stride",   "fit"};
  for (const char* o : kFrameSourceValueOptions) value_options.insert(o);
  Args args(value_options, {"help", "quiet", "smooth", "loop", "dds", "no-votes", "no-tracking-model"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest live: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  LiveOptions o;
  if (auto failed = ParseLiveOptions(args, &o)) return *failed;
  LiveOutputs out;
  if (auto failed = OpenFileOutputs(args, &out)) return *failed;

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
  if (auto failed = StartLivePage(args, &out)) return *failed;
  if (auto failed = StartDds(args, &out)) return *failed;
  InstallStopHandlers();

  const bool tty = isatty(STDERR_FILENO);
  std::fprintf(stderr, "poseforest live: %s on %s; confidence: %s; proposal parameters: %s\n",
               o.forest_path.c_str(), (*source)->Describe().c_str(),
               runtime::DescribeConfidence((*pipeline)->calibration()).c_str(),
               core::DescribeProposalParamsSource((*pipeline)->params_source()));
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

}  // namespace poseforest::apps::commands
