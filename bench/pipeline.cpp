// The whole runtime pipeline on 640x480 frames with one person: classification (eq. 2, the
// compact per-foreground-pixel distributions) + joint proposals with the parts pooled per joint
// on the way in (mean shift, eq. 7-8, or the fast clustering), timed per stage (wall and CPU
// time; checked equal to the two-step path through JointProbabilities), and the
// joint average precision of section 4 on the same held-out renders - inferred parts with
// both proposal methods and, as Fig. 7's upper bound, proposals from the ground-truth parts.
// Also times the classifier with the dense W*H*32 distributions (what it was before) for
// comparison. Runs with OMP_WAIT_POLICY=passive unless the environment sets a policy.
//   build/bench/pipeline --forest F.pff [--frames N] [--seed S] [--poses L.pfposes --clips test]
//                        [--bodies procedural|makehuman|all] [--data DIR] [--threads N]
//                        [--seed-cell F] [--min-probability P] [--cluster-cell F]
// Last line: `frames/s: <value> frames/s` of the whole pipeline with mean shift (the line
// before it says which method and both figures).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <optional>
#include <string>
#include <vector>

#include "bench/bench_cli.h"
#include "renderer/scene_assets.h"
#include "renderer/synthetic_source.h"
#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "runtime/core/malloc_tuning.h"
#include "runtime/joint_metrics.h"
#include "runtime/joint_proposals.h"

using namespace poseforest;
using Clock = std::chrono::steady_clock;

