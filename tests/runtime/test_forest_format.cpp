// Forest file format v1: round trips, and hostile input (truncation and corruption at every byte
// offset, with and without a repaired checksum) that must give errors, never crashes.
#include <catch2/catch.hpp>

#include <cstring>
#include <filesystem>

#include "runtime/core/crc32.h"
#include "runtime/core/forest_format.h"
#include "tests/support/paths.h"
#include "tests/support/synthetic.h"

using namespace poseforest;
using core::ErrorCode;

namespace {

testing::RandomForestSpec SmallSpec(uint64_t seed) {
  testing::RandomForestSpec spec;
  spec.seed = seed;
  spec.num_trees = 2;
  spec.max_depth = 4;
  spec.nodes_per_tree = 15;
  return spec;
}

bool SameForest(const core::Forest& a, const core::Forest& b) {
  if (a.num_parts != b.num_parts || a.part_names != b.part_names || a.trees.size() != b.trees.size() ||
      a.constants.background_mm != b.constants.background_mm || a.constants.offset_unit != b.constants.offset_unit)
    return false;
  for (size_t t = 0; t < a.trees.size(); ++t) {
    const auto &x = a.trees[t], &y = b.trees[t];
    if (x.depth != y.depth || x.num_leaves != y.num_leaves || x.nodes.size() != y.nodes.size() || x.leaves != y.leaves)
      return false;
    if (std::memcmp(x.nodes.data(), y.nodes.data(), x.nodes.size() * sizeof(core::Node)) != 0) return false;
  }
  return true;
}

// Recomputes the trailer checksum so that corruption reaches the structural checks.
void RepairChecksum(std::vector<uint8_t>& bytes) {
  if (bytes.size() < 8) return;
  const uint32_t crc = core::Crc32(bytes.data(), bytes.size() - 8);
  for (int i = 0; i < 4; ++i) bytes[bytes.size() - 8 + size_t(i)] = uint8_t(crc >> (8 * i));
}

}  // namespace

TEST_CASE("round trip through memory keeps every byte of the model", "[format]") {
  for (uint64_t seed : {1, 2, 3}) {
    auto spec = SmallSpec(seed);
    spec.nodes_per_tree = 2000;
    spec.max_depth = 12;
    const core::Forest forest = testing::MakeRandomForest(spec);
    REQUIRE(core::ValidateForest(forest, "mem").ok());
    const auto bytes = core::SerializeForest(forest);
    auto parsed = core::ParseForest(bytes, "mem");
    REQUIRE(parsed.ok());
    CHECK(SameForest(forest, *parsed));
    CHECK(core::SerializeForest(*parsed) == bytes);  // deterministic serialization
  }
}

TEST_CASE("round trip through a file, written atomically", "[format]") {
  const auto dir = testing::ScratchDir("format");
  const std::string path = (dir / "forest.pff").string();
  auto spec = SmallSpec(7);
  spec.num_parts = 5;  // a non-default part table survives too
  const core::Forest forest = testing::MakeRandomForest(spec);
  REQUIRE(core::SaveForest(forest, path).ok());
  auto loaded = core::LoadForest(path);
  REQUIRE(loaded.ok());
  CHECK(SameForest(forest, *loaded));
  // No temporary file is left behind.
  int files = 0;
  for (auto& e : std::filesystem::directory_iterator(dir)) files += e.is_regular_file();
  CHECK(files == 1);
  std::filesystem::remove_all(dir);
}

TEST_CASE("missing file and unwritable folder give errors naming the path", "[format]") {
  auto r = core::LoadForest("/nonexistent/dir/forest.pff");
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kNotFound);
  CHECK_THAT(r.status().message(), Catch::Contains("/nonexistent/dir/forest.pff"));
  const core::Forest forest = testing::MakeRandomForest(SmallSpec(1));
  const auto st = core::SaveForest(forest, "/nonexistent/dir/out.pff");
  CHECK(st.code() == ErrorCode::kIo);
  CHECK_THAT(st.message(), Catch::Contains("/nonexistent/dir/out.pff"));
}

TEST_CASE("truncation at every byte offset is an error, never a crash", "[format][hostile]") {
  const auto bytes = core::SerializeForest(testing::MakeRandomForest(SmallSpec(11)));
  for (size_t len = 0; len < bytes.size(); ++len) {
    auto r = core::ParseForest(std::span(bytes.data(), len), "cut.pff");
    INFO("length " << len);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kDataLoss);
    CHECK_THAT(r.status().message(), Catch::StartsWith("cut.pff: "));
  }
}

