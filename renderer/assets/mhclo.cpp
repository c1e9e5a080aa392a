#include "renderer/assets/mhclo.h"

#include <algorithm>
#include <charconv>
#include <cmath>

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

bool ParseIndex(std::string_view w, size_t limit, uint32_t* out) {
  double v;
  if (!ParseNum(w, &v) || v < 0 || v != std::floor(v) || v >= double(limit)) return false;
  *out = uint32_t(v);
  return true;
}

bool IsNumberWord(std::string_view w) {
  return !w.empty() && (std::isdigit(static_cast<unsigned char>(w[0])) || w[0] == '-' || w[0] == '+' || w[0] == '.');
}

}  // namespace

ProxyKind ProxyKindFromName(std::string_view name) {
  if (name.rfind("shoes", 0) == 0) return ProxyKind::kShoes;
  if (name.rfind("fedora", 0) == 0) return ProxyKind::kHat;
  if (name.find("suit") != std::string_view::npos) return ProxyKind::kOutfit;
  return ProxyKind::kHair;
}

Result<MhcloProxy> ParseMhclo(std::string_view text, const std::string& source, size_t base_vertex_count) {
  MhcloProxy p;
  p.source = source;
  enum { kHeader, kVerts, kDelete, kOther } section = kHeader;
  Status err;
  const std::string limit = std::to_string(base_vertex_count);
  ForEachLine(text, [&](std::string_view line, int line_no) {
    const auto w = Words(line);
    if (w.empty() || w[0].front() == '#') return true;
    auto bad = [&](const std::string& what) {
      err = Status(ErrorCode::kDataLoss, source + ":" + std::to_string(line_no) + ": " + what);
      return false;
    };
    if (!IsNumberWord(w[0]) && w[0] != "-") {  // a keyword (MakeHuman checks keywords first too)
      const std::string_view key = w[0];
      auto rest = [&] {
        std::string s;
        for (size_t k = 1; k < w.size(); ++k) {
          if (k > 1) s.push_back(' ');
          s.append(w[k]);
        }
        return s;
      };
      if (key == "verts") {
        section = kVerts;
      } else if (key == "delete_verts") {
        section = kDelete;
      } else if (key == "weights") {
        section = kOther;  // old-style explicit weights: not used by any hm08 asset
      } else if (key == "name") {  // lower case: upstream spells one "Braid01"
        p.name = rest();
        std::transform(p.name.begin(), p.name.end(), p.name.begin(),
                       [](unsigned char c) { return char(std::tolower(c)); });
      } else if (key == "tag") {
        std::string t = rest();
        std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return char(std::tolower(c)); });
        p.tags.push_back(t);
      } else if (key == "obj_file") {
        if (w.size() < 2) return bad("obj_file needs a file name");
        p.obj_file = rest();
      } else if (key == "x_scale" || key == "y_scale" || key == "z_scale") {
        const int axis = key[0] - 'x';
        MhcloProxy::Scale& s = p.scale[size_t(axis)];
        if (w.size() != 4 || !ParseIndex(w[1], base_vertex_count, &s.a) ||
            !ParseIndex(w[2], base_vertex_count, &s.b) || !ParseNum(w[3], &s.ref) || !(s.ref > 0))
          return bad(std::string(key) + ": expected 'vertexA vertexB referenceDistance' with vertices below " +
                     limit + " and a distance > 0");
        s.has_scale = true;
      } else if (key == "shear_x" || key == "shear_y" || key == "shear_z" || key.rfind("l_shear", 0) == 0 ||
                 key.rfind("r_shear", 0) == 0) {
        return bad(std::string(key) + ": shear offset matrices are not supported (only x/y/z_scale)");
      }
      // Other keywords (uuid, basemesh, material, z_depth, max_pole, vertexboneweights_file, ...)
      // do not change the geometry; skin weights always come through the binding.
      return true;
    }
    if (section == kVerts) {
      std::array<uint32_t, 3> v{};
      std::array<float, 3> wt{1.f, 0.f, 0.f};
      Eigen::Vector3f d = Eigen::Vector3f::Zero();
      if (w.size() == 1) {  // the vertex sits on one base vertex
        if (!ParseIndex(w[0], base_vertex_count, &v[0]))
          return bad("expected a base vertex index below " + limit);
        v[1] = v[2] = v[0];
      } else {
        double x[9] = {};
        bool ok = w.size() == 6 || w.size() == 9;
        for (size_t k = 0; ok && k < 3; ++k) ok = ParseIndex(w[k], base_vertex_count, &v[k]);
        for (size_t k = 3; ok && k < w.size(); ++k) ok = ParseNum(w[k], &x[k]);
        if (!ok)
          return bad("expected 'v1 v2 v3 w1 w2 w3 [d1 d2 d3]' (base vertices below " + limit +
                     ", finite weights and offsets), got " + std::to_string(w.size()) + " words");
        wt = {float(x[3]), float(x[4]), float(x[5])};
        d = Eigen::Vector3f(float(x[6]), float(x[7]), float(x[8]));
      }
      p.ref.push_back(v);
      p.weight.push_back(wt);
      p.offset.push_back(d);
      return true;
    }
    if (section == kDelete) {  // "a b - c d": single vertices and inclusive ranges
      for (size_t k = 0; k < w.size(); ++k) {
        uint32_t a;
        if (w[k] == "-") {
          uint32_t b;
          if (p.delete_verts.empty() || k + 1 >= w.size() || !ParseIndex(w[k + 1], base_vertex_count, &b) ||
              b < p.delete_verts.back())
            return bad("delete_verts: a range 'a - b' needs a b >= a below " + limit);
          for (uint32_t i = p.delete_verts.back() + 1; i <= b; ++i) p.delete_verts.push_back(i);
          ++k;
        } else if (ParseIndex(w[k], base_vertex_count, &a)) {
          p.delete_verts.push_back(a);
        } else {
          return bad("delete_verts: expected base vertex indices below " + limit);
        }
      }
      return true;
    }
    if (section == kOther) return true;
    return bad("a number outside the verts / delete_verts sections");
  });
  if (!err.ok()) return err;
  if (p.ref.empty()) return Status(ErrorCode::kDataLoss, source + ": no vertex bindings (no lines after 'verts')");
  std::sort(p.delete_verts.begin(), p.delete_verts.end());
  p.delete_verts.erase(std::unique(p.delete_verts.begin(), p.delete_verts.end()), p.delete_verts.end());
  if (p.name.empty()) p.name = std::filesystem::path(source).stem().string();
  p.kind = ProxyKindFromName(p.name);
  return p;
}

