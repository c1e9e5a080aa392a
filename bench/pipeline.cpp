// The whole runtime pipeline on 640x480 frames with one person: classification (eq. 2) + joint
// proposals (mean shift, eq. 7-8, or the fast clustering), timed per stage, and the joint
// average precision of section 4 on the same held-out renders - inferred parts with both
// proposal methods and, as Fig. 7's upper bound, proposals from the ground-truth parts.
//   build/bench/pipeline --forest F.pff [--frames N] [--seed S] [--poses L.pfposes --clips test]
//                        [--bodies procedural|makehuman|all] [--data DIR] [--threads N]
// Last line: frames/s of classification + mean shift proposals.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "renderer/scene_assets.h"
#include "renderer/synthetic_source.h"
#include "runtime/classifier.h"
#include "runtime/cli/args.h"
#include "runtime/core/forest_format.h"
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

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  cli::Args args({"forest", "frames", "seed", "poses", "clips", "test-fraction", "split-seed", "bodies", "data", "threads"},
                 {"help"});
  if (auto st = args.Parse(argc, argv); !st.ok() || args.Has("help") || !args.Get("forest")) {
    std::fprintf(stderr,
                 "usage: pipeline --forest F.pff [--frames N] [--seed S] [--poses L.pfposes --clips test] "
                 "[--bodies procedural|makehuman|all] [--data DIR] [--threads N]\n%s\n",
                 st.ok() ? "" : st.message().c_str());
    return 2;
  }
  auto forest = core::LoadForest(*args.Get("forest"));
  if (!forest.ok()) {
    std::fprintf(stderr, "pipeline: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  const int frames = int(args.GetInt("frames", 50, 1, 100000).value());
  const uint64_t seed = uint64_t(args.GetInt("seed", 777, 0, 1L << 40).value());
  const int threads = int(args.GetInt("threads", 0, 0, 256).value());

  renderer::SceneConfig scene;
  if (auto poses = args.Get("poses")) {
    renderer::PoseSelection sel;
    sel.library = *poses;
    const std::string clips = args.GetOr("clips", "test");
    sel.clips = clips == "train" ? renderer::ClipSet::kTrain : clips == "all" ? renderer::ClipSet::kAll : renderer::ClipSet::kTest;
    sel.test_fraction = std::stod(args.GetOr("test-fraction", "0.2"));
    sel.split_seed = std::stoull(args.GetOr("split-seed", "1"));
    auto lib = renderer::LoadPoseSelection(sel);
    if (!lib.ok()) {
      std::fprintf(stderr, "pipeline: %s\n", lib.status().ToString().c_str());
      return 1;
    }
    scene.shared_poses = *lib;
  }
  const std::string bodies = args.GetOr("bodies", "procedural");
  if (bodies != "procedural") {
    const std::string data = args.GetOr("data", "../shared/data");
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
  runtime::ClassifyOptions copt;
  copt.num_threads = threads;
  copt.want_distributions = true;
  runtime::ProposalOptions mean_shift, fast;
  mean_shift.params = fast.params = forest->proposal_params.value_or(core::DefaultProposalParams());
  mean_shift.num_threads = fast.num_threads = threads;
  fast.method = runtime::ProposalMethod::kFastClustering;

  runtime::JointApEvaluator ap_ms, ap_fast, ap_upper;
  std::vector<double> t_cls, t_prob, t_ms, t_fast;
  runtime::Classification cls;
  long foreground = 0;
  for (int i = 0; i < frames; ++i) {
    auto frame = (*renderer)->Render(seed, uint64_t(i));
    if (!frame.ok()) {
      std::fprintf(stderr, "pipeline: %s\n", frame.status().ToString().c_str());
      return 1;
    }
    foreground += core::CountForeground(frame->depth);
    const auto t0 = Clock::now();
    classifier.Classify(frame->depth, copt, &cls);
    const auto t1 = Clock::now();
    const auto probs = runtime::ProbabilitiesFromClassification(frame->depth, cls);
    const auto t2 = Clock::now();
    const auto p_ms = runtime::ProposeJoints(frame->depth, probs, mean_shift);
    const auto t3 = Clock::now();
    const auto p_fast = runtime::ProposeJoints(frame->depth, probs, fast);
    const auto t4 = Clock::now();
    t_cls.push_back(Ms(t0, t1));
    t_prob.push_back(Ms(t1, t2));
    t_ms.push_back(Ms(t2, t3));
    t_fast.push_back(Ms(t3, t4));
    const auto people = People(*frame);
    ap_ms.AddFrame(p_ms, people);
    ap_fast.AddFrame(p_fast, people);
    ap_upper.AddFrame(runtime::ProposeJoints(frame->depth, runtime::ProbabilitiesFromLabels(frame->depth, frame->labels), mean_shift),
                      people);
  }
  std::printf("forest %s: %zu trees, depth %u, %zu nodes; %d held-out frames (seed %llu), %.0f foreground px/frame\n",
              args.Get("forest")->c_str(), forest->trees.size(), forest->max_depth(), forest->total_nodes(), frames,
              (unsigned long long)seed, double(foreground) / frames);
  std::printf("%-11s %9s %9s %12s\n", "joint", "AP mean", "AP fast", "AP gt-parts");
  for (int j = 0; j < core::kNumJoints; ++j)
    std::printf("%-11s %9.3f %9.3f %12.3f\n", std::string(core::JointName(j)).c_str(), ap_ms.AveragePrecision(j),
                ap_fast.AveragePrecision(j), ap_upper.AveragePrecision(j));
  std::printf("mAP: mean shift %.3f, fast clustering %.3f; upper bound from ground-truth parts %.3f "
              "(inferred / upper bound %.2f)\n",
              ap_ms.MeanAveragePrecision(), ap_fast.MeanAveragePrecision(), ap_upper.MeanAveragePrecision(),
              ap_upper.MeanAveragePrecision() > 0 ? ap_ms.MeanAveragePrecision() / ap_upper.MeanAveragePrecision() : 0.0);
  const double cls_ms = Median(t_cls), prob_ms = Median(t_prob), ms_ms = Median(t_ms), fast_ms = Median(t_fast);
  std::printf("median ms/frame: classify %.2f, probabilities %.2f, mean shift %.2f, fast clustering %.2f\n", cls_ms,
              prob_ms, ms_ms, fast_ms);
  std::printf("pipeline with fast clustering: %.1f frames/s\n", 1000.0 / (cls_ms + prob_ms + fast_ms));
  std::printf("frames/s: %.1f frames/s\n", 1000.0 / (cls_ms + prob_ms + ms_ms));
  return 0;
}
