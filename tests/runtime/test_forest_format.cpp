// Forest file format v1: round trips, and hostile input (truncation and corruption at every byte
// offset, with and without a repaired checksum) that must give errors, never crashes.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>

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
      a.constants.background_mm != b.constants.background_mm ||
      a.constants.offset_unit != b.constants.offset_unit || a.constants.edge != b.constants.edge)
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
  // A folder where a file belongs (it opens as a stream on Linux, with a huge size): refused
  // before any allocation, by every reader built on ReadFileBytes.
  const auto dir = testing::ScratchDir("format-folder");
  const std::string folder = (dir / "forest.pff").string();
  std::filesystem::create_directories(folder);
  for (const auto& status : {core::LoadForest(folder).status(), core::ReadFileBytes(folder).status(),
                             core::ReadFileText(folder).status()}) {
    CHECK(status.code() == ErrorCode::kInvalidArgument);
    CHECK_THAT(status.message(), Catch::Equals(folder + ": is a folder, not a file"));
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("TaxonomyDifference says how a forest's parts differ from the paper's 31", "[format]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(1));
  forest.num_parts = core::kNumParts;
  forest.part_names = core::Forest::DefaultPartNames();
  CHECK(forest.TaxonomyDifference().empty());
  forest.part_names[3] = "X";  // 31 parts, one renamed: the count alone would not tell
  CHECK(forest.TaxonomyDifference() ==
        "its part 3 is 'X', the paper's '" + core::Forest::DefaultPartNames()[3] + "'");
  forest.num_parts = 5;
  CHECK(forest.TaxonomyDifference() == "this one has 5 parts");
}

TEST_CASE("truncation at every byte offset is an error, never a crash", "[format][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(11));
  forest.constants.edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);  // PEDG too
  const auto bytes = core::SerializeForest(forest);
  for (size_t len = 0; len < bytes.size(); ++len) {
    auto r = core::ParseForest(std::span(bytes.data(), len), "cut.pff");
    INFO("length " << len);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kDataLoss);
    CHECK_THAT(r.status().message(), Catch::StartsWith("cut.pff: "));
  }
}