TEST_CASE("corruption of any single byte is detected", "[format][hostile]") {
  const auto bytes = core::SerializeForest(testing::MakeRandomForest(SmallSpec(12)));
  for (size_t i = 0; i < bytes.size(); ++i) {
    for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xFF)}) {
      auto bad = bytes;
      bad[i] ^= flip;
      auto r = core::ParseForest(bad, "bad.pff");
      INFO("offset " << i << " flip " << int(flip));
      REQUIRE_FALSE(r.ok());
      CHECK((r.status().code() == ErrorCode::kDataLoss || r.status().code() == ErrorCode::kVersionMismatch));
    }
  }
}

TEST_CASE("structural corruption behind a valid checksum is caught by validation", "[format][hostile]") {
  // With the checksum repaired, every corrupted byte reaches the parser and the validator. The
  // result is either an error or a forest that passes ValidateForest (e.g. a changed threshold
  // or offset is still a valid model) - never a crash or an invalid forest.
  const auto bytes = core::SerializeForest(testing::MakeRandomForest(SmallSpec(13)));
  int rejected = 0, accepted = 0;
  for (size_t i = 0; i < bytes.size() - 8; ++i) {
    for (uint8_t value : {uint8_t(0x00), uint8_t(0x7F), uint8_t(0x80), uint8_t(0xFF)}) {
      auto bad = bytes;
      if (bad[i] == value) continue;
      bad[i] = value;
      RepairChecksum(bad);
      auto r = core::ParseForest(bad, "evil.pff");
      if (r.ok()) {
        ++accepted;
        REQUIRE(core::ValidateForest(*r, "evil.pff").ok());
      } else {
        ++rejected;
        CHECK_FALSE(r.status().message().empty());
      }
    }
  }
  CHECK(rejected > 0);
  CHECK(accepted > 0);  // payload bytes such as thresholds may legitimately change
}

TEST_CASE("another major version is refused naming both versions", "[format]") {
  auto bytes = core::SerializeForest(testing::MakeRandomForest(SmallSpec(3)));
  bytes[8] = 2;  // major = 2
  bytes[10] = 5;  // minor = 5
  RepairChecksum(bytes);
  auto r = core::ParseForest(bytes, "future.pff");
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kVersionMismatch);
  CHECK_THAT(r.status().message(), Catch::Contains("future.pff") && Catch::Contains("2.5") && Catch::Contains("1."));
}

TEST_CASE("a later minor version's optional section is skipped, a required one refused", "[format]") {
  const core::Forest forest = testing::MakeRandomForest(SmallSpec(4));
  auto bytes = core::SerializeForest(forest);
  // Insert a 16-byte-payload section before the trailer and bump the section count + size.
  auto with_section = [&](uint32_t flags) {
    std::vector<uint8_t> out(bytes.begin(), bytes.end() - 8);
    const uint8_t section[] = {'X', 'T', 'R', 'A', uint8_t(flags), 0, 0, 0, 16, 0, 0, 0, 0, 0, 0, 0};
    out.insert(out.end(), section, section + sizeof section);
    for (int i = 0; i < 16; ++i) out.push_back(uint8_t(i));
    out.resize(out.size() + 8);
    const uint64_t size = out.size();
    for (int i = 0; i < 8; ++i) out[16 + size_t(i)] = uint8_t(size >> (8 * i));
    out[28] += 1;  // section count
    out[size - 4] = 'P', out[size - 3] = 'F', out[size - 2] = 'N', out[size - 1] = 'D';
    RepairChecksum(out);
    return out;
  };
  auto ok = core::ParseForest(with_section(0), "newer.pff");
  REQUIRE(ok.ok());
  CHECK(SameForest(forest, *ok));
  auto refused = core::ParseForest(with_section(1), "newer.pff");
  REQUIRE_FALSE(refused.ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("XTRA") && Catch::Contains("newer"));
}