Result<MhcloProxy> LoadMhclo(const std::filesystem::path& path, size_t base_vertex_count) {
  auto bytes = core::ReadFileBytes(path.string());
  if (!bytes.ok()) return bytes.status();
  auto proxy = ParseMhclo(std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()),
                          path.string(), base_vertex_count);
  if (!proxy.ok()) return proxy.status();
  if (proxy->obj_file.empty()) return Status(ErrorCode::kDataLoss, path.string() + ": no obj_file line");
  const auto obj_path = path.parent_path() / proxy->obj_file;
  auto obj = core::ReadFileBytes(obj_path.string());
  if (!obj.ok()) return obj.status();
  const std::string_view text(reinterpret_cast<const char*>(obj->data()), obj->size());
  size_t vertices = 0;
  Status err;
  const size_t n = proxy->vertex_count();
  ForEachLine(text, [&](std::string_view line, int line_no) {
    if (line.size() < 2) return true;
    if (line[0] == 'v' && line[1] == ' ') {
      ++vertices;
    } else if (line[0] == 'f' && line[1] == ' ') {
      const auto w = Words(line);
      std::vector<uint32_t> f;
      for (size_t k = 1; k < w.size(); ++k) {
        double v;
        if (!ParseNum(w[k].substr(0, w[k].find('/')), &v) || v == 0 || v != std::floor(v)) {
          err = Status(ErrorCode::kDataLoss, obj_path.string() + ":" + std::to_string(line_no) + ": bad face index");
          return false;
        }
        const long i = v > 0 ? long(v) - 1 : long(vertices) + long(v);
        if (i < 0 || size_t(i) >= n) {
          err = Status(ErrorCode::kDataLoss, obj_path.string() + ":" + std::to_string(line_no) +
                                                 ": face index out of range (" + path.filename().string() +
                                                 " binds " + std::to_string(n) + " vertices)");
          return false;
        }
        f.push_back(uint32_t(i));
      }
      if (f.size() < 3) {
        err = Status(ErrorCode::kDataLoss, obj_path.string() + ":" + std::to_string(line_no) +
                                               ": face with fewer than 3 vertices");
        return false;
      }
      for (size_t k = 1; k + 1 < f.size(); ++k) proxy->triangles.push_back({f[0], f[k], f[k + 1]});
    }
    return true;
  });
  if (!err.ok()) return err;
  if (vertices != n)
    return Status(ErrorCode::kDataLoss, path.string() + ": " + std::to_string(n) + " vertex bindings, but " +
                                            obj_path.filename().string() + " has " + std::to_string(vertices) +
                                            " vertices (truncated file?)");
  if (proxy->triangles.empty()) return Status(ErrorCode::kDataLoss, obj_path.string() + ": no faces");
  return proxy;
}

