// Training throughput: feature evaluations per second per core in the histogram builder
// (one evaluation = one sample x one candidate: the eq. 1 response, its threshold bin and the
// count), at the root (one node holding every sample) and at a deep level (thousands of small
// nodes, reached by random splits). Frames are procedural 640x480 figures at 1.5-4 m, pixels
// sampled as in training.
//
// Per core = per CPU second of the process (the build machine is shared, so wall time
// understates it; the wall figure is printed too). Headline (last line): root + deep level.
//
// usage: train [--source procedural|rendered] [--images N] [--pixels N] [--candidates N] [--thresholds N]
// [--depth D] [--threads N]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>

#include "runtime/core/rng.h"
#include "worker/candidates.h"
#include "worker/histogram_builder.h"
#include "worker/image_source.h"
#include "worker/sample_set.h"

using namespace poseforest;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
/// CPU seconds of the whole process (all threads): the machine may be shared, so per-core
/// throughput is evaluations per CPU second, not per wall second.
double Cpu() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Figures {
  double build_evals_per_s = 0, range_s = 0, build_s = 0, build_cpu_s = 0, range_cpu_s = 0;
  uint64_t evals = 0;
  size_t nodes = 0;
};

/// Ranges + cuts + histograms for every node of the set's frontier, in batches of `batch`.
Figures RunLevel(const worker::SampleSet& set, const worker::TrainParams& p, int threads, size_t batch) {
  worker::HistogramBuilder builder(p.constants, threads);
  Figures fig;
  const auto& ranges = set.ranges();
  fig.nodes = ranges.size();
  for (size_t b0 = 0; b0 < ranges.size(); b0 += batch) {
    std::vector<worker::NodePlan> plans;
    for (size_t i = b0; i < std::min(ranges.size(), b0 + batch); ++i) {
      worker::NodePlan plan;
      plan.node = ranges[i].node;
      plan.position = plan.node;
      plan.num_samples = ranges[i].end - ranges[i].begin;
      std::vector<uint64_t> parts(core::kNumParts);
      set.CountParts(ranges[i], core::kNumParts, parts.data());
      plan.SetParts(parts);
      plan.sample_bins = worker::UseSampleBins(plan.num_samples, p.thresholds_per_feature, plan.num_slots);
      plan.features = worker::DrawFeatures(p, 0, plan.node);
      plan.cut_stride = worker::CutStride(p.thresholds_per_feature);
      plans.push_back(std::move(plan));
    }
    const double t0 = Now(), c0 = Cpu();
    std::vector<std::vector<worker::ResponseRange>> rr;
    builder.ComputeRanges(set, p, 0, plans, &rr);
    for (size_t i = 0; i < plans.size(); ++i) plans[i].cuts = worker::DrawCuts(p, 0, plans[i].node, rr[i]);
    const double t1 = Now(), c1 = Cpu();
    fig.range_cpu_s += c1 - c0;
    std::vector<worker::NodeHistogram> hists;
    builder.Build(set, plans, p.thresholds_per_feature, &hists);
    const double t2 = Now();
    fig.build_cpu_s += Cpu() - c1;
    fig.range_s += t1 - t0;
    fig.build_s += t2 - t1;
  }
  fig.evals = builder.evaluations();
  fig.build_evals_per_s = double(fig.evals) / fig.build_s;
  return fig;
}

}  // namespace

