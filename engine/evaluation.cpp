#include "engine/evaluation.h"

#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>

#include "runtime/camera_model.h"
#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "runtime/joint_proposals.h"
#include "runtime/segmentation.h"
#include "runtime/skeleton.h"
#include "runtime/visualize.h"
#if POSEFOREST_HAS_RENDERER
#include "engine/rendered_scene.h"
#include "renderer/synthetic_source.h"
#endif

namespace poseforest::engine {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;

std::string IndexedPath(const std::string& folder, const char* stem, uint64_t index, const char* ext) {
  char name[64];
  std::snprintf(name, sizeof name, "%s_%06llu.%s", stem, static_cast<unsigned long long>(index), ext);
  return (std::filesystem::path(folder) / name).string();
}

class ProceduralEvalSource final : public EvalFrameSource {
 public:
  explicit ProceduralEvalSource(SourceSpec spec) : spec_(std::move(spec)) {}
  Result<EvalFrame> Frame(uint64_t index) override {
    LabelledFrame f = MakeProceduralFrame(spec_, index);
    return EvalFrame{std::move(f.depth), std::move(f.labels), {}, {}};
  }
  bool has_joints() const override { return false; }
  uint64_t size() const override { return 0; }
  std::string Describe() const override {
    return "procedural seed " + std::to_string(spec_.seed) + " (no joints)";
  }

 private:
  SourceSpec spec_;
};

class DatasetEvalSource final : public EvalFrameSource {
 public:
  DatasetEvalSource(SourceSpec spec, uint64_t count, bool joints, bool masks, core::CameraIntrinsics camera)
      : spec_(std::move(spec)), count_(count), joints_(joints), masks_(masks), camera_(camera) {}
  Result<EvalFrame> Frame(uint64_t index) override {
    const uint64_t file = spec_.first_index + index;
    auto f = ReadDatasetFrame(spec_.folder, file);
    if (!f.ok()) return f.status();
    EvalFrame out{std::move(f->depth), std::move(f->labels), {}, {}};
    if (out.depth.width != camera_.width || out.depth.height != camera_.height)
      return Status(ErrorCode::kInvalidArgument,
                    IndexedPath(spec_.folder, "depth", file, "png") + " is " +
                        std::to_string(out.depth.width) + "x" + std::to_string(out.depth.height) +
                        " but the folder's camera is " + std::to_string(camera_.width) + "x" +
                        std::to_string(camera_.height));
    if (joints_) {
      auto people = ReadJointsJson(IndexedPath(spec_.folder, "joints", file, "json"));
      if (!people.ok()) return people.status();
      out.people = std::move(*people);
    }
    if (masks_) {
      const std::string path = IndexedPath(spec_.folder, "mask", file, "png");
      auto bytes = core::ReadFileBytes(path);
      if (!bytes.ok()) return bytes.status();
      auto png = runtime::DecodePng(*bytes, path);
      if (!png.ok()) return png.status();
      if (png->bit_depth != 8 || png->channels != 1 || png->width != out.depth.width ||
          png->height != out.depth.height)
        return Status(ErrorCode::kDataLoss,
                      path + ": a person mask must be 8-bit greyscale of the depth's size");
      out.person_masks = core::LabelImage(png->width, png->height);
      out.person_masks.pixels = std::move(png->samples8);
    }
    return out;
  }
  bool has_joints() const override { return joints_; }
  bool has_masks() const override { return masks_; }
  core::CameraIntrinsics camera() const override { return camera_; }
  uint64_t size() const override { return count_; }
  std::string Describe() const override {
    return "dataset " + spec_.folder + " (" + std::to_string(count_) + " frames" +
           (joints_ ? ", with joints" : ", no joints_*.json") + (masks_ ? ", person masks)" : ")");
  }

 private:
  SourceSpec spec_;
  uint64_t count_;
  bool joints_, masks_;
  core::CameraIntrinsics camera_;
};

#if POSEFOREST_HAS_RENDERER
class RenderedEvalSource final : public EvalFrameSource {
 public:
  RenderedEvalSource(SourceSpec spec, std::unique_ptr<renderer::SyntheticRenderer> r)
      : spec_(std::move(spec)), renderer_(std::move(r)) {}
  Result<EvalFrame> Frame(uint64_t index) override {
    auto frame = renderer_->Render(spec_.seed, index);
    if (!frame.ok()) return frame.status();
    EvalFrame out{std::move(frame->depth), std::move(frame->labels), {}, std::move(frame->people)};
    out.people.resize(frame->joints.size());
    for (size_t k = 0; k < frame->joints.size(); ++k) {
      out.people[k].position = frame->joints[k];
      out.people[k].visible = frame->visible[k];
    }
    return out;
  }
  bool has_joints() const override { return true; }
  bool has_masks() const override { return renderer_->config().clutter.enabled(); }
  core::CameraIntrinsics camera() const override { return renderer_->config().camera; }
  uint64_t size() const override { return 0; }
  std::string Describe() const override {
    const int people = renderer_->config().max_people;
    std::string d = "rendered seed " + std::to_string(spec_.seed);
    if (!spec_.pose_library.empty())
      d += std::string(", ") +
           (spec_.clips == ClipSet::kTest    ? "test"
            : spec_.clips == ClipSet::kTrain ? "train"
                                             : "all") +
           " clips of " + spec_.pose_library;
    if (const std::string bodies = DescribeBodies(spec_); !bodies.empty()) d += ", bodies: " + bodies;
    d += ", " + std::to_string(renderer_->config().min_people) +
         (people > renderer_->config().min_people ? ".." + std::to_string(people) : std::string()) +
         " people/frame";
    return d;
  }

