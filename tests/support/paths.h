#pragma once
// Where tests find things: the shared data set (one setting: POSEFOREST_DATA_DIR in the
// environment, else the CMake cache value, which defaults to ../shared/data), the built
// programs, and scratch folders.

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <unistd.h>

namespace poseforest::testing {

/// The shared data folder (mocap, meshes, real frames).
inline std::filesystem::path DataDir() {
  if (const char* env = std::getenv("POSEFOREST_DATA_DIR"); env && *env) return env;
  return POSEFOREST_DATA_DIR_DEFAULT;
}

/// The folder holding the built `poseforest` program: POSEFOREST_BIN_DIR (set by ctest), else
/// the folder of the running test (tests and programs are both built into build/bin).
inline std::filesystem::path BinDir() {
  if (const char* env = std::getenv("POSEFOREST_BIN_DIR"); env && *env) return env;
  std::error_code ec;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::current_path() : self.parent_path();
}

/// The scratch folders this test process made, removed when it exits (a test that fails keeps
/// nothing either: set POSEFOREST_KEEP_TEST_DIRS=1 to keep them for a look). Only the process
/// that made them removes them: a forked child that exits leaves them to its parent.
struct ScratchDirs {
  pid_t owner = ::getpid();
  std::vector<std::filesystem::path> dirs;
  ~ScratchDirs() {
    if (::getpid() != owner) return;
    if (const char* keep = std::getenv("POSEFOREST_KEEP_TEST_DIRS"); keep && *keep && std::string(keep) != "0")
      return;
    for (const auto& dir : dirs) {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
  }
};
inline ScratchDirs& MadeScratchDirs() {
  static ScratchDirs made;
  return made;
}

/// A fresh empty scratch folder under the system temp dir, unique to this process and `name`;
/// removed when the process exits (ScratchDirs).
inline std::filesystem::path ScratchDir(const std::string& name) {
  auto dir = std::filesystem::temp_directory_path() /
             ("poseforest-test-" + name + "-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  MadeScratchDirs().dirs.push_back(dir);
  return dir;
}

}  // namespace poseforest::testing
