#pragma once
// A small, strict command-line parser shared by the subcommands: --name value / --name=value
// options, boolean flags, positional arguments, and clear usage errors.

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::apps::commands {

class Args {
 public:
  /// `value_options`: options that take a value; `flags`: options that take none.
  Args(std::set<std::string> value_options, std::set<std::string> flags)
      : value_options_(std::move(value_options)), flags_(std::move(flags)) {}

  /// Parses argv[1..argc) (argv[0] is the command name). Unknown options are errors.
  core::Status Parse(int argc, char** argv);

  bool Has(const std::string& name) const { return values_.count(name) || set_flags_.count(name); }
  std::optional<std::string> Get(const std::string& name) const;
  std::string GetOr(const std::string& name, const std::string& fallback) const;
  /// Integer option; error if present and not an integer within [lo, hi].
  core::Result<long> GetInt(const std::string& name, long fallback, long lo, long hi) const;
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  std::set<std::string> value_options_, flags_;
  std::map<std::string, std::string> values_;
  std::set<std::string> set_flags_;
  std::vector<std::string> positional_;
};

}  // namespace poseforest::apps::commands
