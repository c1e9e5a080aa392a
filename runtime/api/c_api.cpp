// The C API (poseforest/poseforest.h) over the runtime: the only code of libposeforest whose
// symbols are exported. No exception leaves a pf_ function: each catches, and turns what it
// caught into a status and the calling thread's message.
#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "poseforest/poseforest.h"
#include "runtime/api/skeleton_layout.h"
#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "runtime/joint_proposals.h"
#include "runtime/skeleton_pipeline.h"

struct pf_forest {
  poseforest::core::Forest forest;
  std::string source;  ///< the file or `source` it was loaded from, for messages
  bool has_joints = false;
};

struct pf_skeleton_stream {
  std::unique_ptr<poseforest::runtime::SkeletonPipeline> pipeline;
  poseforest::runtime::SkeletonFrame frame;  ///< the last frame's result (storage reused)
  std::vector<pf_skeleton> last;             ///< its skeletons in the C layout
};

namespace {

using poseforest::core::ErrorCode;
using poseforest::core::Status;

thread_local std::string g_last_error;

constexpr int kMaxSide = 32768;

pf_status ToPf(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk:
      return PF_OK;
    case ErrorCode::kInvalidArgument:
      return PF_INVALID_ARGUMENT;
    case ErrorCode::kDataLoss:
      return PF_DATA_LOSS;
    case ErrorCode::kVersionMismatch:
      return PF_VERSION_MISMATCH;
    case ErrorCode::kIo:
      return PF_IO;
    case ErrorCode::kNotFound:
      return PF_NOT_FOUND;
    case ErrorCode::kUnimplemented:
      return PF_UNIMPLEMENTED;
    case ErrorCode::kInternal:
      return PF_INTERNAL;
  }
  return PF_INTERNAL;
}

/// Records `st` as this thread's last message (its ToString(), as the CLI prints it).
pf_status Fail(const Status& st) {
  g_last_error = st.ToString();
  return ToPf(st.code());
}
pf_status Fail(pf_status code, const std::string& message) {
  g_last_error = std::string(pf_status_name(code)) + ": " + message;
  return code;
}
pf_status Succeed() {
  g_last_error.clear();
  return PF_OK;
}

/// Runs `body` (returning pf_status) with every exception turned into a status.
template <typename F>
pf_status Guard(const char* function, F&& body) noexcept {
  try {
    return body();
  } catch (const std::bad_alloc&) {
    return Fail(PF_OUT_OF_MEMORY, std::string(function) + ": out of memory");
  } catch (const std::exception& e) {
    return Fail(PF_INTERNAL, std::string(function) + ": " + e.what());
  } catch (...) {
    return Fail(PF_INTERNAL, std::string(function) + ": unknown exception");
  }
}

pf_status Adopt(poseforest::core::Result<poseforest::core::Forest> loaded, std::string source,
                pf_forest** out) {
  if (!loaded.ok()) return Fail(loaded.status());
  auto* f = new pf_forest{std::move(*loaded), std::move(source), false};
  f->has_joints = f->forest.num_parts == poseforest::core::kNumParts &&
                  f->forest.part_names == poseforest::core::Forest::DefaultPartNames();
  *out = f;
  return Succeed();
}

/// Checks the image arguments shared by pf_classify and pf_propose_joints.
pf_status CheckImage(const char* function, const pf_forest* forest, const uint16_t* depth_mm, int width,
                     int height) {
  if (!forest) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": forest is NULL");
  if (!depth_mm) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": depth_mm is NULL");
  if (width < 1 || height < 1 || width > kMaxSide || height > kMaxSide)
    return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": image size " + std::to_string(width) + "x" +
                                         std::to_string(height) + " is outside 1..32768 per side");
  return PF_OK;
}

poseforest::core::DepthImage CopyDepth(const uint16_t* depth_mm, int width, int height) {
  poseforest::core::DepthImage depth(width, height);
  std::memcpy(depth.pixels.data(), depth_mm, depth.pixels.size() * sizeof(uint16_t));
  return depth;
}

pf_status TooSmall(const char* function, const char* what, size_t given, size_t needed, const char* unit) {
  return Fail(PF_BUFFER_TOO_SMALL, std::string(function) + ": " + what + " holds " + std::to_string(given) +
                                       " " + unit + ", needs " + std::to_string(needed));
}