TEST_CASE("corruption of any single byte is detected", "[format][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(12));
  forest.constants.edge = GENERATE(core::ProbeEdge::kBackground, core::ProbeEdge::kClamp);  // PEDG too
  const auto bytes = core::SerializeForest(forest);
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

namespace {

// A forest's bytes with one more section (tag, flags, payload) before the trailer: section
// count, file size and checksum fixed, so the section's own checks are what is tested.
std::vector<uint8_t> WithSection(const std::vector<uint8_t>& bytes, const char (&tag)[5], uint32_t flags,
                                 const std::vector<uint8_t>& payload) {
  std::vector<uint8_t> out(bytes.begin(), bytes.end() - 8);
  for (int i = 0; i < 4; ++i) out.push_back(uint8_t(tag[i]));
  for (int i = 0; i < 4; ++i) out.push_back(uint8_t(flags >> (8 * i)));
  for (int i = 0; i < 8; ++i) out.push_back(uint8_t(uint64_t(payload.size()) >> (8 * i)));
  out.insert(out.end(), payload.begin(), payload.end());
  while (out.size() % 8) out.push_back(0);
  out.resize(out.size() + 8);
  const uint64_t size = out.size();
  for (int i = 0; i < 8; ++i) out[16 + size_t(i)] = uint8_t(size >> (8 * i));
  out[28] += 1;  // section count
  out[size - 4] = 'P', out[size - 3] = 'F', out[size - 2] = 'N', out[size - 1] = 'D';
  RepairChecksum(out);
  return out;
}

// Little-endian payload bytes, as the format writes them.
struct PayloadBytes {
  std::vector<uint8_t> out;
  void U32(uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(uint8_t(v >> (8 * i)));
  }
  void F32(float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    U32(u);
  }
};

// An 8-byte payload of two u32 words, the shape of JTFT and PEDG.
std::vector<uint8_t> TwoWords(uint32_t first, uint32_t second) {
  PayloadBytes b;
  b.U32(first);
  b.U32(second);
  return b.out;
}

// Parsing `bytes` is data loss, with a message naming the file (bad.pff), the section `tag` and `text`.
void ExpectLoss(const std::vector<uint8_t>& bytes, const std::string& tag, const std::string& text) {
  auto r = core::ParseForest(bytes, "bad.pff");
  REQUIRE_FALSE(r.ok());
  INFO(r.status().ToString());
  CHECK(r.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(r.status().message(),
             Catch::StartsWith("bad.pff: ") && Catch::Contains(tag) && Catch::Contains(text));
}

// The cases every 8-byte (value, reserved) section shares, JTFT and PEDG: appended to `base` with
// `flags`, a payload cut to 0, 4 or 7 bytes or grown to 12, the value 2 or 0xFFFFFFFF (`what`
// names it, `values` lists the allowed ones) and a non-zero reserved word are each data loss.
void ExpectValueSectionErrors(const std::vector<uint8_t>& base, const char (&tag)[5], uint32_t flags,
                              const std::string& what, const std::string& values) {
  const auto good = TwoWords(1, 0);
  for (size_t n : {0, 4, 7})
    ExpectLoss(WithSection(base, tag, flags, {good.begin(), good.begin() + std::ptrdiff_t(n)}), tag,
               std::string(tag) + " holds " + std::to_string(n) + " bytes, expected 8");
  auto longer = good;
  longer.resize(12);
  ExpectLoss(WithSection(base, tag, flags, longer), tag, std::string(tag) + " holds 12 bytes, expected 8");
  ExpectLoss(WithSection(base, tag, flags, TwoWords(2, 0)), tag, what + " 2, expected " + values);
  ExpectLoss(WithSection(base, tag, flags, TwoWords(0xFFFFFFFFu, 0)), tag, what + " 4294967295");
  ExpectLoss(WithSection(base, tag, flags, TwoWords(1, 7)), tag, "reserved word is 7");
}

// A JPAR/JPFC payload: joint count, then (b, lambda, zeta) per joint.
std::vector<uint8_t> ParamsPayload(const core::ProposalParams& params, uint32_t count = core::kNumJoints) {
  PayloadBytes b;
  b.U32(count);
  for (const auto& p : params) b.F32(p.bandwidth_m), b.F32(p.prob_threshold), b.F32(p.z_offset_m);
  return b.out;
}

core::ProposalParams Distinct(float b) {
  core::ProposalParams params = core::DefaultProposalParams();
  for (int j = 0; j < core::kNumJoints; ++j)
    params[size_t(j)] = {b + 0.001f * float(j), 0.1f + 0.01f * float(j), 0.002f * float(j)};
  return params;
}

}  // namespace

TEST_CASE("one parameter set per proposal method (format 1.2) round trips; the rules of each", "[format]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(7));
  // Nothing stored: both methods run with the paper's means.
  for (bool fast : {false, true}) {
    const auto choice = forest.ProposalParamsFor(fast);
    CHECK(choice.source == core::ProposalParamsSource::kPaperMeans);
    CHECK(choice.params == core::DefaultProposalParams());
  }
  const auto mean_shift = Distinct(0.07f), fast = Distinct(0.11f);
  REQUIRE(mean_shift != fast);

  // Both sets: each method its own; the file is 1.2 and holds both sections.
  forest.proposal_params = mean_shift;
  forest.fast_proposal_params = fast;
  const auto bytes = core::SerializeForest(forest);
  CHECK(bytes[10] == core::kFormatMinor);
  CHECK(core::kFormatMinor >= 2);
  auto parsed = core::ParseForest(bytes, "both.pff");
  REQUIRE(parsed.ok());
  REQUIRE(parsed->proposal_params.has_value());
  REQUIRE(parsed->fast_proposal_params.has_value());
  CHECK(*parsed->proposal_params == mean_shift);
  CHECK(*parsed->fast_proposal_params == fast);
  CHECK(parsed->ProposalParamsFor(false).params == mean_shift);
  CHECK(parsed->ProposalParamsFor(false).source == core::ProposalParamsSource::kLearned);
  CHECK(parsed->ProposalParamsFor(true).params == fast);
  CHECK(parsed->ProposalParamsFor(true).source == core::ProposalParamsSource::kLearned);
  CHECK(core::SerializeForest(*parsed) == bytes);

  // Only the fast clustering's: mean shift keeps the paper's means.
  forest.proposal_params.reset();
  parsed = core::ParseForest(core::SerializeForest(forest), "fast.pff");
  REQUIRE(parsed.ok());
  CHECK_FALSE(parsed->proposal_params.has_value());
  CHECK(parsed->ProposalParamsFor(false).source == core::ProposalParamsSource::kPaperMeans);
  CHECK(parsed->ProposalParamsFor(true).params == fast);

  // Only mean shift's (what a 1.1 file holds): the fast clustering runs with it, as in 1.1.
  forest.proposal_params = mean_shift;
  forest.fast_proposal_params.reset();
  parsed = core::ParseForest(core::SerializeForest(forest), "ms.pff");
  REQUIRE(parsed.ok());
  CHECK_FALSE(parsed->fast_proposal_params.has_value());
  CHECK(parsed->ProposalParamsFor(true).params == mean_shift);
  CHECK(parsed->ProposalParamsFor(true).source == core::ProposalParamsSource::kMeanShiftSet);

  // The fast clustering's set is validated like the other, and the error says which set.
  auto bad = fast;
  bad[2].bandwidth_m = std::numeric_limits<float>::quiet_NaN();
  forest.fast_proposal_params = bad;
  const auto st = core::ValidateForest(forest, "v.pff");
  CHECK_THAT(st.message(), Catch::Contains("fast clustering parameters (JPFC)") &&
                               Catch::Contains("L_shoulder") && Catch::Contains("bandwidth"));
}

TEST_CASE("a format 1.1 file written by the code before per-method parameters still loads", "[format]") {
  // tests/runtime/data/forest_v1_1_jpar.pff was written by `poseforest train` + `poseforest
  // tune-joints` built from commit 19dc8d3 (format 1.1, one JPAR set); see data/README.md.
  const auto path = std::filesystem::path(POSEFOREST_SOURCE_DIR) / "tests/runtime/data/forest_v1_1_jpar.pff";
  auto bytes = core::ReadFileBytes(path.string());
  REQUIRE(bytes.ok());
  CHECK((*bytes)[8] == 1);
  CHECK((*bytes)[10] == 1);  // minor version 1
  auto forest = core::ParseForest(*bytes, path.string());
  REQUIRE(forest.ok());
  CHECK(forest->trees.size() == 1);
  CHECK(forest->total_nodes() == 31);
  REQUIRE(forest->proposal_params.has_value());
  CHECK_FALSE(forest->fast_proposal_params.has_value());
  // The values the old `poseforest inspect --joints` printed for it.
  const auto& p = *forest->proposal_params;
  CHECK(p[0].bandwidth_m == 0.045f);
  CHECK(p[0].prob_threshold == 0.55f);
  CHECK(p[0].z_offset_m == 0.0f);
  CHECK(p[6].prob_threshold == 0.14f);  // L_wrist
  CHECK(p[6].z_offset_m == 0.07f);
  CHECK(p[10].bandwidth_m == 0.16f);  // L_knee
  CHECK(p[10].z_offset_m == 0.02f);
  // 1.1's rule: the one set served both methods; it still does.
  CHECK(forest->ProposalParamsFor(false).params == p);
  CHECK(forest->ProposalParamsFor(true).params == p);
  // Written again it is a 1.2 file with the same set, and the trees are untouched.
  const auto again = core::SerializeForest(*forest);
  CHECK(again[10] == core::kFormatMinor);
  auto reparsed = core::ParseForest(again, "again.pff");
  REQUIRE(reparsed.ok());
  CHECK(SameForest(*forest, *reparsed));
  CHECK(reparsed->proposal_params == forest->proposal_params);
  CHECK_FALSE(reparsed->fast_proposal_params.has_value());
}

TEST_CASE("corrupt or truncated JPAR and JPFC sections give errors naming the section", "[format][hostile]") {
  const auto plain = core::SerializeForest(testing::MakeRandomForest(SmallSpec(8)));
  const auto payload = ParamsPayload(Distinct(0.08f));
  for (const char* tag : {"JPAR", "JPFC"}) {
    const char name[5] = {tag[0], tag[1], tag[2], tag[3], 0};
    INFO(name);
    // Sanity: the well-formed section loads.
    auto ok = core::ParseForest(WithSection(plain, name, 0, payload), "ok.pff");
    REQUIRE(ok.ok());
    CHECK((std::string(name) == "JPAR" ? ok->proposal_params : ok->fast_proposal_params) == Distinct(0.08f));
    // Every shorter (truncated) payload: an error naming the file and the section.
    for (size_t n = 0; n < payload.size(); ++n) {
      std::vector<uint8_t> cut(payload.begin(), payload.begin() + std::ptrdiff_t(n));
      auto r = core::ParseForest(WithSection(plain, name, 0, cut), "cut.pff");
      INFO("payload of " << n << " bytes");
      REQUIRE_FALSE(r.ok());
      CHECK(r.status().code() == ErrorCode::kDataLoss);
      CHECK_THAT(r.status().message(), Catch::Contains("cut.pff") && Catch::Contains(name));
    }
    // Trailing bytes, another joint count, a second copy, values out of range.
    auto longer = payload;
    longer.resize(longer.size() + 4);
    auto r = core::ParseForest(WithSection(plain, name, 0, longer), "long.pff");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(r.status().message(), Catch::Contains(name) && Catch::Contains("16 x 12"));
    r = core::ParseForest(WithSection(plain, name, 0, ParamsPayload(Distinct(0.08f), 15)), "count.pff");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(r.status().message(), Catch::Contains(name) && Catch::Contains("15 joints"));
    r = core::ParseForest(WithSection(WithSection(plain, name, 0, payload), name, 0, payload), "twice.pff");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(r.status().message(), Catch::Contains(std::string("second ") + name));
    auto wild = Distinct(0.08f);
    wild[5].prob_threshold = 3;
    r = core::ParseForest(WithSection(plain, name, 0, ParamsPayload(wild)), "wild.pff");
    REQUIRE_FALSE(r.ok());
    CHECK_THAT(r.status().message(),
               Catch::Contains("wild.pff") && Catch::Contains("R_elbow") && Catch::Contains("threshold"));
  }
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

TEST_CASE("the training focal length (format 1.3, FOCL) round trips; older files mean the Kinect v1", "[format]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(21));
  CHECK(forest.training_fx == float(core::kKinectV1FocalPx));  // what the trainer writes today
  forest.training_fx = 365.5f;
  forest.training_fy = 367.25f;
  const auto bytes = core::SerializeForest(forest);
  CHECK(bytes[10] >= 3);  // FOCL since 1.3
  auto parsed = core::ParseForest(bytes, "focal.pff");
  REQUIRE(parsed.ok());
  CHECK(parsed->training_fx == 365.5f);
  CHECK(parsed->training_fy == 367.25f);
  CHECK(SameForest(forest, *parsed));

  // The 1.1 file from before FOCL: trained for the Kinect v1.
  const auto old_path = std::filesystem::path(POSEFOREST_SOURCE_DIR) / "tests/runtime/data/forest_v1_1_jpar.pff";
  auto old = core::LoadForest(old_path.string());
  REQUIRE(old.ok());
  CHECK(old->training_fx == float(core::kKinectV1FocalPx));
  CHECK(old->training_fy == float(core::kKinectV1FocalPx));

  // A bad focal length behind a valid checksum is refused naming the section.
  auto bad = bytes;
  const std::string text(bad.begin(), bad.end());
  const size_t at = text.rfind("FOCL");
  REQUIRE(at != std::string::npos);
  const float zero = 0.0f;
  std::memcpy(bad.data() + at + 16, &zero, 4);
  RepairChecksum(bad);
  auto refused = core::ParseForest(bad, "focal.pff");
  REQUIRE_FALSE(refused.ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("focal.pff") && Catch::Contains("FOCL"));
  // A FOCL of the wrong size is refused too.
  auto longer = bytes;
  longer[at + 8] = 12;
  RepairChecksum(longer);
  CHECK_FALSE(core::ParseForest(longer, "focal.pff").ok());
}

TEST_CASE("the confidence calibration (format 1.4, JCAL): every byte of it rewritten behind a valid checksum",
          "[format][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(22));
  const auto without = core::SerializeForest(forest);
  core::ConfidenceCalibration cal;
  cal.support_edges_m2 = {1e-4f, 1e-3f};
  for (auto& row : cal.precision) row = {0.25f, 0.75f};
  forest.confidence_calibration = cal;
  const auto bytes = core::SerializeForest(forest);
  REQUIRE(bytes.size() > without.size());
  // The JCAL section sits between FOCL and the trailer.
  const size_t start = without.size() - 8;
  int rejected = 0;
  for (size_t i = start; i < bytes.size() - 8; ++i) {
    for (uint8_t value : {uint8_t(0x00), uint8_t(0x7F), uint8_t(0x80), uint8_t(0xFF)}) {
      auto bad = bytes;
      if (bad[i] == value) continue;
      bad[i] = value;
      RepairChecksum(bad);
      auto r = core::ParseForest(bad, "jcal.pff");
      if (r.ok()) {
        REQUIRE(core::ValidateForest(*r, "jcal.pff").ok());
      } else {
        ++rejected;
        CHECK_FALSE(r.status().message().empty());
      }
    }
  }
  CHECK(rejected > 0);
  // A second JCAL is refused naming it.
  auto twice = bytes;
  std::vector<uint8_t> section(bytes.begin() + long(start), bytes.end() - 8);
  twice.insert(twice.end() - 8, section.begin(), section.end());
  twice[28] = uint8_t(twice[28] + 1);  // section count
  for (int k = 0; k < 8; ++k) twice[16 + size_t(k)] = uint8_t(uint64_t(twice.size()) >> (8 * k));
  RepairChecksum(twice);
  auto r = core::ParseForest(twice, "twice.pff");
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().message().find("second JCAL") != std::string::npos);
}

namespace {

// The JVOT payload of `with` (a forest serialized with offset votes) given the same forest's
// bytes without them: JVOT is the last section, right before the trailer.
std::vector<uint8_t> VotesPayload(const std::vector<uint8_t>& with, const std::vector<uint8_t>& without) {
  const size_t start = without.size() - 8;
  REQUIRE(std::memcmp(with.data() + start, "JVOT", 4) == 0);
  uint64_t size = 0;
  for (int i = 0; i < 8; ++i) size |= uint64_t(with[start + 8 + size_t(i)]) << (8 * i);
  REQUIRE(start + 16 + size <= with.size() - 8);
  return {with.begin() + long(start + 16), with.begin() + long(start + 16 + size)};
}

// Parses `bytes` and expects a DataLoss error naming `source`, the section and `text`.
void ExpectVotesRefused(const std::vector<uint8_t>& bytes, const std::string& source,
                        const std::string& text) {
  auto r = core::ParseForest(bytes, source);
  REQUIRE_FALSE(r.ok());
  INFO(r.status().ToString());
  CHECK(r.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(r.status().message(),
             Catch::StartsWith(source + ": ") && Catch::Contains("JVOT") && Catch::Contains(text));
}

}  // namespace

TEST_CASE(
    "offset votes (format 1.5, JVOT) round trip through memory and a file; files without them have none",
    "[format][votes]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(31));
  const auto without = core::SerializeForest(forest);
  CHECK(without[10] == core::kFormatMinor);  // every file is written as the newest minor version
  auto plain = core::ParseForest(without, "plain.pff");
  REQUIRE(plain.ok());
  CHECK_FALSE(plain->offset_votes.has_value());

  const core::OffsetVotes votes = testing::MakeRandomOffsetVotes(forest, 31);
  REQUIRE(votes.total_votes() > 0);
  forest.offset_votes = votes;
  REQUIRE(core::ValidateForest(forest, "mem").ok());
  const auto bytes = core::SerializeForest(forest);
  CHECK(bytes[10] == core::kFormatMinor);
  CHECK(core::kFormatMinor == 9);
  // Head (16 + 16 x 4 bytes), calibration (3 x 8), per tree (8 + (L + 1) x 4 + V x 8), padding.
  size_t payload = 16 + 16 * 4 + 3 * 4 * 17;
  for (size_t t = 0; t < forest.trees.size(); ++t)
    payload += 8 + (size_t(forest.trees[t].num_leaves) + 1) * 4 + votes.trees[t].votes.size() * 8;
  CHECK(bytes.size() == without.size() + 16 + (payload + 7) / 8 * 8);
  CHECK(VotesPayload(bytes, without).size() == payload);

  auto parsed = core::ParseForest(bytes, "votes.pff");
  REQUIRE(parsed.ok());
  CHECK(SameForest(forest, *parsed));
  REQUIRE(parsed->offset_votes.has_value());
  CHECK(*parsed->offset_votes == votes);
  CHECK(core::SerializeForest(*parsed) == bytes);  // deterministic

  const auto dir = testing::ScratchDir("format-votes");
  const std::string path = (dir / "votes.pff").string();
  REQUIRE(core::SaveForest(forest, path).ok());
  auto loaded = core::LoadForest(path);
  REQUIRE(loaded.ok());
  CHECK(SameForest(forest, *loaded));
  REQUIRE(loaded->offset_votes.has_value());
  CHECK(*loaded->offset_votes == votes);
  std::filesystem::remove_all(dir);

  // A 1.1 file from before votes loads with none.
  const auto old_path =
      std::filesystem::path(POSEFOREST_SOURCE_DIR) / "tests/runtime/data/forest_v1_1_jpar.pff";
  auto old = core::LoadForest(old_path.string());
  REQUIRE(old.ok());
  CHECK_FALSE(old->offset_votes.has_value());
}

TEST_CASE("offset votes: confidence from the calibration table, vote count", "[format][votes]") {
  core::OffsetVotes votes;
  CHECK(votes.Confidence(0, 0.5f) == 0);  // no table
  CHECK(votes.total_votes() == 0);
  votes.share_edges = {0.05f, 0.1f, 0.3f};
  votes.precision = {0.2f, 0.5f, 0.9f};
  CHECK(votes.Confidence(0, 0.5f) == 0);  // one row for 16 joints: not a table
  for (int j = 1; j < core::kNumJoints; ++j) votes.precision.insert(votes.precision.end(), {0.1f, 0.4f, 0.8f});
  CHECK(votes.Confidence(1, 0.0f) == 0.1f);  // joint 1's row
  CHECK(votes.Confidence(15, 0.35f) == 0.8f);
  CHECK(votes.Confidence(16, 0.35f) == 0);  // no such joint
  CHECK(votes.Confidence(0, 0.0f) == 0.2f);  // below the first edge: the first bin
  CHECK(votes.Confidence(0, 0.05f) == 0.2f);
  CHECK(votes.Confidence(0, 0.0999f) == 0.2f);
  CHECK(votes.Confidence(0, 0.1f) == 0.5f);  // on an edge: the bin it opens
  CHECK(votes.Confidence(0, 0.2f) == 0.5f);
  CHECK(votes.Confidence(0, 0.3f) == 0.9f);
  CHECK(votes.Confidence(0, 1.0f) == 0.9f);  // the last bin is open above
  votes.trees.resize(2);
  votes.trees[0].votes.resize(3);
  votes.trees[1].votes.resize(4);
  CHECK(votes.total_votes() == 7);
}

TEST_CASE("corrupt or truncated JVOT sections give errors naming the file and the section",
          "[format][votes][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(32));
  const auto plain = core::SerializeForest(forest);
  const core::OffsetVotes votes = testing::MakeRandomOffsetVotes(forest, 32);
  forest.offset_votes = votes;
  const auto good = core::SerializeForest(forest);
  const auto payload = VotesPayload(good, plain);
  // Sanity: the payload alone, added to the plain file, loads as the same votes.
  auto ok = core::ParseForest(WithSection(plain, "JVOT", 0, payload), "ok.pff");
  REQUIRE(ok.ok());
  REQUIRE(ok->offset_votes.has_value());
  CHECK(*ok->offset_votes == votes);

  SECTION("every shorter (truncated) payload") {
    for (size_t n = 0; n < payload.size(); ++n) {
      INFO("payload of " << n << " bytes");
      std::vector<uint8_t> cut(payload.begin(), payload.begin() + std::ptrdiff_t(n));
      auto r = core::ParseForest(WithSection(plain, "JVOT", 0, cut), "cut.pff");
      REQUIRE_FALSE(r.ok());
      CHECK(r.status().code() == ErrorCode::kDataLoss);
      CHECK_THAT(r.status().message(), Catch::StartsWith("cut.pff: ") && Catch::Contains("JVOT"));
    }
    // The messages say what is missing.
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, {payload.begin(), payload.begin() + 40}), "cut.pff",
                       "JVOT section too short (40 bytes, its head is 80)");
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, {payload.begin(), payload.end() - 1}), "cut.pff",
                       "truncated?");
  }
  SECTION("trailing bytes after the last tree") {
    auto longer = payload;
    longer.resize(longer.size() + 8);
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, longer), "long.pff",
                       "JVOT has 8 bytes after its last tree");
  }
  SECTION("sizes that would overflow or run past the section") {
    auto bins = payload;
    const uint8_t all[4] = {0xFF, 0xFF, 0xFF, 0xFF};
    std::memcpy(bins.data() + 76, all, 4);  // calibration bin count 2^32 - 1
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, bins), "bins.pff", "calibration of 4294967295 bins");
    auto leaves = payload;
    std::memcpy(leaves.data() + 80 + 3 * 4 * 17, all, 4);  // tree 0's leaf count 2^32 - 1
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, leaves), "leaves.pff", "JVOT tree 0: 4294967295 leaves");
    auto count = payload;
    std::memcpy(count.data() + 80 + 3 * 4 * 17 + 4, all, 4);  // tree 0's vote count 2^32 - 1
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, count), "count.pff", "4294967295 votes need");
    auto joints = payload;
    joints[4] = 15;
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, joints), "joints.pff",
                       "JVOT holds 15 joints, expected 16");
  }
  SECTION("a tree count not matching the forest") {
    auto more = forest;
    more.offset_votes->trees.push_back(more.offset_votes->trees[0]);
    ExpectVotesRefused(core::SerializeForest(more), "trees.pff",
                       "JVOT holds votes for 3 trees, the forest declares 2");
    auto fewer = payload;
    fewer[0] = 1;
    ExpectVotesRefused(WithSection(plain, "JVOT", 0, fewer), "trees.pff",
                       "JVOT holds votes for 1 trees, the forest declares 2");
  }
  SECTION("a leaf count not matching the tree's") {
    auto f = forest;
    auto& tree = f.offset_votes->trees[1];
    tree.first.push_back(tree.first.back());  // one leaf too many, still a well-formed table
    const uint32_t leaves = forest.trees[1].num_leaves;
    ExpectVotesRefused(core::SerializeForest(f), "leafcount.pff",
                       "JVOT: tree 1: " + std::to_string(leaves + 2) + " leaf offsets (first), expected " +
                           std::to_string(leaves + 1));
  }
  SECTION("first not ending at the vote count") {
    auto f = forest;
    auto& tree = f.offset_votes->trees[0];
    const size_t v = tree.votes.size();
    REQUIRE(v > 0);
    tree.first.back() = uint32_t(v - 1);
    ExpectVotesRefused(core::SerializeForest(f), "first.pff",
                       "JVOT: tree 0: first ends at " + std::to_string(v - 1) + " but the tree holds " +
                           std::to_string(v) + " votes");
    // Past the votes: caught before any vote is read beyond them.
    tree.first.back() = uint32_t(v + 5);
    ExpectVotesRefused(core::SerializeForest(f), "first.pff", "first ends at " + std::to_string(v + 5));
    tree.first.back() = uint32_t(v);
    tree.first[1] = uint32_t(v + 5);  // leaf 0 ends past the votes, then first decreases
    ExpectVotesRefused(core::SerializeForest(f), "first.pff", "JVOT: tree 0 leaf 0: votes end at");
  }
  SECTION("a joint out of range, joints out of order, a zero weight") {
    auto f = forest;
    auto& tree = f.offset_votes->trees[1];
    uint32_t leaf = 0;
    while (leaf + 1 < tree.first.size() && tree.first[leaf + 1] - tree.first[leaf] < 2) ++leaf;
    REQUIRE(leaf + 1 < tree.first.size());  // a leaf with two votes or more
    const uint32_t at = tree.first[leaf];
    const std::string name = "JVOT: tree 1 leaf " + std::to_string(leaf) + ": ";
    tree.votes[at].joint = 19;
    ExpectVotesRefused(core::SerializeForest(f), "wild.pff", name + "vote joint 19 out of range (16 joints)");
    tree.votes[at].joint = tree.votes[at + 1].joint;
    ExpectVotesRefused(core::SerializeForest(f), "wild.pff", name + "vote joints not increasing");
    tree.votes[at] = votes.trees[1].votes[at];
    tree.votes[at + 1].weight = 0;
    ExpectVotesRefused(core::SerializeForest(f), "wild.pff", name + "vote for joint");
  }
  SECTION("bad constants and calibration") {
    auto f = forest;
    f.offset_votes->max_offset_m = std::numeric_limits<float>::quiet_NaN();
    ExpectVotesRefused(core::SerializeForest(f), "c.pff", "max offset");
    f.offset_votes = votes;
    f.offset_votes->bandwidth_m[4] = 0;
    ExpectVotesRefused(core::SerializeForest(f), "c.pff",
                       "joint " + std::string(core::JointName(4)) + ": bandwidth");
    f.offset_votes = votes;
    f.offset_votes->share_edges[2] = 0.05f;
    ExpectVotesRefused(core::SerializeForest(f), "c.pff", "share edge 2");
    f.offset_votes = votes;
    f.offset_votes->share_edges[2] = 1.0f;
    ExpectVotesRefused(core::SerializeForest(f), "c.pff", "share edge 2");
    f.offset_votes = votes;
    f.offset_votes->precision[1] = 1.5f;
    ExpectVotesRefused(core::SerializeForest(f), "c.pff", "precision 1");
  }
  SECTION("a second JVOT") {
    ExpectVotesRefused(WithSection(good, "JVOT", 0, payload), "twice.pff", "second JVOT section");
  }
  SECTION("JVOT before META") {
    // JVOT as the first section: refused naming it, not read against a tree count of 0.
    std::vector<uint8_t> out(plain.begin(), plain.begin() + 64);
    const uint8_t head[8] = {'J', 'V', 'O', 'T', 0, 0, 0, 0};
    out.insert(out.end(), head, head + 8);
    for (int i = 0; i < 8; ++i) out.push_back(uint8_t(uint64_t(payload.size()) >> (8 * i)));
    out.insert(out.end(), payload.begin(), payload.end());
    while (out.size() % 8) out.push_back(0);
    out.insert(out.end(), plain.begin() + 64, plain.end());
    const uint64_t size = out.size();
    for (int i = 0; i < 8; ++i) out[16 + size_t(i)] = uint8_t(size >> (8 * i));
    out[28] += 1;  // section count
    RepairChecksum(out);
    ExpectVotesRefused(out, "early.pff", "section 0: JVOT before META");
  }
}

