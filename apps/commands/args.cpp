#include "apps/commands/args.h"

#include <cerrno>
#include <cstdlib>

namespace poseforest::apps::commands {

core::Status Args::Parse(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--") {
      for (++i; i < argc; ++i) positional_.emplace_back(argv[i]);
      break;
    }
    if (a.size() > 2 && a.compare(0, 2, "--") == 0) {
      std::string name = a.substr(2), value;
      bool has_value = false;
      if (const auto eq = name.find('='); eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        has_value = true;
      }
      if (flags_.count(name)) {
        if (has_value) return {core::ErrorCode::kInvalidArgument, "option --" + name + " takes no value"};
        set_flags_.insert(name);
      } else if (value_options_.count(name)) {
        if (!has_value) {
          if (i + 1 >= argc) return {core::ErrorCode::kInvalidArgument, "option --" + name + " needs a value"};
          value = argv[++i];
        }
        values_[name] = value;
      } else {
        return {core::ErrorCode::kInvalidArgument, "unknown option --" + name};
      }
    } else if (a.size() > 1 && a[0] == '-' && a != "-") {
      if (a == "-h" && flags_.count("help")) {
        set_flags_.insert("help");
        continue;
      }
      return {core::ErrorCode::kInvalidArgument, "unknown option " + a + " (options are spelt --name)"};
    } else {
      positional_.push_back(a);
    }
  }
  return core::Status::Ok();
}

std::optional<std::string> Args::Get(const std::string& name) const {
  const auto it = values_.find(name);
  if (it == values_.end()) return std::nullopt;
  return it->second;
}

std::string Args::GetOr(const std::string& name, const std::string& fallback) const {
  return Get(name).value_or(fallback);
}

core::Result<long> Args::GetInt(const std::string& name, long fallback, long lo, long hi) const {
  const auto v = Get(name);
  if (!v) return fallback;
  char* end = nullptr;
  errno = 0;
  const long x = std::strtol(v->c_str(), &end, 10);
  if (errno != 0 || end == v->c_str() || *end != '\0' || x < lo || x > hi)
    return core::Status(core::ErrorCode::kInvalidArgument, "--" + name + " must be an integer in [" +
                                                              std::to_string(lo) + ", " + std::to_string(hi) +
                                                              "], got '" + *v + "'");
  return x;
}

}  // namespace poseforest::apps::commands
