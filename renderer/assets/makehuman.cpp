#include "renderer/assets/makehuman.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <unordered_map>

#include "renderer/assets/text_scan.h"
#include "runtime/core/forest_format.h"

namespace poseforest::renderer::assets {
namespace {

using text::ForEachLine;
using text::ParseNum;
using text::Words;

using core::ErrorCode;
using core::Result;
using core::Status;

constexpr double kDecimetre = 0.1;

Result<std::string> ReadFile(const std::filesystem::path& path) {
  auto bytes = core::ReadFileBytes(path.string());
  if (!bytes.ok()) return bytes.status();
  return std::string(bytes->begin(), bytes->end());
}

// ordered_json: bones keep the order of the file (their indices are the skinning's bone ids).
using Json = nlohmann::ordered_json;

/// `text` as JSON; DataLoss naming `source` and the parser's byte offset.
Result<Json> ParseJson(const std::string& text, const std::string& source) {
  try {
    return Json::parse(text);
  } catch (const Json::parse_error& e) {
    return Status(ErrorCode::kDataLoss,
                  source + ": JSON error at byte " + std::to_string(e.byte) + ": " + e.what());
  }
}

struct Target {
  std::vector<uint32_t> index;
  std::vector<Eigen::Vector3f> delta;
};

}  // namespace

struct MakeHumanKit::Impl {
  std::filesystem::path dir;
  std::vector<Eigen::Vector3f> base;               // all base.obj vertices, decimetres
  std::vector<uint32_t> body_vertices;             // compact index -> base index
  std::vector<std::array<uint32_t, 3>> triangles;  // compact indices
  struct Bone {
    std::string name, head, tail, parent;
  };
  std::vector<Bone> bones;
  std::unordered_map<std::string, std::vector<uint32_t>> joints;  // joint name -> base vertices
  RigWeights weights;                                             // per compact vertex (bone index, w)
  RigWeights all_weights;                                         // per base vertex (proxy skinning)
  std::vector<int> compact;                                       // base index -> compact index or -1

  // Per base vertex: the nearest body vertex (compact index) in the neutral mesh; computed on the
  // first dressed build (proxies bind mostly to helper vertices, which have no part of their own).
  mutable std::once_flag anchor_once;
  mutable std::vector<uint32_t> anchor;

  const std::vector<uint32_t>& Anchors() const {
    std::call_once(anchor_once, [&] {
      anchor.assign(base.size(), 0);
      for (size_t i = 0; i < base.size(); ++i) {
        if (compact[i] >= 0) {
          anchor[i] = uint32_t(compact[i]);
          continue;
        }
        float best = std::numeric_limits<float>::infinity();
        uint32_t best_c = 0;
        for (size_t c = 0; c < body_vertices.size(); ++c) {
          const float d = (base[body_vertices[c]] - base[i]).squaredNorm();
          if (d < best) best = d, best_c = uint32_t(c);
        }
        anchor[i] = best_c;
      }
    });
    return anchor;
  }

  mutable std::mutex mu;
  mutable std::map<std::string, std::shared_ptr<const Target>> targets;

