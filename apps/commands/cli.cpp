#include "apps/commands/cli.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <sstream>

#include "apps/commands/commands.h"
#include "runtime/core/command_line.h"
#include "runtime/skeleton.h"

namespace poseforest::apps::commands {

namespace {

/// `text` re-wrapped into lines of at most `width` characters (words never split).
std::string Wrap(const std::string& text, size_t width) {
  std::string out, line, word;
  std::istringstream words(text);
  while (words >> word) {
    if (!line.empty() && line.size() + 1 + word.size() > width) {
      out += line + "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
  }
  return out + line;
}

/// The help layout: the usage line, the description, then "--name VALUE   help line (default D)"
/// wrapped to 100 columns, positionals by name, groups as headings.
class HelpFormatter : public CLI::Formatter {
 public:
  static constexpr size_t kColumn = 34, kWidth = 100;
  HelpFormatter() { column_width(kColumn); }
  std::string make_help(const CLI::App* app, std::string name, CLI::AppFormatMode mode) const override {
    if (mode == CLI::AppFormatMode::Sub) return make_expanded(app);
    return make_usage(app, name) + "\n" + make_description(app) + make_positionals(app) + make_groups(app, mode) +
           make_subcommands(app, mode) + "\n" + make_footer(app);
  }
  std::string make_option_opts(const CLI::Option* opt) const override {
    if (opt->get_positional() || opt->get_type_size() == 0) return "";
    return opt->get_type_name().empty() ? "" : " " + opt->get_type_name();
  }
  std::string make_option_desc(const CLI::Option* opt) const override {
    std::string d = opt->get_description();
    if (opt->get_required()) d += " (required)";
    if (!opt->get_positional() && opt->get_type_size() != 0 && !opt->get_default_str().empty())
      d += " (default " + opt->get_default_str() + ")";
    return Wrap(d, kWidth - kColumn);
  }
  std::string make_usage(const CLI::App* app, std::string name) const override {
    std::string u = "usage: " + name + (app->get_options({}).size() > 1 ? " [options]" : "");
    for (const CLI::Option* p : app->get_options([](const CLI::Option* o) { return o->get_positional(); }))
      u += p->get_required() ? " " + p->get_name() + (p->get_expected_max() > 1 ? "..." : "")
                             : " [" + p->get_name() + (p->get_expected_max() > 1 ? "..." : "") + "]";
    return u + "\n";
  }
};

/// Whether an option's type name (or a positional's name) says its value names a file, folder or
/// frame source: FILE, PATH, DIR, FILE|-, SET, SOURCE, TREE, or a name with an extension
/// (JOB.textproto, FOREST.pff, KEY.pem, F.jsonl).
bool NamesAFile(const std::string& type_name) {
  for (const char* name : {"FILE", "PATH", "DIR", "FILE|-", "SET", "SOURCE", "TREE"})
    if (type_name == name) return true;
  const size_t dot = type_name.find('.');
  if (dot == std::string::npos || dot == 0 || dot + 1 == type_name.size()) return false;
  for (size_t i = 0; i < type_name.size(); ++i) {
    const char c = type_name[i];
    if (i < dot ? !(c >= 'A' && c <= 'Z') : i > dot && !(c >= 'a' && c <= 'z')) return false;
  }
  return true;
}

/// Every option of `app` and its subcommands whose value names a file, folder or source
/// (NamesAFile) gets NonEmptyPath(): "--forest ''" is a usage error naming the option, not
/// "NotFound: : no such file".
void CheckFileOptionsNotEmpty(CLI::App& app) {
  for (CLI::Option* o : app.get_options()) {
    if (!NamesAFile(o->get_type_name()) && !(o->get_positional() && NamesAFile(o->get_name()))) continue;
    try {
      o->get_validator("non-empty path");  // given already (RunCommand ran on this app before)
    } catch (const CLI::OptionNotFound&) {
      o->check(NonEmptyPath());
    }
  }
  for (CLI::App* sub : app.get_subcommands({})) CheckFileOptionsNotEmpty(*sub);
}

/// The option a CLI11 message is about, spelt as on the command line ("--out", "-x").
std::string Unexpected(const std::string& arg) {
  if (arg.size() > 2 && arg.compare(0, 2, "--") == 0) return "unknown option " + arg.substr(0, arg.find('='));
  if (arg.size() > 1 && arg[0] == '-') return "unknown option " + arg + " (options are spelt --name)";
  return "unexpected argument '" + arg + "'";
}

}  // namespace

Command::Command(const std::string& name, const std::string& description)
    : app_("", "poseforest " + name), name_(name) {
  const CommandInfo* info = FindCommand(name);
  std::string text = info ? std::string(info->summary) : "";
  if (!description.empty()) text += (text.empty() ? "" : "\n\n") + description;
  app_.description(text);
  app_.formatter(std::make_shared<HelpFormatter>());
  app_.set_help_flag("-h,--help", "this text");
  // A repeated option keeps its last value (scripts append overrides); defaults show in --help.
  app_.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)->always_capture_default();
}

std::string CheckOutputFile(const std::string& option, const std::string& path,
                            const std::vector<std::string>& inputs) {
  namespace fs = std::filesystem;
  const std::string what = option + " " + path + ": ";
  std::error_code ec;
  if (fs::is_directory(path, ec)) return what + "is a folder; give a file name";
  const fs::path folder = fs::absolute(path, ec).parent_path();
  if (!fs::is_directory(folder, ec)) return what + "folder " + folder.string() + " does not exist";
  if (::access(folder.c_str(), W_OK) != 0) return what + "cannot write in folder " + folder.string();
  if (fs::exists(path, ec))
    for (const std::string& input : inputs)
      if (fs::exists(input, ec) && fs::equivalent(path, input, ec))
        return what + "the same file as the input " + input + " (writing it would destroy that input)";
  return "";
}

std::string FolderFrameCount(const std::string& set_option, const std::string& set, int64_t held,
                             int64_t first, const std::string& count_option, std::optional<int64_t> asked,
                             int64_t* count) {
  const int64_t left = std::max<int64_t>(0, held - first);
  *count = asked.value_or(left);
  if (*count > 0 && *count <= left) return "";
  return set_option + " " + set + " holds " + std::to_string(held) + " frames; " +
         (first > 0 ? "--first " + std::to_string(first) + " " : std::string()) + count_option + " " +
         std::to_string(*count) + " asks for " +
         (*count <= 0 ? std::string("none") : "frames up to " + std::to_string(first + *count - 1));
}

std::string Command::Caller() const {
  // `train JOB --local-workers N` runs this program's coordinator command (poseforest.cpp): say
  // what the user typed, and whose options these are.
  return invoked_as_.empty() || invoked_as_ == name_ ? name_ : invoked_as_ + " (as " + name_ + ")";
}

int Command::UsageError(const std::string& message) const {
  std::fprintf(stderr, "poseforest %s: %s\n", Caller().c_str(), message.c_str());
  return 2;
}

int RunCommand(Command& command, int argc, char** argv) {
  CLI::App& app = command.app();
  if (argc > 0) command.set_invoked_as(argv[0]);
  // "--name=" reaches the option as an empty value (core::ArgumentsForCli11), which an option
  // naming a file refuses.
  std::vector<std::string> args = core::ArgumentsForCli11(argc, argv);
  CheckFileOptionsNotEmpty(app);
  try {
    app.parse(args);
  } catch (const CLI::CallForHelp&) {
    std::fputs(app.help().c_str(), stdout);
    return 0;
  } catch (const CLI::ParseError& e) {
    std::string message = e.what();
    if (dynamic_cast<const CLI::ExtrasError*>(&e) && !app.remaining().empty()) {
      message = Unexpected(app.remaining().front());
    } else if (dynamic_cast<const CLI::ArgumentMismatch*>(&e) && message.ends_with(" missing")) {
      message = "option " + message.substr(0, message.find(':')) + " needs a value";
    } else if (const size_t at = message.find(": must be "); at != std::string::npos) {
      message.erase(at, 1);  // "--threads: must be ..." -> "--threads must be ..."
    }
    std::fprintf(stderr, "poseforest %s: %s\n(poseforest %s --help lists the options)\n",
                 command.Caller().c_str(), message.c_str(), command.name().c_str());
    return 2;
  }
  return command.Run();
}

std::vector<std::string> OptionNames(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* o : app.get_options()) {
    if (o->get_positional()) {
      names.push_back(o->get_name());
      continue;
    }
    for (const std::string& l : o->get_lnames()) names.push_back("--" + l);
  }
  return names;
}

