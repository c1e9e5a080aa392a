// poseforest eval: average per-class accuracy of a forest on held-out labelled frames.
#include <cstdio>
#include <string>

#include "coordinator/evaluation.h"
#include "runtime/cli/args.h"
#include "runtime/cli/commands.h"
#include "runtime/core/forest_format.h"
#include "worker/job_spec.h"

namespace poseforest::cli {
namespace {
constexpr const char* kUsage = R"(usage: poseforest eval --forest FOREST.pff --test-set SET [options]

Classifies every body pixel of held-out labelled frames and reports the paper's metric (section
4): the average per-class accuracy, i.e. the mean of the diagonal of the row-normalized confusion
matrix between ground-truth and most likely inferred part; then the per-part accuracy table and
the confusion matrix as text (and as a picture with --png).

SET is one of:
  DIR                a folder written by `poseforest render` (depth_%06d.png + labels_%06d.png)
  JOB.textproto      a training job config: its test_set { } is used
  procedural:SEED    procedural frames (the test source of the unit tests and benchmarks)

options:
  --forest PATH   forest file (required)
  --test-set SET  (required)
  --images N      frames to evaluate (default: the job's test_set.num_images, else 50; for a
                  folder at most its frame count)
  --first N       first frame index (default 0)
  --threads N     classifier threads (0 = all cores, default)
  --png PATH      also write the confusion matrix as an RGB PNG
  --help          this text
)";
}  // namespace

int EvalMain(int argc, char** argv) {
  Args args({"forest", "test-set", "images", "first", "threads", "png"}, {"help"});
  if (auto st = args.Parse(argc, argv); !st.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n\n%s", st.message().c_str(), kUsage);
    return 2;
  }
  if (args.Has("help")) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (!args.Has("forest") || !args.Has("test-set") || !args.positional().empty()) {
    std::fprintf(stderr, "poseforest eval: need --forest and --test-set\n\n%s", kUsage);
    return 2;
  }
  auto images = args.GetInt("images", -1, 1, 10'000'000);
  auto first = args.GetInt("first", 0, 0, 1L << 40);
  auto threads = args.GetInt("threads", 0, 0, 1024);
  for (const auto* r : {&images, &first, &threads}) {
    if (!r->ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", r->status().message().c_str());
      return 2;
    }
  }
  const std::string set = *args.Get("test-set");
  worker::SourceSpec source;
  int num_images = 50;
  if (set.rfind("procedural:", 0) == 0) {
    source.kind = worker::SourceKind::kProcedural;
    try {
      source.seed = std::stoull(set.substr(11));
    } catch (...) {
      std::fprintf(stderr, "poseforest eval: --test-set %s: expected procedural:SEED with an integer seed\n",
                   set.c_str());
      return 2;
    }
    source.width = 320;
    source.height = 240;
  } else if (set.size() > 10 && set.substr(set.size() - 10) == ".textproto") {
    auto job = worker::LoadJob(set);
    if (!job.ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", job.status().ToString().c_str());
      return 2;
    }
    if (!job->has_test_set) {
      std::fprintf(stderr, "poseforest eval: %s has no test_set { }\n", set.c_str());
      return 2;
    }
    source = job->test_source;
    num_images = job->test_images;
  } else {
    source.kind = worker::SourceKind::kDataset;
    source.folder = set;
    auto probe = worker::MakeImageSource(source);
    if (!probe.ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", probe.status().ToString().c_str());
      return 1;
    }
    num_images = int(std::min<uint64_t>((*probe)->size(), 1'000'000));
  }
  if (*images > 0) num_images = int(*images);
  auto forest = core::LoadForest(*args.Get("forest"));
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  coordinator::EvalOptions eo;
  eo.num_images = num_images;
  eo.first_index = uint64_t(*first);
  eo.threads = int(*threads);
  auto m = coordinator::EvaluateForest(*forest, source, eo);
  if (!m.ok()) {
    std::fprintf(stderr, "poseforest eval: %s\n", m.status().ToString().c_str());
    return 1;
  }
  std::printf("forest %s on %s, %d frames\n\n", args.Get("forest")->c_str(), set.c_str(), num_images);
  std::fputs(coordinator::FormatConfusionText(*m).c_str(), stdout);
  std::printf("\n");
  std::fputs(coordinator::FormatAccuracyTable(*m).c_str(), stdout);
  if (auto png = args.Get("png")) {
    if (auto st = coordinator::WriteConfusionPng(*m, *png); !st.ok()) {
      std::fprintf(stderr, "poseforest eval: %s\n", st.ToString().c_str());
      return 1;
    }
    std::printf("confusion matrix picture: %s\n", png->c_str());
  }
  return 0;
}

}  // namespace poseforest::cli
