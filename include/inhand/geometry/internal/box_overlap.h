#pragma once
// Overlap of solid boxes with triangle surfaces: the finger-closing and approach checks of grasp
// planning (a BarrettHand's finger links are boxes), exact and without a mesh of the box.
#include <cstdint>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

// Whether triangle (a, b, c) meets the solid axis-aligned box [-half, half] (the box's own
// frame): the separating-axis test over the box's 3 axes, the triangle's normal and the 9 cross
// products of their edges. Touching counts as overlap.
bool triangleOverlapsBox(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& half);

// The same by a different route, for tests: a triangle vertex inside the box, a triangle edge
// through the box (slab test) or a box edge through the triangle.
bool triangleOverlapsBoxReference(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& half);

// A fixed set of triangles in a bounding-volume hierarchy (axis-aligned boxes, median splits,
// leaves of up to 4 triangles), for "does this box meet the surface?" queries. Thread-safe after
// construction.
class TriangleBoxIndex {
 public:
  explicit TriangleBoxIndex(const TriangleMesh& mesh);
  bool empty() const { return tris_.empty(); }
  // Whether the solid box of half extents `half`, centred at T_O_box's origin along its axes,
  // meets any triangle (mesh frame O).
  bool overlapsBox(const Iso3& T_O_box, const Vec3& half) const;
  // Brute force over every triangle: the reference for tests.
  bool overlapsBoxReference(const Iso3& T_O_box, const Vec3& half) const;

 private:
  struct Node {
    Vec3 centre, half;  // the node's bounds
    int32_t first = 0;  // leaf: first triangle; inner: index of the second child
    int32_t count = 0;  // leaf: triangle count; inner: 0 (first child follows the node)
  };
  struct Tri3 {
    Vec3 a, b, c;
  };
  int build(std::vector<int>& ids, int begin, int end, const std::vector<Vec3>& centroids,
            const std::vector<Tri3>& source);
  std::vector<Node> nodes_;
  std::vector<Tri3> tris_;  // in leaf order
};

}  // namespace inhand
