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

Result<std::unique_ptr<MakeHumanKit>> MakeHumanKit::Load(const std::filesystem::path& kit_dir) {
  std::unique_ptr<MakeHumanKit> kit(new MakeHumanKit());
  Impl& m = *kit->impl_;
  m.dir = kit_dir;

  // --- base.obj: all vertices, faces of group `body` ---
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

  // --- rigs/default.mhskel ---
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

  // --- rigs/default_weights.mhw ---
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
  return kit;
}

Result<BodyMesh> MakeHumanKit::Build(const MakeHumanParams& p) const {
  auto dressed = BuildDressed(p, {});
  if (!dressed.ok()) return dressed.status();
  return std::move(dressed->body);
}

size_t MakeHumanKit::base_vertex_count() const { return impl_->base.size(); }

Result<DressedMakeHuman> MakeHumanKit::BuildDressed(const MakeHumanParams& p,
                                                    const std::vector<const MhcloProxy*>& proxies) const {
  const Impl& m = *impl_;
  for (const MhcloProxy* proxy : proxies) {
    POSEFOREST_CHECK(proxy != nullptr);
    for (const auto& r : proxy->ref)
      for (uint32_t i : r)
        if (i >= m.base.size())  // LoadMhclo checks against base_vertex_count(); another kit may differ
          return Status(ErrorCode::kInvalidArgument, proxy->source + ": binds base vertex " + std::to_string(i) +
                                                         " but " + (m.dir / "base.obj").string() + " has " +
                                                         std::to_string(m.base.size()));
  }
  for (double v : {p.gender, p.age, p.muscle, p.weight})
    if (!(v >= 0 && v <= 1))
      return Status(ErrorCode::kInvalidArgument,
                    "MakeHuman body '" + p.name + "': macro values must be in [0, 1]");
  if (!(p.height_scale > 0.3 && p.height_scale < 3))
    return Status(ErrorCode::kInvalidArgument, "MakeHuman body '" + p.name + "': height_scale out of range");

  // Macro modifier weights.
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

  std::vector<Eigen::Vector3f> pos = m.base;
  for (const auto& [name, w] : use) {
    auto t = m.GetTarget(name);
    if (!t.ok()) return t.status();
    const Target& tg = **t;
    for (size_t k = 0; k < tg.index.size(); ++k) pos[tg.index[k]] += float(w) * tg.delta[k];
  }
  const double scale = kDecimetre * p.height_scale;

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
  auto rig = FoldRig(bones, source);
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
  constexpr float kWeightThreshold = 1e-4f;  // MakeHuman's Proxy.getVertexWeights
  float min_y = std::numeric_limits<float>::infinity();
  for (const auto& v : body.vertices) min_y = std::min(min_y, v.y());
  for (const MhcloProxy* proxy : proxies) {
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
    f.skin = FoldSkin(*rig, w, f.vertices);
    // Shoes' delete_verts take the whole foot, but the soles do not cover the heel's lower
    // edge seen from behind: hidden feet would leave holes, and feet inside shoes do not show.
    if (proxy->kind != ProxyKind::kShoes)
      for (uint32_t i : proxy->delete_verts)
        if (i < m.compact.size() && m.compact[i] >= 0) out.covered[size_t(m.compact[i])] = 1;
    out.proxies.push_back(std::move(f));
  }
  // PlaceOnFloor, with the shoes' soles (below the feet) counted.
  const Eigen::Vector3d pelvis = body.rest_joints[size_t(SkelJoint::kPelvis)];
  const Eigen::Vector3f shift = Eigen::Vector3d(-pelvis.x(), -double(min_y), -pelvis.z()).cast<float>();
  for (auto& v : body.vertices) v += shift;
  for (auto& j : body.rest_joints) j += shift.cast<double>();
  for (FittedProxy& f : out.proxies)
    for (auto& v : f.vertices) v += shift;
  return out;
}

