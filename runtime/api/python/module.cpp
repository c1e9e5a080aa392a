// The Python module poseforest._poseforest (re-exported by poseforest/__init__.py): NumPy
// arrays in and out over the C++ API (poseforest/poseforest.hpp); the GIL is released while the
// runtime computes, so Python threads can classify in parallel.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <string>

#include "poseforest/poseforest.hpp"

namespace py = pybind11;
using poseforest::api::DepthView;
using poseforest::api::Forest;

namespace {

/// A C-contiguous (height, width) uint16 array of millimetres; anything else is a TypeError.
py::array_t<uint16_t, py::array::c_style> DepthArray(const py::array& depth) {
  if (!depth.dtype().equal(py::dtype::of<uint16_t>()))
    throw py::type_error("depth must be a uint16 array of millimetres, shape (height, width); got dtype " +
                         std::string(py::str(depth.dtype())));
  if (depth.ndim() != 2)
    throw py::value_error("depth must have 2 dimensions (height, width); got " +
                          std::to_string(depth.ndim()));
  return py::array_t<uint16_t, py::array::c_style>::ensure(depth);
}

DepthView View(const py::array_t<uint16_t, py::array::c_style>& a) {
  // The C API takes int sizes of 1..32768: a larger dimension must not wrap into that range.
  if (a.shape(0) > 32768 || a.shape(1) > 32768)
    throw py::value_error("depth must be at most 32768 x 32768 pixels; got shape (" +
                          std::to_string(a.shape(0)) + ", " + std::to_string(a.shape(1)) + ")");
  return {a.data(), int(a.shape(1)), int(a.shape(0))};
}

py::object JointDtype() {
  py::list fields;
  fields.append(py::make_tuple("joint", "<i4"));
  fields.append(py::make_tuple("position_m", "<f4", py::make_tuple(3)));
  fields.append(py::make_tuple("pixel", "<f4", py::make_tuple(2)));
  fields.append(py::make_tuple("confidence", "<f4"));
  return py::module_::import("numpy").attr("dtype")(fields);
}

/// A pf_skeleton_stream owned by Python (the Forest it reads is kept alive by keep_alive).
struct SkeletonStream {
  pf_skeleton_stream* stream = nullptr;
  SkeletonStream() = default;
  SkeletonStream(const SkeletonStream&) = delete;
  SkeletonStream& operator=(const SkeletonStream&) = delete;
  ~SkeletonStream() { pf_skeleton_stream_free(stream); }
};

py::object Xyz(const float* v, int n) {
  py::tuple t(n);
  for (int i = 0; i < n; ++i) t[size_t(i)] = py::float_(v[i]);
  return t;
}

/// The skeletons as the JSON Lines record's people (docs/runtime/live.md): dicts and tuples.
py::list SkeletonsToPython(const std::vector<pf_skeleton>& skeletons) {
  py::list people;
  for (const pf_skeleton& s : skeletons) {
    py::list joints;
    for (int j = 0; j < PF_SKELETON_JOINTS; ++j) {
      const pf_skeleton_joint& pj = s.joints[j];
      py::dict joint;
      joint["name"] = pf_joint_name(j);
      joint["found"] = bool(pj.found);
      joint["tracked"] = bool(pj.tracked);
      joint["position_m"] = pj.found ? Xyz(pj.position_m, 3) : py::none();
      joint["pixel"] = pj.found ? Xyz(pj.pixel, 2) : py::none();
      joint["confidence"] = pj.confidence;
      const char* state = pf_joint_state_name(pj.state);
      joint["state"] = state ? state : "not_tracked";  // the library writes only the three
      joints.append(joint);
    }
    py::dict person;
    person["id"] = s.id;
    person["pixels"] = s.pixels;
    person["centroid_m"] = Xyz(s.centroid_m, 3);
    person["joints"] = joints;
    people.append(person);
  }
  return people;
}

/// poseforest.Forest.
void BindForest(py::module_& m) {
  static_assert(sizeof(pf_joint_proposal) == 28, "the NumPy dtype below mirrors pf_joint_proposal");
  py::class_<Forest>(m, "Forest", "A loaded, validated forest (.pff). Thread-safe.")
      .def(py::init([](const std::string& path) {
             py::gil_scoped_release release;
             return Forest(path);
           }),
           py::arg("path"), "Loads a forest file; raises poseforest.Error with the CLI's message.")
      .def_static(
          "from_bytes",
          [](const py::bytes& bytes, const std::string& source) {
            std::string_view b = bytes;
            py::gil_scoped_release release;
            return Forest::FromMemory(b.data(), b.size(), source);
          },
          py::arg("data"), py::arg("source") = "memory", "Parses a forest from bytes.")
      .def_property_readonly("num_trees", &Forest::num_trees)
      .def_property_readonly("num_parts", &Forest::num_parts)
      .def_property_readonly("max_depth", &Forest::max_depth)
      .def_property_readonly("num_nodes", &Forest::num_nodes)
      .def_property_readonly("has_joints", &Forest::has_joints)
      .def_property_readonly("part_names", &Forest::part_names)
      .def(
          "classify",
          [](const Forest& f, const py::array& depth, int threads) {
            auto d = DepthArray(depth);
            py::array_t<uint8_t> labels({d.shape(0), d.shape(1)});
            uint8_t* out = labels.mutable_data();
            const size_t n = size_t(labels.size());
            const DepthView view = View(d);
            {
              py::gil_scoped_release release;
              f.Classify(view, out, n, nullptr, 0, threads);
            }
            return labels;
          },
          py::arg("depth"), py::arg("threads") = 0,
          "Most likely part per pixel: uint8 (height, width), 255 = background (depth 0).")
      .def(
          "distributions",
          [](const Forest& f, const py::array& depth, int threads) {
            auto d = DepthArray(depth);
            py::array_t<float> probs({d.shape(0), d.shape(1), py::ssize_t(f.num_parts())});
            float* out = probs.mutable_data();
            const size_t n = size_t(probs.size());
            const DepthView view = View(d);
            {
              py::gil_scoped_release release;
              f.Classify(view, nullptr, 0, out, n, threads);
            }
            return probs;
          },
          py::arg("depth"), py::arg("threads") = 0,
          "P(part | pixel): float32 (height, width, num_parts), zero where the depth is 0.")
      .def(
          "joints",
          [](const Forest& f, const py::array& depth, const std::string& method, int threads) {
            auto d = DepthArray(depth);
            poseforest::api::Method m;
            if (method == "meanshift")
              m = poseforest::api::Method::kMeanShift;
            else if (method == "fast")
              m = poseforest::api::Method::kFastClustering;
            else
              throw py::value_error("method must be 'meanshift' or 'fast', got '" + method + "'");
            const DepthView view = View(d);
            std::vector<pf_joint_proposal> found;
            {
              py::gil_scoped_release release;
              found = f.Joints(view, m, threads);
            }
            py::array out(py::dtype::from_args(JointDtype()),
                          std::vector<py::ssize_t>{py::ssize_t(found.size())});
            if (!found.empty())
              std::memcpy(out.mutable_data(), found.data(), found.size() * sizeof(pf_joint_proposal));
            return out;
          },
          py::arg("depth"), py::arg("method") = "meanshift", py::arg("threads") = 0,
          "3D joint proposals as a structured array (joint, position_m[3], pixel[2], confidence), grouped by "
          "joint in JOINT_NAMES order, most confident first.");
}

/// poseforest.SkeletonStream.
void BindSkeletonStream(py::module_& m) {
  py::class_<SkeletonStream>(m, "SkeletonStream",
                             "Per-person skeletons over a stream of depth frames (pf_skeleton_stream: "
                             "segmentation, ids, calibrated confidence, joint states). One thread at a time.")
      .def(py::init([](const Forest& f, int threads) {
             auto s = std::make_unique<SkeletonStream>();
             poseforest::api::Check(pf_skeleton_stream_create(f.handle(), threads, &s->stream));
             return s;
           }),
           py::arg("forest"), py::arg("threads") = 0, py::keep_alive<1, 2>(),
           "A stream over `forest` (31 parts, else poseforest.Error).")
      .def(
          "process",
          [](SkeletonStream& self, const py::array& depth, double timestamp_s) {
            auto d = DepthArray(depth);
            const DepthView view = View(d);
            std::vector<pf_skeleton> out(8);
            size_t count = 0;
            pf_status st;
            {
              py::gil_scoped_release release;
              st = pf_skeleton_stream_process(self.stream, view.data, view.width, view.height, timestamp_s,
                                              out.data(), out.size(), &count);
              if (st == PF_BUFFER_TOO_SMALL) {  // the frame ran: fetch it, never run it twice
                out.resize(count);
                st = pf_skeleton_stream_last(self.stream, out.data(), out.size(), &count);
              }
            }
            poseforest::api::Check(st);
            out.resize(count);
            return SkeletonsToPython(out);
          },
          py::arg("depth"), py::arg("timestamp_s"),
          "Runs one frame (uint16 (height, width) mm; seconds, not decreasing): a list of people, each a "
          "dict "
          "id, pixels, centroid_m, joints (16 dicts: name, found, tracked, position_m, pixel, confidence, "
          "state; position_m and pixel None when not found; state 'tracked', 'inferred' (found, not "
          "tracked: a hidden joint placed by the offset votes) or 'not_tracked'), ordered by id.");
}

}  // namespace

PYBIND11_MODULE(_poseforest, m) {
  m.doc() = "poseforest runtime: body parts and 3D joint proposals from single depth images";
  m.attr("__version__") = poseforest::api::Version();
  m.attr("JOINT_NAMES") = poseforest::api::JointNames();
  py::register_exception<poseforest::api::Error>(m, "Error", PyExc_RuntimeError);
  BindForest(m);
  BindSkeletonStream(m);
}
