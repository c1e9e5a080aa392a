// Writes the inputs of the install/consumer tests (consumers.sh) into a folder: forest.pff (a
// random valid 31-part forest), forest5.pff (5 parts: no joints), corrupt.pff (forest.pff with a
// payload byte flipped), person.raw (a 640x480 little-endian uint16 depth frame, mm) and
// person.labels (the labels the runtime computes for it in-process, one byte per pixel).
#include <cstdio>
#include <filesystem>
#include <span>

#include "runtime/classifier.h"
#include "runtime/core/forest_format.h"
#include "tests/support/synthetic.h"

using namespace poseforest;

namespace {

bool Write(const std::filesystem::path& path, std::span<const uint8_t> bytes) {
  const core::Status st = core::WriteFileAtomic(path.string(), bytes);
  if (!st.ok()) std::fprintf(stderr, "make_api_inputs: %s\n", st.ToString().c_str());
  return st.ok();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_api_inputs OUT_DIR\n");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  std::filesystem::create_directories(out);
  testing::RandomForestSpec spec;
  spec.seed = 21;
  spec.nodes_per_tree = 3000;
  spec.max_depth = 12;
  const core::Forest forest = testing::MakeRandomForest(spec);
  auto bytes = core::SerializeForest(forest);
  if (!Write(out / "forest.pff", bytes)) return 1;
  bytes[bytes.size() / 2] ^= 0x40;
  if (!Write(out / "corrupt.pff", bytes)) return 1;
  spec.num_parts = 5;
  if (!Write(out / "forest5.pff", core::SerializeForest(testing::MakeRandomForest(spec)))) return 1;

  const core::DepthImage depth = testing::MakePersonDepth(2.4, 640, 480, 0.1);
  if (!Write(out / "person.raw",
             std::span(reinterpret_cast<const uint8_t*>(depth.data()), depth.pixels.size() * 2)))
    return 1;
  runtime::Classification c;
  runtime::Classifier(forest).Classify(depth, {}, &c);
  return Write(out / "person.labels", c.labels.pixels) ? 0 : 1;
}
