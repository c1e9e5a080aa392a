// poseforest infer: classify depth images into body parts.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "runtime/classifier.h"
#include "runtime/cli/args.h"
#include "runtime/cli/commands.h"
#include "runtime/core/forest_format.h"
#include "runtime/image_io.h"
#include "runtime/joint_proposals.h"
#include "runtime/visualize.h"

namespace poseforest::cli {
namespace {

constexpr const char* kUsage = R"(usage: poseforest infer --forest FOREST.pff [options] DEPTH [DEPTH...]

Classifies every foreground pixel (depth > 0) of each depth image into the forest's body parts
(eq. 2 of Shotton et al.: leaf distributions averaged over trees) and writes the most likely part
per pixel as a colour PNG.

DEPTH is a 16-bit greyscale PNG in millimetres, or a raw little-endian uint16 frame (e.g. the
640x480 Kinect frames in shared/data/real); 0 means no reading / background.

options:
  --forest FILE        forest file (.pff), required
  --out FILE           colour part picture (one input only; default: <DEPTH>.parts.png)
  --out-dir DIR        write <name>.parts.png (and other outputs) for each input into DIR
  --labels             also write the raw part ids as an 8-bit PNG (<name>.labels.png, 255 = background)
  --distributions      also write P(part | pixel) as float32 NumPy array [height, width, parts]
                       (<name>.probs.npy); background pixels are all zero
  --joints             also propose 3D joints (section 3.4): <name>.joints.json (per joint, every
                       proposal: position in metres, camera frame; pixel; confidence) and
                       <name>.pose.png (depth, parts, joints, front/side/top views); uses the
                       proposal parameters the forest stores for the method (`tune-joints`; the
                       fast clustering without a set of its own uses the mean-shift set), or the
                       paper's means
  --method M           joint proposals by `meanshift` (default) or `fast` (bottom-up clustering)
  --min-confidence C   joints drawn in the picture need this confidence (default 0.05)
  --raw-size WxH       size of raw depth frames (default 640x480)
  --threads N          OpenMP threads (default: all cores)
  --quiet              print nothing but errors
  --help               this text
)";

std::string OutPath(const std::string& depth_path, const std::optional<std::string>& out_dir,
                    const std::string& suffix) {
  std::filesystem::path p(depth_path);
  std::string stem = p.filename().string();
  if (p.extension() == ".png" || p.extension() == ".raw") stem = p.stem().string();
  if (out_dir) return (std::filesystem::path(*out_dir) / (stem + suffix)).string();
  return (p.parent_path() / (stem + suffix)).string();
}

std::string JointsJson(const std::string& source, const core::DepthImage& depth, const runtime::FrameProposals& f,
                       const char* method) {
  std::string out = "{\n  \"frame\": \"";
  for (char c : source) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  char buf[256];
  std::snprintf(buf, sizeof buf, "\",\n  \"width\": %d, \"height\": %d, \"method\": \"%s\",\n  \"joints\": [\n",
                depth.width, depth.height, method);
  out += buf;
  for (int j = 0; j < core::kNumJoints; ++j) {
    out += "    {\"joint\": \"" + std::string(core::JointName(j)) + "\", \"proposals\": [";
    for (size_t k = 0; k < f[size_t(j)].size(); ++k) {
      const auto& p = f[size_t(j)][k];
      std::snprintf(buf, sizeof buf, "%s\n      {\"position_m\": [%.4f, %.4f, %.4f], \"pixel\": [%.1f, %.1f], \"confidence\": %.5g}",
                    k ? "," : "", p.position.x(), p.position.y(), p.position.z(), p.pixel.x(), p.pixel.y(),
                    double(p.confidence));
      out += buf;
    }
    out += f[size_t(j)].empty() ? "]}" : "\n    ]}";
    out += j + 1 < core::kNumJoints ? ",\n" : "\n";
  }
  out += "  ]\n}\n";
  return out;
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

}  // namespace

int InferMain(int argc, char** argv) {
  Args args({"forest", "out", "out-dir", "raw-size", "threads", "method", "min-confidence"},
            {"labels", "distributions", "joints", "quiet", "help"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest infer: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  const auto forest_path = args.Get("forest");
  if (!forest_path || args.positional().empty()) {
    std::fprintf(stderr, "poseforest infer: %s\n\n%s", !forest_path ? "--forest is required" : "no depth image given", kUsage);
    return 2;
  }
  if (args.Get("out") && args.positional().size() != 1) {
    std::fprintf(stderr, "poseforest infer: --out takes one input; use --out-dir for several\n");
    return 2;
  }
  int raw_w = 640, raw_h = 480;
  if (auto rs = args.Get("raw-size")) {
    if (std::sscanf(rs->c_str(), "%dx%d", &raw_w, &raw_h) != 2 || raw_w <= 0 || raw_h <= 0 || raw_w > 32768 || raw_h > 32768) {
      std::fprintf(stderr, "poseforest infer: --raw-size must be WxH, e.g. 640x480 (got '%s')\n", rs->c_str());
      return 2;
    }
  }
  auto threads = args.GetInt("threads", 0, 0, 1024);
  if (!threads.ok()) {
    std::fprintf(stderr, "poseforest infer: %s\n", threads.status().message().c_str());
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
  runtime::ProposalOptions proposal_options;
  proposal_options.method = method == "fast" ? runtime::ProposalMethod::kFastClustering : runtime::ProposalMethod::kMeanShift;
  const auto params =
      forest->ProposalParamsFor(proposal_options.method == runtime::ProposalMethod::kFastClustering);
  proposal_options.params = params.params;
  proposal_options.num_threads = int(*threads);

  runtime::Classifier classifier(*forest);
  runtime::ClassifyOptions options;
  options.num_threads = int(*threads);
  // The compact per-foreground-pixel sums serve both the proposals and the .npy (no dense
  // W*H*stride array is cleared or written).
  options.want_foreground_distributions = args.Has("distributions") || joints;
  runtime::Classification result;
  int failures = 0;
  for (const std::string& depth_path : args.positional()) {
    auto depth = runtime::ReadDepthImage(depth_path, raw_w, raw_h);
    if (!depth.ok()) {
      std::fprintf(stderr, "poseforest infer: %s\n", depth.status().ToString().c_str());
      ++failures;
      continue;
    }
    const auto t0 = std::chrono::steady_clock::now();
    classifier.Classify(*depth, options, &result);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();

    const std::string parts_png = args.Get("out") ? *args.Get("out") : OutPath(depth_path, out_dir, ".parts.png");
    core::Status st = runtime::WriteLabelColourPng(parts_png, result.labels);
    if (st.ok() && args.Has("labels")) st = runtime::WriteLabelPng(OutPath(depth_path, out_dir, ".labels.png"), result.labels);
    if (st.ok() && args.Has("distributions"))
      st = WriteProbabilitiesNpy(OutPath(depth_path, out_dir, ".probs.npy"), result);
    runtime::FrameProposals proposals;
    double proposal_ms = 0;
    if (st.ok() && joints) {
      const auto t1 = std::chrono::steady_clock::now();
      proposals = runtime::ProposeJointsFromClassification(*depth, result, proposal_options);
      proposal_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
      const std::string json = JointsJson(depth_path, *depth, proposals, method.c_str());
      st = core::WriteFileAtomic(OutPath(depth_path, out_dir, ".joints.json"),
                                 std::span(reinterpret_cast<const uint8_t*>(json.data()), json.size()));
      if (st.ok()) {
        const auto fig = runtime::PoseFigure(*depth, result.labels, proposals, proposal_options.camera, min_confidence);
        st = runtime::WriteRgbPng(OutPath(depth_path, out_dir, ".pose.png"), fig.width, fig.height, fig.rgb);
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
      std::printf("%s: %dx%d, %d foreground pixels, classified in %.2f ms -> %s\n", depth_path.c_str(),
                  depth->width, depth->height, fg, ms, parts_png.c_str());
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
          std::printf("    %-11s (%6.3f, %6.3f, %6.3f)  confidence %.4g  (%zu proposals)\n",
                      std::string(core::JointName(j)).c_str(), list[0].position.x(), list[0].position.y(),
                      list[0].position.z(), double(list[0].confidence), list.size());
        }
      }
    }
  }
  return failures == 0 ? 0 : 1;
}

}  // namespace poseforest::cli
