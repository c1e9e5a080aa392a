#include "renderer/assets/mesh_loader.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cmath>
#include <limits>
#include <map>
#include <unordered_map>

#include "renderer/assets/rig.h"

namespace poseforest::renderer::assets {
namespace {

using core::ErrorCode;
using core::Result;
using core::Status;

Eigen::Matrix4d ToEigen(const aiMatrix4x4& m) {
  Eigen::Matrix4d e;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) e(r, c) = double(m[r][c]);
  return e;
}

Eigen::Vector3d Apply(const Eigen::Matrix4d& m, const Eigen::Vector3d& v) {
  return (m * v.homogeneous()).head<3>();
}

struct NodeInfo {
  const aiNode* node;
  Eigen::Matrix4d global;
};

void Walk(const aiNode* n, const Eigen::Matrix4d& parent, std::vector<NodeInfo>* out,
          std::unordered_map<const aiNode*, size_t>* index) {
  const Eigen::Matrix4d g = parent * ToEigen(n->mTransformation);
  (*index)[n] = out->size();
  out->push_back({n, g});
  for (unsigned i = 0; i < n->mNumChildren; ++i) Walk(n->mChildren[i], g, out, index);
}

bool IsPoleTarget(const std::string& name) {
  const std::string_view s = StripRigPrefix(name);
  return s.rfind("PT.", 0) == 0 || s.rfind("PoleTarget", 0) == 0 || s.rfind("IK", 0) == 0 ||
         s.find("_IK") != std::string_view::npos || s.find("pole") != std::string_view::npos;
}

// The scene's nodes in depth-first order with their global transforms, and by name.
struct SceneNodes {
  std::vector<NodeInfo> nodes;
  std::unordered_map<const aiNode*, size_t> node_index;
  std::unordered_map<std::string, size_t> by_name;
};

SceneNodes IndexNodes(const aiScene* scene) {
  SceneNodes s;
  Walk(scene->mRootNode, Eigen::Matrix4d::Identity(), &s.nodes, &s.node_index);
  // Name -> node; where names repeat (Casual_Female has a mesh node and a bone called "Body"),
  // prefer the node that holds no meshes.
  for (size_t i = 0; i < s.nodes.size(); ++i) {
    const std::string name = s.nodes[i].node->mName.C_Str();
    auto it = s.by_name.find(name);
    if (it == s.by_name.end() ||
        (s.nodes[it->second].node->mNumMeshes > 0 && s.nodes[i].node->mNumMeshes == 0))
      s.by_name[name] = i;
  }
  return s;
}

struct BoneAcc {
  std::string name;
  bool has_bind = false;
  Eigen::Matrix4d bind_global = Eigen::Matrix4d::Identity();  // bone frame -> file world, bind pose
};

// The bones met so far, numbered in the order they are first named.
struct BoneTable {
  std::vector<BoneAcc> bones;
  std::unordered_map<std::string, int> bone_of;
  int Index(const std::string& name) {
    auto it = bone_of.find(name);
    if (it != bone_of.end()) return it->second;
    bones.push_back({name});
    bone_of[name] = int(bones.size()) - 1;
    return int(bones.size()) - 1;
  }
};

// The triangles of the file's meshes in the file's world frame, with their bone weights.
struct MeshGeometry {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;
  RigWeights weights;
  size_t skinned_meshes = 0;
};

// The meshes, and their bones: every aiBone of every mesh, bind pose from its offset matrix.
MeshGeometry GatherMeshes(const aiScene* scene, const std::vector<NodeInfo>& nodes,
                          const MeshLoadOptions& options, BoneTable& table) {
  MeshGeometry g;
  auto& bones = table.bones;
  auto& vertices = g.vertices;
  auto& weights = g.weights;
  for (const auto& info : nodes) {
    for (unsigned k = 0; k < info.node->mNumMeshes; ++k) {
      const aiMesh* mesh = scene->mMeshes[info.node->mMeshes[k]];
      if (!(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
      if (mesh->mNumBones == 0 && !options.include_unskinned) continue;
      if (mesh->mNumBones > 0) ++g.skinned_meshes;
      const uint32_t base = uint32_t(vertices.size());
      // Skinning in the bind pose: Global(bone) * Offset(bone) = the mesh node's bind transform,
      // so the vertex in the file's world frame is mesh_global * v.
      for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
        const aiVector3D& p = mesh->mVertices[v];
        vertices.push_back(Apply(info.global, Eigen::Vector3d(p.x, p.y, p.z)).cast<float>());
      }
      weights.resize(vertices.size());
      for (unsigned b = 0; b < mesh->mNumBones; ++b) {
        const aiBone* bone = mesh->mBones[b];
        const int bi = table.Index(bone->mName.C_Str());
        if (!bones[size_t(bi)].has_bind) {
          bones[size_t(bi)].has_bind = true;
          bones[size_t(bi)].bind_global = info.global * ToEigen(bone->mOffsetMatrix).inverse();
        }
        if (IsPoleTarget(bones[size_t(bi)].name)) continue;
        for (unsigned w = 0; w < bone->mNumWeights; ++w) {
          const aiVertexWeight& vw = bone->mWeights[w];
          if (vw.mVertexId < mesh->mNumVertices && vw.mWeight > 0)
            weights[base + vw.mVertexId].push_back({bi, vw.mWeight});
        }
      }
      for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
        const aiFace& face = mesh->mFaces[f];
        if (face.mNumIndices != 3) continue;
        g.triangles.push_back({base + face.mIndices[0], base + face.mIndices[1], base + face.mIndices[2]});
      }
    }
  }
  return g;
}

// Bone hierarchy through the node tree; bones found only as nodes (a rig's root) join the list
// so parent chains stay connected.
std::vector<RigBone> BuildRigBones(const SceneNodes& s, BoneTable& table) {
  const auto& nodes = s.nodes;
  const auto& by_name = s.by_name;
  auto& bones = table.bones;
  const auto& bone_of = table.bone_of;
  std::vector<RigBone> rig_bones;
  // Nodes that are bones, or ancestors of bones below the first bone's armature.
  const size_t original = bones.size();
  for (size_t i = 0; i < original; ++i) {
    auto it = by_name.find(bones[i].name);
    if (it == by_name.end()) continue;
    for (const aiNode* a = nodes[it->second].node->mParent; a && a->mParent; a = a->mParent) {
      const std::string an = a->mName.C_Str();
      if (a->mNumMeshes > 0) break;
      if (bone_of.count(an)) continue;
      // Only nodes inside the armature: stop at a node that has a mesh child at its level.
      table.Index(an);
    }
  }
  rig_bones.resize(bones.size());
  for (size_t i = 0; i < bones.size(); ++i) {
    RigBone& rb = rig_bones[i];
    rb.name = bones[i].name;
    auto it = by_name.find(bones[i].name);
    Eigen::Matrix4d g = bones[i].bind_global;
    if (!bones[i].has_bind && it != by_name.end()) g = nodes[it->second].global;
    rb.head = g.block<3, 1>(0, 3);
    if (it != by_name.end()) {
      for (const aiNode* a = nodes[it->second].node->mParent; a; a = a->mParent) {
        auto pb = bone_of.find(a->mName.C_Str());
        if (pb != bone_of.end() && pb->second != int(i)) {
          rb.parent = pb->second;
          break;
        }
      }
    }
  }
  // A bone with exactly one child bone gets that child's head as its tail.
  std::vector<int> child_count(rig_bones.size(), 0), only_child(rig_bones.size(), -1);
  for (size_t i = 0; i < rig_bones.size(); ++i)
    if (rig_bones[i].parent >= 0)
      ++child_count[size_t(rig_bones[i].parent)], only_child[size_t(rig_bones[i].parent)] = int(i);
  for (size_t i = 0; i < rig_bones.size(); ++i)
    if (child_count[i] == 1)
      rig_bones[i].has_tail = true, rig_bones[i].tail = rig_bones[size_t(only_child[i])].head;
  return rig_bones;
}

// Orientation and scale: the map from the file's frame to the body frame (metres, Y up, facing +Z): the rig's
// axes snapped, and the metric unit that gives a plausible height (or the fallback height).
Result<Eigen::Matrix3d> BodyFrame(const FoldedRig& rig, const std::vector<Eigen::Vector3f>& vertices,
                                  const MeshLoadOptions& options, const std::string& file) {
  auto J = [&](SkelJoint j) { return rig.rest_joints[size_t(int(j))]; };
  Eigen::Vector3d up = J(SkelJoint::kNeck) - J(SkelJoint::kPelvis);
  Eigen::Vector3d left = (J(SkelJoint::kLHip) - J(SkelJoint::kRHip)).normalized() +
                         (J(SkelJoint::kLShoulder) - J(SkelJoint::kRShoulder)).normalized();
  if (up.norm() < 1e-9 || left.norm() < 1e-9)
    return Status(ErrorCode::kInvalidArgument,
                  file + ": degenerate rig (pelvis at the neck or hips on top of each other)");
  up.normalize();
  left = (left - left.dot(up) * up).normalized();
  Eigen::Matrix3d frame;  // rows: where left, up, forward go
  frame.row(0) = left.transpose();
  frame.row(1) = up.transpose();
  frame.row(2) = left.cross(up).transpose();
  const Eigen::Matrix3d rot = SnapToAxes(frame);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const auto& v : vertices) {
    const double y = (rot * v.cast<double>()).y();
    lo = std::min(lo, y), hi = std::max(hi, y);
  }
  const double raw_height = hi - lo;
  double unit = 1.0;
  for (double u : {1.0, 0.1, 0.01, 0.001}) {
    unit = u;
    if (raw_height * u <= 2.6) break;
  }
  if (!(raw_height > 0))
    return Status(ErrorCode::kInvalidArgument, file + ": the skinned meshes are flat (zero height)");
  if (!(raw_height * unit >= 0.5 && raw_height * unit <= 2.6)) {
    // No metric unit fits (Casual_Female is 3.2 units tall): scale to the nominal height.
    if (!(options.fallback_height_m > 0))
      return Status(ErrorCode::kInvalidArgument, file + ": implausible body height " +
                                                     std::to_string(raw_height) +
                                                     " file units (no unit in m/dm/cm/mm gives 0.5..2.6 m)");
    unit = options.fallback_height_m / raw_height;
  }
  const Eigen::Matrix3d to_body = unit * rot;
  return to_body;
}

}  // namespace

