// Bodies: MakeHuman hm08 presets and Assimp rigged meshes as canonical BodyMesh values.

#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "renderer/assets/makehuman.h"
#include "renderer/assets/mesh_loader.h"
#include "renderer/assets/retarget.h"
#include "runtime/core/rng.h"
#include "tests/support/paths.h"

using namespace poseforest::renderer;
using namespace poseforest::renderer::assets;
using poseforest::core::ErrorCode;
namespace fs = std::filesystem;

namespace {

fs::path Meshes() { return poseforest::testing::DataDir() / "meshes"; }

Eigen::Vector3d J(const BodyMesh& b, SkelJoint j) { return b.rest_joints[size_t(int(j))]; }

// Structural checks every canonical body must pass.
void CheckBody(const BodyMesh& b) {
  REQUIRE(!b.vertices.empty());
  REQUIRE(b.skin.size() == b.vertices.size());
  CHECK(b.part.empty());
  size_t bad_index = 0;
  for (const auto& t : b.triangles)
    for (uint32_t i : t) bad_index += i >= b.vertices.size();
  CHECK(bad_index == 0);
  size_t bad_weights = 0;
  for (const auto& s : b.skin) {
    float sum = 0;
    for (int k = 0; k < 4; ++k) {
      sum += s.weight[size_t(k)];
      if (s.weight[size_t(k)] < 0 || s.joint[size_t(k)] >= kNumSkelJoints) ++bad_weights;
    }
    if (std::abs(sum - 1.f) > 1e-4f) ++bad_weights;
  }
  CHECK(bad_weights == 0);
  // Canonical frame: Y up, faces +Z, left = +X, feet on y = 0, pelvis above the origin.
  CHECK(J(b, SkelJoint::kHead).y() > J(b, SkelJoint::kPelvis).y() + 0.3);
  CHECK(J(b, SkelJoint::kPelvis).y() > J(b, SkelJoint::kLAnkle).y() + 0.3);
  CHECK(J(b, SkelJoint::kLShoulder).x() > 0.05);
  CHECK(J(b, SkelJoint::kRShoulder).x() < -0.05);
  CHECK(J(b, SkelJoint::kLHip).x() > 0.02);
  CHECK(J(b, SkelJoint::kLWrist).x() > J(b, SkelJoint::kLElbow).x());
  CHECK(J(b, SkelJoint::kLToe).z() > J(b, SkelJoint::kLAnkle).z());
  CHECK(J(b, SkelJoint::kRToe).z() > J(b, SkelJoint::kRAnkle).z());
  CHECK(std::abs(J(b, SkelJoint::kPelvis).x()) < 1e-6);
  float min_y = 1e9f;
  for (const auto& v : b.vertices) min_y = std::min(min_y, v.y());
  CHECK(std::abs(min_y) < 1e-5f);
  // The legs' weights land on the legs: vertices below the knees follow knee, ankle or toe.
  size_t shin = 0, shin_ok = 0;
  for (size_t v = 0; v < b.vertices.size(); ++v) {
    if (b.vertices[v].y() > 0.5 * J(b, SkelJoint::kLKnee).y() ||
        b.vertices[v].y() < J(b, SkelJoint::kLAnkle).y() + 0.03)
      continue;
    ++shin;
    const int j = b.skin[v].joint[0];
    if (j == int(SkelJoint::kLKnee) || j == int(SkelJoint::kRKnee) || j == int(SkelJoint::kLAnkle) ||
        j == int(SkelJoint::kRAnkle))
      ++shin_ok;
  }
  CHECK(shin > 10);
  CHECK(double(shin_ok) > 0.9 * double(shin));
}

std::string Base64(const std::vector<uint8_t>& in) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < in.size(); i += 3) {
    uint32_t v = uint32_t(in[i]) << 16;
    if (i + 1 < in.size()) v |= uint32_t(in[i + 1]) << 8;
    if (i + 2 < in.size()) v |= in[i + 2];
    out += t[(v >> 18) & 63];
    out += t[(v >> 12) & 63];
    out += i + 1 < in.size() ? t[(v >> 6) & 63] : '=';
    out += i + 2 < in.size() ? t[v & 63] : '=';
  }
  return out;
}

