#pragma once
// A program's arguments as its CLI11 parser should see them. Shared by every program of the
// project that parses a command line with CLI11 (the `poseforest` commands, poseforest-poselib,
// the bench/ programs); it is here, at the bottom layer, so that each of them can include it. It
// uses only the standard library: the runtime's dependency promise is unchanged.

#include <algorithm>
#include <string>
#include <vector>

namespace poseforest::core {

/// argv[1..argc) for CLI11's App::parse(std::vector<std::string>&), which takes them in reverse
/// order. "--name=" (an empty value after '=') is passed on as "--name" and "": CLI11 2.x would
/// take the NEXT argument as the value ("--id= --check-config" set the id to "--check-config",
/// "--forest= x.png" read x.png as the forest), so the option's own check sees the empty value.
/// Arguments after "--" are left as they are.
inline std::vector<std::string> ArgumentsForCli11(int argc, const char* const* argv) {
  std::vector<std::string> args;
  bool options_end = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    options_end = options_end || a == "--";
    if (!options_end && a.size() > 3 && a.starts_with("--") && a.back() == '=' && a.find('=') == a.size() - 1) {
      args.push_back(a.substr(0, a.size() - 1));
      args.emplace_back();
    } else {
      args.push_back(a);
    }
  }
  std::reverse(args.begin(), args.end());
  return args;
}

}  // namespace poseforest::core
