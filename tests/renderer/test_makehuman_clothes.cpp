// Bodies: MakeHuman bodies sampled continuously over the macro targets, and MakeHuman
// clothes, hair and shoes (.mhclo proxies) fitted to them, skinned and part-labelled.
#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>
#include <unordered_map>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/mhclo.h"
#include "renderer/scene_assets.h"
#include "runtime/core/body_parts.h"
#include "runtime/core/rng.h"
#include "tests/support/paths.h"

using namespace poseforest;
using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;
namespace fs = std::filesystem;

namespace {

fs::path KitDir() { return testing::DataDir() / "meshes" / "makehuman_hm08_kit"; }
fs::path ClothesDir() { return testing::DataDir() / "meshes" / "makehuman_clothes"; }

const MakeHumanKit& Kit() {
  static std::unique_ptr<MakeHumanKit> kit = [] {
    auto k = MakeHumanKit::Load(KitDir());
    REQUIRE(k.ok());
    return std::move(k).value();
  }();
  return *kit;
}

const MakeHumanWardrobe& Wardrobe() {
  static const MakeHumanWardrobe w = [] {
    auto loaded = LoadMakeHumanWardrobe(ClothesDir(), Kit().base_vertex_count());
    INFO(loaded.status().ToString());
    REQUIRE(loaded.ok());
    return std::move(loaded).value();
  }();
  return w;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Each proxy vertex's distance to the nearest body vertex (metres), via a 2 cm grid.
std::vector<float> DistanceToBody(const BodyMesh& body, const std::vector<Eigen::Vector3f>& pts) {
  constexpr float kCell = 0.02f;
  auto key = [&](const Eigen::Vector3f& p, int dx, int dy, int dz) {
    const int64_t x = int64_t(std::floor(p.x() / kCell)) + dx, y = int64_t(std::floor(p.y() / kCell)) + dy,
                  z = int64_t(std::floor(p.z() / kCell)) + dz;
    return (x & 0x1FFFFF) << 42 | (y & 0x1FFFFF) << 21 | (z & 0x1FFFFF);
  };
  std::unordered_map<int64_t, std::vector<uint32_t>> grid;
  for (uint32_t v = 0; v < body.vertices.size(); ++v) grid[key(body.vertices[v], 0, 0, 0)].push_back(v);
  std::vector<float> out;
  for (const auto& p : pts) {
    float best = std::numeric_limits<float>::infinity();
    for (int r = 1; r <= 16 && !std::isfinite(best); r *= 2)  // search widening cubes
      for (int dx = -r; dx <= r; ++dx)
        for (int dy = -r; dy <= r; ++dy)
          for (int dz = -r; dz <= r; ++dz) {
            auto it = grid.find(key(p, dx, dy, dz));
            if (it == grid.end()) continue;
            for (uint32_t v : it->second) best = std::min(best, (body.vertices[v] - p).norm());
          }
    out.push_back(best);
  }
  return out;
}

float Percentile(std::vector<float> v, double q) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.f : v[size_t(q * double(v.size() - 1))];
}

}  // namespace

