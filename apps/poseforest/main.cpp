// poseforest: the one program users run. `poseforest help` lists the commands (apps/commands/).
#include <cstdio>
#include <cstring>
#include <string_view>

#include "apps/commands/commands.h"
#include "runtime/core/malloc_tuning.h"
#include "runtime/frame_source.h"
#ifdef POSEFOREST_HAS_FREENECT
#include "apps/devices/freenect_source.h"
#endif
#ifdef POSEFOREST_HAS_OPENNI2
#include "apps/devices/openni2_source.h"
#endif

namespace {

namespace commands = poseforest::apps::commands;

void Usage(FILE* out) {
  std::fprintf(out,
               "poseforest %s - human pose recognition in parts from single depth images\n"
               "(Shotton et al. 2011)\n\n"
               "usage: poseforest <command> [options]     poseforest <command> --help\n"
               "       poseforest help <command>           poseforest --version\n\ncommands:\n",
               POSEFOREST_VERSION);
  for (const commands::CommandInfo& c : commands::AllCommands())
    if (c.make) std::fprintf(out, "  %-11s %s\n", c.name, c.summary);
#ifndef POSEFOREST_WITH_TRAINING
  std::fprintf(out, "\n(runtime-only build: training commands need -DPOSEFOREST_TRAINING=ON)\n");
#endif
}

}  // namespace

int main(int argc, char** argv) {
  poseforest::core::KeepFreedMemory();  // runtime/core/malloc_tuning.h
  // Device back ends built in (optional targets found at configure time).
#ifdef POSEFOREST_HAS_FREENECT
  poseforest::apps::devices::RegisterFreenectBackEnd();
#endif
#ifdef POSEFOREST_HAS_OPENNI2
  poseforest::apps::devices::RegisterOpenNi2BackEnd();
#endif
  if (argc < 2) {
    Usage(stderr);
    return 2;
  }
  const std::string_view cmd = argv[1];
  if (cmd == "help" || cmd == "--help" || cmd == "-h") {
    // --markdown: the README's command table (tests/apps checks the README against it).
    if (argc > 2 && std::string_view(argv[2]) == "--markdown") {
      std::fputs(commands::CommandTableMarkdown().c_str(), stdout);
      return 0;
    }
    // `help CMD` is `CMD --help` (the command's own options), not this list again.
    if (argc > 2) {
      const commands::CommandInfo* c = commands::FindCommand(argv[2]);
      if (c == nullptr) {
        std::fprintf(stderr, "poseforest help: unknown command '%s'\n\n", argv[2]);
        Usage(stderr);
        return 2;
      }
      char help_flag[] = "--help";
      char* sub_argv[] = {argv[2], help_flag, nullptr};
      return commands::RunCommandMain(2, sub_argv);  // "this build has no command" where it lacks it
    }
    Usage(stdout);
    return 0;
  }
  if (cmd == "--version" || cmd == "version") {
    std::printf("poseforest %s\n", POSEFOREST_VERSION);
    const auto back_ends = poseforest::runtime::FrameBackEnds();
    std::printf("frame sources: files (PNG, raw, .npy, .pcd), folders, globs, stdin\n");
    if (back_ends.empty())
      std::printf("device back ends: none (libfreenect and OpenNI2 are found at configure time)\n");
    for (const auto& b : back_ends)
      std::printf("device back end: %s - %s\n", b.scheme.c_str(), b.describe.c_str());
    return 0;
  }
#ifdef POSEFOREST_WITH_TRAINING
  // `train JOB --local-workers N` (or --domain / --min-workers, or a DDS transport flag) runs
  // the job through the distributed service: a coordinator plus worker processes over Fast DDS;
  // same forest.
  if (cmd == "train") {
    for (int i = 2; i < argc; ++i) {
      const std::string_view a = argv[i];
      for (const std::string_view flag : {"--local-workers", "--domain", "--min-workers", "--dds-xml",
                                          "--dds-profile", "--discovery-server", "--security"})
        if (a == flag || (a.starts_with(flag) && a.size() > flag.size() && a[flag.size()] == '='))
          return commands::CoordinatorMain(argc - 1, argv + 1);
    }
  }
#endif
  if (const commands::CommandInfo* c = commands::FindCommand(cmd); c && c->make)
    return commands::RunCommandMain(argc - 1, argv + 1);
  std::fprintf(stderr, "poseforest: unknown command '%s'\n\n", argv[1]);
  Usage(stderr);
  return 2;
}
