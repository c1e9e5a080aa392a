// poseforest live: depth frames in, per-person skeletons out - JSON Lines, pictures with bones,
// a live page in the browser (cpp-httplib, when found at configure time) and, in builds with
// Fast DDS, ROS 2-readable topics.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "runtime/cli/args.h"
#include "runtime/cli/commands.h"
#include "runtime/cli/frame_options.h"
#include "runtime/core/forest_format.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "runtime/skeleton_pipeline.h"
#include "runtime/visualize.h"
#ifdef POSEFOREST_HAS_SKELETON_DDS
#include "runtime/dds/skeleton_publisher.h"
#endif

// After Eigen: httplib.h pulls in <resolv.h>, whose `_res` macro breaks Eigen's headers.
#ifdef POSEFOREST_HAS_HTTPLIB
#include <httplib.h>
#endif

namespace poseforest::cli {
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

#ifdef POSEFOREST_HAS_HTTPLIB
// The live page: a picture refreshed on every frame event, and the people of the frame.
constexpr const char* kPage = R"(<!doctype html>
<html><head><meta charset="utf-8"><title>poseforest live</title>
<style>body{background:#111;color:#ddd;font-family:sans-serif;margin:12px}
img{width:100%;max-width:1920px;image-rendering:pixelated}td{padding:0 8px}</style></head>
<body><h3>poseforest live: depth | parts | skeletons</h3>
<img id="view" alt="waiting for the first frame">
<p>frame <span id="frame">-</span>, <span id="count">0</span> people, <span id="fps">-</span> frames/s</p>
<table id="people"></table>
<script>
const es = new EventSource('/events' + location.search);  // ?frames=N: the stream ends after N
let last = 0, n = 0, t0 = performance.now();
es.onmessage = (e) => {
  const f = JSON.parse(e.data);
  document.getElementById('frame').textContent = f.index;
  document.getElementById('count').textContent = f.people.length;
  document.getElementById('view').src = '/frame.png?index=' + f.index;
  n++;
  const dt = (performance.now() - t0) / 1000;
  if (dt > 0) document.getElementById('fps').textContent = (n / dt).toFixed(1);
  const rows = f.people.map(p => {
    const tracked = p.joints.filter(j => j.tracked), inferred = p.joints.filter(j => j.state === 'inferred');
    return '<tr class="person" data-id="' + p.id + '"><td>id ' + p.id + '</td><td>' + tracked.length +
        ' joints tracked' + (inferred.length ? ', ' + inferred.length + ' inferred' : '') + '</td><td>' +
        tracked.map(j => j.name).join(' ') +
        (inferred.length ? ' (inferred: ' + inferred.map(j => j.name).join(' ') + ')' : '') + '</td></tr>';
  });
  document.getElementById('people').innerHTML = rows.join('');
};
</script></body></html>
)";

// The latest frame for the page: its JSON record and its picture, and a sequence number the
// event streams wait on.
struct LiveState {
  std::mutex mu;
  std::condition_variable cv;
  uint64_t seq = 0;
  std::string json;
  std::vector<uint8_t> png;
  std::atomic<int> clients{0};
  bool closing = false;
};
#endif

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
  std::vector<std::string> specs = args.positional();
  if (auto src = args.Get("source")) specs.insert(specs.begin(), *src);
#ifndef POSEFOREST_HAS_SKELETON_DDS
  for (const char* o : {"dds", "dds-domain", "dds-topic", "dds-frame-id", "dds-wait"})
    if (args.Has(o))
      return UsageError(std::string("--") + o +
                        ": this program was built without Fast DDS (the DDS output is built with the training side, "
                        "-DPOSEFOREST_TRAINING=ON)");
#endif
  if (!args.Has("dds"))
    for (const char* o : {"dds-domain", "dds-topic", "dds-frame-id", "dds-wait"})
      if (args.Has(o)) return UsageError(std::string("--") + o + " needs --dds");
  const auto forest_path = args.Get("forest");
  if (!forest_path) return UsageError("--forest is required (see --help)");
  if (specs.empty()) return UsageError("no source given: --source SOURCE (see --help)");

  runtime::FrameSourceOptions source_options;
  if (auto st = ParseFrameSourceOptions(args, &source_options); !st.ok()) return UsageError(st.message());
  runtime::SkeletonPipelineOptions options;
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
  options.num_threads = int(*threads);
  const bool quiet = args.Has("quiet"), loop = args.Has("loop");