TEST_CASE("an in-memory forest with bad offset votes is refused before saving", "[format][votes]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(33));
  forest.offset_votes = testing::MakeRandomOffsetVotes(forest, 33);
  auto& tree = forest.offset_votes->trees[0];
  uint32_t leaf = 0;
  while (tree.first[leaf + 1] == tree.first[leaf]) ++leaf;
  tree.votes[tree.first[leaf]].joint = 16;
  const std::string expected =
      "f.pff: JVOT: tree 0 leaf " + std::to_string(leaf) + ": vote joint 16 out of range (16 joints)";
  const auto st = core::ValidateForest(forest, "f.pff");
  CHECK(st.code() == ErrorCode::kDataLoss);
  CHECK(st.message() == expected);
  const auto dir = testing::ScratchDir("format-votes-bad");
  const std::string path = (dir / "bad.pff").string();
  const auto saved = core::SaveForest(forest, path);
  CHECK(saved.code() == ErrorCode::kDataLoss);
  CHECK_THAT(saved.message(), Catch::Contains(path + " (in memory): JVOT: tree 0 leaf"));
  CHECK_FALSE(std::filesystem::exists(path));
  // One table per tree.
  forest.offset_votes->trees.pop_back();
  CHECK_THAT(core::ValidateForest(forest, "f.pff").message(),
             Catch::Contains("f.pff: JVOT: votes for 1 trees, the forest has 2"));
  std::filesystem::remove_all(dir);
}