TEST_CASE("a hand-written mhclo parses: bindings, scales, delete ranges", "[unit]") {
  const std::string text =
      "# comment\n"
      "name tiny\n"
      "tag Female\n"
      "obj_file tiny.obj\n"
      "x_scale 0 1 2.0\n"
      "y_scale 1 2 0.5\n"
      "z_depth 50\n"
      "verts 0\n"
      "0 1 2 0.5 0.25 0.25 0.1 0.2 0.3\n"
      "2 1 0 1.0 0.0 0.0\n"
      "1\n"
      "\n"
      "delete_verts\n"
      "3 5 - 7 2\n";
  auto p = ParseMhclo(text, "tiny.mhclo", 10);
  INFO(p.status().ToString());
  REQUIRE(p.ok());
  CHECK(p->name == "tiny");
  CHECK(p->kind == ProxyKind::kHair);
  CHECK(p->tags == std::vector<std::string>{"female"});
  REQUIRE(p->vertex_count() == 3);
  CHECK(p->ref[0] == std::array<uint32_t, 3>{0, 1, 2});
  CHECK(p->weight[0][1] == Approx(0.25));
  CHECK(p->offset[0].z() == Approx(0.3));
  CHECK(p->offset[1].isZero());
  CHECK(p->ref[2] == std::array<uint32_t, 3>{1, 1, 1});
  CHECK(p->delete_verts == std::vector<uint32_t>{2, 3, 5, 6, 7});
  CHECK(p->scale[0].has_scale);
  CHECK(p->scale[1].has_scale);
  CHECK_FALSE(p->scale[2].has_scale);

  // p = sum w_i B[v_i] + diag(s) d, s_x = |B[0].x - B[1].x| / 2 = 2, s_y = |B[1].y - B[2].y| / 0.5 = 4.
  const std::vector<Eigen::Vector3f> base = {{0, 0, 0}, {4, 1, 0}, {0, 3, 2}};
  const auto fitted = FitProxy(*p, base);
  REQUIRE(fitted.size() == 3);
  const Eigen::Vector3f expect0 = 0.5f * base[0] + 0.25f * base[1] + 0.25f * base[2] + Eigen::Vector3f(0.2f, 0.8f, 0.3f);
  CHECK((fitted[0] - expect0).norm() < 1e-5f);
  CHECK((fitted[1] - base[2]).norm() < 1e-6f);
  CHECK((fitted[2] - base[1]).norm() < 1e-6f);
}

TEST_CASE("malformed mhclo files give an error naming the file and line", "[unit]") {
  const std::string head = "name bad\nobj_file bad.obj\nverts 0\n0 1 2 0.5 0.25 0.25 0 0 0\n";
  struct Case {
    std::string text, where;
  };
  for (const Case& c : {Case{head + "0 1 2 0.5 0.25\n", "bad.mhclo:5:"},          // truncated line
                        Case{head + "0 1 99 0.5 0.25 0.25 0 0 0\n", "bad.mhclo:5:"},  // index out of range
                        Case{head + "0 1 2 0.5 x 0.25 0 0 0\n", "bad.mhclo:5:"},     // not a number
                        Case{"name bad\nx_scale 1 2\nverts 0\n", "bad.mhclo:2:"},      // scale without ref
                        Case{head + "delete_verts\n5 - 3\n", "bad.mhclo:6:"},          // backwards range
                        Case{"name bad\nobj_file bad.obj\n", "bad.mhclo"}}) {          // no verts at all
    auto p = ParseMhclo(c.text, "bad.mhclo", 10);
    REQUIRE_FALSE(p.ok());
    CHECK(p.status().code() == core::ErrorCode::kDataLoss);
    CHECK_THAT(p.status().message(), Catch::Contains(c.where));
  }

  // A real file cut short: fewer bindings than .obj vertices names both files.
  const auto dir = testing::ScratchDir("mhclo-truncated");
  const auto src = ClothesDir() / "short04";
  std::ifstream in(src / "short04.mhclo");
  std::string line, cut;
  int n = 0;
  while (std::getline(in, line) && n < 300) {
    cut += line + "\n";
    if (line.rfind("verts", 0) == 0 || n > 0) ++n;
  }
  std::ofstream(dir / "short04.mhclo") << cut;
  fs::copy_file(src / "short04.obj", dir / "short04.obj");
  auto p = LoadMhclo(dir / "short04.mhclo", Kit().base_vertex_count());
  REQUIRE_FALSE(p.ok());
  CHECK_THAT(p.status().message(), Catch::Contains("short04.mhclo") && Catch::Contains("short04.obj") &&
                                       Catch::Contains("truncated"));
  fs::remove_all(dir);
}