  // Outputs.
  FILE* jsonl = nullptr;
  std::unique_ptr<FILE, int (*)(FILE*)> jsonl_file(nullptr, &std::fclose);
  if (auto j = args.Get("jsonl")) {
    if (*j == "-") {
      jsonl = stdout;
    } else {
      jsonl_file.reset(std::fopen(j->c_str(), "w"));
      if (!jsonl_file) {
        std::fprintf(stderr, "poseforest live: %s: cannot write: %s\n", j->c_str(), std::strerror(errno));
        return 1;
      }
      jsonl = jsonl_file.get();
    }
  }
  const auto png_dir = args.Get("png-dir");
  if (png_dir) {
    std::error_code ec;
    fs::create_directories(*png_dir, ec);
    if (ec) {
      std::fprintf(stderr, "poseforest live: %s: cannot create folder: %s\n", png_dir->c_str(),
                   ec.message().c_str());
      return 1;
    }
  }

  auto forest = core::LoadForest(*forest_path);
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest live: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  auto pipeline = runtime::SkeletonPipeline::Create(*forest, options);
  if (!pipeline.ok()) {
    std::fprintf(stderr, "poseforest live: %s: %s\n", forest_path->c_str(),
                 pipeline.status().message().c_str());
    return 1;
  }
  auto source = runtime::OpenFrameSources(specs, source_options);
  if (!source.ok()) {
    std::fprintf(stderr, "poseforest live: %s\n", source.status().ToString().c_str());
    return 1;
  }

#ifdef POSEFOREST_HAS_HTTPLIB
  LiveState live;
  httplib::Server server;
  std::thread server_thread;
  if (auto addr = args.Get("http")) {
    std::string host = "127.0.0.1", port_text = *addr;
    if (const auto colon = addr->rfind(':'); colon != std::string::npos)
      host = addr->substr(0, colon), port_text = addr->substr(colon + 1);
    char* end = nullptr;
    const long port = std::strtol(port_text.c_str(), &end, 10);
    if (port_text.empty() || *end != '\0' || port < 0 || port > 65535)
      return UsageError("--http must be HOST:PORT or PORT (got '" + *addr + "')");
    server.Get("/",
               [](const httplib::Request&, httplib::Response& res) { res.set_content(kPage, "text/html"); });
    server.Get("/skeletons.json", [&live](const httplib::Request&, httplib::Response& res) {
      std::lock_guard lock(live.mu);
      res.set_content(live.json.empty() ? std::string("null") : live.json, "application/json");
    });
    server.Get("/frame.png", [&live](const httplib::Request&, httplib::Response& res) {
      std::lock_guard lock(live.mu);
      if (live.png.empty()) {
        res.status = 404;
        return;
      }
      res.set_content(reinterpret_cast<const char*>(live.png.data()), live.png.size(), "image/png");
      res.set_header("Cache-Control", "no-store");
    });
    // Server-sent events: one "data:" line per frame, the frame's JSON Lines record.
    server.Get("/events", [&live](const httplib::Request& req, httplib::Response& res) {
      res.set_header("Cache-Control", "no-store");
      auto last = std::make_shared<uint64_t>(0);
      // ?frames=N ends the stream after N frames (scripts, and the browser test: a page whose
      // stream has ended lets headless Chromium's virtual time run out and dump it).
      auto left = std::make_shared<long>(
          req.has_param("frames") ? std::atol(req.get_param_value("frames").c_str()) : -1);
      ++live.clients;
      res.set_chunked_content_provider(
          "text/event-stream",
          [&live, last, left](size_t, httplib::DataSink& sink) {
            if (*left == 0) {
              sink.done();
              return true;
            }
            std::string msg;
            {
              std::unique_lock lock(live.mu);
              live.cv.wait_for(lock, std::chrono::seconds(1),
                               [&] { return live.seq != *last || live.closing; });
              if (live.closing) return false;
              if (live.seq == *last) {
                msg = ": keep-alive\n\n";
              } else {
                *last = live.seq;
                // retry: a client whose stream ended (?frames=N) waits 10 minutes before asking again.
                msg = "retry: 600000\ndata: " + live.json + "\n\n";
                if (*left > 0) --*left;
              }
            }
            return sink.write(msg.data(), msg.size());
          },
          [&live](bool) { --live.clients; });
    });
    int bound = int(port);
    if (port == 0) {
      bound = server.bind_to_any_port(host.c_str());
    } else if (!server.bind_to_port(host.c_str(), int(port))) {
      bound = -1;
    }
    if (bound < 0) {
      std::fprintf(stderr, "poseforest live: --http %s: cannot listen there\n", addr->c_str());
      return 1;
    }
    std::fprintf(stderr, "poseforest live: the live page is at http://%s:%d/\n", host.c_str(), bound);
    server_thread = std::thread([&server] { server.listen_after_bind(); });
  }
  auto stop_server = [&] {
    if (!server_thread.joinable()) return;
    {
      std::lock_guard lock(live.mu);
      live.closing = true;
    }
    live.cv.notify_all();
    server.stop();
    server_thread.join();
  };
#else
  if (args.Has("http"))
    return UsageError(
        "--http: this program was built without cpp-httplib (Debian libcpp-httplib-dev, found at configure "
        "time)");
  auto stop_server = [] {};
#endif

#ifdef POSEFOREST_HAS_SKELETON_DDS
  std::unique_ptr<runtime::ros2::SkeletonPublisher> dds;
  if (args.Has("dds")) {
    runtime::ros2::DdsOptions o;
    auto domain = args.GetInt("dds-domain", 0, 0, 232);
    auto wait = args.GetInt("dds-wait", 0, 0, 1000);
    if (!domain.ok()) return UsageError(domain.status().message());
    if (!wait.ok()) return UsageError(wait.status().message());
    o.domain = int(*domain);
    o.topic_prefix = args.GetOr("dds-topic", o.topic_prefix);
    o.frame_id = args.GetOr("dds-frame-id", o.frame_id);
    auto p = runtime::ros2::SkeletonPublisher::Create(o);
    if (!p.ok()) {
      std::fprintf(stderr, "poseforest live: %s\n", p.status().ToString().c_str());
      return p.status().code() == core::ErrorCode::kInvalidArgument ? 2 : 1;
    }
    dds = std::move(*p);
    std::fprintf(stderr, "poseforest live: publishing on %s\n", dds->Describe().c_str());
    if (*wait > 0 && !dds->WaitForSubscribers(int(*wait), 10.0))
      std::fprintf(stderr, "poseforest live: DDS: fewer than %ld subscribers after 10 s; publishing anyway\n",
                   *wait);
  }
#endif

