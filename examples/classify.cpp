// Classifies a raw 640x480 depth frame (little-endian uint16 millimetres) with the C++ API and
// prints the body parts found and each joint's most confident proposal; optionally writes the
// labels (one byte per pixel) and P(part | pixel) (float32, height x width x parts).
//   classify_cpp FOREST.pff DEPTH.raw [LABELS_OUT [DISTRIBUTIONS_OUT]]
// Built by examples/CMakeLists.txt and examples/Makefile; run by the tests (tests/runtime).
#include <cstdio>
#include <fstream>
#include <iostream>
#include <poseforest/poseforest.hpp>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: classify_cpp FOREST.pff DEPTH.raw [LABELS_OUT [DISTRIBUTIONS_OUT]]\n";
    return 2;
  }
  const int width = 640, height = 480;
  std::vector<uint16_t> depth(size_t(width) * height);
  std::ifstream in(argv[2], std::ios::binary);
  if (!in.read(reinterpret_cast<char*>(depth.data()), std::streamsize(depth.size() * 2))) {
    std::cerr << "classify_cpp: cannot read " << width << " x " << height << " depth values from " << argv[2]
              << "\n";
    return 1;
  }
  try {
    std::cout << "poseforest " << poseforest::api::Version() << " (headers " << POSEFOREST_VERSION_STRING
              << ")\n";
    const poseforest::api::Forest forest(argv[1]);
    const poseforest::api::DepthView view{depth.data(), width, height};
    const auto result = forest.Classify(view, /*distributions=*/argc > 4);
    std::vector<int> count(size_t(forest.num_parts()), 0);
    for (uint8_t label : result.labels)
      if (label != 255) ++count[label];
    const auto names = forest.part_names();
    std::cout << "parts:";
    for (size_t p = 0; p < count.size(); ++p)
      if (count[p] > 0) std::cout << " " << names[p] << "=" << count[p];
    std::cout << "\n";
    if (forest.has_joints()) {
      const auto joint_names = poseforest::api::JointNames();
      int last = -1;
      for (const pf_joint_proposal& p : forest.Joints(view))
        if (p.joint != last) {  // the first of a joint is its most confident
          last = p.joint;
          std::printf("  %-11s (%.3f, %.3f, %.3f) m, confidence %.4g\n", joint_names[size_t(p.joint)].c_str(),
                      p.position_m[0], p.position_m[1], p.position_m[2], p.confidence);
        }
    }
    if (argc > 3)
      std::ofstream(argv[3], std::ios::binary)
          .write(reinterpret_cast<const char*>(result.labels.data()), std::streamsize(result.labels.size()));
    if (argc > 4)
      std::ofstream(argv[4], std::ios::binary)
          .write(reinterpret_cast<const char*>(result.distributions.data()),
                 std::streamsize(result.distributions.size() * sizeof(float)));
  } catch (const poseforest::api::Error& e) {
    std::cerr << "classify_cpp: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
