// poseforest train: trains a forest from a job config with the single-process engine.
#include <omp.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "engine/evaluation.h"
#include "engine/job_spec.h"
#include "engine/local_trainer.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {
namespace {

class TrainCommand final : public Command {
 public:
  TrainCommand()
      : Command("train",
                "Trains a randomized decision forest (Shotton et al. 2011, section 3.3) from a job config in\n"
                "protobuf text format (poseforest.v1.TrainerConfig, proto/poseforest/v1/job.proto; examples in\n"
                "docs/training/). Trees grow level by level; every level prints: tree, level, frontier nodes,\n"
                "nodes split, samples, feature evaluations per second, elapsed seconds, memory. The forest is\n"
                "byte-identical for a given config whatever --threads and --shards are.\n"
                "If the job has a test_set, the average per-class accuracy on it is printed at the end.\n"
                "\n"
                "With --local-workers N (or --domain D / --min-workers N, or --dds-xml, --dds-profile,\n"
                "--discovery-server, --security) the same job runs through the distributed service instead:\n"
                "a coordinator in this process and N worker processes on this machine (or workers that join\n"
                "over Fast DDS), with every option of `poseforest coordinator` (see `poseforest coordinator\n"
                "--help`); the forest is byte-identical.") {
    app_.add_option("JOB.textproto", job_, "the job config")->required();
    app_.add_option("--out", out_, "forest file to write")->type_name("PATH")->required();
    app_.add_option("--threads", threads_, "override the job's thread count (0 = all cores)")
        ->type_name("N")
        ->check(IntIn(0, 1024));
    app_.add_option("--shards", shards_, "split the frames over N in-process worker shards (same forest)")
        ->type_name("N")
        ->check(IntIn(1, 256));
    app_.add_flag("--quiet", quiet_, "no per-level progress");
    app_.add_option("--event-log", event_log_,
                    "append a JSON line per level to F (JSON Lines: event LEVEL_DONE, tree, level,\n"
                    "nodes, split, samples, evaluations, evaluations_per_s, seconds, elapsed_s;\n"
                    "the coordinator's event log names, docs/distributed/monitoring.md)")
        ->type_name("F");
  }
  int Run() override;

 private:
  std::string job_, out_, event_log_;
  std::optional<int> threads_;
  int shards_ = 1;
  bool quiet_ = false;
};

int TrainCommand::Run() {
  if (const std::string bad = CheckOutputFile("--out", out_, {job_}); !bad.empty()) return UsageError(bad);
  auto params = engine::LoadJob(job_);
  if (!params.ok()) {
    std::fprintf(stderr, "poseforest train: %s\n", params.status().ToString().c_str());
    return 2;
  }
  if (threads_) params->threads = *threads_;
  const bool quiet = quiet_;
  std::printf("job %s: %s\n", job_.c_str(), engine::DescribeParams(*params).c_str());
  engine::LocalTrainerOptions opt;
  opt.num_shards = shards_;
  opt.log = [](const std::string& m) {
    std::printf("%s\n", m.c_str());
    std::fflush(stdout);
  };
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> event_log(nullptr, std::fclose);
  if (!event_log_.empty()) {
    event_log.reset(std::fopen(event_log_.c_str(), "ae"));
    if (!event_log) {
      std::fprintf(stderr, "poseforest train: --event-log %s: %s\n", event_log_.c_str(),
                   std::strerror(errno));
      return 2;
    }
  }
  if (!quiet || event_log) {
    opt.progress = [quiet, log = event_log.get()](const engine::LevelProgress& p) {
      if (log) {
        const std::string line = nlohmann::ordered_json{{"event", "LEVEL_DONE"},
                                                        {"tree", p.tree},
                                                        {"level", p.level},
                                                        {"nodes", p.frontier_nodes},
                                                        {"split", p.split_nodes},
                                                        {"samples", p.samples},
                                                        {"evaluations", p.evaluations},
                                                        {"evaluations_per_s", p.evaluations_per_s},
                                                        {"seconds", p.level_seconds},
                                                        {"elapsed_s", p.elapsed_s}}
                                     .dump() +
                                 "\n";
        (void)std::fwrite(line.data(), 1, line.size(), log);  // a full disk must not stop training
        (void)std::fflush(log);
      }
      if (quiet) return;
      std::printf(
          "tree %d level %2d: %6zu nodes (%6zu split), %10llu samples, %.3g evaluations/s, %.1f s, %llu "
          "MiB\n",
          p.tree, p.level, p.frontier_nodes, p.split_nodes, static_cast<unsigned long long>(p.samples),
          p.evaluations_per_s, p.elapsed_s, static_cast<unsigned long long>(p.memory_bytes >> 20));
      std::fflush(stdout);
    };
  }
  engine::LocalTrainer trainer(*params, opt);
  auto forest = trainer.Train();
  if (!forest.ok()) {
    std::fprintf(stderr, "poseforest train: %s\n", forest.status().ToString().c_str());
    return 1;
  }
  const auto& s = trainer.stats();
  if (auto st = core::SaveForest(*forest, out_); !st.ok()) {
    std::fprintf(stderr, "poseforest train: %s\n", st.ToString().c_str());
    return 1;
  }
  std::printf("wrote %s: %zu trees, %zu nodes, max depth %u\n", out_.c_str(),
              forest->trees.size(), forest->total_nodes(), forest->max_depth());
  std::printf(
      "%llu samples, %.3g evaluations in %.1f s (histograms %.1f s, ranges %.1f s, frames %.1f s) on %d "
      "threads: "
      "%.3g evaluations/s/core\n",
      static_cast<unsigned long long>(s.samples), double(s.evaluations), s.total_seconds, s.histogram_seconds,
      s.range_seconds, s.load_seconds, s.threads,
      s.histogram_seconds > 0 ? double(s.evaluations) / s.histogram_seconds / s.threads : 0.0);
  std::printf(
      "memory: frames+samples %.1f MiB peak (%llu bytes per image), histograms %.1f MiB peak\n",
      double(s.peak_sample_bytes) / 1048576.0,
      static_cast<unsigned long long>(s.peak_sample_bytes / uint64_t(std::max(1, params->images_per_tree))),
      double(s.peak_histogram_bytes) / 1048576.0);
  if (params->has_test_set) {
    engine::EvalOptions eo;
    eo.num_images = params->test_images;
    eo.threads = params->threads;
    auto m = engine::EvaluateForest(*forest, params->test_source, eo);
    if (!m.ok()) {
      std::fprintf(stderr, "poseforest train: test set: %s\n", m.status().ToString().c_str());
      return 1;
    }
    std::printf("test set (%d frames): average per-class accuracy %.2f%%, pixel accuracy %.2f%%\n",
                eo.num_images, 100.0 * m->AveragePerClassAccuracy(), 100.0 * m->PixelAccuracy());
  }
  return 0;
}

}  // namespace

std::unique_ptr<Command> MakeTrainCommand() { return std::make_unique<TrainCommand>(); }

}  // namespace poseforest::apps::commands