  struct sigaction sa {};
  sa.sa_handler = OnStopSignal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: a read blocked on stdin or a device returns
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  const bool tty = isatty(STDERR_FILENO);
  std::fprintf(stderr, "poseforest live: %s on %s; confidence: %s; proposal parameters: %s\n",
               forest_path->c_str(), (*source)->Describe().c_str(),
               runtime::DescribeConfidence((*pipeline)->calibration()).c_str(),
               core::DescribeProposalParamsSource((*pipeline)->params_source()));
  if (options.pixel_stride > 1)
    std::fprintf(stderr, "poseforest live: pixel stride %d: one pixel in %dx%d classified (--pixel-stride 1: all)\n",
                 options.pixel_stride, options.pixel_stride, options.pixel_stride);

  runtime::Frame frame;
  runtime::SkeletonFrame result;
  std::vector<double> latencies;
  runtime::StageTimes stage_sum;
  double output_ms_sum = 0;
  int64_t frames = 0, bad = 0, write_errors = 0, people_frames = 0;
  int bad_in_a_row = 0, loops = 0;
  int64_t frames_at_replay = 0;
  std::string rescale_said;
  const auto start = std::chrono::steady_clock::now();
  auto last_progress = start;
  int64_t frames_at_progress = 0;
  bool stopped_by_signal = false;
  while (*max_frames < 0 || frames < *max_frames) {
    if (g_stop.load()) {
      stopped_by_signal = true;
      break;
    }
    auto next = (*source)->Next(&frame);
    if (g_stop.load()) {
      stopped_by_signal = true;
      break;
    }
    if (!next.ok()) {
      std::fprintf(stderr, "%sposeforest live: %s\n", tty && !quiet ? "\n" : "",
                   next.status().ToString().c_str());
      ++bad;
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
      if (!loop || frames == frames_at_replay) break;
      frames_at_replay = frames;
      auto again = runtime::OpenFrameSources(specs, source_options);
      if (!again.ok()) {
        std::fprintf(stderr, "poseforest live: %s\n", again.status().ToString().c_str());
        break;
      }
      *source = std::move(*again);
      ++loops;
      continue;
    }
    const auto t_in = std::chrono::steady_clock::now();
    // With --loop, frame indices and times keep counting over the replays.
    frame.index = frames;
    (*pipeline)->Process(frame, &result);
    if (!(*pipeline)->rescale_note().empty() && rescale_said != (*pipeline)->rescale_note()) {
      rescale_said = (*pipeline)->rescale_note();
      std::fprintf(stderr, "poseforest live: camera %s: %s\n", frame.camera.Describe().c_str(),
                   rescale_said.c_str());
    }
    const auto t_out = std::chrono::steady_clock::now();
    const std::string line =
        runtime::SkeletonsJsonLine(frame.index, frame.timestamp_s, frame.source, result.skeletons);
    if (jsonl) {
      std::fputs(line.c_str(), jsonl);
      std::fputc('\n', jsonl);
      std::fflush(jsonl);
    }
#ifdef POSEFOREST_HAS_SKELETON_DDS
    if (dds && !dds->Publish(frame.index, frame.timestamp_s, frame.source, result.skeletons)) {
      std::fprintf(stderr, "poseforest live: DDS: a write failed at frame %lld\n",
                   static_cast<long long>(frame.index));
      ++write_errors;
    }
#endif
    const double latency_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_in).count();
    // The picture is made for --png-dir and while a page is open (its event stream connected):
    // encoding it costs about as much as classifying.
    bool page_open = false;
#ifdef POSEFOREST_HAS_HTTPLIB
    page_open = server_thread.joinable() && live.clients.load() > 0;
#endif
    runtime::RgbImage fig;
    if (png_dir || page_open)
      fig = runtime::SkeletonFigure(*result.depth, result.classification.labels, result.skeletons, 1);
    if (png_dir) {
      char name[40];
      std::snprintf(name, sizeof name, "frame-%06lld.png", static_cast<long long>(frame.index));
      const auto st = runtime::WriteRgbPng((fs::path(*png_dir) / name).string(), fig.width, fig.height, fig.rgb);
      if (!st.ok()) std::fprintf(stderr, "poseforest live: %s\n", st.ToString().c_str()), ++write_errors;
    }
#ifdef POSEFOREST_HAS_HTTPLIB
    if (server_thread.joinable()) {
      std::vector<uint8_t> png;
      if (page_open) png = runtime::EncodePng8(fig.width, fig.height, 3, fig.rgb);
      {
        std::lock_guard lock(live.mu);
        if (page_open) live.png = std::move(png);
        live.json = line;
        ++live.seq;
      }
      live.cv.notify_all();
    }
#endif
    output_ms_sum +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_out).count();
    ++frames;
    latencies.push_back(latency_ms);
    stage_sum.segment_ms += result.times.segment_ms;
    stage_sum.classify_ms += result.times.classify_ms;
    stage_sum.proposals_ms += result.times.proposals_ms;
    stage_sum.skeletons_ms += result.times.skeletons_ms;
    stage_sum.votes_ms += result.times.votes_ms;
    people_frames += int64_t(result.skeletons.size());

    const auto now = std::chrono::steady_clock::now();
    const double since = std::chrono::duration<double>(now - last_progress).count();
    if (!quiet && since >= (tty ? 0.25 : 5.0)) {
      const double fps = double(frames - frames_at_progress) / since;
      int tracked = 0;
      for (const auto& s : result.skeletons) tracked += s.tracked_joints();
      std::fprintf(stderr, "%sframe %lld: %.1f frames/s, latency %.1f ms, %zu people (%d joints tracked)%s",
                   tty ? "\r" : "", static_cast<long long>(frame.index), fps, latency_ms,
                   result.skeletons.size(), tracked, tty ? "   " : "\n");
      last_progress = now;
      frames_at_progress = frames;
    }
  }
  stop_server();