 private:
  SourceSpec spec_;
  std::unique_ptr<renderer::SyntheticRenderer> renderer_;
};
#endif

// The ratio, or 0 when the bound is 0.
double Ratio(double a, double b) { return b > 0 ? a / b : 0.0; }
std::string RatioText(double r) {
  char c[16];
  std::snprintf(c, sizeof c, "%.2f", r);
  return c;
}

}  // namespace

uint64_t ConfusionMatrix::TruthTotal(int part) const {
  uint64_t n = 0;
  for (int p = 0; p < num_parts; ++p) n += counts[size_t(part * num_parts + p)];
  return n;
}

double ConfusionMatrix::PartAccuracy(int part) const {
  const uint64_t n = TruthTotal(part);
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  return double(counts[size_t(part * num_parts + part)]) / double(n);
}

double ConfusionMatrix::AveragePerClassAccuracy() const {
  double sum = 0;
  int k = 0;
  for (int c = 0; c < num_parts; ++c) {
    const double a = PartAccuracy(c);
    if (std::isnan(a)) continue;
    sum += a;
    ++k;
  }
  return k ? sum / k : std::numeric_limits<double>::quiet_NaN();
}

double ConfusionMatrix::PixelAccuracy() const {
  uint64_t right = 0, all = 0;
  for (int c = 0; c < num_parts; ++c) {
    right += counts[size_t(c * num_parts + c)];
    all += TruthTotal(c);
  }
  return all ? double(right) / double(all) : std::numeric_limits<double>::quiet_NaN();
}

int ConfusionMatrix::PartsPresent() const {
  int k = 0;
  for (int c = 0; c < num_parts; ++c) k += TruthTotal(c) > 0;
  return k;
}

void ConfusionMatrix::Add(const ConfusionMatrix& other) {
  for (size_t i = 0; i < counts.size(); ++i) counts[i] += other.counts[i];
}

core::Result<ConfusionMatrix> EvaluateForest(const core::Forest& forest, const SourceSpec& source,
                                             const EvalOptions& options) {
  if (forest.num_parts != core::kNumParts)
    return core::Status(
        core::ErrorCode::kInvalidArgument,
        "forest has " + std::to_string(forest.num_parts) + " parts; evaluation needs the 31-part taxonomy");
  auto src = MakeImageSource(source);
  if (!src.ok()) return src.status();
  runtime::Classifier classifier(forest);
  runtime::ClassifyOptions copt;
  copt.num_threads = options.threads;
  runtime::Classification out;
  ConfusionMatrix m;
  for (int i = 0; i < options.num_images; ++i) {
    auto frame = (*src)->Frame(options.first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    classifier.Classify(frame->depth, copt, &out);
    for (size_t p = 0; p < frame->depth.pixels.size(); ++p) {
      const uint8_t truth = frame->labels.pixels[p];
      if (frame->depth.pixels[p] == 0 || truth >= core::kNumParts) continue;
      const uint8_t pred = out.labels.pixels[p];
      if (pred >= core::kNumParts) continue;  // cannot happen for a foreground pixel
      ++m.counts[size_t(truth) * core::kNumParts + pred];
    }
  }
  return m;
}

Result<std::vector<runtime::PersonJoints>> ReadJointsJson(const std::string& path) {
  auto bytes = core::ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  auto bad = [&](const std::string& what) { return Status(ErrorCode::kDataLoss, path + ": " + what); };
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(bytes->begin(), bytes->end());
  } catch (const nlohmann::json::parse_error& e) {
    return bad("not valid JSON (" + std::string(e.what()) + ")");
  }
  const auto people_it = doc.is_object() ? doc.find("people") : doc.end();
  if (people_it == doc.end() || !people_it->is_array())
    return bad("no \"people\" array (expected joints_%06d.json from `poseforest render`)");
  std::vector<runtime::PersonJoints> people;
  for (const nlohmann::json& p : *people_it) {
    const std::string person = "person " + std::to_string(people.size());
    const auto joints = p.is_object() ? p.find("joints") : p.end();
    if (joints == p.end() || !joints->is_array()) return bad(person + ": no \"joints\" array");
    if (joints->size() != size_t(core::kNumJoints))
      return bad(person + ": " + std::to_string(joints->size()) + " joints, expected " +
                 std::to_string(core::kNumJoints));
    runtime::PersonJoints out;
    for (int j = 0; j < core::kNumJoints; ++j) {
      const std::string who =
          person + ", joint " + std::to_string(j) + " (" + std::string(core::JointName(j)) + ")";
      const nlohmann::json& joint = (*joints)[size_t(j)];
      if (!joint.is_object()) return bad(who + ": not an object");
      float xyz[3];
      const char* keys[3] = {"x", "y", "z"};
      for (int a = 0; a < 3; ++a) {
        const auto v = joint.find(keys[a]);
        if (v == joint.end()) return bad(who + ": missing \"" + keys[a] + "\"");
        if (!v->is_number() || !std::isfinite(v->get<float>()))
          return bad(who + ": \"" + keys[a] + "\" is not a number");
        xyz[a] = v->get<float>();
      }
      out.position[size_t(j)] = Eigen::Vector3f(xyz[0], xyz[1], xyz[2]);
      const auto visible = joint.find("visible");
      if (visible == joint.end()) return bad(who + ": missing \"visible\"");
      if (!visible->is_boolean()) return bad(who + ": \"visible\" must be true or false");
      out.visible[size_t(j)] = visible->get<bool>();
    }
    people.push_back(out);
  }
  return people;
}