template <typename T>
void Put(std::vector<uint8_t>& b, T v) {
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  b.insert(b.end(), p, p + sizeof(T));
}

// A one-triangle glTF skinned to two joints with the given names.
std::string TinySkinnedGltf(const std::string& root, const std::string& child) {
  std::vector<uint8_t> buf;
  for (float f : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) Put(buf, f);  // 0: positions, 36 bytes
  for (int v = 0; v < 3; ++v)
    for (uint8_t j : {uint8_t(v == 2 ? 1 : 0), uint8_t(0), uint8_t(0), uint8_t(0)})
      Put(buf, j);  // 36: joints
  for (int v = 0; v < 3; ++v)
    for (float w : {1.f, 0.f, 0.f, 0.f}) Put(buf, w);                                   // 48: weights
  for (uint16_t i : {uint16_t(0), uint16_t(1), uint16_t(2), uint16_t(0)}) Put(buf, i);  // 96: indices (+pad)
  for (int k = 0; k < 2; ++k)                                                           // 104: IBMs
    for (int e = 0; e < 16; ++e) Put(buf, float(e % 5 == 0 ? 1 : (k == 1 && e == 13 ? -1 : 0)));
  std::ostringstream o;
  o << R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0,2]}],)"
    << R"("nodes":[{"name":")" << root << R"(","children":[1]},{"name":")" << child
    << R"(","translation":[0,1,0]},{"name":"mesh","mesh":0,"skin":0}],)"
    << R"("skins":[{"joints":[0,1],"inverseBindMatrices":4}],)"
    << R"("meshes":[{"primitives":[{"attributes":{"POSITION":0,"JOINTS_0":1,"WEIGHTS_0":2},"indices":3}]}],)"
    << R"("buffers":[{"byteLength":)" << buf.size() << R"(,"uri":"data:application/octet-stream;base64,)"
    << Base64(buf) << R"("}],)"
    << R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":12},)"
    << R"({"buffer":0,"byteOffset":48,"byteLength":48},{"buffer":0,"byteOffset":96,"byteLength":6},)"
    << R"({"buffer":0,"byteOffset":104,"byteLength":128}],)"
    << R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)"
    << R"({"bufferView":1,"componentType":5121,"count":3,"type":"VEC4"},)"
    << R"({"bufferView":2,"componentType":5126,"count":3,"type":"VEC4"},)"
    << R"({"bufferView":3,"componentType":5123,"count":3,"type":"SCALAR"},)"
    << R"({"bufferView":4,"componentType":5126,"count":2,"type":"MAT4"}]})";
  return o.str();
}

}  // namespace

TEST_CASE("MakeHuman presets: >= 15 bodies, child to heavy adult, canonical frame", "[makehuman][data]") {
  auto kit = MakeHumanKit::Load(Meshes() / "makehuman_hm08_kit");
  REQUIRE(kit.ok());
  CHECK((*kit)->body_vertex_count() == 13380);
  const auto& presets = MakeHumanPresets();
  REQUIRE(presets.size() >= 15);
  std::map<std::string, BodyMesh> bodies;
  for (const auto& p : presets) {
    auto b = (*kit)->Build(p);
    REQUIRE(b.ok());
    INFO(p.name);
    CHECK(b->name == "makehuman:" + p.name);
    CHECK(b->vertices.size() == 13380);
    CHECK(b->triangles.size() == 26756);
    CheckBody(*b);
    const double h = BodyHeight(*b);
    CHECK(h > 1.1);
    CHECK(h < 1.95);
    // The head top joint sits at the top of the head.
    CHECK(J(*b, SkelJoint::kHeadTop).y() == Approx(h).margin(0.08));
    bodies[p.name] = std::move(*b);
  }
  auto H = [&](const char* n) { return BodyHeight(bodies.at(n)); };
  auto W = [&](const char* n) { return WaistWidth(bodies.at(n)); };
  CHECK(H("girl-8") < H("girl-14"));
  CHECK(H("girl-14") < H("male-young-average"));
  CHECK(H("boy-8") + 0.3 < H("male-young-average"));
  CHECK(H("female-young-average") < H("male-young-average"));
  CHECK(W("female-young-heavy") > W("female-young-thin") + 0.02);
  CHECK(W("male-young-heavy") > W("male-young-thin") + 0.015);
  // Bone lengths scale with the body: a child's legs are shorter.
  CHECK(LegLength(bodies.at("boy-8").rest_joints) <
        0.8 * LegLength(bodies.at("male-young-average").rest_joints));
}

