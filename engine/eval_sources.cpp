#include "engine/evaluation.h"

// The test-set frames of `eval`, `tune-joints`, `learn-votes` and `learn-tracking`: procedural,
// a `poseforest render` folder (joints and person masks read back) or rendered from the job's
// scene; and how a command-line test-set argument names one.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>

#include "runtime/camera_model.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#if POSEFOREST_HAS_RENDERER
#include "engine/rendered_scene.h"
#include "renderer/synthetic_source.h"
#endif

namespace poseforest::engine {

using core::ErrorCode;
using core::Result;
using core::Status;

namespace {

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
                    DatasetFramePath(spec_.folder, "depth", file, "png") + " is " +
                        std::to_string(out.depth.width) + "x" + std::to_string(out.depth.height) +
                        " but the folder's camera is " + std::to_string(camera_.width) + "x" +
                        std::to_string(camera_.height));
    if (joints_) {
      auto people = ReadJointsJson(DatasetFramePath(spec_.folder, "joints", file, "json"));
      if (!people.ok()) return people.status();
      out.people = std::move(*people);
    }
    if (masks_) {
      const std::string path = DatasetFramePath(spec_.folder, "mask", file, "png");
      auto bytes = core::ReadFileBytes(path);
      if (!bytes.ok()) return bytes.status();
      // 8-bit greyscale only, refused from the header before decoding (runtime/image_io.h).
      auto mask = runtime::DecodeLabelPng(*bytes, path);
      if (!mask.ok()) return mask.status();
      if (mask->width != out.depth.width || mask->height != out.depth.height)
        return Status(ErrorCode::kDataLoss,
                      path + ": a person mask must have its depth image's size; it is " +
                          std::to_string(mask->width) + "x" + std::to_string(mask->height) + ", the depth " +
                          std::to_string(out.depth.width) + "x" + std::to_string(out.depth.height));
      out.person_masks = std::move(*mask);
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

}  // namespace

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
          std::filesystem::exists(DatasetFramePath(source.folder, "joints", source.first_index, "json"), ec);
      const bool masks =
          std::filesystem::exists(DatasetFramePath(source.folder, "mask", source.first_index, "png"), ec);
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

}  // namespace poseforest::engine