/// Copies `all` to `out` under the buffer protocol (count set; nothing written if short).
pf_status CopySkeletons(const char* function, const std::vector<pf_skeleton>& all, pf_skeleton* out,
                        size_t capacity, size_t* count) {
  *count = all.size();
  if (all.size() > capacity) return TooSmall(function, "skeletons", capacity, all.size(), "skeletons");
  if (!all.empty()) std::memcpy(out, all.data(), all.size() * sizeof(pf_skeleton));
  return Succeed();
}

}  // namespace

extern "C" {

uint32_t pf_version(void) { return POSEFOREST_VERSION_NUMBER; }
const char* pf_version_string(void) { return POSEFOREST_VERSION_STRING; }

const char* pf_status_name(pf_status status) {
  switch (status) {
    case PF_OK:
      return "Ok";
    case PF_INVALID_ARGUMENT:
      return "InvalidArgument";
    case PF_DATA_LOSS:
      return "DataLoss";
    case PF_VERSION_MISMATCH:
      return "VersionMismatch";
    case PF_IO:
      return "Io";
    case PF_NOT_FOUND:
      return "NotFound";
    case PF_UNIMPLEMENTED:
      return "Unimplemented";
    case PF_INTERNAL:
      return "Internal";
    case PF_BUFFER_TOO_SMALL:
      return "BufferTooSmall";
    case PF_OUT_OF_MEMORY:
      return "OutOfMemory";
  }
  return "Unknown";
}

const char* pf_last_error_message(void) { return g_last_error.c_str(); }

pf_status pf_forest_load_file(const char* path, pf_forest** out) {
  return Guard("pf_forest_load_file", [&]() -> pf_status {
    if (!out) return Fail(PF_INVALID_ARGUMENT, "pf_forest_load_file: out is NULL");
    *out = nullptr;
    if (!path) return Fail(PF_INVALID_ARGUMENT, "pf_forest_load_file: path is NULL");
    return Adopt(poseforest::core::LoadForest(path), path, out);
  });
}

pf_status pf_forest_load_memory(const void* bytes, size_t size, const char* source, pf_forest** out) {
  return Guard("pf_forest_load_memory", [&]() -> pf_status {
    if (!out) return Fail(PF_INVALID_ARGUMENT, "pf_forest_load_memory: out is NULL");
    *out = nullptr;
    if (!bytes && size != 0) return Fail(PF_INVALID_ARGUMENT, "pf_forest_load_memory: bytes is NULL");
    const std::string name = source ? source : "memory";
    const auto* p = static_cast<const uint8_t*>(bytes);
    return Adopt(poseforest::core::ParseForest(std::span<const uint8_t>(p, p ? size : 0), name), name, out);
  });
}

void pf_forest_free(pf_forest* forest) { delete forest; }

int pf_forest_num_trees(const pf_forest* forest) { return forest ? int(forest->forest.trees.size()) : -1; }
int pf_forest_num_parts(const pf_forest* forest) { return forest ? forest->forest.num_parts : -1; }
int pf_forest_max_depth(const pf_forest* forest) { return forest ? int(forest->forest.max_depth()) : -1; }
size_t pf_forest_num_nodes(const pf_forest* forest) { return forest ? forest->forest.total_nodes() : 0; }
const char* pf_forest_part_name(const pf_forest* forest, int part) {
  if (!forest || part < 0 || part >= forest->forest.num_parts) return nullptr;
  return forest->forest.part_names[size_t(part)].c_str();
}
int pf_forest_has_joints(const pf_forest* forest) { return forest && forest->has_joints ? 1 : 0; }

int pf_num_joints(void) { return poseforest::core::kNumJoints; }
const char* pf_joint_name(int joint) {
  // JointName returns views of string literals, so .data() is NUL-terminated static storage.
  if (joint < 0 || joint >= poseforest::core::kNumJoints) return nullptr;
  return poseforest::core::JointName(joint).data();
}

const char* pf_joint_state_name(int32_t state) {
  // JointStateName returns views of string literals, so .data() is NUL-terminated static storage.
  if (state < PF_JOINT_NOT_TRACKED || state > PF_JOINT_TRACKED) return nullptr;
  return poseforest::runtime::JointStateName(poseforest::runtime::JointState(state)).data();
}

pf_status pf_classify(const pf_forest* forest, const uint16_t* depth_mm, int width, int height,
                      int num_threads, uint8_t* labels, size_t labels_len, float* distributions,
                      size_t distributions_len) {
  namespace core = poseforest::core;
  namespace rt = poseforest::runtime;
  return Guard("pf_classify", [&]() -> pf_status {
    if (pf_status st = CheckImage("pf_classify", forest, depth_mm, width, height); st != PF_OK) return st;
    if (!labels && !distributions)
      return Fail(PF_INVALID_ARGUMENT, "pf_classify: neither labels nor distributions asked for");
    if (num_threads < 0) return Fail(PF_INVALID_ARGUMENT, "pf_classify: num_threads < 0");
    const size_t pixels = size_t(width) * size_t(height);
    const size_t parts = size_t(forest->forest.num_parts);
    if (labels && labels_len < pixels) return TooSmall("pf_classify", "labels", labels_len, pixels, "bytes");
    if (distributions && distributions_len < pixels * parts)
      return TooSmall("pf_classify", "distributions", distributions_len, pixels * parts, "floats");

    const core::DepthImage depth = CopyDepth(depth_mm, width, height);
    rt::ClassifyOptions options;
    options.num_threads = num_threads;
    options.want_foreground_distributions = distributions != nullptr;
    rt::Classification c;
    rt::Classifier(forest->forest).Classify(depth, options, &c);
    if (labels) std::memcpy(labels, c.labels.pixels.data(), pixels);
    if (distributions) {
      // Exactly what `poseforest infer --distributions` writes to its .npy (infer_command.cpp):
      // zeros, then each foreground pixel's sums times one float reciprocal.
      std::memset(distributions, 0, pixels * parts * sizeof(float));
      const float norm = 1.0f / float(core::kLeafTotal * c.num_trees);
      for (size_t k = 0; k < c.foreground.size(); ++k) {
        float* row = distributions + size_t(c.foreground[k]) * parts;
        const uint16_t* sums = c.foreground_sums.data() + k * size_t(c.stride);
        for (size_t p = 0; p < parts; ++p) row[p] = float(sums[p]) * norm;
      }
    }
    return Succeed();
  });
}

pf_status pf_propose_joints(const pf_forest* forest, const uint16_t* depth_mm, int width, int height,
                            pf_proposal_method method, int num_threads, pf_joint_proposal* proposals,
                            size_t capacity, size_t* count, uint8_t* labels, size_t labels_len) {
  namespace core = poseforest::core;
  namespace rt = poseforest::runtime;
  return Guard("pf_propose_joints", [&]() -> pf_status {
    if (pf_status st = CheckImage("pf_propose_joints", forest, depth_mm, width, height); st != PF_OK)
      return st;
    if (!count) return Fail(PF_INVALID_ARGUMENT, "pf_propose_joints: count is NULL");
    *count = 0;
    if (!proposals && capacity != 0) return Fail(PF_INVALID_ARGUMENT, "pf_propose_joints: proposals is NULL");
    if (method != PF_MEAN_SHIFT && method != PF_FAST_CLUSTERING)
      return Fail(PF_INVALID_ARGUMENT, "pf_propose_joints: unknown method " + std::to_string(int(method)));
    if (num_threads < 0) return Fail(PF_INVALID_ARGUMENT, "pf_propose_joints: num_threads < 0");
    const size_t pixels = size_t(width) * size_t(height);
    if (labels && labels_len < pixels)
      return TooSmall("pf_propose_joints", "labels", labels_len, pixels, "bytes");
    if (!forest->has_joints)
      return Fail(Status(core::ErrorCode::kInvalidArgument,
                         forest->source +
                             ": joint proposals need a forest with the paper's 31-part taxonomy (" +
                             forest->forest.TaxonomyDifference() + ")"));

    // As `poseforest infer --joints` (infer_command.cpp): the forest's parameters for the method.
    rt::ProposalOptions options;
    options.method =
        method == PF_FAST_CLUSTERING ? rt::ProposalMethod::kFastClustering : rt::ProposalMethod::kMeanShift;
    options.params = forest->forest.ProposalParamsFor(method == PF_FAST_CLUSTERING).params;
    options.num_threads = num_threads;
    rt::ClassifyOptions classify_options;
    classify_options.num_threads = num_threads;
    classify_options.want_foreground_distributions = true;

    const core::DepthImage depth = CopyDepth(depth_mm, width, height);
    rt::Classification c;
    rt::Classifier(forest->forest).Classify(depth, classify_options, &c);
    const rt::FrameProposals found = rt::ProposeJointsFromClassification(depth, c, options);
    size_t n = 0;
    for (const auto& list : found) n += list.size();
    *count = n;
    if (n > capacity) return TooSmall("pf_propose_joints", "proposals", capacity, n, "proposals");
    size_t k = 0;
    for (int j = 0; j < core::kNumJoints; ++j)
      for (const rt::JointProposal& p : found[size_t(j)]) {
        pf_joint_proposal& o = proposals[k++];
        o.joint = j;
        for (int i = 0; i < 3; ++i) o.position_m[i] = p.position[i];
        o.pixel[0] = p.pixel.x();
        o.pixel[1] = p.pixel.y();
        o.confidence = p.confidence;
      }
    if (labels) std::memcpy(labels, c.labels.pixels.data(), pixels);
    return Succeed();
  });
}

pf_status pf_skeleton_stream_create(const pf_forest* forest, int num_threads, pf_skeleton_stream** out) {
  namespace rt = poseforest::runtime;
  return Guard("pf_skeleton_stream_create", [&]() -> pf_status {
    if (!out) return Fail(PF_INVALID_ARGUMENT, "pf_skeleton_stream_create: out is NULL");
    *out = nullptr;
    if (!forest) return Fail(PF_INVALID_ARGUMENT, "pf_skeleton_stream_create: forest is NULL");
    if (num_threads < 0) return Fail(PF_INVALID_ARGUMENT, "pf_skeleton_stream_create: num_threads < 0");
    if (!forest->has_joints)
      return Fail(Status(ErrorCode::kInvalidArgument,
                         forest->source + ": skeletons need a forest with the paper's 31-part taxonomy (" +
                             forest->forest.TaxonomyDifference() + ")"));
    rt::SkeletonPipelineOptions options;  // `poseforest live`'s defaults
    options.num_threads = num_threads;
    auto pipeline = rt::SkeletonPipeline::Create(forest->forest, options);
    if (!pipeline.ok()) return Fail(pipeline.status());
    auto stream = std::make_unique<pf_skeleton_stream>();
    stream->pipeline = std::move(*pipeline);
    *out = stream.release();
    return Succeed();
  });
}

void pf_skeleton_stream_free(pf_skeleton_stream* stream) { delete stream; }

pf_status pf_skeleton_stream_process(pf_skeleton_stream* stream, const uint16_t* depth_mm, int width,
                                     int height, double timestamp_s, pf_skeleton* skeletons, size_t capacity,
                                     size_t* count) {
  namespace rt = poseforest::runtime;
  const char* const function = "pf_skeleton_stream_process";
  return Guard(function, [&]() -> pf_status {
    if (!count) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": count is NULL");
    *count = 0;
    if (!stream) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": stream is NULL");
    if (!skeletons && capacity != 0)
      return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": skeletons is NULL");
    if (!depth_mm) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": depth_mm is NULL");
    if (width < 1 || height < 1 || width > kMaxSide || height > kMaxSide)
      return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": image size " + std::to_string(width) + "x" +
                                           std::to_string(height) + " is outside 1..32768 per side");
    if (!std::isfinite(timestamp_s))
      return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": timestamp_s is not finite");
    rt::Frame frame;
    frame.depth = CopyDepth(depth_mm, width, height);
    frame.timestamp_s = timestamp_s;
    frame.source = "pf_skeleton_stream";
    stream->pipeline->Process(frame, &stream->frame);
    stream->frame.depth = nullptr;  // pointed into `frame`
    stream->last.clear();
    for (const rt::Skeleton& s : stream->frame.skeletons)
      stream->last.push_back(poseforest::capi::ToPfSkeleton(s));
    return CopySkeletons(function, stream->last, skeletons, capacity, count);
  });
}

pf_status pf_skeleton_stream_last(const pf_skeleton_stream* stream, pf_skeleton* skeletons, size_t capacity,
                                  size_t* count) {
  const char* const function = "pf_skeleton_stream_last";
  return Guard(function, [&]() -> pf_status {
    if (!count) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": count is NULL");
    *count = 0;
    if (!stream) return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": stream is NULL");
    if (!skeletons && capacity != 0)
      return Fail(PF_INVALID_ARGUMENT, std::string(function) + ": skeletons is NULL");
    return CopySkeletons(function, stream->last, skeletons, capacity, count);
  });
}

}  // extern "C"
