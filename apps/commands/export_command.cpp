// `poseforest export`: the runtime forest from the last checkpoint of a finished or stopped
// distributed job (coordinator/checkpoint_export.h).

#include <cstdio>
#include <filesystem>
#include <string>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "coordinator/checkpoint_export.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {

using core::Status;

namespace {

class ExportCommand final : public Command {
 public:
  ExportCommand()
      : Command("export",
                "Writes the runtime forest from the checkpoint of a distributed job (`coordinator\n"
                "--checkpoint DIR`). A finished job gives the coordinator's --out file byte for byte. For\n"
                "a stopped job the finished trees are written, and the tree in progress is finished as\n"
                "leaves from its frontier's part counts (--partial leaves, the default) or dropped\n"
                "(--partial drop).") {
    app_.add_option("--checkpoint", dir_, "the job's checkpoint folder")->type_name("DIR")->required();
    app_.add_option("--out", out_, "forest file to write")->type_name("FOREST.pff")->required();
    app_.add_option("--partial", partial_, "the tree in progress: finished as leaves, or dropped")
        ->type_name("leaves|drop")
        ->check(OneOf({"leaves", "drop"}));
  }
  int Run() override;

 private:
  std::string dir_, out_, partial_ = "leaves";
};

int ExportCommand::Run() {
  const std::string &dir = dir_, &out = out_, &partial = partial_;
  if (const std::string bad =
          CheckOutputFile("--out", out, {dir, (std::filesystem::path(dir) / "checkpoint.pb").string()});
      !bad.empty())
    return UsageError(bad);
  auto r = coordinator::ForestFromCheckpoint(
      dir, partial == "leaves" ? coordinator::PartialTree::kFinishAsLeaves : coordinator::PartialTree::kDrop);
  if (!r.ok()) {
    std::fprintf(stderr, "export: %s\n", r.status().ToString().c_str());
    return 1;
  }
  if (r->job_finished) {
    std::printf("job %s finished: %d of %d trees\n", r->job_id.c_str(), r->finished_trees, r->job_trees);
  } else {
    std::printf("job %s stopped: %d of %d trees finished", r->job_id.c_str(), r->finished_trees,
                r->job_trees);
    if (r->partial_included)
      std::printf(
          "; tree %d (in progress, %d levels decided) finished as %zu leaves from its frontier counts\n",
          r->finished_trees, r->partial_levels, r->partial_leaves);
    else if (r->partial_levels > 0)
      std::printf("; tree %d (in progress, %d levels decided) dropped\n", r->finished_trees,
                  r->partial_levels);
    else
      std::printf("; no tree in progress\n");
  }
  if (Status st = core::SaveForest(r->forest, out); !st.ok()) {
    std::fprintf(stderr, "export: %s\n", st.ToString().c_str());
    return 1;
  }
  size_t nodes = 0;
  for (const auto& t : r->forest.trees) nodes += t.nodes.size();
  std::printf("wrote %s: %zu trees, %zu nodes\n", out.c_str(), r->forest.trees.size(), nodes);
  return 0;
}

}  // namespace

std::unique_ptr<Command> MakeExportCommand() { return std::make_unique<ExportCommand>(); }

}  // namespace poseforest::apps::commands