TEST_CASE("MakeHuman variation is small, deterministic and changes the body", "[makehuman][data]") {
  auto kit = MakeHumanKit::Load(Meshes() / "makehuman_hm08_kit");
  REQUIRE(kit.ok());
  const MakeHumanParams base = MakeHumanPresets()[7];
  poseforest::core::RngStream a{poseforest::core::CounterRng(3)}, b{poseforest::core::CounterRng(3)};
  for (int i = 0; i < 20; ++i) {
    const MakeHumanParams va = VaryMakeHuman(base, a), vb = VaryMakeHuman(base, b);
    CHECK(va.height_scale == vb.height_scale);
    CHECK(va.weight == vb.weight);
    CHECK(std::abs(va.height_scale / base.height_scale - 1) <= 0.08 + 1e-12);
    CHECK(va.weight >= 0);
    CHECK(va.weight <= 1);
  }
  poseforest::core::RngStream r{poseforest::core::CounterRng(9)};
  MakeHumanParams v = VaryMakeHuman(base, r);
  v.height_scale = base.height_scale * 1.05;
  auto b0 = (*kit)->Build(base);
  auto b1 = (*kit)->Build(v);
  REQUIRE(b0.ok());
  REQUIRE(b1.ok());
  CHECK(BodyHeight(*b1) == Approx(1.05 * BodyHeight(*b0)).epsilon(0.01));
  // Out-of-range parameters are refused.
  MakeHumanParams bad = base;
  bad.age = 1.5;
  auto e = (*kit)->Build(bad);
  REQUIRE_FALSE(e.ok());
  CHECK(e.status().code() == ErrorCode::kInvalidArgument);
}

TEST_CASE("MakeHuman kit errors name the file", "[makehuman]") {
  auto r = MakeHumanKit::Load("/nonexistent/kit");
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kNotFound);
  CHECK_THAT(r.status().message(), Catch::Contains("/nonexistent/kit/base.obj"));

  // A kit whose rig file is broken JSON, and one whose target file is malformed.
  const fs::path kit = Meshes() / "makehuman_hm08_kit";
  const fs::path dir = poseforest::testing::ScratchDir("mhkit");
  fs::create_directories(dir / "rigs");
  fs::create_directories(dir / "targets");
  fs::create_symlink(kit / "base.obj", dir / "base.obj");
  fs::create_symlink(kit / "rigs" / "default_weights.mhw", dir / "rigs" / "default_weights.mhw");
  std::ofstream(dir / "rigs" / "default.mhskel") << "{\"bones\": {\"root\": {\"head\": \"a\", }}";
  r = MakeHumanKit::Load(dir);
  REQUIRE_FALSE(r.ok());
  CHECK(r.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(r.status().message(), Catch::Contains("default.mhskel: JSON error at byte"));

  fs::remove(dir / "rigs" / "default.mhskel");
  fs::create_symlink(kit / "rigs" / "default.mhskel", dir / "rigs" / "default.mhskel");
  fs::create_directories(dir / "targets" / "macrodetails");
  for (const auto& e : fs::directory_iterator(kit / "targets" / "macrodetails"))
    fs::create_symlink(e.path(), dir / "targets" / "macrodetails" / e.path().filename());
  fs::remove(dir / "targets" / "macrodetails" / "caucasian-female-young.target");
  std::ofstream(dir / "targets" / "macrodetails" / "caucasian-female-young.target")
      << "# ok\n12 0.1 0.2 0.3\n99999999 1 2 3\n";
  auto ok_kit = MakeHumanKit::Load(dir);
  REQUIRE(ok_kit.ok());
  MakeHumanParams female;
  female.gender = 0;
  auto b = (*ok_kit)->Build(female);
  REQUIRE_FALSE(b.ok());
  CHECK(b.status().code() == ErrorCode::kDataLoss);
  CHECK_THAT(b.status().message(), Catch::Contains("caucasian-female-young.target:3:"));
  fs::remove_all(dir);
}

