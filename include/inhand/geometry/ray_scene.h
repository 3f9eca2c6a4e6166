#pragma once
// Embree 3 ray-casting scene. Batches are cast as 8-ray packets (rtcIntersect8 /
// rtcOccluded8) spread over both cores; a scalar one-ray path is kept as the reference.
// After commit() every query is const and thread-safe.
#include <embree3/rtcore.h>

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

struct Ray {
  Vec3f origin = Vec3f::Zero();
  Vec3f dir = Vec3f::UnitZ();  // need not be unit; t is in units of |dir|
  float tnear = 0.f;
  float tfar = std::numeric_limits<float>::infinity();
};

struct Hit {
  float t = std::numeric_limits<float>::infinity();
  int geometry = -1;  // id returned by addMesh/addInstance; -1 when the ray hit nothing
  int inner = -1;     // for hits through an instance: the geometry id inside the instanced scene
  int triangle = -1;
  float u = 0.f, v = 0.f;        // barycentrics: point = (1-u-v)·v0 + u·v1 + v·v2
  Vec3f normal = Vec3f::Zero();  // geometric normal in this scene's frame, not normalised
  bool valid() const { return geometry >= 0; }
};

class RayScene {
 public:
  RayScene();
  ~RayScene();
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;
  RayScene(RayScene&&) noexcept;
  RayScene& operator=(RayScene&&) noexcept;

  // Adds a copy of `mesh` transformed by T; returns its geometry id (0, 1, 2, … in call order).
  int addMesh(const TriangleMesh& mesh, const Iso3& T = Iso3::Identity());
  // Adds `inner` (committed; must outlive this scene) placed by T, without copying or rebuilding
  // its BVH (Embree instancing). Returns its geometry id; hits report inner's geometry in `inner`.
  int addInstance(const RayScene& inner, const Iso3& T);
  // Builds the BVH. Must be called after the last addMesh and before any query. `high` spends
  // longer on the build (SAH with spatial splits) for faster queries: for scenes cast many times.
  void commit(bool high = false);
  bool committed() const { return committed_; }
  int geometryCount() const { return geometryCount_; }

  // Closest hit of each ray: packets of 8 consecutive rays, on both cores unless `parallel` is
  // false (for callers that already run one task per core).
  void intersect(const Ray* rays, Hit* hits, size_t count, bool parallel = true) const;
  // blocked[i] = 1 when something lies on ray i within [tnear, tfar].
  void occluded(const Ray* rays, uint8_t* blocked, size_t count, bool parallel = true) const;
  // Scalar reference path (rtcIntersect1), one ray.
  Hit intersectOne(const Ray& ray) const;

  // The triangles this scene was built from, for other renderers (the rasteriser): each added
  // mesh with its placement T·(instance placements) in the frame that T maps this scene into,
  // and its bounding box in its own frame, instanced scenes expanded recursively. Pointers live
  // as long as the scenes.
  struct PlacedMesh {
    const TriangleMesh* mesh;
    Iso3 T;
    const Aabb* bounds;
  };
  void collectMeshes(const Iso3& T, std::vector<PlacedMesh>* out) const;

 private:
  // The hit an Embree ray reported, written to *h (every field).
  void makeHit(float t, unsigned geomID, unsigned instID, unsigned primID, float u, float v,
               const Vec3f& Ng, Hit* h) const;
  RTCScene scene_ = nullptr;
  std::vector<Eigen::Matrix3f> instanceRotation_;  // per geometry id (identity for meshes)
  // Per geometry id: the mesh as added (already placed), or the instanced scene and placement.
  std::vector<TriangleMesh> meshes_;
  std::vector<Aabb> bounds_;  // per geometry id: its mesh's bounds
  std::vector<std::pair<const RayScene*, Iso3>> instances_;
  int geometryCount_ = 0;
  bool committed_ = false;
};

}  // namespace inhand
