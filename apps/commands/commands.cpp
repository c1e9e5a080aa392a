#include "apps/commands/commands.h"

#include <cstdio>

#include "apps/commands/cli.h"

namespace poseforest::apps::commands {

namespace {
#ifdef POSEFOREST_WITH_TRAINING
#define POSEFOREST_TRAINING_COMMAND(make) make
#else
#define POSEFOREST_TRAINING_COMMAND(make) nullptr
#endif
}  // namespace

const std::vector<CommandInfo>& AllCommands() {
  static const std::vector<CommandInfo> commands = {
      {"train", "trains a forest from a job config, level by level; `--local-workers N` on the service",
       "[training](docs/training/README.md)", POSEFOREST_TRAINING_COMMAND(MakeTrainCommand)},
      {"coordinator", "runs a training job on a cluster, the same forest byte for byte",
       "[service](docs/distributed/service.md)", POSEFOREST_TRAINING_COMMAND(MakeCoordinatorCommand)},
      {"worker",
       "joins training jobs: renders its shard, builds histograms, trains subtrees; `--http ADDR` serves its "
       "own Prometheus metrics",
       "[service](docs/distributed/service.md), [worker metrics](docs/distributed/monitoring.md#the-workers-metrics)",
       POSEFOREST_TRAINING_COMMAND(MakeWorkerCommand)},
      {"monitor", "live view of a training job (also JSON, Prometheus, a dashboard)",
       "[monitoring](docs/distributed/monitoring.md)", POSEFOREST_TRAINING_COMMAND(MakeMonitorCommand)},
      {"export", "the runtime forest from a distributed job's checkpoint",
       "[monitoring](docs/distributed/monitoring.md#poseforest-export)",
       POSEFOREST_TRAINING_COMMAND(MakeExportCommand)},
      {"eval", "joint AP and mAP on renders; skeletons on hand-labelled real frames",
       "[joints](docs/runtime/joints.md#joint-accuracy-poseforest-eval), [realism](docs/training/realism.md)",
       POSEFOREST_TRAINING_COMMAND(MakeEvalCommand)},
      {"tune-joints", "learns the joint-proposal parameters and the confidence calibration",
       "[joints](docs/runtime/joints.md)", POSEFOREST_TRAINING_COMMAND(MakeTuneJointsCommand)},
      {"learn-votes", "offset votes per leaf: joint candidates from every pixel", "[votes](docs/runtime/votes.md)",
       POSEFOREST_TRAINING_COMMAND(MakeLearnVotesCommand)},
      {"render", "a synthetic labelled depth data set, rendered headlessly",
       "[renderer](renderer/README.md#poseforest-render)", POSEFOREST_TRAINING_COMMAND(MakeRenderCommand)},
      {"infer", "body parts and 3D joint proposals for depth frames from any source",
       "[frames](docs/runtime/frames.md)", MakeInferCommand},
      {"live", "per-person skeletons as frames come: JSON Lines, pictures, a page, DDS",
       "[live](docs/runtime/live.md)", MakeLiveCommand},
      {"frames", "reads, converts and lists depth frames and devices",
       "[frames](docs/runtime/frames.md#frame-sources)", MakeFramesCommand},
      {"inspect", "validates forest files and prints what they hold", "[format](runtime/FORMAT.md)",
       MakeInspectCommand},
      {"import-pcl", "converts the Point Cloud Library's trained people trees",
       "[commands](docs/commands.md#poseforest-import-pcl)", MakeImportPclCommand},
  };
  return commands;
}

const CommandInfo* FindCommand(std::string_view name) {
  for (const CommandInfo& c : AllCommands())
    if (name == c.name) return &c;
  return nullptr;
}

std::string CommandTableMarkdown() {
  std::string t = "| command | what it does | doc |\n|---|---|---|\n";
  for (const CommandInfo& c : AllCommands())
    t += std::string("| [`") + c.name + "`](docs/commands.md#poseforest-" + c.name + ") | " + c.summary + " | " +
         c.docs + " |\n";
  return t;
}

int RunCommandMain(int argc, char** argv) {
  const CommandInfo* info = argc > 0 ? FindCommand(argv[0]) : nullptr;
  if (!info || !info->make) {
    std::fprintf(stderr, "poseforest: %s command '%s'\n", info ? "this build has no" : "unknown",
                 argc > 0 ? argv[0] : "");
    return 2;
  }
  return RunCommand(*info->make(), argc, argv);
}

#ifdef POSEFOREST_WITH_TRAINING
int RenderMain(int argc, char** argv) { return RunCommand(*MakeRenderCommand(), argc, argv); }
int CoordinatorMain(int argc, char** argv) { return RunCommand(*MakeCoordinatorCommand(), argc, argv); }
#endif

}  // namespace poseforest::apps::commands