TEST_CASE("every staged rigged mesh loads as a canonical body", "[mesh][data]") {
  struct Case {
    const char* file;
    const char* family;
    double min_h, max_h;
  };
  for (const Case& c : {Case{"cesium_man/CesiumMan.glb", "cesium_man", 1.4, 1.6},
                        Case{"quaternius_casual_female/Casual_Female.gltf", "quaternius", 1.65, 1.75},
                        Case{"quaternius_modular_women/Adventurer.gltf", "quaternius", 1.75, 1.9},
                        Case{"quaternius_modular_women/Soldier.gltf", "quaternius", 1.75, 1.9},
                        Case{"makehuman_export_fbx/MakeHumanModel.fbx", "makehuman_default", 1.7, 1.85}}) {
    INFO(c.file);
    auto b = LoadRiggedMesh(Meshes() / c.file);
    REQUIRE(b.ok());
    CheckBody(*b);
    const double h = BodyHeight(*b);
    CHECK(h > c.min_h);
    CHECK(h < c.max_h);
    CHECK(b->triangles.size() > 1000);
    // Retargeting onto the mesh's own skeleton keeps its bone lengths.
    Pose pose;
    pose.rotation[size_t(int(SkelJoint::kLShoulder))] =
        Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitZ()));
    const auto posed = PoseJoints(b->rest_joints, pose);
    CHECK(LegLength(posed) == Approx(LegLength(b->rest_joints)));
  }
}

TEST_CASE("meshes that cannot be bodies give clear errors", "[mesh]") {
  const fs::path dir = poseforest::testing::ScratchDir("meshes");
  SECTION("a mesh without bones (OBJ)") {
    const fs::path obj = dir / "tri.obj";
    std::ofstream(obj) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    auto r = LoadRiggedMesh(obj);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kInvalidArgument);
    CHECK_THAT(r.status().message(), Catch::Contains(obj.string()) && Catch::Contains("no skinned mesh"));
  }
  SECTION("the staged MakeHuman m07 OBJ has no rig") {
    const fs::path obj = Meshes() / "makehuman_m07_pcl_bodypart_labels" / "base_m07.obj";
    auto r = LoadRiggedMesh(obj);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kInvalidArgument);
    CHECK_THAT(r.status().message(), Catch::Contains("base_m07.obj") && Catch::Contains("no skinned mesh"));
  }
  SECTION("file not found") {
    auto r = LoadRiggedMesh(dir / "missing.glb");
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kNotFound);
  }
  SECTION("unreadable file: Assimp's message is included") {
    const fs::path junk = dir / "junk.glb";
    std::ofstream(junk) << "this is not a mesh at all";
    auto r = LoadRiggedMesh(junk);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kIo);
    CHECK_THAT(r.status().message(), Catch::Contains(junk.string()) && Catch::Contains("Assimp"));
  }
  SECTION("unknown bone names are listed") {
    const fs::path g = dir / "odd.gltf";
    std::ofstream(g) << TinySkinnedGltf("Foo", "Bar");
    auto r = LoadRiggedMesh(g);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kInvalidArgument);
    CHECK_THAT(r.status().message(), Catch::Contains(g.string()) && Catch::Contains("Foo") &&
                                         Catch::Contains("Bar") && Catch::Contains("pelvis") &&
                                         Catch::Contains("L_elbow"));
  }
  SECTION("a rig with known names but not a humanoid") {
    const fs::path g = dir / "partial.gltf";
    std::ofstream(g) << TinySkinnedGltf("Hips", "Abdomen");
    auto r = LoadRiggedMesh(g);
    REQUIRE_FALSE(r.ok());
    CHECK(r.status().code() == ErrorCode::kInvalidArgument);
    CHECK_THAT(r.status().message(), Catch::Contains("closest map: quaternius") &&
                                         Catch::Contains("L_knee") && !Catch::Contains("pelvis ("));
  }
  fs::remove_all(dir);
}
