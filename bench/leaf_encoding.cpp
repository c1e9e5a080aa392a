// What the forest file's uint8 leaf encoding costs: trains a depth-20 forest on rendered frames
// (or the job given as argument), keeps every leaf's exact part counts as training makes them,
// and classifies held-out frames twice - with the file's quantized leaves (runtime::Classifier)
// and with the exact float distributions (averaged over trees in double precision). Prints the
// forest's size, both average per-class accuracies, the pixel agreement of the two argmaxes and
// the largest probability difference. Last line: the accuracy cost in percentage points.
//   build/bench/leaf_encoding [JOB.textproto] (--help)
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "bench/bench_cli.h"
#include "engine/evaluation.h"
#include "engine/image_source.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "poseforest/v1/job.pb.h"
#include "runtime/classifier.h"
#include "runtime/core/feature.h"
#include "runtime/core/forest_format.h"

using namespace poseforest;

namespace {

constexpr const char* kDefaultJob = R"(
seed: 20
num_trees: 3
max_depth: 20
images_per_tree: 120
pixels_per_image: 1000
candidate_features: 300
thresholds_per_feature: 30
source { rendered { seed: 5 } }
test_set { source { rendered { seed: 77 } } num_images: 25 }
)";

// Leaf index reached by the pixel in one tree (the obvious walk).
uint32_t Walk(const core::Tree& tree, const core::DepthImage& d, int x, int y, const core::FeatureConstants& c) {
  uint32_t i = 0;
  while (!tree.nodes[i].is_leaf()) {
    const core::Node& n = tree.nodes[i];
    i = n.child + (core::FeatureResponse(d, x, y, n.offsets, c) < n.threshold ? 0u : 1u);
  }
  return tree.nodes[i].leaf_index();
}

}  // namespace

int main(int argc, char** argv) {
  std::string job_path;
  CLI::App app(
      "What the forest file's uint8 leaf encoding costs in accuracy; last line `accuracy cost: N "
      "percentage points`",
      "bench/leaf_encoding");
  app.add_option("JOB.textproto", job_path,
                 "the job to train (default: a depth-20 forest on rendered frames)")
      ->check(bench::kNonEmptyPath);
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  core::Result<engine::TrainParams> params = !job_path.empty() ? engine::LoadJob(job_path) : [] {
    auto config = engine::ParseJobText(kDefaultJob, "embedded job");
    if (!config.ok()) return core::Result<engine::TrainParams>(config.status());
    return engine::ParamsFromConfig(*config, "embedded job");
  }();
  if (!params.ok()) {
    std::fprintf(stderr, "leaf_encoding: %s\n", params.status().ToString().c_str());
    return 1;
  }
  // Exact leaf distributions, normalized, per tree and leaf.
  std::vector<std::map<uint32_t, std::vector<double>>> exact(size_t(params->num_trees));
  engine::LocalTrainerOptions options;
  options.leaf_counts = [&](int tree, uint32_t leaf, std::span<const uint64_t> counts) {
    double total = 0;
    for (uint64_t v : counts) total += double(v);
    std::vector<double> p(counts.size());
    for (size_t c = 0; c < counts.size(); ++c) p[c] = total > 0 ? double(counts[c]) / total : 0.0;
    exact[size_t(tree)][leaf] = std::move(p);
  };
  const auto t0 = std::chrono::steady_clock::now();
  engine::LocalTrainer trainer(*params, options);
  auto forest = trainer.Train();
  if (!forest.ok()) {
    std::fprintf(stderr, "leaf_encoding: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  const double train_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto bytes = core::SerializeForest(*forest);
  size_t leaves = 0;
  for (const auto& t : forest->trees) leaves += t.num_leaves;
  std::printf("forest: %zu trees, depth %u, %zu nodes, %zu leaves, file %zu bytes (%.1f MB); trained in %.0f s\n",
              forest->trees.size(), forest->max_depth(), forest->total_nodes(), leaves, bytes.size(),
              double(bytes.size()) / 1e6, train_s);
  std::printf("leaf encoding: %d bytes per leaf (uint8, sum 255) vs %d as float32: leaves take %.1f MB instead of %.1f MB\n",
              forest->leaf_stride(), forest->num_parts * 4, double(leaves * size_t(forest->leaf_stride())) / 1e6,
              double(leaves * size_t(forest->num_parts) * 4) / 1e6);

  auto source = engine::MakeImageSource(params->test_source);
  if (!source.ok()) {
    std::fprintf(stderr, "leaf_encoding: %s\n", source.status().ToString().c_str());
    return 1;
  }
  runtime::Classifier classifier(*forest);
  runtime::Classification result;
  engine::ConfusionMatrix quantized, floating;
  uint64_t pixels = 0, agree = 0;
  double max_diff = 0;
  const int trees = int(forest->trees.size());
  for (int i = 0; i < params->test_images; ++i) {
    auto frame = (*source)->Frame(uint64_t(i));
    if (!frame.ok()) {
      std::fprintf(stderr, "leaf_encoding: %s\n", frame.status().ToString().c_str());
      return 1;
    }
    const auto& d = frame->depth;
    classifier.Classify(d, {0, true}, &result);
    for (int y = 0; y < d.height; ++y)
      for (int x = 0; x < d.width; ++x) {
        const uint8_t truth = frame->labels.at(x, y);
        if (d.at(x, y) == 0 || truth >= core::kNumParts) continue;
        std::vector<double> p(size_t(core::kNumParts), 0.0);
        for (int t = 0; t < trees; ++t) {
          const auto& row = exact[size_t(t)].at(Walk(forest->trees[size_t(t)], d, x, y, forest->constants));
          for (int c = 0; c < core::kNumParts; ++c) p[size_t(c)] += row[size_t(c)] / trees;
        }
        int best = 0;
        for (int c = 1; c < core::kNumParts; ++c)
          if (p[size_t(c)] > p[size_t(best)]) best = c;
        for (int c = 0; c < core::kNumParts; ++c)
          max_diff = std::max(max_diff, std::abs(double(result.Probability(x, y, c)) - p[size_t(c)]));
        const int q = result.labels.at(x, y);
        quantized.counts[size_t(truth) * core::kNumParts + size_t(q)]++;
        floating.counts[size_t(truth) * core::kNumParts + size_t(best)]++;
        agree += q == best;
        ++pixels;
      }
  }
  const double acc_q = quantized.AveragePerClassAccuracy(), acc_f = floating.AveragePerClassAccuracy();
  std::printf("held-out: %d frames, %llu body pixels\n", params->test_images, (unsigned long long)pixels);
  std::printf("average per-class accuracy: float leaves %.3f%%, uint8 leaves %.3f%%\n", 100 * acc_f, 100 * acc_q);
  std::printf("most likely part identical on %.4f%% of pixels; largest |P_uint8 - P_float| = %.4f\n",
              100.0 * double(agree) / double(pixels), max_diff);
  std::printf("accuracy cost: %.3f percentage points\n", 100 * (acc_f - acc_q));
  return 0;
}
