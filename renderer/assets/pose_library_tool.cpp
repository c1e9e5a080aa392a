// poseforest-poselib: builds and inspects pose libraries (pose_library.h).
//
//   poseforest-poselib build --out lib.pfposes [--min-distance 0.05] [--test-fraction F --seed S]
//                            [--max-frames N] FILES/DIRS...
//   poseforest-poselib info FILE
//   poseforest-poselib bvh FILES/DIRS...      (per clip: family, frames, units, height)

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "renderer/assets/bvh.h"
#include "renderer/assets/pose_library.h"
#include "renderer/assets/retarget.h"

namespace {

using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;

int Usage() {
  std::fprintf(
      stderr,
      "usage:\n"
      "  poseforest-poselib build --out LIB.pfposes [--min-distance M] [--test-fraction F] [--seed S]\n"
      "                           [--max-frames N] FILES/DIRS...\n"
      "      retarget every BVH clip, keep poses >= M metres apart (default 0.05);\n"
      "      with --test-fraction, only the training clips of the clip-level split are used;\n"
      "      folders are searched below, linked folders included\n"
      "  poseforest-poselib info LIB.pfposes\n"
      "  poseforest-poselib bvh FILES/DIRS...\n");
  return 2;
}

bool ParseNumber(const char* s, double* out) {
  char* end = nullptr;
  *out = std::strtod(s, &end);
  return end && *end == '\0' && end != s;
}

int Build(int argc, char** argv) {
  std::string out;
  double min_distance = 0.05, test_fraction = 0, seed = 0, max_frames = -1;
  std::vector<std::filesystem::path> inputs;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](double* v) {
      if (i + 1 >= argc || !ParseNumber(argv[i + 1], v)) {
        std::fprintf(stderr, "poseforest-poselib: %s needs a number\n", a.c_str());
        return false;
      }
      ++i;
      return true;
    };
    if (a == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (a == "--min-distance") {
      if (!value(&min_distance)) return 2;
    } else if (a == "--test-fraction") {
      if (!value(&test_fraction)) return 2;
    } else if (a == "--seed") {
      if (!value(&seed)) return 2;
    } else if (a == "--max-frames") {
      if (!value(&max_frames)) return 2;
    } else if (a.rfind("--", 0) == 0) {
      std::fprintf(stderr, "poseforest-poselib: unknown option %s\n", a.c_str());
      return 2;
    } else {
      inputs.emplace_back(a);
    }
  }
  if (out.empty() || inputs.empty()) return Usage();
  auto files = CollectBvhFiles(inputs);
  if (!files.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", files.status().ToString().c_str());
    return 1;
  }
  std::vector<std::filesystem::path> use = *files;
  if (test_fraction > 0) {
    const ClipSplit split = SplitClips(*files, test_fraction, uint64_t(seed));
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
  opt.max_frames_per_clip = int(max_frames);
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

int Info(int argc, char** argv) {
  if (argc != 1) return Usage();
  auto lib = LoadPoseLibrary(argv[0]);
  if (!lib.ok()) {
    std::fprintf(stderr, "poseforest-poselib: %s\n", lib.status().ToString().c_str());
    return 1;
  }
  std::printf("%s: format %u.%u, %zu poses from %zu clips, min distance %.3f m\n", argv[0], kPoseLibraryMajor,
              kPoseLibraryMinor, lib->poses.size(), lib->clips.size(), lib->min_distance_m);
  std::vector<size_t> per_clip(lib->clips.size(), 0);
  for (const auto& s : lib->sources) ++per_clip[s.clip];
  for (size_t c = 0; c < lib->clips.size(); ++c)
    std::printf("  %-50s %6zu poses\n", lib->clips[c].c_str(), per_clip[c]);
  return 0;
}

int Bvh(int argc, char** argv) {
  std::vector<std::filesystem::path> inputs(argv, argv + argc);
  if (inputs.empty()) return Usage();
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
  if (argc < 2) return Usage();
  const std::string cmd = argv[1];
  if (cmd == "build") return Build(argc - 2, argv + 2);
  if (cmd == "info") return Info(argc - 2, argv + 2);
  if (cmd == "bvh") return Bvh(argc - 2, argv + 2);
  return Usage();
}
