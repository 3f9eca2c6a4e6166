#pragma once
// Distances between points and triangle surfaces, and uniform samples of a surface by area: what
// the ground-truth evaluation (coverage, accuracy, F-score) is built on.
#include <cstdint>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

// Closest point of triangle (a, b, c) to p (exact, every Voronoi region handled).
Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// `count` points drawn uniformly by area over the triangles whose entry in `use` is nonzero (all
// triangles when `use` is empty), from a generator seeded with `seed`. Empty when the selected
// area is zero.
std::vector<Vec3> sampleSurfaceUniform(const TriangleMesh& mesh, int count, uint64_t seed,
                                       const std::vector<uint8_t>& use = {});

// Nearest-surface queries against a fixed set of triangles: a uniform grid of cells holding every
// triangle whose box touches them, searched in growing shells around the query point until no
// closer triangle can remain. Thread-safe after construction.
class TriangleDistanceIndex {
 public:
  // Indexes the triangles of `mesh` whose entry in `use` is nonzero (all when `use` is empty).
  TriangleDistanceIndex(const TriangleMesh& mesh, const std::vector<uint8_t>& use = {},
                        double cell_m = 0);
  bool empty() const { return tris_.empty(); }
  // Distance from p to the nearest indexed triangle; +inf when the index is empty. With
  // `max_m` finite, any value ≥ max_m may be returned as soon as none nearer can exist.
  double distance(const Vec3& p, double max_m = std::numeric_limits<double>::infinity()) const;
  // The same, with the nearest triangle (its index in the mesh; -1 when none) and the nearest
  // point on it (when found before max_m allowed stopping).
  double nearest(const Vec3& p, int* triangle, Vec3* point,
                 double max_m = std::numeric_limits<double>::infinity()) const;
  // Whether some indexed triangle lies within r of p (distance(p) ≤ r), stopping at the first.
  bool within(const Vec3& p, double r) const;
  // Brute-force reference: every indexed triangle.
  double distanceReference(const Vec3& p) const;

 private:
  struct T {
    Vec3 a, b, c;
  };
  std::vector<T> tris_;
  std::vector<int> ids_;  // each indexed triangle's index in the mesh
  Vec3 origin_ = Vec3::Zero();
  double cell_ = 1;
  Vec3i dims_ = Vec3i::Ones();
  std::vector<uint32_t> start_;  // CSR: cell → range in items_
  std::vector<uint32_t> items_;
};

}  // namespace inhand