  Result<std::shared_ptr<const Target>> GetTarget(const std::string& name) const {
    {
      std::lock_guard<std::mutex> lock(mu);
      auto it = targets.find(name);
      if (it != targets.end()) return it->second;
    }
    const auto path = dir / "targets" / "macrodetails" / (name + ".target");
    auto text = ReadFile(path);
    if (!text.ok()) return text.status();
    auto t = std::make_shared<Target>();
    Status err;
    ForEachLine(*text, [&](std::string_view line, int line_no) {
      const auto w = Words(line);
      if (w.empty() || w[0].front() == '#') return true;
      double v[4];
      if (w.size() != 4 || !ParseNum(w[0], &v[0]) || !ParseNum(w[1], &v[1]) || !ParseNum(w[2], &v[2]) ||
          !ParseNum(w[3], &v[3]) || v[0] < 0 || v[0] >= double(base.size()) || v[0] != std::floor(v[0])) {
        err =
            Status(ErrorCode::kDataLoss, path.string() + ":" + std::to_string(line_no) +
                                             ": expected 'vertexIndex dx dy dz' with a vertex index below " +
                                             std::to_string(base.size()));
        return false;
      }
      t->index.push_back(uint32_t(v[0]));
      t->delta.emplace_back(float(v[1]), float(v[2]), float(v[3]));
      return true;
    });
    if (!err.ok()) return err;
    std::lock_guard<std::mutex> lock(mu);
    targets[name] = t;
    return std::shared_ptr<const Target>(t);
  }
};

MakeHumanKit::MakeHumanKit() : impl_(std::make_unique<Impl>()) {}
MakeHumanKit::~MakeHumanKit() = default;
size_t MakeHumanKit::body_vertex_count() const { return impl_->body_vertices.size(); }

namespace {

using Impl = MakeHumanKit::Impl;

// base.obj: all vertices, faces of group `body`.
Status LoadBaseMesh(const std::filesystem::path& kit_dir, Impl& m) {
  const auto obj_path = kit_dir / "base.obj";
  auto obj = ReadFile(obj_path);
  if (!obj.ok()) return obj.status();
  std::vector<std::vector<uint32_t>> faces;
  std::string group;
  Status err;
  ForEachLine(*obj, [&](std::string_view line, int line_no) {
    if (line.size() < 2) return true;
    auto bad = [&](const std::string& what) {
      err = Status(ErrorCode::kDataLoss, obj_path.string() + ":" + std::to_string(line_no) + ": " + what);
      return false;
    };
    if (line[0] == 'v' && line[1] == ' ') {
      const auto w = Words(line);
      double x, y, z;
      if (w.size() < 4 || !ParseNum(w[1], &x) || !ParseNum(w[2], &y) || !ParseNum(w[3], &z))
        return bad("bad vertex line");
      m.base.emplace_back(float(x), float(y), float(z));
    } else if (line[0] == 'g' && line[1] == ' ') {
      const auto w = Words(line);
      group = w.size() > 1 ? std::string(w[1]) : "";
    } else if (line[0] == 'f' && line[1] == ' ' && group == "body") {
      const auto w = Words(line);
      std::vector<uint32_t> f;
      for (size_t k = 1; k < w.size(); ++k) {
        const std::string_view idx = w[k].substr(0, w[k].find('/'));
        double v;
        if (!ParseNum(idx, &v) || v == 0 || v != std::floor(v)) return bad("bad face index");
        const long i = v > 0 ? long(v) - 1 : long(m.base.size()) + long(v);
        if (i < 0 || i >= long(m.base.size())) return bad("face index out of range");
        f.push_back(uint32_t(i));
      }
      if (f.size() < 3) return bad("face with fewer than 3 vertices");
      faces.push_back(std::move(f));
    }
    return true;
  });
  if (!err.ok()) return err;
  if (faces.empty()) return Status(ErrorCode::kDataLoss, obj_path.string() + ": no faces in group 'body'");
  m.compact.assign(m.base.size(), -1);
  std::vector<int>& compact = m.compact;
  for (const auto& f : faces)
    for (uint32_t i : f)
      if (compact[i] < 0) {
        compact[i] = int(m.body_vertices.size());
        m.body_vertices.push_back(i);
      }
  for (const auto& f : faces)
    for (size_t k = 1; k + 1 < f.size(); ++k)
      m.triangles.push_back({uint32_t(compact[f[0]]), uint32_t(compact[f[k]]), uint32_t(compact[f[k + 1]])});
  return Status::Ok();
}

// rigs/default.mhskel: the joints (vertex lists) and bones (head and tail joints).
Status LoadSkeleton(const std::filesystem::path& kit_dir, Impl& m) {
  const auto skel_path = kit_dir / "rigs" / "default.mhskel";
  auto skel_text = ReadFile(skel_path);
  if (!skel_text.ok()) return skel_text.status();
  auto skel = ParseJson(*skel_text, skel_path.string());
  if (!skel.ok()) return skel.status();
  const auto bones = skel->find("bones"), joints = skel->find("joints");
  if (bones == skel->end() || !bones->is_object() || joints == skel->end() || !joints->is_object())
    return Status(ErrorCode::kDataLoss, skel_path.string() + ": missing 'bones' or 'joints'");
  for (const auto& [name, jv] : joints->items()) {
    if (!jv.is_array() || jv.empty())
      return Status(ErrorCode::kDataLoss, skel_path.string() + ": joint '" + name + "' has no vertex list");
    std::vector<uint32_t> idx;
    for (const auto& e : jv) {
      if (!e.is_number() || !(e.get<double>() >= 0 && e.get<double>() < double(m.base.size())))
        return Status(ErrorCode::kDataLoss,
                      skel_path.string() + ": joint '" + name + "' names a vertex out of range");
      idx.push_back(uint32_t(e.get<double>()));
    }
    m.joints[name] = std::move(idx);
  }
  auto string_member = [](const Json& v, const char* key) -> const std::string* {
    if (!v.is_object()) return nullptr;
    const auto it = v.find(key);
    return it != v.end() && it->is_string() ? it->get_ptr<const std::string*>() : nullptr;
  };
  for (const auto& [name, bv] : bones->items()) {
    const std::string* head = string_member(bv, "head");
    const std::string* tail = string_member(bv, "tail");
    const std::string* parent = string_member(bv, "parent");
    if (!head || !tail || !m.joints.count(*head) || !m.joints.count(*tail))
      return Status(ErrorCode::kDataLoss,
                    skel_path.string() + ": bone '" + name + "' has no valid head/tail joint");
    m.bones.push_back({name, *head, *tail, parent ? *parent : ""});
  }
  return Status::Ok();
}

// rigs/default_weights.mhw: the skinning weights, per body vertex and per base vertex.
Status LoadWeights(const std::filesystem::path& kit_dir, Impl& m) {
  const std::vector<int>& compact = m.compact;
  const auto mhw_path = kit_dir / "rigs" / "default_weights.mhw";
  auto mhw_text = ReadFile(mhw_path);
  if (!mhw_text.ok()) return mhw_text.status();
  auto mhw = ParseJson(*mhw_text, mhw_path.string());
  if (!mhw.ok()) return mhw.status();
  const auto weights = mhw->find("weights");
  if (weights == mhw->end() || !weights->is_object())
    return Status(ErrorCode::kDataLoss, mhw_path.string() + ": missing 'weights'");
  m.weights.assign(m.body_vertices.size(), {});
  m.all_weights.assign(m.base.size(), {});
  for (const auto& [bone, list] : weights->items()) {
    int b = -1;
    for (size_t k = 0; k < m.bones.size(); ++k)
      if (m.bones[k].name == bone) b = int(k);
    if (b < 0)
      return Status(ErrorCode::kDataLoss, mhw_path.string() + ": weights for unknown bone '" + bone + "'");
    if (!list.is_array())
      return Status(ErrorCode::kDataLoss, mhw_path.string() + ": bone '" + bone + "': not a list");
    for (const auto& pair : list) {
      if (!pair.is_array() || pair.size() != 2 || !pair[0].is_number() || !pair[1].is_number() ||
          !(pair[0].get<double>() >= 0 && pair[0].get<double>() < double(m.base.size())))
        return Status(ErrorCode::kDataLoss,
                      mhw_path.string() + ": bone '" + bone + "': bad [vertex, weight] pair");
      const int c = compact[size_t(pair[0].get<double>())];
      if (pair[1].get<double>() > 0) {
        if (c >= 0) m.weights[size_t(c)].push_back({b, float(pair[1].get<double>())});
        m.all_weights[size_t(pair[0].get<double>())].push_back({b, float(pair[1].get<double>())});
      }
    }
  }
  return Status::Ok();
}

}  // namespace

Result<std::unique_ptr<MakeHumanKit>> MakeHumanKit::Load(const std::filesystem::path& kit_dir) {
  std::unique_ptr<MakeHumanKit> kit(new MakeHumanKit());
  Impl& m = *kit->impl_;
  m.dir = kit_dir;
  POSEFOREST_RETURN_IF_ERROR(LoadBaseMesh(kit_dir, m));
  POSEFOREST_RETURN_IF_ERROR(LoadSkeleton(kit_dir, m));
  POSEFOREST_RETURN_IF_ERROR(LoadWeights(kit_dir, m));
  return kit;
}

Result<BodyMesh> MakeHumanKit::Build(const MakeHumanParams& p) const {
  auto dressed = BuildDressed(p, {});
  if (!dressed.ok()) return dressed.status();
  return std::move(dressed->body);
}

size_t MakeHumanKit::base_vertex_count() const { return impl_->base.size(); }

namespace {

// The proxies bind to vertices of this kit, and the macro values are in range.
Status CheckDressInputs(const Impl& m, const MakeHumanParams& p,
                        const std::vector<const MhcloProxy*>& proxies) {
  for (const MhcloProxy* proxy : proxies) {
    POSEFOREST_CHECK(proxy != nullptr);
    for (const auto& r : proxy->ref)
      for (uint32_t i : r)
        if (i >= m.base.size())  // LoadMhclo checks against base_vertex_count(); another kit may differ
          return Status(ErrorCode::kInvalidArgument,
                        proxy->source + ": binds base vertex " + std::to_string(i) + " but " +
                            (m.dir / "base.obj").string() + " has " + std::to_string(m.base.size()));
  }
  for (double v : {p.gender, p.age, p.muscle, p.weight})
    if (!(v >= 0 && v <= 1))
      return Status(ErrorCode::kInvalidArgument,
                    "MakeHuman body '" + p.name + "': macro values must be in [0, 1]");
  if (!(p.height_scale > 0.3 && p.height_scale < 3))
    return Status(ErrorCode::kInvalidArgument, "MakeHuman body '" + p.name + "': height_scale out of range");
  return Status::Ok();
}

// Macro modifier weights: the macro targets and their weights for `p`.
std::vector<std::pair<std::string, double>> MacroTargets(const MakeHumanParams& p) {
  const std::pair<const char*, double> gender[] = {{"female", 1 - p.gender}, {"male", p.gender}};
  double baby = 0, child = 0, young = 0, old = 0;
  if (p.age < 0.5) {
    baby = std::max(0.0, 1 - p.age / 0.1875);
    young = std::max(0.0, (p.age - 0.1875) / 0.3125);
    child = std::max(0.0, std::min(1.0, p.age / 0.1875) - young);
  } else {
    old = 2 * p.age - 1;
    young = 1 - old;
  }
  const std::pair<const char*, double> age[] = {
      {"baby", baby}, {"child", child}, {"young", young}, {"old", old}};
  auto three = [](double x) {
    const double mn = std::max(0.0, 1 - 2 * x), mx = std::max(0.0, 2 * x - 1);
    return std::array<double, 3>{mn, 1 - mn - mx, mx};
  };
  const auto mus = three(p.muscle), wei = three(p.weight);
  const char* levels[] = {"min", "average", "max"};
  std::vector<std::pair<std::string, double>> use;
  for (const auto& [g, gw] : gender)
    for (const auto& [a, aw] : age) {
      if (gw * aw < 1e-6) continue;
      for (const char* race : {"african", "asian", "caucasian"})
        use.push_back({std::string(race) + "-" + g + "-" + a, gw * aw / 3.0});
      for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) {
          const double w = gw * aw * mus[size_t(i)] * wei[size_t(k)];
          if (w < 1e-6) continue;
          use.push_back(
              {std::string("universal-") + g + "-" + a + "-" + levels[i] + "muscle-" + levels[k] + "weight",
               w});
        }
    }
  return use;
}

// The rig at the morphed vertices `pos` (decimetres, times `scale`), folded to our skeleton.
Result<FoldedRig> MorphedRig(const Impl& m, const std::vector<Eigen::Vector3f>& pos, double scale) {
  auto joint_pos = [&](const std::string& joint) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    const auto& idx = m.joints.at(joint);
    for (uint32_t i : idx) s += pos[i].cast<double>();
    return Eigen::Vector3d(s / double(idx.size()) * scale);
  };
  std::vector<RigBone> bones(m.bones.size());
  for (size_t b = 0; b < m.bones.size(); ++b) {
    bones[b].name = m.bones[b].name;
    bones[b].head = joint_pos(m.bones[b].head);
    bones[b].tail = joint_pos(m.bones[b].tail);
    bones[b].has_tail = true;
    for (size_t k = 0; k < m.bones.size(); ++k)
      if (m.bones[k].name == m.bones[b].parent) bones[b].parent = int(k);
  }
  const std::string source = (m.dir / "rigs" / "default.mhskel").string();
  return FoldRig(bones, source);
}

