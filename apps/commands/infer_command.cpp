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
#include <set>
#include <string>
#include <vector>

#include "apps/commands/cli.h"
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

// Where an output of `frame` goes: DIR/<stem><suffix> with --out-dir DIR, else beside --out FILE
// when given, else beside the file it came from (the working folder for other sources).
std::string OutputPath(const runtime::Frame& frame, const std::optional<std::string>& out_dir,
                       const std::string& suffix, const std::optional<std::string>& out = std::nullopt) {
  const std::string stem = FrameStem(frame);
  if (out_dir) return (fs::path(*out_dir) / (stem + suffix)).string();
  if (out) return (fs::path(*out).parent_path() / (stem + suffix)).string();
  const bool file = frame.source.find(':') == std::string::npos && frame.source != "stdin";
  fs::path parent = file ? fs::path(frame.source.substr(0, frame.source.find('['))).parent_path() : fs::path(".");
  return (parent / (stem + suffix)).string();
}

class InferCommand final : public Command {
 public:
  InferCommand();
  int Run() override;

 private:
  /// What the frames of one run share: the forest (rescaled once per focal length met), the
  /// options and the buffers.
  struct Run_ {
    core::Forest forest;
    std::optional<core::Forest> rescaled;
    double rescaled_fx = 0, rescaled_fy = 0;
    const core::ConfidenceCalibration* calibration = nullptr;
    core::ProposalParamsChoice params;
    runtime::ProposalOptions proposal_options;
    runtime::ClassifyOptions options;
    runtime::SegmentationOptions seg_options;
    runtime::Classification result;
    runtime::SegmentationResult seg;
    runtime::FrameSourceOptions source_options;
  };
  /// The options checked and the forest loaded into `run`: nullopt to go on, else the exit code.
  std::optional<int> Prepare(Run_* run);
  /// The forest for `frame`'s camera.
  const core::Forest& ForestFor(Run_& run, const runtime::Frame& frame) const;
  /// Writes the outputs of one classified frame; `parts_png`: where the part picture went.
  core::Status WriteOutputs(Run_& run, const runtime::Frame& frame, const core::DepthImage& depth,
                            const std::string& parts_png, runtime::FrameProposals* proposals,
                            double* proposal_ms);
  /// The lines printed for one frame.
  void PrintFrame(const Run_& run, const runtime::Frame& frame, const core::DepthImage& depth,
                  const std::string& parts_png, double ms, double seg_ms, const runtime::FrameProposals& proposals,
                  double proposal_ms) const;

  std::string forest_, method_ = "meanshift";
  std::vector<std::string> sources_;
  std::optional<std::string> source_, out_, out_dir_;
  int threads_ = 0, pixel_stride_ = 1;
  float min_confidence_ = 0.05f;
  bool labels_ = false, distributions_ = false, joints_ = false, masks_ = false, quiet_ = false;
  FrameSourceFlags frames_;
  SegmentationFlags segmentation_;
};