TEST_CASE("joint-proposal parameters (format 1.1) round trip and are validated", "[format]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(6));
  CHECK_FALSE(core::ParseForest(core::SerializeForest(forest), "a").value().proposal_params.has_value());
  core::ProposalParams params = core::DefaultProposalParams();
  params[3].bandwidth_m = 0.08f;
  params[7].z_offset_m = -0.01f;
  forest.proposal_params = params;
  const auto bytes = core::SerializeForest(forest);
  CHECK(bytes[10] == core::kFormatMinor);
  auto parsed = core::ParseForest(bytes, "b");
  REQUIRE(parsed.ok());
  REQUIRE(parsed->proposal_params.has_value());
  CHECK(*parsed->proposal_params == params);
  // Corruption inside the section behind a repaired checksum is still caught.
  for (size_t i = bytes.size() - 8 - 16 * 12; i < bytes.size() - 8; ++i) {
    auto bad = bytes;
    bad[i] = 0xFF;
    RepairChecksum(bad);
    auto r = core::ParseForest(bad, "c");
    if (r.ok()) REQUIRE(core::ValidateForest(*r, "c").ok());
  }
  params[0].bandwidth_m = -1;
  forest.proposal_params = params;
  CHECK_THAT(core::ValidateForest(forest, "d").message(), Catch::Contains("head") && Catch::Contains("bandwidth"));
  params[0].bandwidth_m = 0.05f;
  params[1].prob_threshold = std::numeric_limits<float>::infinity();
  forest.proposal_params = params;
  CHECK_THAT(core::ValidateForest(forest, "d").message(), Catch::Contains("neck") && Catch::Contains("threshold"));
}

TEST_CASE("ValidateForest names each broken invariant", "[format]") {
  const core::Forest good = testing::MakeRandomForest(SmallSpec(5));
  REQUIRE(core::ValidateForest(good, "x").ok());
  auto expect = [](const core::Forest& f, const char* text) {
    const auto st = core::ValidateForest(f, "f.pff");
    INFO(st.ToString());
    CHECK_FALSE(st.ok());
    CHECK_THAT(st.message(), Catch::Contains(text));
  };
  auto first_split = [](core::Tree& t) -> core::Node& {
    for (auto& n : t.nodes)
      if (!n.is_leaf()) return n;
    FAIL("no split node");
    return t.nodes[0];
  };
  {
    auto f = good;
    first_split(f.trees[0]).child = 0;  // points backwards
    expect(f, "children");
  }
  {
    auto f = good;
    first_split(f.trees[0]).child = uint32_t(f.trees[0].nodes.size() - 1);  // right child out of range
    expect(f, "children");
  }
  {
    auto f = good;
    first_split(f.trees[0]).threshold = std::numeric_limits<float>::quiet_NaN();
    expect(f, "non-finite threshold");
  }
  {
    auto f = good;
    f.trees[1].nodes.back() = core::Node::Leaf(f.trees[1].num_leaves);
    expect(f, "points at leaf");
  }
  {
    auto f = good;
    f.trees[0].leaves[0] += 1;
    expect(f, "sums to");
  }
  {
    auto f = good;
    f.trees[0].leaves[31] = 1;  // padding of leaf 0 (31 parts, stride 32)
    expect(f, "padding");
  }
  {
    auto f = good;
    f.trees[0].depth += 1;
    expect(f, "depth");
  }
  {
    auto f = good;
    f.part_names.pop_back();
    expect(f, "names");
  }
  {
    auto f = good;
    f.trees.clear();
    expect(f, "no trees");
  }
}

TEST_CASE("QuantizeDistribution sums to 255 and tracks the probabilities", "[format]") {
  std::vector<uint8_t> out(31);
  std::vector<float> p(31, 0.0f);
  p[3] = 1.0f;
  core::QuantizeDistribution(p.data(), 31, out.data());
  CHECK(out[3] == 255);
  std::vector<float> q(31);
  for (int i = 0; i < 31; ++i) q[size_t(i)] = float(i + 1);
  core::QuantizeDistribution(q.data(), 31, out.data());
  int sum = 0;
  for (int i = 0; i < 31; ++i) {
    sum += out[size_t(i)];
    CHECK(std::abs(double(out[size_t(i)]) - 255.0 * (i + 1) / 496.0) < 1.0);
  }
  CHECK(sum == 255);
  std::vector<float> zero(31, 0.0f);
  core::QuantizeDistribution(zero.data(), 31, out.data());
  sum = 0;
  for (uint8_t v : out) sum += v;
  CHECK(sum == 255);
}