CLI::Validator IntIn(long long lo, long long hi) {
  return CLI::Validator(
      [lo, hi](std::string& v) -> std::string {
        char* end = nullptr;
        errno = 0;
        const long long x = std::strtoll(v.c_str(), &end, 10);
        if (errno != 0 || end == v.c_str() || *end != '\0' || x < lo || x > hi)
          return "must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got '" + v +
                 "'";
        return "";
      },
      "");
}

CLI::Validator NonNegativeInt() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        char* end = nullptr;
        errno = 0;
        (void)std::strtoull(v.c_str(), &end, 10);
        if (v.empty() || v[0] == '-' || errno != 0 || *end != '\0')
          return "must be a non-negative integer, not '" + v + "'";
        return "";
      },
      "");
}

CLI::Validator NumberIn(double lo, double hi, const std::string& what) {
  return CLI::Validator(
      [lo, hi, what](std::string& v) -> std::string {
        char* end = nullptr;
        const double d = std::strtod(v.c_str(), &end);
        if (end == v.c_str() || *end != '\0' || !(d >= lo && d <= hi)) {
          char range[96];
          std::snprintf(range, sizeof range, "[%g, %g]", lo, hi);
          return "must be " + what + " in " + range + " (got '" + v + "')";
        }
        return "";
      },
      "");
}

CLI::Validator SkeletonFitValidator() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        return runtime::SkeletonFitFromName(v) ? "" : "must be kinematic or greedy (got '" + v + "')";
      },
      "");
}

CLI::Validator NonEmptyName() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        if (v.empty()) return "must be a non-empty name (leave the option out for its default)";
        for (unsigned char c : v)
          if (c < 0x20 || c == 0x7f) return "must be printable (no control characters)";
        return "";
      },
      "");
}

CLI::Validator NonEmptyPath() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        return v.empty() ? "must be a file or folder name, not empty" : "";
      },
      "", "non-empty path");
}

CLI::Validator OneOf(std::vector<std::string> names) {
  return CLI::Validator(
      [names](std::string& v) -> std::string {
        for (const std::string& n : names)
          if (v == n) return "";
        std::string list;
        for (size_t i = 0; i < names.size(); ++i)
          list += (i == 0 ? "" : i + 1 == names.size() ? " or " : ", ") + names[i];
        return "must be " + list + ", not '" + v + "'";
      },
      "");
}

}  // namespace poseforest::apps::commands
