#pragma once
// The subcommands of the `poseforest` program. Each takes argv with argv[0] = the command
// name and returns the process exit code (0 ok, 1 runtime failure, 2 usage error).

namespace poseforest::cli {

int InferMain(int argc, char** argv);    ///< runtime/cli/infer_command.cpp
int InspectMain(int argc, char** argv);  ///< runtime/cli/inspect_command.cpp
int ImportPclMain(int argc, char** argv);  ///< runtime/cli/import_pcl_command.cpp
int FramesMain(int argc, char** argv);   ///< runtime/cli/frames_command.cpp
int LiveMain(int argc, char** argv);     ///< runtime/cli/live_command.cpp

// Training side (only in builds with POSEFOREST_TRAINING=ON; see main.cpp).
int RenderMain(int argc, char** argv);   ///< renderer: write a synthetic dataset + montage
int TrainMain(int argc, char** argv);    ///< coordinator: train a forest from a job config
int EvalMain(int argc, char** argv);     ///< coordinator: per-class accuracy on a test set
int TuneJointsMain(int argc, char** argv);  ///< coordinator: learn joint-proposal parameters
int LearnVotesMain(int argc, char** argv);  ///< engine/cli: offset votes of a trained forest
int CoordinatorMain(int argc, char** argv);  ///< coordinator/: train over Fast DDS
int WorkerMain(int argc, char** argv);       ///< worker/: join a job over Fast DDS
int MonitorMain(int argc, char** argv);      ///< coordinator/monitoring/: live status of a job
int ExportMain(int argc, char** argv);       ///< coordinator/: forest from a checkpoint

}  // namespace poseforest::cli
