// `poseforest export`: the runtime forest from the last checkpoint of a finished or stopped
// distributed job (coordinator/checkpoint_export.h).

#include <cstdio>
#include <string>

#include "apps/commands/args.h"
#include "apps/commands/commands.h"
#include "coordinator/checkpoint_export.h"
#include "runtime/core/forest_format.h"

namespace poseforest::apps::commands {

using core::Status;

int ExportMain(int argc, char** argv) {
  Args args({"checkpoint", "out", "partial"}, {"help"});
  if (Status st = args.Parse(argc, argv); !st.ok() || args.Has("help") || !args.positional().empty() ||
                                          !args.Has("checkpoint") || !args.Has("out")) {
    if (!st.ok()) std::fprintf(stderr, "export: %s\n", st.message().c_str());
    std::fprintf(
        stderr,
        "usage: poseforest export --checkpoint DIR --out FOREST.pff [--partial leaves|drop]\n"
        "  Writes the runtime forest from the checkpoint of a distributed job (`coordinator\n"
        "  --checkpoint DIR`). A finished job gives the coordinator's --out file byte for byte. For\n"
        "  a stopped job the finished trees are written, and the tree in progress is finished as\n"
        "  leaves from its frontier's part counts (--partial leaves, the default) or dropped\n"
        "  (--partial drop).\n");
    return args.Has("help") ? 0 : 2;
  }
  const std::string partial = args.GetOr("partial", "leaves");
  if (partial != "leaves" && partial != "drop") {
    std::fprintf(stderr, "export: --partial %s: expected leaves or drop\n", partial.c_str());
    return 2;
  }
  const std::string dir = *args.Get("checkpoint"), out = *args.Get("out");
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

}  // namespace poseforest::apps::commands
