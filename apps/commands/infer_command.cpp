// poseforest infer: classify depth images into body parts.
#include <omp.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include <cctype>
#include <cmath>
#include <optional>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "runtime/camera_model.h"
#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "runtime/frame_source.h"
#include "runtime/image_io.h"
#include "runtime/joint_proposals.h"
#include "runtime/segmentation.h"
#include "runtime/skeleton.h"
#include "runtime/visualize.h"

namespace poseforest::apps::commands {
namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage = R"(usage: poseforest infer --forest FOREST.pff [options] SOURCE [SOURCE...]

Classifies every foreground pixel of each depth frame into the forest's body parts (eq. 2 of
Shotton et al.: leaf distributions averaged over trees) and writes the most likely part per pixel
as a colour PNG. Raw frames (a floor, walls, furniture) are segmented into people first; frames
that are already segmented (most pixels 0, no floor) pass unchanged (--segment).

SOURCE (also --source SOURCE; docs/runtime/frames.md):
  FILE        a 16-bit greyscale PNG in millimetres, a raw little-endian uint16 frame (e.g. the
              640x480 Kinect frames in shared/data/real), a .npy (uint16 mm or float32 metres,
              [H,W] or [N,H,W]), or an organized .pcd point cloud (x y z, metres); 0 = no reading
  FOLDER      every file in it, in name order;  'PATTERN'  a glob (quoted), in name order
  -           raw uint16 frames on stdin, back to back (a pipe works)
  freenect:N  Kinect v1 number N through libfreenect;  openni2:[URI]  an OpenNI2 device or .oni
              (device back ends: those `poseforest --version` lists)
A bad frame (truncated, wrong size) is reported naming the source and frame, skipped and counted.