InferCommand::InferCommand()
    : Command(
          "infer",
          "Classifies every foreground pixel of each depth frame into the forest's body parts (eq. 2 of\n"
          "Shotton et al.: leaf distributions averaged over trees) and writes the most likely part per\n"
          "pixel as a colour PNG. Raw frames (a floor, walls, furniture) are segmented into people first;\n"
          "frames that are already segmented (most pixels 0, no floor) pass unchanged (--segment).\n"
          "\n"
          "SOURCE (also --source SOURCE; docs/runtime/frames.md):\n"
          "  FILE        a 16-bit greyscale PNG in millimetres, a raw little-endian uint16 frame (e.g. the\n"
          "              640x480 Kinect frames in shared/data/real), a .npy (uint16 mm or float32 metres,\n"
          "              [H,W] or [N,H,W]), or an organized .pcd point cloud (x y z, metres); 0 = no "
          "reading\n"
          "  FOLDER      every frame file in it, in name order (left out: infer's and render's own\n"
          "              outputs, text and documents such as COPYING, .md, .json);  'PATTERN'  a glob\n"
          "              (quoted), every file it matches, in name order\n"
          "  -           raw uint16 frames on stdin, back to back (a pipe works)\n"
          "  freenect:N  Kinect v1 number N through libfreenect;  openni2:[URI]  an OpenNI2 device or .oni\n"
          "              (device back ends: those `poseforest --version` lists)\n"
          "A bad frame (truncated, wrong size) is reported naming the source and frame, skipped and "
          "counted.\n"
          "A forest records the focal length it was trained for; for another one its offsets are rescaled.") {
  app_.add_option("SOURCE", sources_, "depth frames (above)");
  app_.add_option("--source", source_, "one more SOURCE, read first")->type_name("SOURCE");
  app_.add_option("--forest", forest_, "forest file (.pff)")->type_name("FILE")->required();
  app_.add_option("--out", out_,
                  "colour part picture (one input only; default: <DEPTH>.parts.png); the other outputs\n"
                  "(--labels, --joints, ...) go into its folder")
      ->type_name("FILE");
  app_.add_option("--out-dir", out_dir_, "write <name>.parts.png (and other outputs) for each input into DIR")
      ->type_name("DIR");
  app_.add_flag("--labels", labels_, "also write the raw part ids as an 8-bit PNG (<name>.labels.png, 255 = background)");
  app_.add_flag("--distributions", distributions_,
                "also write P(part | pixel) as float32 NumPy array [height, width, parts]\n"
                "(<name>.probs.npy); background pixels are all zero");
  app_.add_flag("--joints", joints_,
                "also propose 3D joints (section 3.4): <name>.joints.json (per joint, every proposal:\n"
                "position in metres, camera frame; pixel; raw confidence; the calibrated confidence in\n"
                "0..1, docs/runtime/live.md) and <name>.pose.png (depth, parts, joints, front/side/top\n"
                "views); uses the proposal parameters the forest stores for the method (`tune-joints`;\n"
                "the fast clustering without a set of its own uses the mean-shift set), or the paper's\n"
                "means");
  app_.add_option("--method", method_, "joint proposals by `meanshift` or `fast` (bottom-up clustering)")
      ->type_name("M")
      ->check(OneOf({"meanshift", "fast"}));
  app_.add_option("--pixel-stride", pixel_stride_,
                  "classify every N-th pixel in x and y only (1: every pixel); the others take their grid\n"
                  "pixel's part; the joints are proposed from the grid pixels, each weighted as N x N pixels")
      ->type_name("N")
      ->check(IntIn(1, 16));
  app_.add_option("--min-confidence", min_confidence_, "joints drawn in the picture need this confidence")
      ->type_name("C")
      ->check(NumberIn(0.0, 1e30));
  app_.add_option("--threads", threads_, "OpenMP threads (0: all cores)")->type_name("N")->check(IntIn(0, 1024));
  app_.add_flag("--quiet", quiet_, "print nothing but errors");
  AddSegmentationOptions(app_, &segmentation_);
  app_.add_flag("--masks", masks_, "also write the person masks (<name>.mask.png: 0 background, k person k)")
      ->group("segmentation");
  AddFrameSourceOptions(app_, &frames_);
}

std::optional<int> InferCommand::Prepare(Run_* run) {
  if (sources_.empty() && !source_) return UsageError("no depth image given");
  if (out_ && sources_.size() + (source_ ? 1 : 0) != 1)
    return UsageError("--out takes one input; use --out-dir for several");
  if (out_) {
    std::vector<std::string> inputs = sources_;
    inputs.push_back(forest_);
    if (source_) inputs.push_back(*source_);
    if (const std::string bad = CheckOutputFile("--out", *out_, inputs); !bad.empty()) return UsageError(bad);
  }
  auto source_options = FrameSourceFromFlags(frames_);
  if (!source_options.ok()) return UsageError(source_options.status().message());
  run->source_options = *source_options;
  if (segmentation_.segment == "on") run->seg_options.presegmented = false;
  if (core::Status st = SegmentationFromFlags(segmentation_, &run->seg_options); !st.ok())
    return UsageError(st.message());
  if (out_dir_) {
    std::error_code ec;
    std::filesystem::create_directories(*out_dir_, ec);
    if (ec) return Fail({core::ErrorCode::kIo, *out_dir_ + ": cannot create folder: " + ec.message()});
  }
  auto forest = core::LoadForest(forest_);
  if (!forest.ok()) return Fail(forest.status());
  run->forest = std::move(*forest);
  const core::Forest& f = run->forest;
  if (!quiet_)
    std::printf("forest %s: %zu trees, depth %u, %zu nodes, %d parts\n", forest_.c_str(), f.trees.size(),
                f.max_depth(), f.total_nodes(), f.num_parts);
  if (const std::string differs = f.TaxonomyDifference(); joints_ && !differs.empty())
    return Fail({core::ErrorCode::kInvalidArgument,
                 forest_ + ": --joints needs a forest with the paper's 31-part taxonomy (" + differs + ")"});
  // The calibration applies to the method it was measured with.
  run->calibration =
      f.confidence_calibration &&
              (f.confidence_calibration->method == core::ConfidenceCalibration::Method::kFastClustering) ==
                  (method_ == "fast")
          ? &*f.confidence_calibration
          : nullptr;
  runtime::ProposalOptions& proposal_options = run->proposal_options;
  proposal_options.method =
      method_ == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  run->params = f.ProposalParamsFor(proposal_options.method == runtime::ProposalMethod::kFastClustering);
  proposal_options.params = run->params.params;
  proposal_options.num_threads = threads_;
  run->options.num_threads = threads_;
  // The compact per-foreground-pixel sums serve both the proposals and the .npy (no dense
  // W*H*stride array is cleared or written).
  run->options.want_foreground_distributions = distributions_ || joints_;
  run->options.pixel_stride = pixel_stride_;
  return std::nullopt;
}