double MakeHumanAgeFromYears(double years) {
  years = std::clamp(years, 1.0, 90.0);
  if (years < 11) return 0.1875 * (years - 1) / 10.0;
  if (years < 25) return 0.1875 + 0.3125 * (years - 11) / 14.0;
  return 0.5 + 0.5 * (years - 25) / 65.0;
}

const std::vector<MakeHumanParams>& MakeHumanPresets() {
  static const std::vector<MakeHumanParams> presets = [] {
    auto P = [](const char* name, double gender, double years, double muscle, double weight, double height) {
      MakeHumanParams p;
      p.name = name;
      p.gender = gender;
      p.age = MakeHumanAgeFromYears(years);
      p.muscle = muscle;
      p.weight = weight;
      p.height_scale = height;
      return p;
    };
    return std::vector<MakeHumanParams>{
        // MakeHuman's child targets without its height modifier come out short for their age,
        // so children get a height_scale towards typical heights (~1.28, 1.45, 1.60 m).
        P("girl-8", 0.0, 8, 0.5, 0.5, 1.17),
        P("boy-8", 1.0, 8, 0.5, 0.5, 1.12),
        P("girl-11-thin", 0.0, 11, 0.4, 0.25, 1.15),
        P("boy-11-heavy", 1.0, 11, 0.5, 0.85, 1.08),
        P("girl-14", 0.0, 14, 0.5, 0.5, 1.15),
        P("boy-14", 1.0, 14, 0.55, 0.5, 1.12),
        P("female-young-thin", 0.0, 25, 0.4, 0.15, 1.0),
        P("female-young-average", 0.0, 25, 0.5, 0.5, 1.0),
        P("female-young-heavy", 0.0, 30, 0.45, 0.95, 0.98),
        P("female-athletic-tall", 0.0, 28, 0.85, 0.45, 1.05),
        P("male-young-thin", 1.0, 25, 0.45, 0.15, 1.0),
        P("male-young-average", 1.0, 25, 0.5, 0.5, 1.02),
        P("male-young-heavy", 1.0, 35, 0.5, 1.0, 1.0),
        P("male-muscular-tall", 1.0, 28, 1.0, 0.6, 1.07),
        P("androgynous-short", 0.5, 30, 0.5, 0.5, 0.93),
        P("female-old", 0.0, 75, 0.35, 0.6, 0.96),
        P("male-old", 1.0, 75, 0.35, 0.55, 0.97),
        P("male-old-heavy", 1.0, 65, 0.4, 0.9, 0.98),
    };
  }();
  return presets;
}

MakeHumanParams VaryMakeHuman(const MakeHumanParams& base, core::RngStream& rng) {
  MakeHumanParams p = base;
  p.height_scale = base.height_scale * (1.0 + std::clamp(0.03 * rng.Normal(), -0.08, 0.08));
  p.weight = std::clamp(base.weight + 0.06 * rng.Normal(), 0.0, 1.0);
  p.name = base.name + "~var";
  return p;
}

MakeHumanParams SampleMakeHumanParams(core::RngStream& rng) {
  MakeHumanParams p;
  const double g = rng.Uniform01(), gv = rng.Uniform01();
  p.gender = g < 0.1 ? gv : g < 0.55 ? 0.2 * gv : 0.8 + 0.2 * gv;
  const double a = rng.Uniform01(), av = rng.Uniform01();
  const double years = a < 0.12 ? 6 + 7 * av : a < 0.22 ? 13 + 5 * av : a < 0.85 ? 18 + 47 * av : 65 + 25 * av;
  p.age = MakeHumanAgeFromYears(years);
  const double adult = std::clamp((years - 18) / 40, 0.0, 1.0), old = std::clamp((years - 50) / 40, 0.0, 1.0);
  p.weight = std::clamp(0.42 + 0.12 * adult + 0.22 * rng.Normal(), 0.0, 1.0);
  p.muscle = std::clamp(0.5 - 0.15 * old + 0.2 * rng.Normal(), 0.0, 1.0);
  // MakeHuman's child and teen targets come out short without its height modifier (see the
  // presets): bring them to typical heights, and old bodies a little down.
  const double young_scale = 1.11 + 0.05 * (1 - p.gender);
  const double base = years <= 14   ? young_scale
                      : years < 20  ? young_scale + (1.0 - young_scale) * (years - 14) / 6
                      : years <= 60 ? 1.0
                                    : 1.0 - 0.04 * (years - 60) / 30;
  p.height_scale = base * (1 + std::clamp(0.04 * rng.Normal(), -0.1, 0.1));
  char name[48];
  std::snprintf(name, sizeof name, "sampled-%s%d", p.gender < 0.5 ? "f" : "m", int(years));
  p.name = name;
  return p;
}

