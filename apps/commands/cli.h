#pragma once
// The commands' command lines on CLI11 (Debian libcli11-dev, header-only): each command declares
// its options once (name, type, default, help line) on a Command's CLI::App; `--help` is
// generated from that declaration, and a usage error (an unknown option, a missing or bad value)
// prints one line naming the option and exits 2. Conventions shared by every command: options
// are spelt --name (--name VALUE or --name=VALUE), a repeated option keeps its last value, `--`
// ends the options, -h is --help.

#include <CLI/CLI.hpp>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace poseforest::apps::commands {

/// One command of the program: its parser, with the options bound to the command's own
/// fields, and the work. Run() sees the fields filled in by a successful parse.
class Command {
 public:
  /// `name`: the command's name in commands.h's table (its summary opens the help text);
  /// `description`: the paragraphs between the summary and the options.
  Command(const std::string& name, const std::string& description);
  virtual ~Command() = default;
  Command(const Command&) = delete;
  Command& operator=(const Command&) = delete;

  CLI::App& app() { return app_; }
  const std::string& name() const { return name_; }
  /// The command the user typed, where another one runs this one (`train --local-workers N`).
  void set_invoked_as(const std::string& command) { invoked_as_ = command; }
  /// How messages name the command: "coordinator", or "train (as coordinator)".
  std::string Caller() const;
  /// The work after a successful parse: the process exit code (0 ok, 1 failure, 2 usage error).
  virtual int Run() = 0;

 protected:
  /// Whether --`option` was given on the command line (for defaults that depend on it).
  bool Given(const std::string& option) const { return app_.count("--" + option) > 0; }
  /// Prints "poseforest NAME: message" on stderr and returns 2 (a usage error found after parsing).
  int UsageError(const std::string& message) const;

  CLI::App app_;
  std::string name_;
  std::string invoked_as_;
};

/// Parses argv[1..argc) (argv[0] is the command's name) and runs the command: 0 after --help
/// (on stdout), 2 after a usage error (on stderr, naming the option), else what Run() returns.
int RunCommand(Command& command, int argc, char** argv);

/// The option names of `app` as written on a command line (--name, positionals by name).
std::vector<std::string> OptionNames(const CLI::App& app);

/// Checked before any work: `path` can be written as an output file. Its folder exists and is
/// writable, it is not a folder, and it is not the same file as any of `inputs` (by another name
/// too), which writing it would destroy. The message starts with `option` and the path:
/// "--out job.textproto: the same file as the input job.textproto". Empty when it can.
std::string CheckOutputFile(const std::string& option, const std::string& path,
                            const std::vector<std::string>& inputs = {});

/// The frames to take from a folder of `held` frames (`set`, given as `set_option`), from frame
/// `first` on: `asked` (given as `count_option`) if given, else every frame left. Asking for none
/// or for more than the folder holds is refused here, before any work, rather than failing on the
/// first missing file. Empty on success (`*count` set), else the usage error:
/// "--test-set D holds 4 frames; --first 2 --images 5 asks for frames up to 6".
std::string FolderFrameCount(const std::string& set_option, const std::string& set, int64_t held,
                             int64_t first, const std::string& count_option, std::optional<int64_t> asked,
                             int64_t* count);

// Checks for option values. Each error message starts "must be" and is printed after the
// option's name: "--threads must be an integer in [1, 1024], got 'four'".

/// An integer in [lo, hi].
CLI::Validator IntIn(long long lo, long long hi);
/// A non-negative integer that fits 64 bits (seeds).
CLI::Validator NonNegativeInt();
/// A number in [lo, hi]; `what` names it in the message ("a number", "metres").
CLI::Validator NumberIn(double lo, double hi, const std::string& what = "a number");
/// A name or id that is not empty and holds no control characters (--job-id, --id, --job).
CLI::Validator NonEmptyName();
/// A file or folder name: not empty. RunCommand gives it to every option whose type name (or,
/// for a positional, name) is FILE, PATH, DIR, FILE|-, SET, SOURCE, TREE or NAME.ext, so a
/// command need not add it.
CLI::Validator NonEmptyPath();
/// One of `names`.
CLI::Validator OneOf(std::vector<std::string> names);
/// A skeleton fit's name (runtime::SkeletonFitFromName): "kinematic" or "greedy" (`--fit`).
CLI::Validator SkeletonFitValidator();

}  // namespace poseforest::apps::commands
