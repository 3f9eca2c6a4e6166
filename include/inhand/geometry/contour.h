#pragma once
// Iso-surface extraction (f = 0) from a dense scalar grid by marching tetrahedra over the Kuhn
// (Freudenthal) split of every cube into 6 tetrahedra. The split is the same in every cube, so
// neighbouring cubes share their face diagonals: the surface is watertight by construction, with
// no ambiguous cases (unlike the 256-case marching cubes table). Negative values are inside.
#include <cstdint>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

struct ScalarGrid {
  Vec3i dims = Vec3i::Zero();  // samples per axis; x varies fastest in `values`
  Vec3 origin = Vec3::Zero();  // position of sample (0,0,0), metres
  double spacing = 0.0;        // metres between samples
  std::vector<float> values;

  size_t index(int x, int y, int z) const {
    return (size_t(z) * size_t(dims.y()) + size_t(y)) * size_t(dims.x()) + size_t(x);
  }
  Vec3 point(int x, int y, int z) const { return origin + spacing * Vec3(x, y, z); }
};

// Where each output vertex came from: the grid edge (a, b) (linear sample indices) at
// position a + t (b − a). Lets callers interpolate their own per-sample attributes.
struct EdgeVertex {
  uint32_t a;
  uint32_t b;
  float t;
};

struct ContourResult {
  TriangleMesh mesh;
  std::vector<EdgeVertex> sources;  // one per mesh vertex
};

// Parallel over both cores; output is deterministic (independent of scheduling).
ContourResult contour(const ScalarGrid& grid);

}  // namespace inhand
