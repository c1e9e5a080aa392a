// The commands' command lines (apps/commands/cli.h): each command's --help is generated from its
// CLI11 declaration and lists every option; usage errors name the option and exit 2; a shared
// option group (camera and frame source, DDS transport) parses the same in every command.
#include <catch2/catch.hpp>
#include <fstream>
#include <string>
#include <vector>

#include "apps/commands/cli.h"
#include "apps/commands/commands.h"
#include "apps/commands/frame_options.h"
#include "tests/support/process.h"

using namespace poseforest;
namespace cmd = poseforest::apps::commands;
using testing::RunPoseforest;

namespace {
/// Parses `args` (after the command's name) with `command`'s parser; throws CLI11's errors.
void Parse(cmd::Command& command, std::vector<std::string> args) {
  std::vector<std::string> reversed(args.rbegin(), args.rend());  // CLI11 takes them last first
  command.app().parse(reversed);
}

/// The values the options of `names` received in `command`, as written.
std::vector<std::vector<std::string>> Results(cmd::Command& command, const std::vector<std::string>& names) {
  std::vector<std::vector<std::string>> out;
  for (const std::string& n : names) out.push_back(command.app().get_option(n)->results());
  return out;
}
}  // namespace

TEST_CASE("every command's --help exits 0 and lists every option it declares", "[cli]") {
  int built = 0;
  for (const cmd::CommandInfo& info : cmd::AllCommands()) {
    if (!info.make) continue;
    ++built;
    auto help = RunPoseforest(std::string(info.name) + " --help");
    INFO(info.name << "\n" << help.output);
    CHECK(help.exit_code == 0);
    CHECK_THAT(help.output, Catch::Contains("usage: poseforest " + std::string(info.name)));
    CHECK_THAT(help.output, Catch::Contains(info.summary));
    const auto command = info.make();
    const auto names = cmd::OptionNames(command->app());
    CHECK(names.size() > 1);
    for (const std::string& name : names) {
      INFO(name);
      CHECK_THAT(help.output, Catch::Contains(name));
    }
  }
  CHECK(built >= 5);  // the inference commands are in every build
}

TEST_CASE("usage errors name the option and exit 2", "[cli]") {
  auto bad = RunPoseforest("infer --forest f.pff --threads four x.png");
  CHECK(bad.exit_code == 2);
  CHECK_THAT(bad.output, Catch::Contains("poseforest infer: --threads must be an integer in [0, 1024], got 'four'"));
  auto range = RunPoseforest("frames --record-fps 0 x.png");
  CHECK(range.exit_code == 2);
  CHECK_THAT(range.output, Catch::Contains("--record-fps must be a number in [0.001, 10000] (got '0')"));
  auto choice = RunPoseforest("live --forest f.pff --source x --method slow");
  CHECK(choice.exit_code == 2);
  CHECK_THAT(choice.output, Catch::Contains("--method must be meanshift or fast, not 'slow'"));
  auto size = RunPoseforest("frames --raw-size 640 x.raw");
  CHECK(size.exit_code == 2);
  CHECK_THAT(size.output, Catch::Contains("--raw-size must be WxH, e.g. 640x480 (got '640')"));
  auto unknown = RunPoseforest("inspect --bogus=3 f.pff");
  CHECK(unknown.exit_code == 2);
  CHECK_THAT(unknown.output, Catch::Contains("poseforest inspect: unknown option --bogus") &&
                                 Catch::Contains("poseforest inspect --help"));
  auto dash = RunPoseforest("inspect -x f.pff");
  CHECK(dash.exit_code == 2);
  CHECK_THAT(dash.output, Catch::Contains("unknown option -x (options are spelt --name)"));
  auto missing = RunPoseforest("import-pcl tree.txt");
  CHECK(missing.exit_code == 2);
  CHECK_THAT(missing.output, Catch::Contains("--out is required"));
  auto no_value = RunPoseforest("import-pcl tree.txt --out");
  CHECK(no_value.exit_code == 2);
  CHECK_THAT(no_value.output, Catch::Contains("option --out needs a value"));
  auto no_file = RunPoseforest("inspect");
  CHECK(no_file.exit_code == 2);
  CHECK_THAT(no_file.output, Catch::Contains("FOREST.pff is required"));
}

TEST_CASE("a repeated option keeps its last value; -- ends the options", "[cli]") {
  const auto infer = cmd::MakeInferCommand();
  Parse(*infer, {"--forest", "a.pff", "--threads", "3", "--threads=5", "--", "--odd-name.png"});
  CHECK(infer->app().get_option("--threads")->as<int>() == 5);
  CHECK(infer->app().get_option("SOURCE")->as<std::vector<std::string>>() ==
        std::vector<std::string>{"--odd-name.png"});
}