std::vector<const MhcloProxy*> DrawOutfit(const MakeHumanWardrobe& wardrobe, const MakeHumanParams& params,
                                          core::RngStream& rng) {
  const bool female = params.gender < 0.5;
  // A proxy from `list`: with probability `prefer_share` one whose name starts with one of
  // `preferred` (when the wardrobe has any), else any.
  auto pick = [&](const std::vector<std::shared_ptr<const MhcloProxy>>& list,
                  std::initializer_list<const char*> preferred, double prefer_share) -> const MhcloProxy* {
    if (list.empty()) return nullptr;
    std::vector<const MhcloProxy*> pref, all;
    for (const auto& p : list) {
      all.push_back(p.get());
      for (const char* name : preferred)
        if (p->name.rfind(name, 0) == 0) {
          pref.push_back(p.get());
          break;
        }
    }
    const bool use_pref = rng.Uniform01() < prefer_share && !pref.empty();
    const auto& from = use_pref ? pref : all;
    return from[rng.UniformInt(uint32_t(from.size()))];
  };
  std::vector<const MhcloProxy*> out;
  if (const MhcloProxy* o = female ? pick(wardrobe.outfits, {"female"}, 0.8) : pick(wardrobe.outfits, {"male"}, 0.8))
    out.push_back(o);
  const bool bald = !female && rng.Uniform01() < 0.1;
  const MhcloProxy* hair =
      female ? pick(wardrobe.hair, {"long", "ponytail", "braid", "bob", "short03"}, 0.75)
             : pick(wardrobe.hair, {"short01", "short02", "short04", "afro"}, 0.85);
  if (hair && !bald) out.push_back(hair);
  if (rng.Uniform01() < 0.07)
    if (const MhcloProxy* hat = pick(wardrobe.hats, {}, 0.0)) out.push_back(hat);
  if (rng.Uniform01() < 0.92)
    if (const MhcloProxy* shoes = pick(wardrobe.shoes, {}, 0.0)) out.push_back(shoes);
  return out;
}

double BodyHeight(const BodyMesh& body) {
  if (body.vertices.empty()) return 0;
  float lo = body.vertices[0].y(), hi = lo;
  for (const auto& v : body.vertices) lo = std::min(lo, v.y()), hi = std::max(hi, v.y());
  return double(hi - lo);
}

double WaistWidth(const BodyMesh& body) {
  const double y0 = body.rest_joints[size_t(SkelJoint::kPelvis)].y();
  const double y1 = body.rest_joints[size_t(SkelJoint::kChest)].y();
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t v = 0; v < body.vertices.size(); ++v) {
    const auto& x = body.vertices[v];
    if (x.y() < y0 || x.y() > y1) continue;
    // Torso only: the arms hang beside the waist in the A-pose.
    if (v < body.skin.size()) {
      const auto& s = body.skin[v];
      const int j = s.joint[0];
      if (j != int(SkelJoint::kPelvis) && j != int(SkelJoint::kSpine) && j != int(SkelJoint::kChest))
        continue;
    }
    lo = std::min(lo, x.x());
    hi = std::max(hi, x.x());
  }
  return hi > lo ? double(hi - lo) : 0.0;
}

}  // namespace poseforest::renderer::assets