Result<std::unique_ptr<EvalFrameSource>> MakeEvalFrameSource(const SourceSpec& source, int people) {
  if (people < 0 || people > 8)
    return Status(ErrorCode::kInvalidArgument, "people = " + std::to_string(people) + ": must be in 0..8");
  if (people > 0 && source.kind != SourceKind::kRendered)
    return Status(ErrorCode::kInvalidArgument,
                  "--people needs a rendered test set (a job's test_set with source.rendered); a folder or "
                  "procedural set has its people already");
  switch (source.kind) {
    case SourceKind::kProcedural:
      return std::unique_ptr<EvalFrameSource>(new ProceduralEvalSource(source));
    case SourceKind::kDataset: {
      auto probe = MakeImageSource(source);  // checks the folder, counts frames
      if (!probe.ok()) return probe.status();
      std::error_code ec;
      const bool joints =
          std::filesystem::exists(IndexedPath(source.folder, "joints", source.first_index, "json"), ec);
      const bool masks =
          std::filesystem::exists(IndexedPath(source.folder, "mask", source.first_index, "png"), ec);
      core::CameraIntrinsics camera = core::CameraIntrinsics::KinectV1();
      const std::string camera_file = (std::filesystem::path(source.folder) / "camera.txt").string();
      if (std::filesystem::exists(camera_file, ec)) {
        auto model = runtime::ReadCameraModelFile(camera_file);
        if (!model.ok()) return model.status();
        camera = model->intrinsics;
      }
      return std::unique_ptr<EvalFrameSource>(
          new DatasetEvalSource(source, (*probe)->size(), joints, masks, camera));
    }
    case SourceKind::kRendered: {
#if POSEFOREST_HAS_RENDERER
      // The job's scene (poses, bodies in job order), as the training frames are rendered;
      // --people overrides the number of people.
      renderer::SceneConfig scene;
      POSEFOREST_RETURN_IF_ERROR(ApplySceneOptions(source, &scene));
      if (people > 0) scene.min_people = scene.max_people = people;
      auto r = renderer::SyntheticRenderer::Create(scene);
      if (!r.ok()) return r.status();
      return std::unique_ptr<EvalFrameSource>(new RenderedEvalSource(source, std::move(*r)));
#else
      return Status(ErrorCode::kUnimplemented, "rendered test set: this build has no synthetic renderer");
#endif
    }
  }
  return Status(ErrorCode::kInternal, "unknown source kind");
}

namespace {
bool HasJointTaxonomy(const core::Forest& forest) {
  return forest.num_parts == core::kNumParts && forest.part_names == core::Forest::DefaultPartNames();
}
void AddConfusion(const EvalFrame& frame, const core::LabelImage& predicted, ConfusionMatrix* m) {
  for (size_t p = 0; p < frame.depth.pixels.size(); ++p) {
    const uint8_t truth = frame.labels.pixels[p];
    if (frame.depth.pixels[p] == 0 || truth >= core::kNumParts) continue;
    const uint8_t pred = predicted.pixels[p];
    if (pred >= core::kNumParts) continue;
    ++m->counts[size_t(truth) * core::kNumParts + pred];
  }
}
double MsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

// The frame with every pixel outside `keep` (nonzero) set to 0: what a segmentation hands the
// forest.
EvalFrame Masked(const EvalFrame& frame, const core::LabelImage& keep) {
  EvalFrame m;
  m.depth = frame.depth;
  m.labels = frame.labels;
  for (size_t p = 0; p < m.depth.pixels.size(); ++p)
    if (keep.pixels[p] == 0) m.depth.pixels[p] = 0;
  return m;
}

// Segmentation of one frame against its ground-truth masks (IoU per person), and the forest on
// the frame masked by the truth ("clean") and by the segmentation.
void ScoreSegmentation(const runtime::Classifier& classifier, const runtime::ClassifyOptions& copt,
                       const runtime::ProposalOptions& ms, bool joints, int index, const EvalFrame& frame,
                       runtime::SegmentationResult* seg, Evaluation* e) {
  const auto t = std::chrono::steady_clock::now();
  runtime::SegmentationOptions so;
  so.presegmented = false;  // a frame of one person alone would pass unchanged anyway
  runtime::SegmentPeople(frame.depth, e->camera, so, seg);
  e->segment_ms += MsSince(t);
  int truth_people = 0;
  std::vector<int> pixels(256, 0);
  for (uint8_t k : frame.person_masks.pixels) ++pixels[k];
  for (int k = 1; k < 256; ++k) {
    if (pixels[size_t(k)] == 0) continue;
    ++truth_people;
    PersonSegmentation p{index, k, pixels[size_t(k)], 0.0};
    for (int j = 1; j <= int(seg->people.size()); ++j)
      p.iou = std::max(p.iou, runtime::MaskIoU(frame.person_masks, k, seg->labels, j));
    e->segmentation.push_back(p);
  }
  e->frames_right_count += truth_people == int(seg->people.size());
  runtime::Classification out;
  for (int pass = 0; pass < 2; ++pass) {
    const EvalFrame m = Masked(frame, pass == 0 ? frame.person_masks : seg->labels);
    classifier.Classify(m.depth, copt, &out);
    AddConfusion(m, out.labels, pass == 0 ? &e->clean_confusion : &e->segmented_confusion);
    if (joints)
      (pass == 0 ? e->clean_mean_shift : e->segmented_mean_shift)
          .AddFrame(runtime::ProposeJointsFromClassification(m.depth, out, ms), frame.people);
  }
}
}  // namespace