// One proxy fitted to the morphed body, scaled, and skinned from the base vertices it binds to;
// `min_y` is lowered to its lowest vertex. Marks the body vertices it covers in `covered`.
FittedProxy FitDressProxy(const Impl& m, const MhcloProxy* proxy, const std::vector<Eigen::Vector3f>& pos,
                          double scale, const FoldedRig& rig, const std::vector<uint32_t>& anchor,
                          float& min_y, std::vector<char>& covered) {
  constexpr float kWeightThreshold = 1e-4f;  // MakeHuman's Proxy.getVertexWeights
  FittedProxy f;
  f.name = proxy->name;
  f.kind = proxy->kind;
  f.vertices = FitProxy(*proxy, pos);
  for (auto& v : f.vertices) {
    v = (v.cast<double>() * scale).cast<float>();
    min_y = std::min(min_y, v.y());
  }
  f.triangles = proxy->triangles;
  RigWeights w(f.vertices.size());
  f.body_vertex.resize(f.vertices.size());
  std::vector<float> acc(m.bones.size());
  for (size_t k = 0; k < f.vertices.size(); ++k) {
    std::fill(acc.begin(), acc.end(), 0.f);
    int heaviest = 0;
    for (int r = 0; r < 3; ++r) {
      const float wr = proxy->weight[k][size_t(r)];
      if (wr > proxy->weight[k][size_t(heaviest)]) heaviest = r;
      for (const auto& [bone, bw] : m.all_weights[proxy->ref[k][size_t(r)]])
        if (wr * bw > kWeightThreshold) acc[size_t(bone)] += wr * bw;
    }
    for (size_t b = 0; b < acc.size(); ++b)
      if (acc[b] > 0) w[k].push_back({int(b), acc[b]});
    f.body_vertex[k] = anchor[proxy->ref[k][size_t(heaviest)]];
  }
  f.skin = FoldSkin(rig, w, f.vertices);
  // Shoes' delete_verts take the whole foot, but the soles do not cover the heel's lower
  // edge seen from behind: hidden feet would leave holes, and feet inside shoes do not show.
  if (proxy->kind != ProxyKind::kShoes)
    for (uint32_t i : proxy->delete_verts)
      if (i < m.compact.size() && m.compact[i] >= 0) covered[size_t(m.compact[i])] = 1;
  return f;
}

}  // namespace

