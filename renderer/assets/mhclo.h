#pragma once
// MakeHuman 1.1 proxy assets (.mhclo + .obj: clothes, hair, hats, shoes) for the hm08 base mesh,
// e.g. /work/shared/data/meshes/makehuman_clothes (see its README.md).
//
// Binding (MakeHuman makehuman/shared/proxy.py, Proxy.getCoords and TMatrix.getMatrix): proxy
// vertex k sits at
//   p_k = w1*B[v1] + w2*B[v2] + w3*B[v3] + S * d_k,   S = diag(sx, sy, sz),
//   sx = |B[a].x - B[b].x| / ref for the `x_scale a b ref` line (y, z likewise),
// where B are the (morphed, rest-pose) base-mesh vertices in base-mesh units (decimetres), all
// 19,158 of base.obj including the helper-* groups the clothes bind to. Offsets are in world axes,
// so proxies are fitted in the rest pose and then skinned. The .obj gives faces and vertex order
// only; its positions are ignored.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "runtime/core/result.h"

namespace poseforest::renderer::assets {

/// What a proxy is, from its name (the wardrobe draws one of each kind per body).
enum class ProxyKind { kOutfit, kHair, kHat, kShoes };

/// One parsed proxy: the binding of every proxy vertex and the proxy's triangles.
struct MhcloProxy {
  std::string name;    ///< `name` line in lower case (else the file stem)
  std::string source;  ///< the .mhclo path, for messages
  ProxyKind kind = ProxyKind::kOutfit;
  std::vector<std::string> tags;  ///< `tag` lines, lower case
  /// x, y, z: base vertices a, b and the reference distance (dm) of the offset scale; has_scale
  /// false for an axis without a line (scale 1).
  struct Scale {
    bool has_scale = false;
    uint32_t a = 0, b = 0;
    double ref = 1.0;
  };
  std::array<Scale, 3> scale;
  std::vector<std::array<uint32_t, 3>> ref;    ///< per proxy vertex: 3 base vertices
  std::vector<std::array<float, 3>> weight;    ///< per proxy vertex: their weights (sum 1, may be < 0)
  std::vector<Eigen::Vector3f> offset;         ///< per proxy vertex: offset d, base-mesh units (dm)
  std::vector<uint32_t> delete_verts;          ///< base vertices the proxy covers (sorted, unique)
  std::string obj_file;                        ///< `obj_file` line (relative to the .mhclo)
  std::vector<std::array<uint32_t, 3>> triangles;  ///< proxy vertex indices (faces fanned), from the .obj

  size_t vertex_count() const { return ref.size(); }
};

/// ProxyKind from a proxy name: "shoes*" shoes, "fedora*" a hat, "*suit*" an outfit, else hair.
ProxyKind ProxyKindFromName(std::string_view name);

/// Parses the text of a .mhclo (no .obj). Base-vertex indices must be below `base_vertex_count`.
/// Errors: kDataLoss naming `source` and the line ("f.mhclo:42: expected 'v1 v2 v3 w1 w2 w3
/// [d1 d2 d3]' ..."), and a file without `verts` lines.
core::Result<MhcloProxy> ParseMhclo(std::string_view text, const std::string& source,
                                    size_t base_vertex_count);

/// Reads a .mhclo and the faces of its obj_file; the .obj must have exactly one vertex per
/// binding line. Errors name the file (and line).
core::Result<MhcloProxy> LoadMhclo(const std::filesystem::path& path, size_t base_vertex_count);

/// Fitted proxy vertices from base-mesh vertices `base` (any units; offsets scale with them only
/// through the x/y/z_scale ratios, as in MakeHuman). `base` must hold every vertex the proxy names.
std::vector<Eigen::Vector3f> FitProxy(const MhcloProxy& proxy, const std::vector<Eigen::Vector3f>& base);

/// Every proxy of a clothes folder (each subfolder's *.mhclo), sorted by name within each kind,
/// so the same folder gives the same wardrobe on every machine.
struct MakeHumanWardrobe {
  std::filesystem::path dir;
  std::vector<std::shared_ptr<const MhcloProxy>> outfits, hair, hats, shoes;
  size_t size() const { return outfits.size() + hair.size() + hats.size() + shoes.size(); }
};

/// Loads a wardrobe folder (e.g. <data>/meshes/makehuman_clothes). Errors: the folder is missing
/// or has no outfit, hair or shoes (kNotFound), or a proxy fails to load (its error).
core::Result<MakeHumanWardrobe> LoadMakeHumanWardrobe(const std::filesystem::path& dir,
                                                      size_t base_vertex_count);

}  // namespace poseforest::renderer::assets