TEST_CASE("the camera and frame-source group parses the same in infer, frames and live", "[cli]") {
  const std::vector<std::string> group = {"--camera", "--fx", "--fy", "--cx", "--cy", "--depth-scale", "--raw-size",
                                          "--fps"};
  const std::vector<std::string> args = {"--camera", "azure-nfov", "--fx", "500", "--cx=300", "--depth-scale",
                                         "0.5", "--raw-size", "320x288", "--fps", "15"};
  auto with = [&](std::vector<std::string> extra) {
    extra.insert(extra.end(), args.begin(), args.end());
    return extra;
  };
  const auto infer = cmd::MakeInferCommand(), frames = cmd::MakeFramesCommand(), live = cmd::MakeLiveCommand();
  Parse(*infer, with({"--forest", "f.pff", "x.raw"}));
  Parse(*frames, with({"x.raw"}));
  Parse(*live, with({"--forest", "f.pff", "--source", "x.raw"}));
  const auto expected = Results(*infer, group);
  CHECK(expected[1] == std::vector<std::string>{"500"});
  CHECK(Results(*frames, group) == expected);
  CHECK(Results(*live, group) == expected);

  // ...and the group's values make the same frame-source settings everywhere.
  CLI::App app;
  cmd::FrameSourceFlags flags;
  cmd::AddFrameSourceOptions(app, &flags);
  std::vector<std::string> reversed(args.rbegin(), args.rend());
  app.parse(reversed);
  auto options = cmd::FrameSourceFromFlags(flags);
  REQUIRE(options.ok());
  CHECK(options->camera.name == "azure-nfov+custom");
  CHECK(options->camera.intrinsics.fx == 500);
  CHECK(options->camera.intrinsics.fy == 500);  // --fx alone: square pixels
  CHECK(options->camera.intrinsics.cx == 300);
  CHECK(options->camera.depth_scale_mm == 0.5);
  CHECK(options->camera_given);
  CHECK(options->raw_width == 320);
  CHECK(options->fps == 15);
}

#ifdef POSEFOREST_TEST_TRAINING
TEST_CASE("the DDS transport group parses the same in coordinator, worker and monitor", "[cli]") {
  const std::vector<std::string> group = {"--profile", "--peers", "--interfaces", "--dds-xml", "--dds-profile",
                                          "--discovery-server", "--security"};
  const std::vector<std::string> args = {"--profile", "udp", "--peers=10.0.0.1,10.0.0.2:7412", "--interfaces",
                                         "10.0.0.9", "--security", "ca/worker-1"};
  auto with = [&](std::vector<std::string> extra) {
    extra.insert(extra.end(), args.begin(), args.end());
    return extra;
  };
  const auto coordinator = cmd::MakeCoordinatorCommand(), worker = cmd::MakeWorkerCommand(),
             monitor = cmd::MakeMonitorCommand();
  Parse(*coordinator, with({"job.textproto", "--out", "f.pff"}));
  Parse(*worker, with({}));
  Parse(*monitor, with({"--domain", "3"}));
  const auto expected = Results(*coordinator, group);
  CHECK(expected[0] == std::vector<std::string>{"udp"});
  CHECK(expected[1] == std::vector<std::string>{"10.0.0.1,10.0.0.2:7412"});
  CHECK(Results(*worker, group) == expected);
  CHECK(Results(*monitor, group) == expected);
  // A bad value of the group is an error naming the option, in each command.
  for (const char* c : {"worker --profile tcp --check-config", "monitor --domain 3 --profile tcp --once"}) {
    auto bad = RunPoseforest(c);
    INFO(c << "\n" << bad.output);
    CHECK(bad.exit_code == 2);
    CHECK_THAT(bad.output, Catch::Contains("tcp") && Catch::Contains("shm, udp or default"));
  }
}

TEST_CASE(
    "the service's commands refuse empty ids, a malformed --url and --job with --url; train names itself",
    "[cli]") {
  for (const char* c :
       {"worker --id= --check-config", "worker --job '' --check-config",
        "coordinator --job-id '' --out f.pff job.textproto", "monitor --domain 3 --job '' --once"}) {
    auto r = RunPoseforest(c);
    INFO(c << "\n" << r.output);
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.output, Catch::Contains("must be a non-empty name"));
  }
  // A URL the client cannot use is a usage error before any connection (2, not 1 as a refused one).
  auto bogus = RunPoseforest("monitor --url bogus --once");
  INFO(bogus.output);
  CHECK(bogus.exit_code == 2);
  CHECK_THAT(bogus.output, Catch::Contains("--url bogus: expected http://HOST[:PORT][/PATH]"));
  auto job_with_url = RunPoseforest("monitor --url http://127.0.0.1:9 --job j --once");
  CHECK(job_with_url.exit_code == 2);
  CHECK_THAT(job_with_url.output, Catch::Contains("--job is for --domain"));
  // `train --local-workers N` runs the coordinator command: its usage errors say so.
  auto train = RunPoseforest("train job.textproto --out f.pff --local-workers -1");
  CHECK(train.exit_code == 2);
  CHECK_THAT(train.output, Catch::Contains("poseforest train (as coordinator): --local-workers must be") &&
                               Catch::Contains("poseforest coordinator --help lists the options"));
  // Fast DDS's own errors on a bad XML profile: plain lines into a pipe (no terminal colours),
  // before the command's message.
  const auto dir = testing::ScratchDir("commands-dds-xml");
  std::ofstream((dir / "bad.xml").string())
      << "<?xml version=\"1.0\"?><dds "
         "xmlns=\"http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles\"><profiles>"
         "<participant profile_name=\"x\"><rtps><bogus/></rtps></participant></profiles></dds>";
  auto xml =
      RunPoseforest("worker --dds-xml " + (dir / "bad.xml").string() + " --dds-profile x --check-config");
  INFO(xml.output);
  CHECK(xml.exit_code == 2);
  CHECK(xml.output.find('\x1b') == std::string::npos);
  const size_t fast_dds = xml.output.find("Fast DDS: [XMLPARSER Error] Invalid element");
  const size_t ours = xml.output.find("Fast DDS cannot parse the XML profiles");
  CHECK(fast_dds != std::string::npos);
  CHECK(ours != std::string::npos);
  CHECK(fast_dds < ours);
}
#endif

