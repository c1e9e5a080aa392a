// poseforest-poselib: builds and inspects pose libraries (pose_library.h).
//
//   poseforest-poselib build --out lib.pfposes [--min-distance 0.05] [--test-fraction F --seed S]
//                            [--max-frames N] FILES/DIRS...
//   poseforest-poselib info FILE
//   poseforest-poselib bvh FILES/DIRS...      (per clip: family, frames, units, height)
//   poseforest-poselib [SUBCOMMAND] --help

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "renderer/assets/bvh.h"
#include "renderer/assets/pose_library.h"
#include "renderer/assets/retarget.h"
#include "runtime/core/command_line.h"

namespace {

using namespace poseforest;
using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;

struct BuildArgs {
  std::string out;
  double min_distance = 0.05, test_fraction = 0;
  uint64_t seed = 0;
  int max_frames = -1;  // -1: every frame
  std::vector<std::filesystem::path> inputs;
};

int Build(const BuildArgs& args) {
  const std::string& out = args.out;
  const double min_distance = args.min_distance, test_fraction = args.test_fraction;
  const uint64_t seed = args.seed;
  const auto& inputs = args.inputs;
  auto files = CollectBvhFiles(inputs);
  if (!files.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", files.status().ToString().c_str());
    return 1;
  }
  std::vector<std::filesystem::path> use = *files;
  if (test_fraction > 0) {
    const ClipSplit split = SplitClips(*files, test_fraction, seed);
    std::printf("clip split (seed %llu, test fraction %.3f): %zu train, %zu test clips\n",
                (unsigned long long)seed, test_fraction, split.train.size(), split.test.size());
    use = split.train;
  }
  if (use.empty()) {
    std::fprintf(
        stderr,
        "poseforest-poselib: no clips left to build from: all %zu are test clips at test fraction %.3f\n",
        files->size(), test_fraction);
    return 1;
  }
  std::printf("building from %zu BVH clips, min distance %.3f m\n", use.size(), min_distance);
  const auto t0 = std::chrono::steady_clock::now();
  BuildOptions opt;
  opt.min_distance_m = min_distance;
  opt.max_frames_per_clip = args.max_frames;
  opt.progress = [&](size_t c, size_t n, const std::filesystem::path& f, size_t frames, size_t total) {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("[%3zu/%zu] %6.1fs %-50s %6zu frames (%zu total)\n", c + 1, n, s,
                f.filename().string().c_str(), frames, total);
    std::fflush(stdout);
  };
  auto lib = BuildPoseLibrary(use, opt);
  if (!lib.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", lib.status().ToString().c_str());
    return 1;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (auto st = SavePoseLibrary(*lib, out); !st.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", st.ToString().c_str());
    return 1;
  }
  std::printf("kept %zu poses from %zu clips at %.3f m in %.1f s -> %s\n", lib->poses.size(),
              lib->clips.size(), lib->min_distance_m, secs, out.c_str());
  return 0;
}

int Info(const std::string& file) {
  auto lib = LoadPoseLibrary(file);
  if (!lib.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", lib.status().ToString().c_str());
    return 1;
  }
  std::printf("%s: format %u.%u, %zu poses from %zu clips, min distance %.3f m\n", file.c_str(),
              kPoseLibraryMajor, kPoseLibraryMinor, lib->poses.size(), lib->clips.size(),
              lib->min_distance_m);
  std::vector<size_t> per_clip(lib->clips.size(), 0);
  for (const auto& s : lib->sources) ++per_clip[s.clip];
  for (size_t c = 0; c < lib->clips.size(); ++c)
    std::printf("  %-50s %6zu poses\n", lib->clips[c].c_str(), per_clip[c]);
  return 0;
}

int Bvh(const std::vector<std::filesystem::path>& inputs) {
  auto files = CollectBvhFiles(inputs);
  if (!files.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", files.status().ToString().c_str());
    return 1;
  }
  int failures = 0;
  size_t total = 0;
  for (const auto& f : *files) {
    auto clip = LoadBvh(f);
    if (!clip.ok()) {
      std::printf("%s: ERROR %s\n", f.string().c_str(), clip.status().ToString().c_str());
      ++failures;
      continue;
    }
    auto tracks = ExtractCanonicalTracks(*clip);
    if (!tracks.ok()) {
      std::printf("%s: ERROR %s\n", f.string().c_str(), tracks.status().ToString().c_str());
      ++failures;
      continue;
    }
    const auto& s0 = tracks->frames.empty() ? ReferenceRestJoints() : tracks->frames[0];
    const double height = s0[size_t(SkelJoint::kHeadTop)].y() - tracks->floor_y_m;
    total += size_t(clip->num_frames);
    std::printf(
        "%-45s %-15s %-18s %5d frames %5.1f fps unit %.4f m%s drop %d extra %d  leg %.2f m  frame0 "
        "head-top %.2f m\n",
        f.filename().string().c_str(), std::string(SkeletonFamilyName(clip->family)).c_str(),
        tracks->family.c_str(), clip->num_frames, 1.0 / clip->frame_time_s, clip->unit_to_m,
        clip->z_up_input ? " Z-up-data" : (clip->z_up_hierarchy ? " Z-up-rest" : ""),
        clip->dropped_leading_frames, clip->ignored_trailing_lines, tracks->leg_length_m, height);
  }
  std::printf("%zu clips, %zu frames, %d failed\n", files->size(), total, failures);
  return failures ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app(
      "poseforest-poselib: builds and inspects pose libraries (.pfposes: retargeted mocap poses that\n"
      "`render --poses` and jobs' pose_library draw from)",
      "poseforest-poselib");
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "every subcommand's options");

  BuildArgs build;
  CLI::App* b = app.add_subcommand("build",
                                   "retarget every BVH clip and keep poses at least --min-distance apart;\n"
                                   "folders are searched below, linked folders included");
  b->add_option("--out", build.out, "the library to write")
      ->type_name("LIB.pfposes")
      ->required()
      ->check(CLI::Validator(
          [](const std::string& v) { return v.empty() ? std::string("must be a file name") : ""; }, "",
          "non-empty"));
  b->add_option("--min-distance", build.min_distance, "keep poses at least this far apart, metres")
      ->type_name("M")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10.0));
  b->add_option("--test-fraction", build.test_fraction,
                "split the clips (not frames) into train and test, this share of them test, and build from\n"
                "the training clips only (0: every clip)")
      ->type_name("F")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  b->add_option("--seed", build.seed, "seed of the clip split")->type_name("S")->capture_default_str();
  b->add_option("--max-frames", build.max_frames, "frames read per clip (default: all)")
      ->type_name("N")
      ->check(CLI::Range(1, 100000000));
  b->add_option("FILES/DIRS", build.inputs, "BVH clips, or folders of them")->required();

  std::string info_file;
  CLI::App* i = app.add_subcommand("info", "the library's format, poses and clips");
  i->add_option("LIB.pfposes", info_file, "a pose library")->required();

  std::vector<std::filesystem::path> bvh_inputs;
  CLI::App* v = app.add_subcommand("bvh", "per clip: skeleton family, frames, units, height");
  v->add_option("FILES/DIRS", bvh_inputs, "BVH clips, or folders of them")->required();

  try {
    // "--out=" reaches --out as an empty value, not as the next argument (core::ArgumentsForCli11).
    std::vector<std::string> args = core::ArgumentsForCli11(argc, argv);
    app.parse(args);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "poseforest-poselib: %s (see --help)\n", e.what());
    return 2;
  }
  if (b->parsed()) return Build(build);
  if (i->parsed()) return Info(info_file);
  return Bvh(bvh_inputs);
}