#ifdef POSEFOREST_HAS_SKELETON_DDS
  // Let matched subscribers receive what was published before the writers go away.
  if (dds && !dds->Flush(3.0))
    std::fprintf(stderr, "poseforest live: DDS: not every subscriber acknowledged within 3 s\n");
  dds.reset();
#endif
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (tty && !quiet) std::fputc('\n', stderr);
  std::fprintf(stderr,
               "poseforest live: %s: %lld frames in %.2f s (%.1f frames/s%s), %lld bad frames skipped%s\n",
               stopped_by_signal ? "stopped by signal" : "end of source", static_cast<long long>(frames),
               seconds, seconds > 0 ? double(frames) / seconds : 0.0,
               loops ? (", " + std::to_string(loops) + " replays").c_str() : "", static_cast<long long>(bad),
               write_errors ? (", " + std::to_string(write_errors) + " write errors").c_str() : "");
  if (frames > 0) {
    const double n = double(frames);
    std::fprintf(stderr,
                 "poseforest live: latency p50 %.2f ms, p99 %.2f ms (frame in to JSON line out and "
                 "published); per frame: segment "
                 "%.2f ms, classify %.2f ms, proposals %.2f ms, votes %.2f ms, skeletons %.2f ms, pictures/page "
                 "%.2f ms\n",
                 Percentile(latencies, 0.5), Percentile(latencies, 0.99), stage_sum.segment_ms / n,
                 stage_sum.classify_ms / n, stage_sum.proposals_ms / n, stage_sum.votes_ms / n,
                 stage_sum.skeletons_ms / n, output_ms_sum / n);
    std::fprintf(stderr, "poseforest live: %d people seen (ids 1..%d), %.2f people per frame\n",
                 (*pipeline)->tracker().people_seen(), (*pipeline)->tracker().people_seen(),
                 double(people_frames) / n);
  }
  return bad == 0 && write_errors == 0 ? 0 : 1;
}

}  // namespace poseforest::cli