TEST_CASE("poseforest help lists the commands of this build; --markdown the README's table", "[cli]") {
  auto help = RunPoseforest("help");
  CHECK(help.exit_code == 0);
  auto table = RunPoseforest("help --markdown");
  CHECK(table.exit_code == 0);
  for (const cmd::CommandInfo& info : cmd::AllCommands()) {
    INFO(info.name);
    CHECK_THAT(table.output, Catch::Contains("| [`" + std::string(info.name) + "`](docs/commands.md#poseforest-" +
                                             info.name + ") | " + info.summary));
    if (info.make) CHECK_THAT(help.output, Catch::Contains(info.summary));
  }
}

TEST_CASE("poseforest help CMD prints that command's options; an unknown one is a usage error", "[cli]") {
  auto general = RunPoseforest("help");
  CHECK_THAT(general.output, Catch::Contains("poseforest help <command>") && Catch::Contains("--version"));
  auto infer = RunPoseforest("help infer");
  INFO(infer.output);
  CHECK(infer.exit_code == 0);
  // infer's own help, which names its options; the general list does not.
  CHECK_THAT(infer.output, Catch::Contains("--forest") && Catch::Contains("--out-dir"));
  CHECK(infer.output == RunPoseforest("infer --help").output);
  auto bogus = RunPoseforest("help no-such-command");
  CHECK(bogus.exit_code == 2);
  CHECK_THAT(bogus.output, Catch::Contains("unknown command 'no-such-command'"));
}

TEST_CASE("an empty file or folder name is a usage error naming the option", "[cli]") {
  // Every option whose type name (a positional's name) says it names a file, folder or source
  // (FILE, PATH, DIR, SET, SOURCE, NAME.ext), in several commands, given as '' and as "--name=":
  // exit 2 and the option named, before any work (it was "NotFound: : no such file", exit 1, or
  // the empty name taken as "not given").
  std::vector<std::pair<std::string, std::string>> cases = {
      {"infer --forest '' x.png", "--forest"},
      {"infer --forest= x.png", "--forest"},
      {"live --forest= --source x.png", "--forest"},
      {"infer --forest f.pff --out-dir '' x.png", "--out-dir"},
      {"live --forest f.pff --source ''", "--source"},
      {"infer --forest f.pff ''", "SOURCE"},
      {"inspect f.pff ''", "FOREST.pff"},
      {"frames ''", "SOURCE"}};
#ifdef POSEFOREST_TEST_TRAINING  // the training and service commands: the full build's
  cases.insert(cases.end(), {{"eval --forest '' --test-set d", "--forest"},
                             {"eval --forest f.pff --real-labels ''", "--real-labels"},
                             {"eval --forest f.pff --test-set ''", "--test-set"},
                             {"coordinator --status-file '' --out f.pff job.textproto", "--status-file"},
                             {"render --out '' --frames 1", "--out"},
                             {"train ''", "JOB.textproto"}});
#endif
  for (const auto& [c, option] : cases) {
    auto r = RunPoseforest(c);
    INFO(c << "\n" << r.output);
    CHECK(r.exit_code == 2);
    CHECK_THAT(r.output, Catch::Contains(option + " must be a file or folder name, not empty"));
  }
  // Parsing one command twice (as the in-process tests do) adds the check once.
  auto infer = cmd::MakeInferCommand();
  for (int i = 0; i < 2; ++i) {
    std::vector<std::string> args = {"infer", "--forest", "", "x.png"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    CHECK(cmd::RunCommand(*infer, int(argv.size()), argv.data()) == 2);
  }
  CLI::Option* forest = infer->app().get_option("--forest");
  int checks = 0;
  for (int k = 0;; ++k) {
    try {
      checks += forest->get_validator(k)->get_name() == "non-empty path";
    } catch (const CLI::OptionNotFound&) {
      break;
    }
  }
  CHECK(checks == 1);
}