TEST_CASE("offset votes (format 1.5, JVOT): every byte of them rewritten behind a valid checksum",
          "[format][votes][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(34));
  const auto without = core::SerializeForest(forest);
  forest.offset_votes = testing::MakeRandomOffsetVotes(forest, 34, 1.5);
  const auto bytes = core::SerializeForest(forest);
  const size_t start = without.size() - 8;
  int rejected = 0, accepted = 0;
  for (size_t i = start; i < bytes.size() - 8; ++i) {
    for (uint8_t value : {uint8_t(0x00), uint8_t(0x7F), uint8_t(0x80), uint8_t(0xFF)}) {
      auto bad = bytes;
      if (bad[i] == value) continue;
      bad[i] = value;
      RepairChecksum(bad);
      auto r = core::ParseForest(bad, "jvot.pff");
      if (r.ok()) {
        ++accepted;
        REQUIRE(core::ValidateForest(*r, "jvot.pff").ok());
      } else {
        ++rejected;
        CHECK(r.status().code() == ErrorCode::kDataLoss);
        CHECK_THAT(r.status().message(), Catch::StartsWith("jvot.pff: "));
      }
    }
  }
  CHECK(rejected > 0);
  CHECK(accepted > 0);  // offsets and weights may legitimately change
  // Truncating the file anywhere inside the section is an error too.
  for (size_t len = start; len < bytes.size(); ++len)
    CHECK_FALSE(core::ParseForest(std::span(bytes.data(), len), "cut.pff").ok());
}