std::vector<Eigen::Vector3f> FitProxy(const MhcloProxy& p, const std::vector<Eigen::Vector3f>& base) {
  Eigen::Vector3f s = Eigen::Vector3f::Ones();
  for (int axis = 0; axis < 3; ++axis) {
    const MhcloProxy::Scale& sc = p.scale[size_t(axis)];
    if (sc.has_scale) s[axis] = float(std::abs(base[sc.a][axis] - base[sc.b][axis]) / sc.ref);
  }
  std::vector<Eigen::Vector3f> out(p.vertex_count());
  for (size_t k = 0; k < out.size(); ++k) {
    const auto& v = p.ref[k];
    const auto& w = p.weight[k];
    out[k] = w[0] * base[v[0]] + w[1] * base[v[1]] + w[2] * base[v[2]] + s.cwiseProduct(p.offset[k]);
  }
  return out;
}

Result<MakeHumanWardrobe> LoadMakeHumanWardrobe(const std::filesystem::path& dir, size_t base_vertex_count) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return Status(ErrorCode::kNotFound, dir.string() + ": clothes folder not found (expected MakeHuman .mhclo "
                                                       "proxies, e.g. <data>/meshes/makehuman_clothes)");
  std::vector<fs::path> files;
  for (const auto& sub : fs::directory_iterator(dir, ec)) {
    if (!sub.is_directory()) continue;
    for (const auto& f : fs::directory_iterator(sub.path(), ec))
      if (f.is_regular_file() && f.path().extension() == ".mhclo") files.push_back(f.path());
  }
  if (ec) return Status(ErrorCode::kIo, dir.string() + ": cannot list: " + ec.message());
  std::sort(files.begin(), files.end(),
            [](const fs::path& a, const fs::path& b) { return a.filename() < b.filename(); });
  MakeHumanWardrobe w;
  w.dir = dir;
  for (const fs::path& f : files) {
    auto proxy = LoadMhclo(f, base_vertex_count);
    if (!proxy.ok()) return proxy.status();
    auto shared = std::make_shared<const MhcloProxy>(std::move(proxy).value());
    switch (shared->kind) {
      case ProxyKind::kOutfit:
        w.outfits.push_back(shared);
        break;
      case ProxyKind::kHair:
        w.hair.push_back(shared);
        break;
      case ProxyKind::kHat:
        w.hats.push_back(shared);
        break;
      case ProxyKind::kShoes:
        w.shoes.push_back(shared);
        break;
    }
  }
  if (w.outfits.empty() || w.hair.empty() || w.shoes.empty())
    return Status(ErrorCode::kNotFound, dir.string() + ": needs at least one outfit (*suit*), one hairstyle and "
                                                       "one pair of shoes (shoes*); found " +
                                            std::to_string(w.outfits.size()) + ", " + std::to_string(w.hair.size()) +
                                            ", " + std::to_string(w.shoes.size()));
  return w;
}

}  // namespace poseforest::renderer::assets