TEST_CASE("all 26 MakeHuman proxies load and fit the bodies closely", "[unit][data]") {
  // 26 asset folders, 27 proxies: fedora01 holds two (fedora, fedora_cocked).
  const MakeHumanWardrobe& w = Wardrobe();
  CHECK(w.size() == 27);
  CHECK(w.outfits.size() == 12);
  CHECK(w.hair.size() == 10);
  CHECK(w.hats.size() == 2);
  CHECK(w.shoes.size() == 3);
  // Fitted to a neutral body and to two extreme ones, every proxy lies near the body: most
  // vertices within a few cm; long hair, the skirt and the hat brim further.
  MakeHumanParams child = MakeHumanPresets()[0], heavy = MakeHumanPresets()[12];
  for (const MakeHumanParams& params : {MakeHumanParams{}, child, heavy}) {
    std::vector<const MhcloProxy*> all;
    for (const auto* list : {&w.outfits, &w.hair, &w.hats, &w.shoes})
      for (const auto& p : *list) all.push_back(p.get());
    auto dressed = Kit().BuildDressed(params, all);
    REQUIRE(dressed.ok());
    REQUIRE(dressed->proxies.size() == all.size());
    for (size_t i = 0; i < all.size(); ++i) {
      const FittedProxy& f = dressed->proxies[i];
      INFO(params.name << " / " << f.name);
      const auto d = DistanceToBody(dressed->body, f.vertices);
      const float median = Percentile(d, 0.5), p90 = Percentile(d, 0.9), max = Percentile(d, 1.0);
      const bool loose = f.name == "long01" || f.name == "ponytail01" || f.name == "braid01" ||
                         f.name.rfind("fedora", 0) == 0 || f.name == "female_elegantsuit01";
      CHECK(median < (loose ? 0.06f : 0.035f));
      CHECK(p90 < (loose ? 0.15f : 0.06f));
      CHECK(max < 0.35f);
    }
  }
}

TEST_CASE("sampled MakeHuman bodies are deterministic and varied", "[unit][data]") {
  // The parameters: deterministic in the stream, spread over the population.
  std::vector<MakeHumanParams> params;
  for (uint64_t k = 0; k < 400; ++k) {
    core::RngStream rng(core::CounterRng(7, 0xB0D1E5, k, 0));
    params.push_back(SampleMakeHumanParams(rng));
    core::RngStream again(core::CounterRng(7, 0xB0D1E5, k, 0));
    const MakeHumanParams b = SampleMakeHumanParams(again);
    CHECK(b.age == params.back().age);
    CHECK(b.height_scale == params.back().height_scale);
  }
  int children = 0, old = 0, thin = 0, heavy = 0, female = 0, male = 0;
  for (const auto& p : params) {
    CHECK(p.gender >= 0);
    CHECK(p.gender <= 1);
    CHECK(p.muscle >= 0);
    CHECK(p.muscle <= 1);
    children += p.age < MakeHumanAgeFromYears(13);
    old += p.age > MakeHumanAgeFromYears(65);
    thin += p.weight < 0.25;
    heavy += p.weight > 0.75;
    female += p.gender < 0.2;
    male += p.gender > 0.8;
  }
  CHECK(children > 20);
  CHECK(children < 90);
  CHECK(old > 30);
  CHECK(thin > 20);
  CHECK(heavy > 20);
  CHECK(female > 120);
  CHECK(male > 120);

  // The bodies: the same options give identical vertices; heights and widths spread.
  MakeHumanBodyOptions options;
  options.sampled_bodies = 6;
  options.seed = 3;
  const auto t0 = std::chrono::steady_clock::now();
  auto a = MakeHumanBodies(KitDir(), options);
  const double seconds = Seconds(t0);
  REQUIRE(a.ok());
  std::printf("18 presets + 6 sampled MakeHuman bodies: %.2f s\n", seconds);
  auto b = MakeHumanBodies(KitDir(), options);
  REQUIRE(b.ok());
  REQUIRE(a->size() == 24);
  double hmin = 9, hmax = 0, wmin = 9, wmax = 0;
  for (size_t i = 0; i < a->size(); ++i) {
    CHECK((*a)[i].vertices == (*b)[i].vertices);
    CHECK((*a)[i].part == (*b)[i].part);
    if (i < 18) continue;
    const double h = BodyHeight((*a)[i]), w = WaistWidth((*a)[i]) / h;
    hmin = std::min(hmin, h), hmax = std::max(hmax, h), wmin = std::min(wmin, w), wmax = std::max(wmax, w);
    CHECK(h > 1.1);
    CHECK(h < 2.1);
  }
  CHECK(hmax - hmin > 0.12);
  CHECK(wmax / wmin > 1.1);
  options.seed = 4;
  auto c = MakeHumanBodies(KitDir(), options);
  REQUIRE(c.ok());
  CHECK((*c)[18].vertices != (*a)[18].vertices);
  CHECK((*c)[0].vertices == (*a)[0].vertices);  // the presets stay as they are
}