namespace {

// A JTRK payload: joints, cues, samples, then intercepts, slopes and shared weights.
std::vector<uint8_t> TrackingPayload(const core::TrackingModel& m, uint32_t joints = core::kNumJoints,
                                     uint32_t cues = core::kNumTrackingFeatures) {
  PayloadBytes b;
  b.U32(joints);
  b.U32(cues);
  b.U32(m.samples);
  for (float v : m.intercept) b.F32(v);
  for (float v : m.slope) b.F32(v);
  for (float v : m.shared) b.F32(v);
  return b.out;
}

core::TrackingModel SomeTrackingModel() {
  core::TrackingModel m;
  for (int j = 0; j < core::kNumJoints; ++j) m.intercept[size_t(j)] = 0.1f * float(j) - 0.5f, m.slope[size_t(j)] = 0.8f;
  for (int k = 0; k < core::kNumTrackingFeatures; ++k) m.shared[size_t(k)] = 0.25f * float(k % 5) - 0.5f;
  m.samples = 1234;
  return m;
}

}  // namespace

TEST_CASE("the tracking decision (format 1.6, JTRK) round trips; files without it have none", "[format][tracking]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(41));
  const auto without = core::SerializeForest(forest);
  auto plain = core::ParseForest(without, "plain.pff");
  REQUIRE(plain.ok());
  CHECK_FALSE(plain->tracking_model.has_value());
  forest.tracking_model = SomeTrackingModel();
  const auto bytes = core::SerializeForest(forest);
  // The section: 16-byte header, 12 + 4 x (16 + 16 + cues) bytes, padded to 8.
  const size_t payload = 12 + 4 * (2 * core::kNumJoints + core::kNumTrackingFeatures);
  CHECK(bytes.size() == without.size() + 16 + (payload + 7) / 8 * 8);
  CHECK(WithSection(without, "JTRK", 0, TrackingPayload(*forest.tracking_model)) == bytes);
  auto parsed = core::ParseForest(bytes, "trk.pff");
  REQUIRE(parsed.ok());
  REQUIRE(parsed->tracking_model.has_value());
  CHECK(*parsed->tracking_model == *forest.tracking_model);
  CHECK(core::SerializeForest(*parsed) == bytes);
  const auto dir = testing::ScratchDir("format-tracking");
  const std::string path = (dir / "trk.pff").string();
  REQUIRE(core::SaveForest(forest, path).ok());
  auto loaded = core::LoadForest(path);
  REQUIRE(loaded.ok());
  CHECK(loaded->tracking_model == forest.tracking_model);
  std::filesystem::remove_all(dir);
}

