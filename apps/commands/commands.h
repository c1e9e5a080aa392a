#pragma once
// The subcommands of the `poseforest` program (apps/poseforest/main.cpp), one file each in this
// folder. Each takes argv with argv[0] = the command name and returns the process exit code (0 ok,
// 1 runtime failure, 2 usage error).

namespace poseforest::apps::commands {

// Inference (every build).
int InferMain(int argc, char** argv);      ///< infer_command.cpp: body parts of depth images
int InspectMain(int argc, char** argv);    ///< inspect_command.cpp: print and validate a forest
int ImportPclMain(int argc, char** argv);  ///< import_pcl_command.cpp: PCL's people trees
int FramesMain(int argc, char** argv);     ///< frames_command.cpp: read, check, convert frames
int LiveMain(int argc, char** argv);       ///< live_command.cpp: per-person skeletons, live

// Training side (only in builds with POSEFOREST_TRAINING=ON; see main.cpp).
int RenderMain(int argc, char** argv);       ///< render_command.cpp: synthetic dataset + montage
int TrainMain(int argc, char** argv);        ///< train_command.cpp: a forest from a job config
int EvalMain(int argc, char** argv);         ///< eval_command.cpp: joint AP, per-class accuracy
int TuneJointsMain(int argc, char** argv);   ///< tune_joints_command.cpp: joint-proposal parameters
int LearnVotesMain(int argc, char** argv);   ///< learn_votes_command.cpp: offset votes of a forest
int CoordinatorMain(int argc, char** argv);  ///< coordinator_command.cpp: train over Fast DDS
int WorkerMain(int argc, char** argv);       ///< worker_command.cpp: join a job over Fast DDS
int MonitorMain(int argc, char** argv);      ///< monitor_command.cpp: live status of a job
int ExportMain(int argc, char** argv);       ///< export_command.cpp: forest from a checkpoint

}  // namespace poseforest::apps::commands
