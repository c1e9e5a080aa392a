#include "runtime/pcl_import.h"

#include <sys/wait.h>

#include <charconv>
#include <cstdio>
#include <memory>

#include "runtime/core/forest_format.h"

namespace poseforest::runtime {

const std::vector<std::string>& PclPartNames() {
  static const std::vector<std::string> names = {
      "Lfoot", "Lleg",  "Lknee",  "Lthigh",   "Rfoot",    "Rleg",   "Rknee",   "Rthigh",  "Rhips",
      "Lhips", "Neck",  "Rarm",   "Relbow",   "Rforearm", "Rhand",  "Larm",    "Lelbow",  "Lforearm",
      "Lhand", "FaceLB", "FaceRB", "FaceLT",  "FaceRT",   "Rchest", "Lchest",
  };
  return names;
}

namespace {

// Reads the next whitespace-separated integer; false at the end or on garbage.
bool NextInt(std::string_view& text, int& value) {
  size_t i = 0;
  while (i < text.size() && (text[i] == ' ' || text[i] == '\t' || text[i] == '\n' || text[i] == '\r')) ++i;
  const auto [end, ec] = std::from_chars(text.data() + i, text.data() + text.size(), value);
  if (ec != std::errc() || end == text.data() + i) return false;
  text.remove_prefix(size_t(end - text.data()));
  return true;
}

}  // namespace

core::Status AppendPclTree(std::string_view in, const std::string& source, core::Forest* forest) {
  auto loss = [&](const std::string& what) { return core::Status(core::ErrorCode::kDataLoss, source + ": " + what); };
  int height = 0;
  if (!NextInt(in, height)) return loss("cannot read the tree height on line 1");
  if (height < 1 || height > 24) return loss("tree height " + std::to_string(height) + " outside 1..24");
  const uint32_t num_splits = (1u << height) - 1, num_leaves = 1u << height;
  const int num_parts = int(PclPartNames().size());
  const int stride = core::LeafStride(num_parts);

  core::Tree tree;
  tree.nodes.resize(size_t(num_splits) + num_leaves);
  tree.depth = uint32_t(height);
  for (uint32_t n = 0; n < num_splits; ++n) {
    int du1, dv1, du2, dv2, thresh;
    if (!NextInt(in, du1) || !NextInt(in, dv1) || !NextInt(in, du2) || !NextInt(in, dv2) || !NextInt(in, thresh))
      return loss("split node " + std::to_string(n) + " (line " + std::to_string(n + 2) + ") is missing or malformed");
    for (int v : {du1, dv1, du2, dv2, thresh})
      if (v < -32768 || v > 32767) return loss("value " + std::to_string(v) + " of node " + std::to_string(n) + " is not int16");
    const core::FeatureOffsets f{int16_t(du1), int16_t(dv1), int16_t(du2), int16_t(dv2)};
    tree.nodes[n] = core::Node::Split(f, float(thresh) + 0.5f, 2 * n + 1);
  }
  // One leaf row per part (one-hot); PCL's leaves are labels, so leaves share rows.
  tree.num_leaves = uint32_t(num_parts);
  tree.leaves.assign(size_t(num_parts) * size_t(stride), 0);
  for (int p = 0; p < num_parts; ++p) tree.leaves[size_t(p) * size_t(stride) + size_t(p)] = core::kLeafTotal;
  for (uint32_t l = 0; l < num_leaves; ++l) {
    int label;
    if (!NextInt(in, label)) return loss("leaf " + std::to_string(l) + " (line " + std::to_string(num_splits + l + 2) + ") is missing");
    if (label < 0 || label >= num_parts)
      return loss("leaf " + std::to_string(l) + " has label " + std::to_string(label) + " outside 0.." + std::to_string(num_parts - 1));
    tree.nodes[num_splits + l] = core::Node::Leaf(uint32_t(label));
  }
  int extra;
  if (NextInt(in, extra)) return loss("unexpected data after the last leaf");
  forest->trees.push_back(std::move(tree));
  return core::Status::Ok();
}

core::Result<core::Forest> ImportPclTrees(const std::vector<std::string>& paths) {
  core::Forest forest;
  forest.num_parts = int(PclPartNames().size());
  forest.part_names = PclPartNames();
  forest.constants.background_mm = 65535;
  forest.constants.offset_unit = 1.0f;
  for (const std::string& path : paths) {
    if (path.size() > 4 && path.compare(path.size() - 4, 4, ".bz2") == 0) {
      POSEFOREST_RETURN_IF_ERROR(core::CheckReadableFile(path));
      // Decompress through the bzip2 program (the runtime links no compression library).
      std::string quoted = "'";
      for (char c : path) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
      quoted += "'";
      std::unique_ptr<FILE, int (*)(FILE*)> pipe(::popen(("bzip2 -dc " + quoted + " 2>/dev/null").c_str(), "r"), ::pclose);
      if (!pipe) return core::Status(core::ErrorCode::kIo, path + ": cannot run bzip2 to decompress it");
      std::string text;
      char buf[1 << 16];
      size_t n;
      while ((n = std::fread(buf, 1, sizeof buf, pipe.get())) > 0) text.append(buf, n);
      const int wait_status = ::pclose(pipe.release());
      const int exit_code = wait_status != -1 && WIFEXITED(wait_status) ? WEXITSTATUS(wait_status) : -1;
      // The shell says 127 when it finds no bzip2; bzip2 says 2 for a corrupt or truncated file.
      if (exit_code == 127)
        return core::Status(core::ErrorCode::kUnimplemented,
                            path +
                                ": decompressing .bz2 needs the bzip2 program, which is not installed "
                                "(apt-get install bzip2, or give the file decompressed)");
      if (exit_code == 2)
        return core::Status(core::ErrorCode::kDataLoss,
                            path + ": not a whole bzip2 file (corrupt, or cut short: " +
                                std::to_string(text.size()) + " bytes decompressed before the fault)");
      if (exit_code != 0 || text.empty())
        return core::Status(core::ErrorCode::kDataLoss,
                            path + ": bzip2 could not decompress it (exit status " +
                                std::to_string(exit_code) +
                                (text.empty() && exit_code == 0 ? "; it decompresses to nothing" : "") + ")");
      POSEFOREST_RETURN_IF_ERROR(AppendPclTree(text, path, &forest));
    } else {
      auto bytes = core::ReadFileBytes(path);
      if (!bytes.ok()) return bytes.status();
      POSEFOREST_RETURN_IF_ERROR(AppendPclTree(
          std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()), path, &forest));
    }
  }
  if (forest.trees.empty()) return core::Status(core::ErrorCode::kInvalidArgument, "no PCL tree files given");
  POSEFOREST_RETURN_IF_ERROR(core::ValidateForest(forest, "imported PCL forest"));
  return forest;
}

}  // namespace poseforest::runtime