TEST_CASE("corrupt or truncated JTRK sections give errors naming the file and the section",
          "[format][tracking][hostile]") {
  const core::Forest forest = testing::MakeRandomForest(SmallSpec(42));
  const auto plain = core::SerializeForest(forest);
  const core::TrackingModel model = SomeTrackingModel();
  const auto payload = TrackingPayload(model);
  auto expect = [](const std::vector<uint8_t>& bytes, const std::string& text) {
    auto r = core::ParseForest(bytes, "bad.pff");
    REQUIRE_FALSE(r.ok());
    INFO(r.status().ToString());
    CHECK(r.status().code() == ErrorCode::kDataLoss);
    CHECK_THAT(r.status().message(), Catch::StartsWith("bad.pff: ") && Catch::Contains("JTRK") &&
                                         Catch::Contains(text));
  };
  for (size_t n = 0; n < payload.size(); n += 3)
    expect(WithSection(plain, "JTRK", 0, {payload.begin(), payload.begin() + std::ptrdiff_t(n)}),
           "JTRK holds " + std::to_string(n) + " bytes, expected " + std::to_string(payload.size()));
  auto longer = payload;
  longer.resize(longer.size() + 4);
  expect(WithSection(plain, "JTRK", 0, longer), "bytes, expected");
  // Another cue count (a newer model this reader cannot apply) or joint count.
  auto more_cues = TrackingPayload(model, core::kNumJoints, core::kNumTrackingFeatures + 1);
  more_cues.resize(payload.size());
  expect(WithSection(plain, "JTRK", 0, more_cues), "cues, expected");
  auto joints = TrackingPayload(model, 15);
  expect(WithSection(plain, "JTRK", 0, joints), "holds 15 joints");
  // Weights that are not numbers, or absurd.
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(), 5e3f}) {
    core::TrackingModel m = model;
    m.shared[3] = bad;
    expect(WithSection(plain, "JTRK", 0, TrackingPayload(m)), "cue 'has proposal'");
    m = model;
    m.slope[7] = bad;
    expect(WithSection(plain, "JTRK", 0, TrackingPayload(m)), "joint 7");
  }
  // Twice.
  auto once = WithSection(plain, "JTRK", 0, payload);
  expect(WithSection(once, "JTRK", 0, payload), "second JTRK section");
  // The good payload alone loads.
  auto ok = core::ParseForest(once, "ok.pff");
  REQUIRE(ok.ok());
  CHECK(ok->tracking_model == model);
}