camera (the model frames are checked against; default kinect-v1):
  --camera PRESET      kinect-v1 (640x480), kinect-v2 (512x424), azure-nfov (640x576),
                       azure-nfov-binned (320x288), azure-wfov (512x512), azure-wfov-unbinned
                       (1024x1024), realsense-d435 (848x480), realsense-d435-640 (640x480)
  --fx F --fy F --cx C --cy C   intrinsics in pixels (override the preset's)
  --depth-scale S      millimetres per raw depth unit (default 1; raw, PNG and uint16 .npy)
  A forest records the focal length it was trained for; for another one its offsets are rescaled.

segmentation:
  --segment auto|on|off  auto (default): segment raw frames, pass pre-segmented ones unchanged;
                       on: always segment; off: every pixel with depth > 0 is foreground
  --floor A,B,C,D      a known floor plane A*x + B*y + C*z + D = 0 (camera frame, metres)
  --near M --far M     depth band in metres (default 0.4, 4.5)
  --masks              also write the person masks (<name>.mask.png: 0 background, k person k)

options:
  --forest FILE        forest file (.pff), required
  --out FILE           colour part picture (one input only; default: <DEPTH>.parts.png)
  --out-dir DIR        write <name>.parts.png (and other outputs) for each input into DIR
  --labels             also write the raw part ids as an 8-bit PNG (<name>.labels.png, 255 = background)
  --distributions      also write P(part | pixel) as float32 NumPy array [height, width, parts]
                       (<name>.probs.npy); background pixels are all zero
  --joints             also propose 3D joints (section 3.4): <name>.joints.json (per joint, every
                       proposal: position in metres, camera frame; pixel; raw confidence; the
                       calibrated confidence in 0..1, docs/runtime/live.md) and
                       <name>.pose.png (depth, parts, joints, front/side/top views); uses the
                       proposal parameters the forest stores for the method (`tune-joints`; the
                       fast clustering without a set of its own uses the mean-shift set), or the
                       paper's means
  --method M           joint proposals by `meanshift` (default) or `fast` (bottom-up clustering)
  --pixel-stride N     classify every N-th pixel in x and y only (default 1: every pixel); the
                       others take their grid pixel's part; the joints are proposed from the
                       grid pixels, each weighted as N x N pixels
  --min-confidence C   joints drawn in the picture need this confidence (default 0.05)
  --raw-size WxH       size of raw depth frames (default: the camera's, 640x480)
  --fps N              deliver at most N frames per second (a folder played at camera rate)
  --threads N          OpenMP threads (default: all cores)
  --quiet              print nothing but errors
  --help               this text
)";

// Confidence in 0..1 of a proposal: the forest's calibration (format 1.4, JCAL: the precision of
// proposals of this support on validation renders) or the documented fallback (docs/runtime/live.md).
float CalibratedConfidence(const core::ConfidenceCalibration* cal, int joint, const runtime::JointProposal& p,
                           const core::CameraIntrinsics& camera) {
  const float support = float(double(p.confidence) / (camera.fx * camera.fy));
  return cal ? cal->Confidence(joint, support) : core::FallbackConfidence(support);
}

// Positions rounded to 0.1 mm, pixels to 0.1 px, confidence to 5 significant digits.
std::string JointsJson(const std::string& source, const core::DepthImage& depth, const runtime::FrameProposals& f,
                       const char* method, const core::ConfidenceCalibration* cal, const core::CameraIntrinsics& camera) {
  using Json = nlohmann::ordered_json;
  using runtime::PrintedValue;
  Json joints = Json::array();
  for (int j = 0; j < core::kNumJoints; ++j) {
    Json proposals = Json::array();
    for (const auto& p : f[size_t(j)]) {
      proposals.push_back(
          {{"position_m",
            {PrintedValue(p.position.x(), "%.4f"), PrintedValue(p.position.y(), "%.4f"),
             PrintedValue(p.position.z(), "%.4f")}},
           {"pixel", {PrintedValue(p.pixel.x(), "%.1f"), PrintedValue(p.pixel.y(), "%.1f")}},
           {"confidence", PrintedValue(double(p.confidence), "%.5g")},
           {"calibrated_confidence", PrintedValue(double(CalibratedConfidence(cal, j, p, camera)), "%.4f")}});
    }
    joints.push_back({{"joint", core::JointName(j)}, {"proposals", std::move(proposals)}});
  }
  const Json doc = {{"frame", source},  // a file name may hold any byte: invalid UTF-8 becomes U+FFFD
                    {"width", depth.width},
                    {"height", depth.height},
                    {"method", method},
                    {"joints", std::move(joints)}};
  return doc.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

core::Status WriteProbabilitiesNpy(const std::string& path, const runtime::Classification& c) {
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" + std::to_string(c.height) + ", " +
                       std::to_string(c.width) + ", " + std::to_string(c.num_parts) + "), }";
  // Magic (6) + version (2) + length (2) + header, padded with spaces to a multiple of 64, ending in \n.
  while ((10 + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::vector<uint8_t> bytes = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, uint8_t(header.size() & 0xFF),
                                uint8_t(header.size() >> 8)};
  bytes.insert(bytes.end(), header.begin(), header.end());
  const size_t offset = bytes.size();
  bytes.resize(offset + size_t(c.width) * size_t(c.height) * size_t(c.num_parts) * 4);
  float* out = reinterpret_cast<float*>(bytes.data() + offset);  // offset is a multiple of 64
  const float norm = 1.0f / float(core::kLeafTotal * c.num_trees);
  // From the compact foreground sums (want_foreground_distributions); background pixels keep
  // the zeros of the resize.
  for (size_t k = 0; k < c.foreground.size(); ++k) {
    float* row = out + size_t(c.foreground[k]) * size_t(c.num_parts);
    const uint16_t* sums = c.foreground_sums.data() + k * size_t(c.stride);
    for (int p = 0; p < c.num_parts; ++p) row[p] = float(sums[p]) * norm;
  }
  return core::WriteFileAtomic(path, bytes);
}

int Fail(const core::Status& st) {
  std::fprintf(stderr, "poseforest infer: %s\n", st.ToString().c_str());
  return 1;
}


// Output stem of a frame: a file's name without .png/.raw/.npy/.pcd, else "<source>-<index>".
std::string FrameStem(const runtime::Frame& f) {
  const bool file = f.source.find(':') == std::string::npos && f.source != "stdin" && f.source.find('[') == std::string::npos;
  if (file) {
    fs::path p(f.source);
    std::string stem = p.filename().string();
    for (const char* ext : {".png", ".raw", ".npy", ".pcd"})
      if (p.extension() == ext) stem = p.stem().string();
    return stem;
  }
  std::string base = f.source.substr(0, f.source.find('['));
  base = fs::path(base).filename().string();
  for (const char* ext : {".npy", ".pcd", ".oni"})
    if (fs::path(base).extension() == ext) base = fs::path(base).stem().string();
  for (char& c : base)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') c = '_';
  char idx[32];
  std::snprintf(idx, sizeof idx, "-%06lld", static_cast<long long>(f.index));
  return base + idx;
}

}  // namespace

int InferMain(int argc, char** argv) {
  std::set<std::string> value_options = {"forest",  "out",          "out-dir",        "threads",
                                         "method",  "pixel-stride", "min-confidence", "source",
                                         "segment", "floor",        "near",           "far"};
  for (const char* o : kFrameSourceValueOptions) value_options.insert(o);
  Args args(value_options, {"labels", "distributions", "joints", "quiet", "help", "masks"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest infer: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  std::vector<std::string> specs = args.positional();
  if (auto src = args.Get("source")) specs.insert(specs.begin(), *src);
  const auto forest_path = args.Get("forest");
  if (!forest_path || specs.empty()) {
    std::fprintf(stderr, "poseforest infer: %s\n\n%s", !forest_path ? "--forest is required" : "no depth image given", kUsage);
    return 2;
  }
  if (args.Get("out") && specs.size() != 1) {
    std::fprintf(stderr, "poseforest infer: --out takes one input; use --out-dir for several\n");
    return 2;
  }
  auto usage_error = [](const std::string& msg) {
    std::fprintf(stderr, "poseforest infer: %s\n", msg.c_str());
    return 2;
  };
  runtime::FrameSourceOptions source_options;
  if (auto st = ParseFrameSourceOptions(args, &source_options); !st.ok()) return usage_error(st.message());
  const std::string segment_mode = args.GetOr("segment", "auto");
  if (segment_mode != "auto" && segment_mode != "on" && segment_mode != "off")
    return usage_error("--segment must be auto, on or off (got '" + segment_mode + "')");
  runtime::SegmentationOptions seg_options;
  if (segment_mode == "on") seg_options.presegmented = false;
  if (auto fl = args.Get("floor")) {
    double a, b, c, d;
    if (std::sscanf(fl->c_str(), "%lf,%lf,%lf,%lf", &a, &b, &c, &d) != 4 || std::hypot(a, b, c) < 1e-9)
      return usage_error("--floor must be A,B,C,D with (A,B,C) != 0 (got '" + *fl + "')");
    const double n = std::hypot(a, b, c);
    seg_options.floor_plane = Eigen::Vector4d(a / n, b / n, c / n, d / n);
  }
  {
    auto near = GetDouble(args, "near", seg_options.near_m, 0.0, 60.0);
    auto far = GetDouble(args, "far", seg_options.far_m, 0.0, 65.0);
    if (!near.ok()) return usage_error(near.status().message());
    if (!far.ok()) return usage_error(far.status().message());
    if (*near >= *far) return usage_error("--near must be less than --far");
    seg_options.near_m = *near, seg_options.far_m = *far;
  }
  auto threads = args.GetInt("threads", 0, 0, 1024);
  if (!threads.ok()) {
    std::fprintf(stderr, "poseforest infer: %s\n", threads.status().message().c_str());
    return 2;
  }
  auto pixel_stride = args.GetInt("pixel-stride", 1, 1, 16);
  if (!pixel_stride.ok()) {
    std::fprintf(stderr, "poseforest infer: %s\n", pixel_stride.status().message().c_str());
    return 2;
  }
  const bool quiet = args.Has("quiet");
  const bool joints = args.Has("joints");
  const std::string method = args.GetOr("method", "meanshift");
  if (method != "meanshift" && method != "fast") {
    std::fprintf(stderr, "poseforest infer: --method must be meanshift or fast (got '%s')\n", method.c_str());
    return 2;
  }
  float min_confidence = 0.05f;
  if (auto mc = args.Get("min-confidence")) {
    char* end = nullptr;
    min_confidence = std::strtof(mc->c_str(), &end);
    if (end == mc->c_str() || *end != '\0' || !(min_confidence >= 0)) {
      std::fprintf(stderr, "poseforest infer: --min-confidence must be a number >= 0 (got '%s')\n", mc->c_str());
      return 2;
    }
  }
  const auto out_dir = args.Get("out-dir");
  if (out_dir) {
    std::error_code ec;
    std::filesystem::create_directories(*out_dir, ec);
    if (ec) return Fail({core::ErrorCode::kIo, *out_dir + ": cannot create folder: " + ec.message()});
  }

  auto forest = core::LoadForest(*forest_path);
  if (!forest.ok()) return Fail(forest.status());
  if (!quiet)
    std::printf("forest %s: %zu trees, depth %u, %zu nodes, %d parts\n", forest_path->c_str(), forest->trees.size(),
                forest->max_depth(), forest->total_nodes(), forest->num_parts);

  if (joints && (forest->num_parts != core::kNumParts || forest->part_names != core::Forest::DefaultPartNames()))
    return Fail({core::ErrorCode::kInvalidArgument,
                 *forest_path + ": --joints needs a forest with the paper's 31-part taxonomy (this one has " +
                     std::to_string(forest->num_parts) + " parts)"});
  // The calibration applies to the method it was measured with.
  const core::ConfidenceCalibration* calibration =
      forest->confidence_calibration &&
              (forest->confidence_calibration->method == core::ConfidenceCalibration::Method::kFastClustering) ==
                  (method == "fast")
          ? &*forest->confidence_calibration
          : nullptr;
  runtime::ProposalOptions proposal_options;
  proposal_options.method = method == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  const auto params =
      forest->ProposalParamsFor(proposal_options.method == runtime::ProposalMethod::kFastClustering);
  proposal_options.params = params.params;
  proposal_options.num_threads = int(*threads);

  auto source = runtime::OpenFrameSources(specs, source_options);
  if (!source.ok()) return Fail(source.status());

  // The forest for the frames' camera: rescaled once per focal length met.
  std::optional<core::Forest> rescaled;
  double rescaled_fx = 0, rescaled_fy = 0;
  runtime::ClassifyOptions options;
  options.num_threads = int(*threads);
  // The compact per-foreground-pixel sums serve both the proposals and the .npy (no dense
  // W*H*stride array is cleared or written).
  options.want_foreground_distributions = args.Has("distributions") || joints;
  options.pixel_stride = int(*pixel_stride);
  runtime::Classification result;
  runtime::SegmentationResult seg;
  int failures = 0, bad_frames = 0, frames_done = 0, segmented_frames = 0, bad_in_a_row = 0;
  runtime::Frame frame;
  while (true) {
    auto next = (*source)->Next(&frame);
    if (!next.ok()) {
      std::fprintf(stderr, "poseforest infer: %s\n", next.status().ToString().c_str());
      ++bad_frames;
      if (++bad_in_a_row >= runtime::kMaxConsecutiveBadFrames) {
        std::fprintf(stderr, "poseforest infer: %s: giving up after %d bad frames in a row\n", (*source)->Describe().c_str(),
                     bad_in_a_row);
        break;
      }
      continue;
    }
    bad_in_a_row = 0;
    if (!*next) break;
    if (args.Get("out") && frames_done > 0) {
      std::fprintf(stderr, "poseforest infer: %s: --out takes one frame but the source holds more; use --out-dir\n",
                   frame.Name().c_str());
      ++failures;
      break;
    }
    const auto& cam = frame.camera.intrinsics;
    const core::Forest* run_forest = &*forest;
    if (!runtime::SameFocalLength(*forest, cam.fx, cam.fy)) {
      if (!rescaled || rescaled_fx != cam.fx || rescaled_fy != cam.fy) {
        rescaled = runtime::ForestForFocalLength(*forest, cam.fx, cam.fy);
        rescaled_fx = cam.fx, rescaled_fy = cam.fy;
        if (!quiet)
          std::printf("camera %s: the forest was trained for fx %.1f fy %.1f; offsets rescaled by %.4f x %.4f\n",
                      frame.camera.Describe().c_str(), double(forest->training_fx), double(forest->training_fy),
                      cam.fx / forest->training_fx, cam.fy / forest->training_fy);
      }
      run_forest = &*rescaled;
    }
    const core::DepthImage* depth = &frame.depth;
    const auto t_seg = std::chrono::steady_clock::now();
    double seg_ms = 0;
    if (segment_mode != "off") {
      runtime::SegmentPeople(frame.depth, cam, seg_options, &seg);
      seg_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_seg).count();
      if (!seg.presegmented) {
        depth = &seg.depth;
        ++segmented_frames;
      }
    }
    runtime::Classifier classifier(*run_forest);
    const auto t0 = std::chrono::steady_clock::now();
    classifier.Classify(*depth, options, &result);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ++frames_done;

    const std::string stem = FrameStem(frame);
    auto out_path = [&](const std::string& suffix) {
      if (out_dir) return (fs::path(*out_dir) / (stem + suffix)).string();
      const bool file = frame.source.find(':') == std::string::npos && frame.source != "stdin";
      fs::path parent = file ? fs::path(frame.source.substr(0, frame.source.find('['))).parent_path() : fs::path(".");
      return (parent / (stem + suffix)).string();
    };
    const std::string parts_png = args.Get("out") ? *args.Get("out") : out_path(".parts.png");
    core::Status st = runtime::WriteLabelColourPng(parts_png, result.labels);
    if (st.ok() && args.Has("labels")) st = runtime::WriteLabelPng(out_path(".labels.png"), result.labels);
    if (st.ok() && args.Has("masks")) {
      core::LabelImage mask = seg.labels;
      if (segment_mode == "off" || mask.empty()) {
        mask = core::LabelImage(depth->width, depth->height, 0);
        for (size_t i = 0; i < mask.pixels.size(); ++i) mask.pixels[i] = depth->pixels[i] ? 1 : 0;
      }
      st = runtime::WriteLabelPng(out_path(".mask.png"), mask);
    }
    if (st.ok() && args.Has("distributions")) st = WriteProbabilitiesNpy(out_path(".probs.npy"), result);
    runtime::FrameProposals proposals;
    double proposal_ms = 0;
    if (st.ok() && joints) {
      proposal_options.camera = cam;
      const auto t1 = std::chrono::steady_clock::now();
      proposals = runtime::ProposeJointsFromClassification(*depth, result, proposal_options);
      proposal_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
      const std::string json =
          JointsJson(frame.source, *depth, proposals, method.c_str(), calibration, proposal_options.camera);
      st = core::WriteFileAtomic(out_path(".joints.json"),
                                 std::span(reinterpret_cast<const uint8_t*>(json.data()), json.size()));
      if (st.ok()) {
        const auto fig = runtime::PoseFigure(*depth, result.labels, proposals, proposal_options.camera, min_confidence);
        st = runtime::WriteRgbPng(out_path(".pose.png"), fig.width, fig.height, fig.rgb);
      }
    }
    if (!st.ok()) {
      std::fprintf(stderr, "poseforest infer: %s\n", st.ToString().c_str());
      ++failures;
      continue;
    }
    if (!quiet) {
      std::vector<int> counts(size_t(forest->num_parts), 0);
      int fg = 0;
      for (uint8_t l : result.labels.pixels)
        if (l != core::kBackgroundLabel) ++counts[l], ++fg;
      std::printf("%s: %dx%d, %d foreground pixels, classified in %.2f ms -> %s\n", frame.Name().c_str(),
                  depth->width, depth->height, fg, ms, parts_png.c_str());
      if (segment_mode != "off") {
        if (seg.presegmented)
          std::printf("  segmentation: pre-segmented, passed unchanged\n");
        else
          std::printf("  segmentation: %zu person(s), floor %s, %d components, %.2f ms\n", seg.people.size(),
                      seg.floor ? "found" : "none", seg.components, seg_ms);
      }
      std::vector<int> order(counts.size());
      for (size_t i = 0; i < order.size(); ++i) order[i] = int(i);
      std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return counts[size_t(a)] > counts[size_t(b)]; });
      std::printf("  most frequent parts:");
      for (size_t i = 0; i < std::min<size_t>(5, order.size()) && counts[size_t(order[i])] > 0; ++i)
        std::printf(" %s %.1f%%", forest->part_names[size_t(order[i])].c_str(),
                    100.0 * counts[size_t(order[i])] / std::max(1, fg));
      std::printf("\n");
      if (joints) {
        std::printf(
            "  joints (%s with %s, %.2f ms; most confident proposal of each, camera frame, metres):\n",
            method.c_str(),
            params.source == core::ProposalParamsSource::kLearned ? "the forest's learned parameters"
            : params.source == core::ProposalParamsSource::kMeanShiftSet
                ? "the forest's learned mean-shift parameters (none learned for the fast clustering)"
                : "the paper's mean parameters",
            proposal_ms);
        for (int j = 0; j < core::kNumJoints; ++j) {
          const auto& list = proposals[size_t(j)];
          if (list.empty()) {
            std::printf("    %-11s none\n", std::string(core::JointName(j)).c_str());
            continue;
          }
          std::printf("    %-11s (%6.3f, %6.3f, %6.3f)  confidence %.4g, %s %.2f  (%zu proposals)\n",
                      std::string(core::JointName(j)).c_str(), list[0].position.x(), list[0].position.y(),
                      list[0].position.z(), double(list[0].confidence), calibration ? "calibrated" : "fallback",
                      double(CalibratedConfidence(calibration, j, list[0], proposal_options.camera)), list.size());
        }
      }
    }
  }
  if (!quiet || bad_frames > 0)
    std::printf("%s: %d frame(s) classified, %d bad frame(s) skipped, %d segmented\n", (*source)->Describe().c_str(),
                frames_done, bad_frames, segmented_frames);
  return failures == 0 && bad_frames == 0 ? 0 : 1;
}

}  // namespace poseforest::apps::commands