TEST_CASE("a clothed body's vertex, skin and part arrays are consistent", "[unit][data]") {
  MakeHumanBodyOptions options;
  options.sampled_bodies = 2;
  options.seed = 11;
  options.clothed_share = 1.0;
  options.clothes_dir = ClothesDir();
  const auto t0 = std::chrono::steady_clock::now();
  auto bodies = MakeHumanBodies(KitDir(), options);
  std::printf("18 presets + 2 sampled MakeHuman bodies, all clothed: %.2f s\n", Seconds(t0));
  INFO(bodies.status().ToString());
  REQUIRE(bodies.ok());
  auto naked = MakeHumanBodies(KitDir(), MakeHumanBodyOptions{2, 11, 0.0, {}});
  REQUIRE(naked.ok());
  std::set<std::string> worn;
  for (size_t i = 0; i < bodies->size(); ++i) {
    const BodyMesh& b = (*bodies)[i];
    INFO(b.name);
    REQUIRE(b.skin.size() == b.vertices.size());
    REQUIRE(b.part.size() == b.vertices.size());
    CHECK(b.name.find('+') != std::string::npos);  // every body wears something
    size_t bad = 0;
    for (const auto& t : b.triangles)
      for (uint32_t v : t) bad += v >= b.vertices.size();
    CHECK(bad == 0);
    for (const auto& s : b.skin) {
      float sum = 0;
      for (int k = 0; k < 4; ++k) sum += s.weight[size_t(k)], bad += s.joint[size_t(k)] >= kNumSkelJoints;
      bad += std::abs(sum - 1.f) > 1e-4f;
    }
    CHECK(bad == 0);
    for (uint8_t p : b.part) bad += p >= core::kNumParts;
    CHECK(bad == 0);
    CHECK(b.vertices.size() > (*naked)[i].vertices.size());
    // Same skeleton as the naked body (clothes do not move joints); soles on the floor.
    float min_y = 1e9f;
    for (const auto& v : b.vertices) min_y = std::min(min_y, v.y());
    CHECK(std::abs(min_y) < 1e-5f);
    const double dy = b.rest_joints[0].y() - (*naked)[i].rest_joints[0].y();
    CHECK(dy >= -1e-6);
    CHECK(dy < 0.03);
    for (size_t name_at = b.name.find('+'); name_at != std::string::npos; name_at = b.name.find('+', name_at + 1))
      worn.insert(b.name.substr(name_at + 1, b.name.find('+', name_at + 1) - name_at - 1));
  }
  CHECK(worn.size() >= 10);  // outfits, hairstyles and shoes of several kinds

  // Clothes take the part of the body beneath: on a dressed adult, the head's proxies (hair)
  // are head parts and the shoes are feet or ankles.
  std::vector<const MhcloProxy*> outfit;
  for (const auto& p : Wardrobe().hair)
    if (p->name == "short02") outfit.push_back(p.get());
  for (const auto& p : Wardrobe().shoes)
    if (p->name == "shoes02") outfit.push_back(p.get());
  for (const auto& p : Wardrobe().outfits)
    if (p->name == "male_casualsuit04") outfit.push_back(p.get());
  REQUIRE(outfit.size() == 3);
  auto dressed = Kit().BuildDressed(MakeHumanPresets()[11], outfit);
  REQUIRE(dressed.ok());
  size_t covered = 0;
  for (char c : dressed->covered) covered += c != 0;
  CHECK(covered > 2000);  // the suit's (the shoes' are not used)
  const DressedMakeHuman parts_of = *dressed;  // the proxies' body vertices and skin, kept
  const BodyMesh hidden = AssembleDressedBody(*dressed, /*hide_covered_skin=*/true);
  const BodyMesh mesh = AssembleDressedBody(std::move(dressed).value());
  CHECK(hidden.triangles.size() + 2000 < mesh.triangles.size());
  using core::Part;
  auto is_head = [](uint8_t p) {
    return p == uint8_t(Part::kLUHead) || p == uint8_t(Part::kRUHead) || p == uint8_t(Part::kLWHead) ||
           p == uint8_t(Part::kRWHead) || p == uint8_t(Part::kNeck);
  };
  auto is_foot = [](uint8_t p) {
    return p == uint8_t(Part::kLFoot) || p == uint8_t(Part::kRFoot) || p == uint8_t(Part::kLAnkle) ||
           p == uint8_t(Part::kRAnkle);
  };
  // Body vertices keep their indices in the assembled mesh; proxies come after the body.
  const FittedProxy& hair = parts_of.proxies[0];
  const FittedProxy& shoes = parts_of.proxies[1];
  const FittedProxy& suit = parts_of.proxies[2];
  size_t hair_head = 0, shoe_foot = 0;
  for (uint32_t b : hair.body_vertex) hair_head += is_head(mesh.part[b]);
  for (uint32_t b : shoes.body_vertex) shoe_foot += is_foot(mesh.part[b]);
  CHECK(double(hair_head) > 0.97 * double(hair.vertices.size()));
  CHECK(double(shoe_foot) > 0.9 * double(shoes.vertices.size()));  // the rest: lower leg at the top
  // The suit's skin follows the body: its sleeves' vertices follow the arm joints.
  size_t arm = 0;
  for (const auto& s : suit.skin) {
    const int j = s.joint[0];
    arm += j == int(SkelJoint::kLShoulder) || j == int(SkelJoint::kLElbow) || j == int(SkelJoint::kRShoulder) ||
           j == int(SkelJoint::kRElbow);
  }
  CHECK(arm > suit.vertices.size() / 20);
  // The assembled mesh holds every proxy vertex (more where outfit and shoe boundaries were refined).
  CHECK(mesh.vertices.size() >= parts_of.body.vertices.size() + hair.vertices.size() + shoes.vertices.size() +
                                     suit.vertices.size());
}

TEST_CASE("building sampled bodies: start-up cost", "[unit][data][.timing]") {
  for (int n : {0, 20}) {
    for (double clothed : {0.0, 1.0}) {
      MakeHumanBodyOptions options{n, 1, clothed, ClothesDir()};
      const auto t0 = std::chrono::steady_clock::now();
      auto bodies = MakeHumanBodies(KitDir(), options);
      REQUIRE(bodies.ok());
      size_t tris = 0;
      for (const auto& b : *bodies) tris += b.triangles.size();
      std::printf("18 presets + %d sampled, clothed share %.1f: %.2f s, %.0f k triangles per body\n", n, clothed,
                  Seconds(t0), double(tris) / 1000.0 / double(bodies->size()));
    }
  }
}
