#pragma once
// The commands of the `poseforest` program (apps/poseforest/main.cpp), one file each in this
// folder, and the table that lists them: `poseforest help` and the README's command list
// (`poseforest help --markdown`) are printed from it. Each XMain takes argv with argv[0] = the
// command name and returns the process exit code (0 ok, 1 runtime failure, 2 usage error).

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace poseforest::apps::commands {

class Command;  // cli.h

/// One command: what `poseforest help` and the README say of it, and the command itself.
struct CommandInfo {
  const char* name;
  const char* summary;  ///< one line: `poseforest help`, the README's table, the top of --help
  const char* docs;     ///< the README table's doc column: Markdown links from the repository root
  /// The command with its parser; nullptr where this build leaves it out (the training side of
  /// a runtime-only build, POSEFOREST_TRAINING=OFF).
  std::unique_ptr<Command> (*make)();
};

/// Every command, built or not, in the README's order.
const std::vector<CommandInfo>& AllCommands();
/// The command called `name`, or nullptr.
const CommandInfo* FindCommand(std::string_view name);
/// The README's command table (Markdown), from AllCommands().
std::string CommandTableMarkdown();

// Inference (every build).
std::unique_ptr<Command> MakeInferCommand();      ///< infer_command.cpp: body parts of depth images
std::unique_ptr<Command> MakeInspectCommand();    ///< inspect_command.cpp: print and validate a forest
std::unique_ptr<Command> MakeImportPclCommand();  ///< import_pcl_command.cpp: PCL's people trees
std::unique_ptr<Command> MakeFramesCommand();     ///< frames_command.cpp: read, check, convert frames
std::unique_ptr<Command> MakeLiveCommand();       ///< live_command.cpp: per-person skeletons, live

// Training side (only in builds with POSEFOREST_TRAINING=ON).
std::unique_ptr<Command> MakeRenderCommand();       ///< render_command.cpp: synthetic dataset + montage
std::unique_ptr<Command> MakeTrainCommand();        ///< train_command.cpp: a forest from a job config
std::unique_ptr<Command> MakeEvalCommand();         ///< eval_command.cpp: joint AP, per-class accuracy
std::unique_ptr<Command> MakeTuneJointsCommand();   ///< tune_joints_command.cpp: joint-proposal parameters
std::unique_ptr<Command> MakeLearnVotesCommand();   ///< learn_votes_command.cpp: offset votes of a forest
std::unique_ptr<Command> MakeCoordinatorCommand();  ///< coordinator_command.cpp: train over Fast DDS
std::unique_ptr<Command> MakeWorkerCommand();       ///< worker_command.cpp: join a job over Fast DDS
std::unique_ptr<Command> MakeMonitorCommand();      ///< monitor_command.cpp: live status of a job
std::unique_ptr<Command> MakeExportCommand();       ///< export_command.cpp: forest from a checkpoint

/// Runs the command called argv[0] with its arguments (2 with a message for an unknown or
/// unbuilt name). Tests run commands in-process through it.
int RunCommandMain(int argc, char** argv);

/// `render` (tests run it in-process) and `coordinator` (also `train` with a DDS flag, main.cpp)
/// whatever argv[0] says.
int RenderMain(int argc, char** argv);
int CoordinatorMain(int argc, char** argv);

}  // namespace poseforest::apps::commands