TEST_CASE("the tracking decision's skeleton fit (format 1.7, JTFT): written for kinematic, greedy without it",
          "[format][tracking]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(43));
  forest.tracking_model = SomeTrackingModel();
  REQUIRE(forest.tracking_model->fit == core::TrackingFit::kGreedy);  // the default: what 1.6 files mean
  const auto greedy = core::SerializeForest(forest);
  forest.tracking_model->fit = core::TrackingFit::kKinematic;
  const auto kinematic = core::SerializeForest(forest);
  // JTFT after JTRK: u32 fit 1, u32 reserved 0; a greedy model's file has no JTFT.
  PayloadBytes fit;
  fit.U32(1);
  fit.U32(0);
  CHECK(WithSection(greedy, "JTFT", 0, fit.out) == kinematic);
  CHECK(kinematic.size() == greedy.size() + 16 + 8);
  auto parsed = core::ParseForest(kinematic, "kin.pff");
  REQUIRE(parsed.ok());
  REQUIRE(parsed->tracking_model.has_value());
  CHECK(parsed->tracking_model->fit == core::TrackingFit::kKinematic);
  CHECK(*parsed->tracking_model == *forest.tracking_model);
  CHECK(core::SerializeForest(*parsed) == kinematic);
  auto old = core::ParseForest(greedy, "old.pff");
  REQUIRE(old.ok());
  CHECK(old->tracking_model->fit == core::TrackingFit::kGreedy);
  CHECK(std::string(core::TrackingFitName(core::TrackingFit::kKinematic)) == "kinematic");
  CHECK(std::string(core::TrackingFitName(core::TrackingFit::kGreedy)) == "greedy");
}

TEST_CASE("corrupt JTFT sections, or one without JTRK, give errors naming the file and the section",
          "[format][tracking][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(44));
  const auto plain = core::SerializeForest(forest);
  forest.tracking_model = SomeTrackingModel();
  const auto with_model = core::SerializeForest(forest);
  const auto payload = TwoWords;
  auto expect = [](const std::vector<uint8_t>& bytes, const std::string& text) {
    ExpectLoss(bytes, "JTFT", text);
  };
  const auto good = payload(1, 0);
  ExpectValueSectionErrors(with_model, "JTFT", 0, "skeleton fit", "0 (greedy) or 1 (kinematic)");
  const auto once = WithSection(with_model, "JTFT", 0, good);
  expect(WithSection(once, "JTFT", 0, good), "second JTFT section");
  // A fit for a tracking decision the file does not hold.
  expect(WithSection(plain, "JTFT", 0, good), "a JTFT section without the JTRK section it describes");
  // Explicitly greedy (0) loads as greedy.
  auto zero = core::ParseForest(WithSection(with_model, "JTFT", 0, payload(0, 0)), "zero.pff");
  REQUIRE(zero.ok());
  CHECK(zero->tracking_model->fit == core::TrackingFit::kGreedy);
}

namespace {

// A JSEE payload: joints, cues, then intercepts, slopes and shared weights.
std::vector<uint8_t> SeenPayload(const core::TrackingWeights& m, uint32_t joints = core::kNumJoints,
                                 uint32_t cues = core::kNumTrackingFeatures) {
  PayloadBytes b;
  b.U32(joints);
  b.U32(cues);
  for (float v : m.intercept) b.F32(v);
  for (float v : m.slope) b.F32(v);
  for (float v : m.shared) b.F32(v);
  return b.out;
}

core::TrackingWeights SomeSeenWeights() {
  core::TrackingWeights w;
  for (int j = 0; j < core::kNumJoints; ++j) w.intercept[size_t(j)] = 0.5f - 0.05f * float(j), w.slope[size_t(j)] = 0.3f;
  for (int k = 0; k < core::kNumTrackingFeatures; ++k) w.shared[size_t(k)] = 0.5f - 0.125f * float(k % 7);
  return w;
}

}  // namespace

TEST_CASE("the seen decision (format 1.8, JSEE) round trips beside JTRK; files without it have none",
          "[format][tracking]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(45));
  forest.tracking_model = SomeTrackingModel();
  const auto without = core::SerializeForest(forest);
  auto plain = core::ParseForest(without, "plain.pff");
  REQUIRE(plain.ok());
  REQUIRE(plain->tracking_model.has_value());
  CHECK_FALSE(plain->tracking_model->seen.has_value());  // a 1.7 decision: tracked by P(within)
  forest.tracking_model->seen = SomeSeenWeights();
  const auto bytes = core::SerializeForest(forest);
  // The section after JTRK: 16-byte header, 8 + 4 x (16 + 16 + cues) bytes, padded to 8.
  const size_t payload = 8 + 4 * (2 * core::kNumJoints + core::kNumTrackingFeatures);
  CHECK(bytes.size() == without.size() + 16 + (payload + 7) / 8 * 8);
  CHECK(WithSection(without, "JSEE", 0, SeenPayload(*forest.tracking_model->seen)) == bytes);
  auto parsed = core::ParseForest(bytes, "seen.pff");
  REQUIRE(parsed.ok());
  REQUIRE(parsed->tracking_model.has_value());
  CHECK(*parsed->tracking_model == *forest.tracking_model);
  CHECK(core::SerializeForest(*parsed) == bytes);
  // With a kinematic model too (JTRK, JTFT, JSEE), through a file.
  forest.tracking_model->fit = core::TrackingFit::kKinematic;
  const auto dir = testing::ScratchDir("format-seen");
  const std::string path = (dir / "seen.pff").string();
  REQUIRE(core::SaveForest(forest, path).ok());
  auto loaded = core::LoadForest(path);
  REQUIRE(loaded.ok());
  CHECK(loaded->tracking_model == forest.tracking_model);
  std::filesystem::remove_all(dir);
}

