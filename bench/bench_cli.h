#pragma once
// The bench/ programs' command lines, on CLI11 (Debian libcli11-dev, as the `poseforest`
// commands): every option checked, --help, and a usage error (exit status 2) that names the
// option instead of a silent default. The `poseforest` commands' own parser (apps/commands/cli.h)
// lives in the apps layer, which these programs do not link.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <string>

#include "runtime/core/command_line.h"

namespace poseforest::bench {

/// A check for options that name a file or folder: an empty value ("--forest=") is refused, not
/// taken as "not given".
inline const CLI::Validator kNonEmptyPath(
    [](const std::string& v) { return v.empty() ? std::string("must be a file or folder name, not empty") : ""; }, "",
    "non-empty");

/// The options of a bench that times a loop over frames: --threads N, --frames N (how many
/// frames it builds), --seconds S (how long it times), each with its default shown.
inline void AddFrameLoopOptions(CLI::App& app, int* threads, const std::string& threads_help, int* frames,
                                const std::string& frames_help, double* seconds) {
  app.add_option("--threads", *threads, threads_help)
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  app.add_option("--frames", *frames, frames_help)
      ->type_name("N")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  app.add_option("--seconds", *seconds, "how long to time")
      ->type_name("S")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 86400.0));
}

/// Parses argv into `app` (named "bench/NAME"). Empty when the program goes on; else the exit
/// status: 0 after --help (on stdout), 2 after a usage error (on stderr).
inline std::optional<int> ParseBenchCommandLine(CLI::App& app, int argc, char** argv) {
  std::vector<std::string> args = core::ArgumentsForCli11(argc, argv);
  try {
    app.parse(args);
  } catch (const CLI::CallForHelp&) {
    std::fputs(app.help().c_str(), stdout);
    return 0;
  } catch (const CLI::ParseError& e) {
    std::string message = e.what();
    if (const size_t at = message.find(": must be "); at != std::string::npos)
      message.erase(at, 1);  // "--threads: must be ..." -> "--threads must be ..."
    std::fprintf(stderr, "%s: %s\n(%s --help lists the options)\n", app.get_name().c_str(), message.c_str(),
                 app.get_name().c_str());
    return 2;
  }
  return std::nullopt;
}

}  // namespace poseforest::bench