Result<DressedMakeHuman> MakeHumanKit::BuildDressed(const MakeHumanParams& p,
                                                    const std::vector<const MhcloProxy*>& proxies) const {
  const Impl& m = *impl_;
  POSEFOREST_RETURN_IF_ERROR(CheckDressInputs(m, p, proxies));
  const std::vector<std::pair<std::string, double>> use = MacroTargets(p);
  std::vector<Eigen::Vector3f> pos = m.base;
  for (const auto& [name, w] : use) {
    auto t = m.GetTarget(name);
    if (!t.ok()) return t.status();
    const Target& tg = **t;
    for (size_t k = 0; k < tg.index.size(); ++k) pos[tg.index[k]] += float(w) * tg.delta[k];
  }
  const double scale = kDecimetre * p.height_scale;

  auto rig = MorphedRig(m, pos, scale);
  if (!rig.ok()) return rig.status();

  DressedMakeHuman out;
  BodyMesh& body = out.body;
  body.name = "makehuman:" + p.name;
  body.vertices.reserve(m.body_vertices.size());
  for (uint32_t i : m.body_vertices) body.vertices.push_back((pos[i].cast<double>() * scale).cast<float>());
  body.triangles = m.triangles;
  body.skin = FoldSkin(*rig, m.weights, body.vertices);
  EstimateMissingJoints(*rig, body.vertices, body.skin);
  body.rest_joints = rig->rest_joints;
  out.covered.assign(body.vertices.size(), 0);
  if (proxies.empty()) {
    PlaceOnFloor(&body);
    return out;
  }

  const std::vector<uint32_t>& anchor = m.Anchors();
  float min_y = std::numeric_limits<float>::infinity();
  for (const auto& v : body.vertices) min_y = std::min(min_y, v.y());
  for (const MhcloProxy* proxy : proxies)
    out.proxies.push_back(FitDressProxy(m, proxy, pos, scale, *rig, anchor, min_y, out.covered));
  // PlaceOnFloor, with the shoes' soles (below the feet) counted.
  const Eigen::Vector3d pelvis = body.rest_joints[size_t(SkelJoint::kPelvis)];
  const Eigen::Vector3f shift = Eigen::Vector3d(-pelvis.x(), -double(min_y), -pelvis.z()).cast<float>();
  for (auto& v : body.vertices) v += shift;
  for (auto& j : body.rest_joints) j += shift.cast<double>();
  for (FittedProxy& f : out.proxies)
    for (auto& v : f.vertices) v += shift;
  return out;
}

}  // namespace poseforest::renderer::assets