TEST_CASE("corrupt or truncated JSEE sections, or one without JTRK, give errors naming the file and the section",
          "[format][tracking][hostile]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(46));
  const auto plain = core::SerializeForest(forest);
  forest.tracking_model = SomeTrackingModel();
  const auto with_model = core::SerializeForest(forest);
  const core::TrackingWeights seen = SomeSeenWeights();
  const auto payload = SeenPayload(seen);
  auto expect = [](const std::vector<uint8_t>& bytes, const std::string& text) {
    auto r = core::ParseForest(bytes, "bad.pff");
    REQUIRE_FALSE(r.ok());
    INFO(r.status().ToString());
    CHECK(r.status().code() == ErrorCode::kDataLoss);
    CHECK_THAT(r.status().message(), Catch::StartsWith("bad.pff: ") && Catch::Contains("JSEE") &&
                                         Catch::Contains(text));
  };
  for (size_t n = 0; n < payload.size(); n += 3)
    expect(WithSection(with_model, "JSEE", 0, {payload.begin(), payload.begin() + std::ptrdiff_t(n)}),
           "JSEE holds " + std::to_string(n) + " bytes, expected " + std::to_string(payload.size()));
  auto longer = payload;
  longer.resize(longer.size() + 4);
  expect(WithSection(with_model, "JSEE", 0, longer), "bytes, expected");
  auto more_cues = SeenPayload(seen, core::kNumJoints, core::kNumTrackingFeatures + 1);
  more_cues.resize(payload.size());
  expect(WithSection(with_model, "JSEE", 0, more_cues), "cues, expected");
  expect(WithSection(with_model, "JSEE", 0, SeenPayload(seen, 15)), "holds 15 joints");
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::infinity(), 5e3f}) {
    core::TrackingWeights w = seen;
    w.shared[5] = bad;
    expect(WithSection(with_model, "JSEE", 0, SeenPayload(w)), "cue 'near cut edge'");
    w = seen;
    w.intercept[11] = bad;
    expect(WithSection(with_model, "JSEE", 0, SeenPayload(w)), "joint 11");
  }
  const auto once = WithSection(with_model, "JSEE", 0, payload);
  expect(WithSection(once, "JSEE", 0, payload), "second JSEE section");
  // A seen decision for a tracking decision the file does not hold.
  expect(WithSection(plain, "JSEE", 0, payload), "a JSEE section without the JTRK section it belongs to");
  auto ok = core::ParseForest(once, "ok.pff");
  REQUIRE(ok.ok());
  REQUIRE(ok->tracking_model.has_value());
  CHECK(ok->tracking_model->seen == seen);
}

TEST_CASE("the tracking model's probability: sigmoid of intercept, slope on the confidence's logit, and cues",
          "[tracking]") {
  core::TrackingModel m;
  core::TrackingFeatures f{};
  CHECK(m.Probability(0, 0.7f, f) == Approx(0.5));  // all weights 0
  m.intercept[2] = 1.0f;
  m.slope[2] = 2.0f;
  m.shared[core::kFeatNearCutEdge] = -3.0f;
  const double logit = std::log(0.7 / 0.3);
  CHECK(m.Probability(2, 0.7f, f) == Approx(1 / (1 + std::exp(-(1 + 2 * logit)))).epsilon(1e-5));
  f[core::kFeatNearCutEdge] = 1;
  CHECK(m.Probability(2, 0.7f, f) == Approx(1 / (1 + std::exp(-(1 + 2 * logit - 3)))).epsilon(1e-5));
  // The confidence is clamped to [0.01, 0.99] before its logit.
  CHECK(m.Probability(2, 1.0f, f) == m.Probability(2, 0.99f, f));
  CHECK(m.Probability(2, 0.0f, f) == m.Probability(2, 0.01f, f));
  CHECK(m.Probability(-1, 0.7f, f) == 0);
  CHECK(m.Probability(core::kNumJoints, 0.7f, f) == 0);
  CHECK(std::string(core::TrackingFeatureName(core::kFeatDepthGap)) == "depth gap");
  CHECK(std::string(core::TrackingFeatureName(99)) == "?");
}

TEST_CASE("the probe edge (format 1.9, PEDG): a required section, written only for clamp", "[format]") {
  core::Forest forest = testing::MakeRandomForest(SmallSpec(61));
  REQUIRE(forest.constants.edge == core::ProbeEdge::kBackground);  // the default: what every older file means
  const auto background = core::SerializeForest(forest);
  forest.constants.edge = core::ProbeEdge::kClamp;
  const auto clamp = core::SerializeForest(forest);
  // One section more: 16 bytes of head, u32 edge 1 and u32 reserved 0, flagged required so that a
  // reader before 1.9 refuses the trees it would evaluate wrongly.
  CHECK(clamp.size() == background.size() + 16 + 8);
  const auto at = std::search(clamp.begin(), clamp.end(), std::begin("PEDG"), std::begin("PEDG") + 4);
  REQUIRE(at != clamp.end());
  const auto word = [&](std::ptrdiff_t i) {
    uint32_t v = 0;
    for (int k = 0; k < 4; ++k) v |= uint32_t(at[i + k]) << (8 * k);
    return v;
  };
  CHECK(word(4) == 1u);   // flags: required
  CHECK(word(8) == 8u);   // payload size (low word)
  CHECK(word(16) == 1u);  // edge: clamp
  CHECK(word(20) == 0u);  // reserved
  CHECK(std::search(background.begin(), background.end(), std::begin("PEDG"), std::begin("PEDG") + 4) ==
        background.end());
  for (const auto& [bytes, edge] :
       {std::pair{clamp, core::ProbeEdge::kClamp}, std::pair{background, core::ProbeEdge::kBackground}}) {
    auto parsed = core::ParseForest(bytes, "f.pff");
    REQUIRE(parsed.ok());
    CHECK(parsed->constants.edge == edge);
    CHECK(core::SerializeForest(*parsed) == bytes);
  }
  // Through a file too.
  const auto path = testing::ScratchDir("format-probe-edge") / "clamp.pff";
  REQUIRE(core::SaveForest(forest, path.string()).ok());
  auto loaded = core::LoadForest(path.string());
  REQUIRE(loaded.ok());
  CHECK(loaded->constants.edge == core::ProbeEdge::kClamp);
  CHECK(std::string(core::ProbeEdgeName(core::ProbeEdge::kClamp)) == "clamp");
  CHECK(std::string(core::ProbeEdgeName(core::ProbeEdge::kBackground)) == "background");
}

TEST_CASE("corrupt or repeated PEDG sections give errors naming the file and the section",
          "[format][hostile]") {
  const core::Forest forest = testing::MakeRandomForest(SmallSpec(62));
  const auto plain = core::SerializeForest(forest);
  const auto payload = TwoWords;
  auto expect = [](const std::vector<uint8_t>& bytes, const std::string& text) {
    ExpectLoss(bytes, "PEDG", text);
  };
  const auto good = payload(1, 0);
  ExpectValueSectionErrors(plain, "PEDG", 1, "probe edge", "0 (background) or 1 (clamp)");
  expect(WithSection(WithSection(plain, "PEDG", 1, good), "PEDG", 1, good), "second PEDG section");
  // Appended after the trees, it reads as the writer's.
  auto ok = core::ParseForest(WithSection(plain, "PEDG", 1, good), "ok.pff");
  REQUIRE(ok.ok());
  CHECK(ok->constants.edge == core::ProbeEdge::kClamp);
  auto zero = core::ParseForest(WithSection(plain, "PEDG", 1, payload(0, 0)), "zero.pff");
  REQUIRE(zero.ok());
  CHECK(zero->constants.edge == core::ProbeEdge::kBackground);
}