int main(int argc, char** argv) {
  // Defaults: the paper's per-node search (2000 features x 50 thresholds, 2000 pixels/frame).
  int images = 20, pixels = 2000, candidates = 2000, thresholds = 50, depth = 10, threads = 1;
  bool rendered = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    const int v = std::atoi(argv[i + 1]);
    if (a == "--source")
      rendered = std::string(argv[i + 1]) == "rendered";
    else if (a == "--images")
      images = v;
    else if (a == "--pixels")
      pixels = v;
    else if (a == "--candidates")
      candidates = v;
    else if (a == "--thresholds")
      thresholds = v;
    else if (a == "--depth")
      depth = v;
    else if (a == "--threads")
      threads = v;
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[i]);
      return 2;
    }
  }
  worker::TrainParams p;
  p.seed = 1;
  p.candidate_features = candidates;
  p.thresholds_per_feature = thresholds;
  p.source.kind = rendered ? worker::SourceKind::kRendered : worker::SourceKind::kProcedural;
  p.source.width = 640;
  p.source.height = 480;
  auto source = worker::MakeImageSource(p.source);
  if (!source.ok()) {
    std::fprintf(stderr, "train bench: %s\n", source.status().ToString().c_str());
    return 1;
  }
  worker::SampleSet set;
  for (int i = 0; i < images; ++i) {
    auto frame = (*source)->Frame(uint64_t(i));
    if (!frame.ok()) {
      std::fprintf(stderr, "train bench: %s\n", frame.status().ToString().c_str());
      return 1;
    }
    worker::LabelledFrame f = std::move(*frame);
    auto px =
        worker::SamplePixels(f, pixels, 1.0, core::CounterRng(1, 0, uint64_t(i), worker::kSamplingStream));
    set.AddFrame(uint64_t(i), std::move(f.depth), px, p.constants);
  }
  set.StartTree(0);
  std::printf("train bench: %d %s frames 640x480, %zu samples, %d candidates x %d thresholds, %d thread(s)\n",
              images, rendered ? "rendered" : "procedural", set.num_samples(), candidates, thresholds,
              threads);

  const Figures root = RunLevel(set, p, threads, 1);
  std::printf(
      "root:     1 node,  %.3g evaluations in %.2f s wall, %.2f s CPU (+ ranges %.2f s wall, %.2f s CPU): "
      "%.3g evaluations/s wall, %.3g per CPU second\n",
      double(root.evals), root.build_s, root.build_cpu_s, root.range_s, root.range_cpu_s,
      root.build_evals_per_s, double(root.evals) / root.build_cpu_s);

  // Deep level: split every node by a random candidate at the response of its first sample,
  // `depth` times (the shape of a real level: many nodes, few samples each).
  for (int level = 0; level < depth; ++level) {
    std::vector<worker::SampleSet::Split> splits;
    uint32_t next = 0;
    for (const auto& r : set.ranges()) {
      const core::CounterRng rng(7, uint64_t(level), r.node, 0);
      const auto f = worker::DrawFeatures(p, 0, r.node)[rng.UniformInt(0, uint32_t(candidates))];
      const size_t s = r.begin + (r.end - r.begin) / 2;
      const int32_t cut = set.Response(s, f, p.constants.background_mm);
      splits.push_back({r.node, f, cut, next});
      next += 2;
    }
    set.ApplySplits(splits, p.constants, threads);
  }
  const Figures deep = RunLevel(set, p, threads, 256);
  // The same level through the fused single-shard pass (what LocalTrainer runs for nodes whose
  // samples all sit on one shard): ranges + cuts + histograms with one evaluation per sample
  // and candidate.
  double fused_cpu = 0;
  uint64_t fused_evals = 0;
  {
    worker::HistogramBuilder builder(p.constants, threads);
    const auto& ranges = set.ranges();
    for (size_t b0 = 0; b0 < ranges.size(); b0 += 256) {
      std::vector<worker::NodePlan> plans;
      for (size_t i = b0; i < std::min(ranges.size(), b0 + 256); ++i) {
        worker::NodePlan plan;
        plan.node = ranges[i].node;
        plan.position = plan.node;
        plan.num_samples = ranges[i].end - ranges[i].begin;
        std::vector<uint64_t> parts(core::kNumParts);
        set.CountParts(ranges[i], core::kNumParts, parts.data());
        plan.SetParts(parts);
        plan.sample_bins = worker::UseSampleBins(plan.num_samples, p.thresholds_per_feature, plan.num_slots);
        plan.features = worker::DrawFeatures(p, 0, plan.node);
        if (worker::HistogramBuilder::CanFuse(set, p, plan)) plans.push_back(std::move(plan));
      }
      const double c0 = Cpu();
      std::vector<worker::NodeHistogram> hists;
      builder.BuildFused(set, p, 0, plans, &hists);
      fused_cpu += Cpu() - c0;
    }
    fused_evals = builder.evaluations();
  }
  std::printf(
      "level %d: %zu nodes (%.0f samples/node), %.3g evaluations in %.2f s wall, %.2f s CPU (+ ranges %.2f s "
      "wall, %.2f s CPU): %.3g evaluations/s wall, %.3g per CPU second\n",
      depth, deep.nodes, double(set.num_samples()) / double(deep.nodes), double(deep.evals), deep.build_s,
      deep.build_cpu_s, deep.range_s, deep.range_cpu_s, deep.build_evals_per_s,
      double(deep.evals) / deep.build_cpu_s);
  std::printf(
      "level %d fused (ranges + cuts + histograms in one pass, %.3g evaluations): %.3g evaluations per CPU "
      "second\n",
      depth, double(fused_evals), double(fused_evals) / fused_cpu);
  std::printf("wall-clock per core (shared machine, pessimistic): %.4g evaluations/s/core\n",
              double(root.evals + deep.evals) / (root.build_s + deep.build_s) / threads);
  std::printf("with the threshold-range pass counted as overhead: %.4g evaluations/s/core (CPU)\n",
              double(root.evals + deep.evals) /
                  (root.build_cpu_s + deep.build_cpu_s + root.range_cpu_s + deep.range_cpu_s));
  const double all = double(root.evals + deep.evals) / (root.build_cpu_s + deep.build_cpu_s);
  std::printf(
      "(root + level %d together, per CPU second; the threshold-range pass is reported separately above)\n",
      depth);
  std::printf("evaluations/s/core: %.4g evaluations/s/core\n", all);
  return 0;
}