const core::Forest& InferCommand::ForestFor(Run_& run, const runtime::Frame& frame) const {
  const auto& cam = frame.camera.intrinsics;
  const core::Forest& forest = run.forest;
  if (runtime::SameFocalLength(forest, cam.fx, cam.fy)) return forest;
  if (!run.rescaled || run.rescaled_fx != cam.fx || run.rescaled_fy != cam.fy) {
    run.rescaled = runtime::ForestForFocalLength(forest, cam.fx, cam.fy);
    run.rescaled_fx = cam.fx, run.rescaled_fy = cam.fy;
    if (!quiet_)
      std::printf("camera %s: the forest was trained for fx %.1f fy %.1f; offsets rescaled by %.4f x %.4f\n",
                  frame.camera.Describe().c_str(), double(forest.training_fx), double(forest.training_fy),
                  cam.fx / forest.training_fx, cam.fy / forest.training_fy);
  }
  return *run.rescaled;
}

int InferCommand::Run() {
  Run_ run;
  if (auto rc = Prepare(&run)) return *rc;
  std::vector<std::string> specs = sources_;
  if (source_) specs.insert(specs.begin(), *source_);
  auto source = runtime::OpenFrameSources(specs, run.source_options);
  if (!source.ok()) return Fail(source.status());

  int failures = 0, bad_frames = 0, frames_done = 0, frames_seen = 0, segmented_frames = 0, bad_in_a_row = 0;
  std::set<std::string> written;  // the part pictures written by this run (their canonical paths)
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
    if (out_ && frames_seen > 0) {
      std::fprintf(stderr, "poseforest infer: %s: --out takes one frame but the source holds more; use --out-dir\n",
                   frame.Name().c_str());
      ++failures;
      break;
    }
    ++frames_seen;
    const std::string parts_png = out_ ? *out_ : OutputPath(frame, out_dir_, ".parts.png");
    // Two inputs of one name (A/x.png and B/x.png into one --out-dir) would write the same
    // outputs: the second is refused, not written over the first.
    if (!written.insert(fs::weakly_canonical(parts_png).string()).second) {
      std::fprintf(stderr,
                   "poseforest infer: %s: its outputs (%s) would overwrite those of an earlier input of the "
                   "same name; skipped (give the inputs other names or other --out-dir runs)\n",
                   frame.source.c_str(), parts_png.c_str());
      ++failures;
      continue;
    }
    const core::Forest& run_forest = ForestFor(run, frame);
    const core::DepthImage* depth = &frame.depth;
    const auto t_seg = std::chrono::steady_clock::now();
    double seg_ms = 0;
    if (segmentation_.segment != "off") {
      runtime::SegmentPeople(frame.depth, frame.camera.intrinsics, run.seg_options, &run.seg);
      seg_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_seg).count();
      if (!run.seg.presegmented) {
        depth = &run.seg.depth;
        ++segmented_frames;
      }
    }
    runtime::Classifier classifier(run_forest);
    const auto t0 = std::chrono::steady_clock::now();
    classifier.Classify(*depth, run.options, &run.result);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    runtime::FrameProposals proposals;
    double proposal_ms = 0;
    if (core::Status st = WriteOutputs(run, frame, *depth, parts_png, &proposals, &proposal_ms); !st.ok()) {
      std::fprintf(stderr, "poseforest infer: %s\n", st.ToString().c_str());
      ++failures;
      continue;
    }
    ++frames_done;  // classified and its outputs written
    if (!quiet_) PrintFrame(run, frame, *depth, parts_png, ms, seg_ms, proposals, proposal_ms);
  }
  // A frame whose outputs were refused or failed to write counts as "not written", not classified.
  const int not_written = frames_seen - frames_done;
  if (!quiet_ || bad_frames > 0 || not_written > 0)
    std::printf("%s: %d frame(s) classified, %s%d bad frame(s) skipped, %d segmented\n",
                (*source)->Describe().c_str(), frames_done,
                not_written > 0 ? (std::to_string(not_written) + " not written (above), ").c_str() : "",
                bad_frames, segmented_frames);
  return failures == 0 && bad_frames == 0 ? 0 : 1;
}