Result<BodyMesh> LoadRiggedMesh(const std::filesystem::path& path, const MeshLoadOptions& options) {
  const std::string file = path.string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return Status(ErrorCode::kNotFound, file + ": no such file");
  Assimp::Importer importer;
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* scene = importer.ReadFile(
      file, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_SortByPType);
  if (!scene || !scene->mRootNode)
    return Status(ErrorCode::kIo, file + ": Assimp cannot read it: " + importer.GetErrorString());

  const SceneNodes nodes = IndexNodes(scene);
  BoneTable bones;
  MeshGeometry mesh = GatherMeshes(scene, nodes.nodes, options, bones);
  if (mesh.skinned_meshes == 0)
    return Status(ErrorCode::kInvalidArgument, file + ": no skinned mesh (no bones) among its " +
                                                   std::to_string(scene->mNumMeshes) +
                                                   " meshes: a body needs a rig to be posed");
  if (mesh.triangles.empty())
    return Status(ErrorCode::kInvalidArgument, file + ": the skinned meshes have no triangles");

  const std::vector<RigBone> rig_bones = BuildRigBones(nodes, bones);
  auto folded = FoldRig(rig_bones, file, options.bone_maps);
  if (!folded.ok()) return folded.status();
  FoldedRig rig = std::move(*folded);

  auto to_body = BodyFrame(rig, mesh.vertices, options, file);
  if (!to_body.ok()) return to_body.status();
  std::vector<Eigen::Vector3f>& vertices = mesh.vertices;
  for (auto& v : vertices) v = (*to_body * v.cast<double>()).cast<float>();
  for (auto& j : rig.rest_joints) j = *to_body * j;

  BodyMesh body;
  body.name = "mesh:" + path.filename().string();
  body.skin = FoldSkin(rig, mesh.weights, vertices);
  EstimateMissingJoints(rig, vertices, body.skin);
  body.vertices = std::move(vertices);
  body.triangles = std::move(mesh.triangles);
  body.rest_joints = rig.rest_joints;
  PlaceOnFloor(&body);
  return body;
}

}  // namespace poseforest::renderer::assets
