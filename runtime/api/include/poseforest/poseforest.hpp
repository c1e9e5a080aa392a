// poseforest.hpp: the C++ API of the poseforest runtime, header-only over the C API
// (poseforest/poseforest.h), so the library exports C symbols only and a program built with
// another C++ standard library or compiler links it all the same. C++17.
// Reference: docs/runtime/api.md.
//
// Errors are exceptions of type poseforest::api::Error whose what() is the C API's message
// (the text `poseforest infer` prints). Thread safety is the C API's: a Forest may be used by
// many threads at once (const methods); moving or destroying it may not overlap other calls.
#ifndef POSEFOREST_POSEFOREST_HPP_
#define POSEFOREST_POSEFOREST_HPP_

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "poseforest/poseforest.h"

namespace poseforest::api {

/// A failed call: status() is the C status, what() its message ("DataLoss: f.pff: ...").
class Error : public std::runtime_error {
 public:
  Error(pf_status status, const std::string& message) : std::runtime_error(message), status_(status) {}
  pf_status status() const noexcept { return status_; }

 private:
  pf_status status_;
};

/// Throws Error for a status other than PF_OK, with this thread's last message.
inline void Check(pf_status status) {
  if (status != PF_OK) throw Error(status, pf_last_error_message());
}

/// Version of the library loaded at run time ("0.4.0"); POSEFOREST_VERSION_STRING is the
/// version of the headers.
inline std::string Version() { return pf_version_string(); }

enum class Method { kMeanShift = PF_MEAN_SHIFT, kFastClustering = PF_FAST_CLUSTERING };

/// A row-major depth image in millimetres (0 = no reading) that the caller owns.
struct DepthView {
  const uint16_t* data = nullptr;  ///< width * height values
  int width = 0;
  int height = 0;
};

/// Labels and distributions of one image (Forest::Classify).
struct Classification {
  int width = 0, height = 0, num_parts = 0;
  std::vector<uint8_t> labels;       ///< width*height; part index, 255 = background
  std::vector<float> distributions;  ///< width*height*num_parts if asked for, else empty
};

/// Names of the joints, in the order of pf_joint_proposal::joint.
inline std::vector<std::string> JointNames() {
  std::vector<std::string> names;
  for (int j = 0; j < pf_num_joints(); ++j) names.emplace_back(pf_joint_name(j));
  return names;
}

/// A loaded, validated forest. Movable, not copyable.
class Forest {
 public:
  /// Loads a forest file; throws Error (PF_IO, PF_DATA_LOSS, PF_VERSION_MISMATCH, ...).
  explicit Forest(const std::string& path) { Check(pf_forest_load_file(path.c_str(), &forest_)); }
  /// Parses a forest from memory (copied); `source` names it in messages.
  static Forest FromMemory(const void* bytes, size_t size, const std::string& source = "memory") {
    pf_forest* f = nullptr;
    Check(pf_forest_load_memory(bytes, size, source.c_str(), &f));
    return Forest(f);
  }
  Forest(Forest&& other) noexcept : forest_(std::exchange(other.forest_, nullptr)) {}
  Forest& operator=(Forest&& other) noexcept {
    if (this != &other) {
      pf_forest_free(forest_);
      forest_ = std::exchange(other.forest_, nullptr);
    }
    return *this;
  }
  Forest(const Forest&) = delete;
  Forest& operator=(const Forest&) = delete;
  ~Forest() { pf_forest_free(forest_); }

  int num_trees() const { return pf_forest_num_trees(forest_); }
  int num_parts() const { return pf_forest_num_parts(forest_); }
  int max_depth() const { return pf_forest_max_depth(forest_); }
  size_t num_nodes() const { return pf_forest_num_nodes(forest_); }
  bool has_joints() const { return pf_forest_has_joints(forest_) != 0; }
  std::vector<std::string> part_names() const {
    std::vector<std::string> names;
    for (int p = 0; p < num_parts(); ++p) names.emplace_back(pf_forest_part_name(forest_, p));
    return names;
  }

  /// Labels per pixel, and P(part | pixel) if `distributions` (see pf_classify).
  Classification Classify(DepthView depth, bool distributions = false, int num_threads = 0) const {
    // A moved-from Forest has no parts to size the distributions by: Error, as every call on it.
    if (forest_ == nullptr)
      throw Error(PF_INVALID_ARGUMENT, "poseforest::api::Forest: no forest (moved from)");
    Classification c;
    c.width = depth.width;
    c.height = depth.height;
    c.num_parts = num_parts();
    const size_t pixels = Pixels(depth);
    c.labels.resize(pixels);
    if (distributions) c.distributions.resize(pixels * size_t(c.num_parts));
    Check(pf_classify(forest_, depth.data, depth.width, depth.height, num_threads, c.labels.data(),
                      c.labels.size(), distributions ? c.distributions.data() : nullptr,
                      c.distributions.size()));
    return c;
  }
  /// Into caller-owned buffers (either may be null; sizes in elements), as pf_classify.
  void Classify(DepthView depth, uint8_t* labels, size_t labels_len, float* distributions,
                size_t distributions_len, int num_threads = 0) const {
    Check(pf_classify(forest_, depth.data, depth.width, depth.height, num_threads, labels, labels_len,
                      distributions, distributions_len));
  }

  /// 3D joint proposals, grouped by joint in joint order, most confident first (see
  /// pf_propose_joints). If `labels` is given it receives the labels of the same pass.
  std::vector<pf_joint_proposal> Joints(DepthView depth, Method method = Method::kMeanShift,
                                        int num_threads = 0, std::vector<uint8_t>* labels = nullptr) const {
    std::vector<pf_joint_proposal> out(size_t(pf_num_joints()) * 8);
    if (labels) labels->resize(Pixels(depth));
    for (;;) {
      size_t count = 0;
      const pf_status st =
          pf_propose_joints(forest_, depth.data, depth.width, depth.height,
                            static_cast<pf_proposal_method>(method), num_threads, out.data(), out.size(),
                            &count, labels ? labels->data() : nullptr, labels ? labels->size() : 0);
      if (st == PF_BUFFER_TOO_SMALL && count > out.size()) {
        out.resize(count);
        continue;
      }
      Check(st);
      out.resize(count);
      return out;
    }
  }

  /// The C handle, for calls this header does not wrap. Owned by this object.
  const pf_forest* handle() const { return forest_; }

 private:
  explicit Forest(pf_forest* f) : forest_(f) {}
  static size_t Pixels(DepthView d) {
    return d.width > 0 && d.height > 0 ? size_t(d.width) * size_t(d.height) : 0;
  }
  pf_forest* forest_ = nullptr;
};

}  // namespace poseforest::api

#endif  // POSEFOREST_POSEFOREST_HPP_