core::Status InferCommand::WriteOutputs(Run_& run, const runtime::Frame& frame, const core::DepthImage& depth,
                                        const std::string& parts_png, runtime::FrameProposals* proposals,
                                        double* proposal_ms) {
  auto out_path = [&](const std::string& suffix) { return OutputPath(frame, out_dir_, suffix, out_); };
  const runtime::Classification& result = run.result;
  core::Status st = runtime::WriteLabelColourPng(parts_png, result.labels);
  if (st.ok() && labels_) st = runtime::WriteLabelPng(out_path(".labels.png"), result.labels);
  if (st.ok() && masks_) {
    core::LabelImage mask = run.seg.labels;
    if (segmentation_.segment == "off" || mask.empty()) {
      mask = core::LabelImage(depth.width, depth.height, 0);
      for (size_t i = 0; i < mask.pixels.size(); ++i) mask.pixels[i] = depth.pixels[i] ? 1 : 0;
    }
    st = runtime::WriteLabelPng(out_path(".mask.png"), mask);
  }
  if (st.ok() && distributions_) st = WriteProbabilitiesNpy(out_path(".probs.npy"), result);
  if (st.ok() && joints_) {
    runtime::ProposalOptions& proposal_options = run.proposal_options;
    proposal_options.camera = frame.camera.intrinsics;
    const auto t1 = std::chrono::steady_clock::now();
    *proposals = runtime::ProposeJointsFromClassification(depth, result, proposal_options);
    *proposal_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
    const std::string json =
        JointsJson(frame.source, depth, *proposals, method_.c_str(), run.calibration, proposal_options.camera);
    st = core::WriteFileAtomic(out_path(".joints.json"),
                               std::span(reinterpret_cast<const uint8_t*>(json.data()), json.size()));
    if (st.ok()) {
      const auto fig = runtime::PoseFigure(depth, result.labels, *proposals, proposal_options.camera, min_confidence_);
      st = runtime::WriteRgbPng(out_path(".pose.png"), fig.width, fig.height, fig.rgb);
    }
  }
  return st;
}

void InferCommand::PrintFrame(const Run_& run, const runtime::Frame& frame, const core::DepthImage& depth,
                              const std::string& parts_png, double ms, double seg_ms,
                              const runtime::FrameProposals& proposals, double proposal_ms) const {
  const core::Forest& forest = run.forest;
  const runtime::SegmentationResult& seg = run.seg;
  std::vector<int> counts(size_t(forest.num_parts), 0);
  int fg = 0;
  for (uint8_t l : run.result.labels.pixels)
    if (l != core::kBackgroundLabel) ++counts[l], ++fg;
  std::printf("%s: %dx%d, %d foreground pixels, classified in %.2f ms -> %s\n", frame.Name().c_str(), depth.width,
              depth.height, fg, ms, parts_png.c_str());
  if (segmentation_.segment != "off") {
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
    std::printf(" %s %.1f%%", forest.part_names[size_t(order[i])].c_str(),
                100.0 * counts[size_t(order[i])] / std::max(1, fg));
  std::printf("\n");
  if (!joints_) return;
  std::printf("  joints (%s with %s, %.2f ms; most confident proposal of each, camera frame, metres):\n",
              method_.c_str(),
              run.params.source == core::ProposalParamsSource::kLearned ? "the forest's learned parameters"
              : run.params.source == core::ProposalParamsSource::kMeanShiftSet
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
                list[0].position.z(), double(list[0].confidence), run.calibration ? "calibrated" : "fallback",
                double(CalibratedConfidence(run.calibration, j, list[0], run.proposal_options.camera)), list.size());
  }
}

}  // namespace

std::unique_ptr<Command> MakeInferCommand() { return std::make_unique<InferCommand>(); }

}  // namespace poseforest::apps::commands