double Evaluation::MeanIoU() const {
  if (segmentation.empty()) return 0;
  double sum = 0;
  for (const PersonSegmentation& p : segmentation) sum += p.iou;
  return sum / double(segmentation.size());
}

Result<Evaluation> EvaluateForestJoints(const core::Forest& forest, const SourceSpec& source,
                                        const JointEvalOptions& options) {
  if (forest.num_parts != core::kNumParts)
    return Status(ErrorCode::kInvalidArgument, "forest has " + std::to_string(forest.num_parts) +
                                                   " parts; evaluation needs the 31-part taxonomy");
  auto src = MakeEvalFrameSource(source, options.people);
  if (!src.ok()) return src.status();
  Evaluation e{.mean_shift = runtime::JointApEvaluator(options.distance_m),
               .fast = runtime::JointApEvaluator(options.distance_m),
               .upper_bound = runtime::JointApEvaluator(options.distance_m),
               .clean_mean_shift = runtime::JointApEvaluator(options.distance_m),
               .segmented_mean_shift = runtime::JointApEvaluator(options.distance_m)};
  using Segment = JointEvalOptions::Segment;
  if (options.segment == Segment::kOn && !(*src)->has_masks())
    return Status(ErrorCode::kInvalidArgument,
                  (*src)->Describe() +
                      ": has no ground-truth person masks (render with --clutter, "
                      "--occluders or --masks)");
  e.segmented = options.segment != Segment::kOff && (*src)->has_masks();
  // Frames of another focal length: the forest's offsets rescaled (runtime/camera_model.h).
  e.camera = (*src)->camera();
  e.rescaled = options.rescale && !runtime::SameFocalLength(forest, e.camera.fx, e.camera.fy);
  const core::Forest scaled =
      e.rescaled ? runtime::ForestForFocalLength(forest, e.camera.fx, e.camera.fy) : core::Forest();
  const core::Forest& model = e.rescaled ? scaled : forest;
  e.distance_m = options.distance_m;
  e.ran_fast = options.fast;
  e.ran_upper_bound = options.upper_bound;
  e.has_joints = (*src)->has_joints() && HasJointTaxonomy(forest);
  // Each method with its own set (core::Forest::ProposalParamsFor), unless given.
  const auto ms_choice = forest.ProposalParamsFor(false), fast_choice = forest.ProposalParamsFor(true);
  e.params_given = options.params.has_value();
  e.params = e.params_given ? *options.params : ms_choice.params;
  e.params_source = ms_choice.source;
  e.learned_params = !e.params_given && ms_choice.source == core::ProposalParamsSource::kLearned;
  e.fast_params_given = options.fast_params.has_value();
  e.fast_params = e.fast_params_given ? *options.fast_params : fast_choice.params;
  e.fast_params_source = fast_choice.source;
  runtime::Classifier classifier(model);
  runtime::ClassifyOptions copt;
  copt.num_threads = options.threads;
  // The compact per-foreground-pixel sums (what the proposals read; the confusion matrix uses
  // the classifier's argmax labels, computed from the same sums).
  copt.want_foreground_distributions = e.has_joints;
  copt.want_foreground_leaves = e.has_joints && options.votes && classifier.forest().offset_votes.has_value();
  copt.pixel_stride = options.pixel_stride;
  runtime::ProposalOptions ms;
  ms.params = e.params;
  ms.num_threads = options.threads;
  ms.camera = e.camera;
  runtime::ProposalOptions fast = ms;
  fast.method = runtime::ProposalMethod::kFastClustering;
  fast.params = e.fast_params;
  // The skeleton's confidence: the forest's calibration if measured for mean shift.
  const core::ConfidenceCalibration* calibration = forest.CalibrationFor(/*fast_clustering=*/false);
  e.calibrated = calibration != nullptr;
  runtime::Classification out;
  runtime::SegmentationResult seg;
  for (int i = 0; i < options.num_images; ++i) {
    auto frame = (*src)->Frame(options.first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    if (e.segmented && (frame->person_masks.width != frame->depth.width ||
                        frame->person_masks.height != frame->depth.height))
      return Status(ErrorCode::kDataLoss, (*src)->Describe() + ": frame " +
                                              std::to_string(options.first_index + uint64_t(i)) +
                                              " has no person mask of the depth's size");
    auto t = std::chrono::steady_clock::now();
    classifier.Classify(frame->depth, copt, &out);
    e.classify_ms += MsSince(t);
    AddConfusion(*frame, out.labels, &e.confusion);
    ++e.frames;
    if (e.has_joints) {
      e.people += int(frame->people.size());
      t = std::chrono::steady_clock::now();
      const auto proposals = runtime::ProposeJointsFromClassification(frame->depth, out, ms);
      e.mean_shift.AddFrame(proposals, frame->people);
      e.mean_shift_ms += MsSince(t);
      if (frame->people.size() == 1) {
        // The skeleton as `live` builds it: the person's mask is the ground-truth mask when the
        // frames have one (clutter), else every pixel with depth.
        const bool has_mask = frame->person_masks.width == frame->depth.width &&
                              frame->person_masks.height == frame->depth.height;
        core::LabelImage mask(frame->depth.width, frame->depth.height, 0);
        for (size_t k = 0; k < mask.pixels.size(); ++k)
          mask.pixels[k] = has_mask ? (frame->person_masks.pixels[k] == 1) : (frame->depth.pixels[k] ? 1 : 0);
        runtime::SkeletonOptions so;
        so.fit = options.skeleton_fit;
        so.agree_radius_m = options.agree_radius_m;
        so.use_tracking_model = options.tracking_model;
        // The forest's offset votes (format 1.5), when it has them and they are not turned off.
        std::vector<runtime::PersonVotes> votes;
        if (options.votes && classifier.forest().offset_votes)
          votes = runtime::CastVotes(classifier.forest(), frame->depth, mask, 1, ms.camera, {}, &out);
        const auto& model = classifier.forest().tracking_model;
        const auto skeletons = runtime::BuildSkeletons(proposals, mask, 1, frame->depth, ms.camera, calibration, so,
                                                       votes.empty() ? nullptr : &votes, model ? &*model : nullptr);
        if (!skeletons.empty()) {
          auto& acc = e.skeleton;
          ++acc.frames;
          const auto& truth = frame->people[0];
          for (int j = 0; j < core::kNumJoints; ++j) {
            const auto& joint = skeletons[0].joints[size_t(j)];
            const bool near =
                joint.found && (joint.position_m - truth.position[size_t(j)]).norm() <= options.distance_m;
            const bool visible = truth.visible[size_t(j)];
            acc.visible[size_t(j)] += visible;
            acc.tracked_within[size_t(j)] += visible && joint.tracked && near;
            acc.found_within[size_t(j)] += visible && near;
            acc.hidden[size_t(j)] += !visible;
            acc.hidden_within[size_t(j)] +=
                !visible && joint.found && (joint.position_m - truth.position[size_t(j)]).norm() <= 0.15f;
            acc.tracked[size_t(j)] += joint.tracked;
            acc.tracked_right[size_t(j)] += joint.tracked && near;
            acc.untracked[size_t(j)] += !joint.tracked;
            acc.untracked_invisible[size_t(j)] += !joint.tracked && !visible;
          }
        }
      }
      if (options.fast) {
        t = std::chrono::steady_clock::now();
        e.fast.AddFrame(runtime::ProposeJointsFromClassification(frame->depth, out, fast), frame->people);
        e.fast_ms += MsSince(t);
      }
      if (options.upper_bound)
        e.upper_bound.AddFrame(
            runtime::ProposeJoints(frame->depth,
                                   runtime::ProbabilitiesFromLabels(frame->depth, frame->labels), ms),
            frame->people);
    }
    if (e.segmented) ScoreSegmentation(classifier, copt, ms, e.has_joints, i, *frame, &seg, &e);
    if (options.progress) options.progress(i + 1, options.num_images);
  }
  return e;
}

std::string FormatSkeletonTable(const Evaluation& e) {
  const auto& a = e.skeleton;
  std::string out;
  char buf[640];
  std::snprintf(
      buf, sizeof buf,
      "skeleton accuracy (what `live` reports: per joint one position, tracked or not; %d one-person "
      "frames, D = %.2f m, confidence %s):\n",
      a.frames, double(e.distance_m), e.calibrated ? "calibrated (JCAL)" : "the uncalibrated fallback");
  out += buf;
  std::snprintf(buf, sizeof buf, "%-11s %8s %16s %16s %18s %14s %18s\n", "joint", "visible", "tracked within D",
                "tracked & right", "not tracked right", "found within", "hidden: in 0.15 m");
  out += buf;
  auto ratio = [](int n, int d) { return d ? double(n) / d : 0.0; };
  double within = 0, right = 0, untracked = 0, found = 0, hidden = 0;
  int joints = 0, untracked_joints = 0, tracked_joints = 0, hidden_joints = 0;
  for (int j = 0; j < core::kNumJoints; ++j) {
    const size_t k = size_t(j);
    auto cell = [&](int n, int d) {
      char c[32];
      if (d)
        std::snprintf(c, sizeof c, "%.3f (%d)", ratio(n, d), d);
      else
        std::snprintf(c, sizeof c, "- (0)");
      return std::string(c);
    };
    std::snprintf(buf, sizeof buf, "%-11s %8d %16s %16s %18s %14.3f %18s\n", std::string(core::JointName(j)).c_str(),
                  a.visible[k], cell(a.tracked_within[k], a.visible[k]).c_str(),
                  cell(a.tracked_right[k], a.tracked[k]).c_str(),
                  cell(a.untracked_invisible[k], a.untracked[k]).c_str(), ratio(a.found_within[k], a.visible[k]),
                  cell(a.hidden_within[k], a.hidden[k]).c_str());
    if (a.hidden[k]) hidden += ratio(a.hidden_within[k], a.hidden[k]), ++hidden_joints;
    out += buf;
    if (a.visible[k]) within += ratio(a.tracked_within[k], a.visible[k]), found += ratio(a.found_within[k], a.visible[k]), ++joints;
    if (a.tracked[k]) right += ratio(a.tracked_right[k], a.tracked[k]), ++tracked_joints;
    if (a.untracked[k]) untracked += ratio(a.untracked_invisible[k], a.untracked[k]), ++untracked_joints;
  }
  std::snprintf(
      buf, sizeof buf,
      "mean over joints: tracked within %.2f m when visible %.3f, tracked & right %.3f, not tracked right "
      "%.3f, found within %.3f, hidden placed within 0.15 m %.3f\n(columns: fraction (count): of the frames where the "
      "joint is visible / tracked / not tracked / hidden; found within: visible and the position, tracked or not, "
      "within D)\n",
      double(e.distance_m), joints ? within / joints : 0.0, tracked_joints ? right / tracked_joints : 0.0,
      untracked_joints ? untracked / untracked_joints : 0.0, joints ? found / joints : 0.0,
      hidden_joints ? hidden / hidden_joints : 0.0);
  out += buf;
  return out;
}

std::string FormatJointApTable(const Evaluation& e) {
  std::string s;
  char line[320];
  std::snprintf(
      line, sizeof line,
      "joint average precision (section 4: D = %.2f m, every proposal counts), %d frames, %d people;\n",
      double(e.distance_m), e.frames, e.people);
  s += line;
  // Each method's own parameter set, and where it came from.
  auto params_line = [&](const char* method, const core::ProposalParams& params,
                         core::ProposalParamsSource source, bool given) {
    double b = 0, lambda = 0, zeta = 0;
    for (const auto& p : params) b += p.bandwidth_m, lambda += p.prob_threshold, zeta += p.z_offset_m;
    std::snprintf(line, sizeof line,
                  "proposal parameters, %s: %s, mean b = %.3f m, lambda = %.3f, zeta = %.3f m\n", method,
                  given ? "given" : core::DescribeProposalParamsSource(source), b / core::kNumJoints,
                  lambda / core::kNumJoints, zeta / core::kNumJoints);
    s += line;
  };
  params_line(e.ran_upper_bound ? "mean shift (and gt-parts)" : "mean shift", e.params, e.params_source,
              e.params_given);
  if (e.ran_fast) params_line("fast clustering", e.fast_params, e.fast_params_source, e.fast_params_given);
  std::snprintf(line, sizeof line, "%-11s %9s %9s %9s %11s %9s\n", "joint", "visible", "AP mean", "AP fast",
                "AP gt-parts", "mean/gt");
  s += line;
  // A method that did not run prints "-", never a misleading 0.
  auto cell = [](bool ran, double v) {
    char c[16];
    if (ran)
      std::snprintf(c, sizeof c, "%.3f", v);
    else
      std::snprintf(c, sizeof c, "-");
    return std::string(c);
  };
  for (int j = 0; j < core::kNumJoints; ++j) {
    const double ms = e.mean_shift.AveragePrecision(j), up = e.upper_bound.AveragePrecision(j);
    std::snprintf(line, sizeof line, "%-11s %9d %9.3f %9s %11s %9s\n",
                  std::string(core::JointName(j)).c_str(), e.mean_shift.positives(j), ms,
                  cell(e.ran_fast, e.fast.AveragePrecision(j)).c_str(), cell(e.ran_upper_bound, up).c_str(),
                  e.ran_upper_bound ? RatioText(Ratio(ms, up)).c_str() : "-");
    s += line;
  }
  const double ms = e.mean_shift.MeanAveragePrecision(), up = e.upper_bound.MeanAveragePrecision();
  std::snprintf(line, sizeof line, "%-11s %9s %9.3f %9s %11s %9s\n", "mAP", "", ms,
                cell(e.ran_fast, e.fast.MeanAveragePrecision()).c_str(), cell(e.ran_upper_bound, up).c_str(),
                e.ran_upper_bound ? RatioText(Ratio(ms, up)).c_str() : "-");
  s += line;
  s += "mAP: mean shift " + cell(true, ms);
  if (e.ran_fast) s += ", fast clustering " + cell(true, e.fast.MeanAveragePrecision());
  if (e.ran_upper_bound) {
    std::snprintf(line, sizeof line, "; upper bound (ground-truth parts) %.3f; inferred / upper bound %.2f",
                  up, Ratio(ms, up));
    s += line;
  }
  s += "\n(the paper, synthetic test set: mean shift 0.731, fast 0.677)\n";
  return s;
}

Status WritePrCurves(const Evaluation& e, const std::string& dir) {
  if (!e.has_joints)
    return Status(ErrorCode::kInvalidArgument, "no joints in this test set: no precision-recall curves");
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status(ErrorCode::kIo, dir + ": cannot create folder: " + ec.message());
  const core::Rgb blue{31, 119, 180}, orange{255, 127, 14}, green{44, 160, 44};
  std::vector<runtime::PrPanel> panels;
  for (int j = 0; j < core::kNumJoints; ++j) {
    runtime::PrPanel p{std::string(core::JointName(j)), {}};
    p.series.push_back({"mean shift", blue, e.mean_shift.Curve(j), e.mean_shift.AveragePrecision(j)});
    if (e.fast.positives(j))
      p.series.push_back({"fast", orange, e.fast.Curve(j), e.fast.AveragePrecision(j)});
    if (e.upper_bound.positives(j))
      p.series.push_back(
          {"gt parts (upper bound)", green, e.upper_bound.Curve(j), e.upper_bound.AveragePrecision(j)});
    panels.push_back(std::move(p));
  }
  const auto grid = runtime::PrCurvesFigure(panels, 4);
  POSEFOREST_RETURN_IF_ERROR(runtime::WriteRgbPng((std::filesystem::path(dir) / "pr_joints.png").string(),
                                                  grid.width, grid.height, grid.rgb));
  runtime::PrPanel mean{"mean over joints (mAP)", {}};
  mean.series.push_back({"mean shift", blue, e.mean_shift.MeanCurve(), e.mean_shift.MeanAveragePrecision()});
  if (e.fast.MeanAveragePrecision() > 0 || e.fast.positives(0))
    mean.series.push_back({"fast", orange, e.fast.MeanCurve(), e.fast.MeanAveragePrecision()});
  if (e.upper_bound.positives(0) || e.upper_bound.MeanAveragePrecision() > 0)
    mean.series.push_back(
        {"gt parts (upper bound)", green, e.upper_bound.MeanCurve(), e.upper_bound.MeanAveragePrecision()});
  const auto big = runtime::PrCurvesFigure({mean}, 1, 720, 540, 2);
  return runtime::WriteRgbPng((std::filesystem::path(dir) / "pr_mean.png").string(), big.width, big.height,
                              big.rgb);
}

Result<NamedSource> ResolveSourceArgument(const std::string& set, JobSource which) {
  NamedSource out;
  if (set.rfind("procedural:", 0) == 0) {
    out.source.kind = SourceKind::kProcedural;
    char* end = nullptr;
    const char* digits = set.c_str() + 11;
    out.source.seed = std::strtoull(digits, &end, 10);
    if (end == digits || *end != '\0')
      return Status(ErrorCode::kInvalidArgument, set + ": expected procedural:SEED with an integer seed");
    out.source.width = 320;
    out.source.height = 240;
    return out;
  }
  if (set.size() > 10 && set.substr(set.size() - 10) == ".textproto") {
    auto job = LoadJob(set);
    if (!job.ok()) return job.status();
    if (which == JobSource::kTraining) {
      out.source = job->source;
      out.num_images = 50;
      return out;
    }
    if (!job->has_test_set) return Status(ErrorCode::kInvalidArgument, set + " has no test_set { }");
    out.source = job->test_source;
    out.num_images = job->test_images;
    return out;
  }
  out.source.kind = SourceKind::kDataset;
  out.source.folder = set;
  auto probe = MakeImageSource(out.source);
  if (!probe.ok()) return probe.status();
  out.num_images = int(std::min<uint64_t>((*probe)->size(), 1'000'000));
  return out;
}

Result<std::vector<runtime::ValidationFrame>> MakeValidationFrames(
    const core::Forest& forest, const SourceSpec& source, int num_images, uint64_t first_index, int threads,
    int people, const std::function<void(int done, int total)>& progress, core::CameraIntrinsics* camera) {
  if (!HasJointTaxonomy(forest))
    return Status(ErrorCode::kInvalidArgument,
                  "the forest has " + std::to_string(forest.num_parts) +
                      " parts; joint proposals need the paper's 31-part taxonomy");
  auto src = MakeEvalFrameSource(source, people);
  if (!src.ok()) return src.status();
  if (!(*src)->has_joints())
    return Status(ErrorCode::kInvalidArgument,
                  (*src)->Describe() +
                      ": has no ground-truth joints (use rendered frames or a `poseforest render` folder)");
  // Frames of another focal length (a render folder's camera.txt): the forest rescaled, as eval does.
  const core::CameraIntrinsics cam = (*src)->camera();
  if (camera) *camera = cam;
  const bool rescale = !runtime::SameFocalLength(forest, cam.fx, cam.fy);
  const core::Forest scaled = rescale ? runtime::ForestForFocalLength(forest, cam.fx, cam.fy) : core::Forest();
  runtime::Classifier classifier(rescale ? scaled : forest);
  runtime::ClassifyOptions copt;
  copt.num_threads = threads;
  copt.want_foreground_distributions = true;  // compact sums: ProbabilitiesFromClassification reads them
  runtime::Classification out;
  std::vector<runtime::ValidationFrame> frames;
  frames.reserve(size_t(num_images));
  for (int i = 0; i < num_images; ++i) {
    auto frame = (*src)->Frame(first_index + uint64_t(i));
    if (!frame.ok()) return frame.status();
    classifier.Classify(frame->depth, copt, &out);
    runtime::ValidationFrame v;
    v.probs = runtime::ProbabilitiesFromClassification(frame->depth, out, threads);
    v.depth = std::move(frame->depth);
    v.people = std::move(frame->people);
    frames.push_back(std::move(v));
    if (progress) progress(i + 1, num_images);
  }
  return frames;
}

std::string FormatAccuracyTable(const ConfusionMatrix& m) {
  std::string s = "part            pixels   accuracy\n";
  char line[96];
  for (int c = 0; c < m.num_parts; ++c) {
    const uint64_t n = m.TruthTotal(c);
    if (n == 0) {
      std::snprintf(line, sizeof(line), "%-12s %9s   %8s\n", std::string(core::PartName(c)).c_str(), "0",
                    "-");
    } else {
      std::snprintf(line, sizeof(line), "%-12s %9llu   %7.2f%%\n", std::string(core::PartName(c)).c_str(),
                    static_cast<unsigned long long>(n), 100.0 * m.PartAccuracy(c));
    }
    s += line;
  }
  std::snprintf(line, sizeof(line),
                "average per-class accuracy: %.2f%% over %d parts (pixel accuracy %.2f%%)\n",
                100.0 * m.AveragePerClassAccuracy(), m.PartsPresent(), 100.0 * m.PixelAccuracy());
  s += line;
  return s;
}

std::string FormatConfusionText(const ConfusionMatrix& m) {
  // Rows: truth; columns: predicted part index; entries: percent of the row, rounded.
  std::string s = "confusion (rows = truth, columns = predicted part index, % of row)\n          ";
  char cell[32];
  for (int p = 0; p < m.num_parts; ++p) {
    std::snprintf(cell, sizeof(cell), "%4d", p);
    s += cell;
  }
  s += "\n";
  for (int t = 0; t < m.num_parts; ++t) {
    std::snprintf(cell, sizeof(cell), "%2d %-7.7s", t, std::string(core::PartName(t)).c_str());
    s += cell;
    const uint64_t n = m.TruthTotal(t);
    for (int p = 0; p < m.num_parts; ++p) {
      if (n == 0) {
        s += "   .";
        continue;
      }
      const double pct = 100.0 * double(m.counts[size_t(t * m.num_parts + p)]) / double(n);
      if (m.counts[size_t(t * m.num_parts + p)] == 0)
        s += "   .";
      else {
        std::snprintf(cell, sizeof(cell), "%4.0f", pct);
        s += cell;
      }
    }
    s += "\n";
  }
  return s;
}

core::Status WriteConfusionPng(const ConfusionMatrix& m, const std::string& path, int cell_px) {
  const int n = m.num_parts, size = n * cell_px + 1;
  std::vector<uint8_t> rgb(static_cast<size_t>(size) * size_t(size) * 3, 64);  // grid lines: dark grey
  for (int t = 0; t < n; ++t) {
    const uint64_t total = m.TruthTotal(t);
    for (int p = 0; p < n; ++p) {
      const double f = total ? double(m.counts[size_t(t * n + p)]) / double(total) : 0.0;
      const auto v = uint8_t(std::lround(255.0 * std::sqrt(f)));  // sqrt: small confusions visible
      const uint8_t r = t == p ? uint8_t(v / 2) : v, g = v, b = t == p ? uint8_t(v / 2) : v;
      for (int y = t * cell_px + 1; y < (t + 1) * cell_px; ++y)
        for (int x = p * cell_px + 1; x < (p + 1) * cell_px; ++x) {
          uint8_t* px = &rgb[(size_t(y) * size_t(size) + size_t(x)) * 3];
          px[0] = r;
          px[1] = g;
          px[2] = b;
        }
    }
  }
  return runtime::WriteRgbPng(path, size, size, rgb);
}

}  // namespace poseforest::engine
