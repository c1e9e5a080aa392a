#pragma once
// Running programs from tests, as a user would: a shell command line, its exit code and its
// combined stdout + stderr.

#include <sys/wait.h>

#include <cstdio>
#include <string>

#include "tests/support/paths.h"

namespace poseforest::testing {

struct CommandResult {
  int exit_code = -1;  ///< -1 if the command could not start or did not exit normally
  std::string output;  ///< stdout and stderr together
};

/// Runs `cmd` through /bin/sh and waits for it.
inline CommandResult RunCommand(const std::string& cmd) {
  CommandResult r;
  FILE* pipe = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.output.append(buf, n);
  const int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

/// Runs the built `poseforest` program with `args`.
inline CommandResult RunPoseforest(const std::string& args) {
  return RunCommand((BinDir() / "poseforest").string() + " " + args);
}

}  // namespace poseforest::testing