namespace {

double Ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

std::vector<runtime::PersonJoints> People(const renderer::RenderedFrame& f) {
  std::vector<runtime::PersonJoints> people(f.joints.size());
  for (size_t k = 0; k < f.joints.size(); ++k) {
    people[k].position = f.joints[k];
    people[k].visible = f.visible[k];
  }
  return people;
}

/// CPU time of the whole process (all threads), milliseconds.
double CpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

std::string LoadAverage() {
  double l[3] = {0, 0, 0};
  if (getloadavg(l, 3) != 3) return "?";
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.2f %.2f %.2f", l[0], l[1], l[2]);
  return buf;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  poseforest::core::KeepFreedMemory();  // runtime/core/malloc_tuning.h
  // Idle OpenMP threads sleep instead of spinning: on a shared machine a spinning thread
  // steals the core its partner needs (as bench/classify).
  if (std::getenv("OMP_WAIT_POLICY") == nullptr) {
    ::setenv("OMP_WAIT_POLICY", "passive", 1);
    ::execv("/proc/self/exe", argv);  // returns only on failure: then measure as we are
  }
  // ProposalOptions: seed_cell_fraction, min_probability, cluster_cell_fraction.
  std::string forest_path, clips = "test", bodies = "procedural", data = "../shared/data";
  std::optional<std::string> poses;
  int frames = 50, threads = 0;
  uint64_t seed = 777, split_seed = 1;
  double test_fraction = 0.2;
  std::optional<float> seed_cell, min_probability, cluster_cell;
  CLI::App app("The runtime pipeline on 640x480 renders, timed per stage, and its joint AP.",
               "bench/pipeline");
  app.add_option("--forest", forest_path, "forest file")->required()->check(bench::kNonEmptyPath);
  app.add_option("--frames", frames, "frames")->check(CLI::Range(1, 100000));
  app.add_option("--seed", seed, "render seed")->check(CLI::Range(uint64_t(0), uint64_t(1) << 40));
  app.add_option("--poses", poses, "a pose library (.pfposes) instead of the procedural poses");
  app.add_option("--clips", clips, "clips of --poses: train, test or all")
      ->check(CLI::IsMember({"train", "test", "all"}));
  app.add_option("--test-fraction", test_fraction, "share of test clips")->check(CLI::Range(0.0, 1.0));
  app.add_option("--split-seed", split_seed, "seed of the clip split");
  app.add_option("--bodies", bodies, "procedural, makehuman or all")
      ->check(CLI::IsMember({"procedural", "makehuman", "all"}));
  app.add_option("--data", data, "shared data folder")->check(bench::kNonEmptyPath);
  app.add_option("--threads", threads, "threads (0: all cores)")->check(CLI::Range(0, 256));
  app.add_option("--seed-cell", seed_cell, "ProposalOptions::seed_cell_fraction");
  app.add_option("--min-probability", min_probability, "ProposalOptions::min_probability");
  app.add_option("--cluster-cell", cluster_cell, "ProposalOptions::cluster_cell_fraction");
  if (const auto exit_status = bench::ParseBenchCommandLine(app, argc, argv)) return *exit_status;
  auto forest = core::LoadForest(forest_path);
  if (!forest.ok()) {
    std::fprintf(stderr, "pipeline: %s\n", forest.status().ToString().c_str());
    return 1;
  }

  renderer::SceneConfig scene;
  if (poses) {
    renderer::PoseSelection sel;
    sel.library = *poses;
    sel.clips = clips == "train" ? renderer::ClipSet::kTrain : clips == "all" ? renderer::ClipSet::kAll : renderer::ClipSet::kTest;
    sel.test_fraction = test_fraction;
    sel.split_seed = split_seed;
    auto lib = renderer::LoadPoseSelection(sel);
    if (!lib.ok()) {
      std::fprintf(stderr, "pipeline: %s\n", lib.status().ToString().c_str());
      return 1;
    }
    scene.shared_poses = *lib;
  }
  if (bodies != "procedural") {
    auto mh = renderer::MakeHumanPresetBodies(data + "/meshes/makehuman_hm08_kit");
    if (!mh.ok()) {
      std::fprintf(stderr, "pipeline: %s\n", mh.status().ToString().c_str());
      return 1;
    }
    scene.bodies = std::move(*mh);
    scene.use_procedural_bodies = bodies == "all";
  }
  auto renderer = renderer::SyntheticRenderer::Create(scene);
  if (!renderer.ok()) {
    std::fprintf(stderr, "pipeline: %s\n", renderer.status().ToString().c_str());
    return 1;
  }

  runtime::Classifier classifier(*forest);
  runtime::ClassifyOptions copt, dense;
  copt.num_threads = dense.num_threads = threads;
  copt.want_foreground_distributions = true;
  dense.want_distributions = true;
  runtime::ProposalOptions mean_shift, fast;
  // Each method with the forest's set for it (the fast clustering without one: the mean-shift set).
  mean_shift.params = forest->ProposalParamsFor(false).params;
  fast.params = forest->ProposalParamsFor(true).params;
  mean_shift.num_threads = fast.num_threads = threads;
  if (seed_cell) mean_shift.seed_cell_fraction = *seed_cell;
  if (min_probability) mean_shift.min_probability = *min_probability;
  if (cluster_cell) fast.cluster_cell_fraction = *cluster_cell;
  fast.method = runtime::ProposalMethod::kFastClustering;

  runtime::JointApEvaluator ap_ms, ap_fast, ap_upper;
  // Per stage, per frame: wall ms and process CPU ms.
  enum Stage { kClassify, kMeanShift, kFast, kProbabilities, kDense, kStages };
  std::vector<double> wall[kStages], cpu[kStages];
  runtime::Classification cls, cls_dense;
  long foreground = 0;
  const std::string load_before = LoadAverage();
  for (int i = 0; i < frames; ++i) {
    auto frame = (*renderer)->Render(seed, uint64_t(i));
    if (!frame.ok()) {
      std::fprintf(stderr, "pipeline: %s\n", frame.status().ToString().c_str());
      return 1;
    }
    foreground += core::CountForeground(frame->depth);
    Clock::time_point t[kStages + 1];
    double c[kStages + 1];
    auto mark = [&](int k) {
      t[k] = Clock::now();
      c[k] = CpuMs();
    };
    // The pipeline: classify, then proposals straight from the compact sums (parts pooled per
    // joint inside the proposals' first pass). Then, for comparison only, the separate
    // probability array and the dense classifier.
    mark(0);
    classifier.Classify(frame->depth, copt, &cls);
    mark(1);
    const auto p_ms = runtime::ProposeJointsFromClassification(frame->depth, cls, mean_shift);
    mark(2);
    const auto p_fast = runtime::ProposeJointsFromClassification(frame->depth, cls, fast);
    mark(3);
    const auto probs = runtime::ProbabilitiesFromClassification(frame->depth, cls, threads);
    mark(4);
    classifier.Classify(frame->depth, dense, &cls_dense);
    mark(5);
    // The fused path must equal the two-step one.
    const auto p_check = runtime::ProposeJoints(frame->depth, probs, mean_shift);
    for (int j = 0; j < core::kNumJoints; ++j) {
      bool same = p_check[size_t(j)].size() == p_ms[size_t(j)].size();
      for (size_t m = 0; same && m < p_ms[size_t(j)].size(); ++m)
        same = p_check[size_t(j)][m].position == p_ms[size_t(j)][m].position;
      if (!same) {
        std::fprintf(stderr, "pipeline: fused and two-step proposals differ on frame %d, joint %d\n", i, j);
        return 1;
      }
    }
    for (int k = 0; k < kStages; ++k) {
      wall[k].push_back(Ms(t[k], t[k + 1]));
      cpu[k].push_back(c[k + 1] - c[k]);
    }
    if (cls_dense.labels.pixels != cls.labels.pixels) {
      std::fprintf(stderr, "pipeline: dense and foreground classifications differ on frame %d\n", i);
      return 1;
    }
    const auto people = People(*frame);
    ap_ms.AddFrame(p_ms, people);
    ap_fast.AddFrame(p_fast, people);
    ap_upper.AddFrame(runtime::ProposeJoints(frame->depth, runtime::ProbabilitiesFromLabels(frame->depth, frame->labels), mean_shift),
                      people);
  }
  std::printf("forest %s: %zu trees, depth %u, %zu nodes; %d held-out frames (seed %llu), %.0f foreground px/frame\n",
              forest_path.c_str(), forest->trees.size(), forest->max_depth(), forest->total_nodes(), frames,
              (unsigned long long)seed, double(foreground) / frames);
  std::printf("%-11s %9s %9s %12s\n", "joint", "AP mean", "AP fast", "AP gt-parts");
  for (int j = 0; j < core::kNumJoints; ++j)
    std::printf("%-11s %9.3f %9.3f %12.3f\n", std::string(core::JointName(j)).c_str(), ap_ms.AveragePrecision(j),
                ap_fast.AveragePrecision(j), ap_upper.AveragePrecision(j));
  std::printf("mAP: mean shift %.3f, fast clustering %.3f; upper bound from ground-truth parts %.3f "
              "(inferred / upper bound %.2f)\n",
              ap_ms.MeanAveragePrecision(), ap_fast.MeanAveragePrecision(), ap_upper.MeanAveragePrecision(),
              ap_upper.MeanAveragePrecision() > 0 ? ap_ms.MeanAveragePrecision() / ap_upper.MeanAveragePrecision() : 0.0);
  const char* policy = std::getenv("OMP_WAIT_POLICY");
  std::printf("threads %d (0 = all), OMP_WAIT_POLICY=%s; load average before: %s, after: %s\n", threads,
              policy != nullptr ? policy : "(unset)", load_before.c_str(), LoadAverage().c_str());
  const char* names[kStages] = {"classify (foreground distributions)", "proposals: mean shift (fused)",
                                "proposals: fast clustering (fused)",
                                "[separate probability array, not needed]",
                                "[classify with dense W*H*32 distributions]"};
  double w[kStages], u[kStages];
  std::printf("%-44s %14s %14s\n", "stage (median over frames)", "wall ms", "CPU ms");
  for (int k = 0; k < kStages; ++k) {
    w[k] = Median(wall[k]);
    u[k] = Median(cpu[k]);
    std::printf("%-44s %14.3f %14.3f\n", names[k], w[k], u[k]);
  }
  const double with_ms = w[kClassify] + w[kMeanShift];
  const double with_fast = w[kClassify] + w[kFast];
  std::printf("pipeline with mean shift: %.3f ms/frame = %.1f frames/s (mAP %.3f); CPU %.3f ms/frame\n", with_ms,
              1000.0 / with_ms, ap_ms.MeanAveragePrecision(), u[kClassify] + u[kMeanShift]);
  std::printf("pipeline with fast clustering: %.3f ms/frame = %.1f frames/s (mAP %.3f); CPU %.3f ms/frame\n",
              with_fast, 1000.0 / with_fast, ap_fast.MeanAveragePrecision(), u[kClassify] + u[kFast]);
  std::printf("headline: the whole pipeline with mean shift = classify + mean shift proposals (wall, median per "
              "stage)\n");
  std::printf("frames/s: %.1f frames/s\n", 1000.0 / with_ms);
  return 0;
}
