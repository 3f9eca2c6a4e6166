#pragma once
// Iso-surface extraction (f = 0) from a dense scalar grid. Negative values are inside.
//
// contour(): marching tetrahedra over the Kuhn (Freudenthal) split of every cube into 6
// tetrahedra. The split is the same in every cube, so neighbouring cubes share their face
// diagonals: the surface is watertight by construction, with no ambiguous cases (unlike the
// 256-case marching cubes table). Dense: about 6–12 triangles per surface cube.
//
// surfaceNets(): one vertex per cube the surface crosses (the mean of the crossings on its 12
// axis edges), one quad (two triangles) per axis edge that crosses, joining the 4 cubes around it.
// About a fifth of marching tetrahedra's triangles, each vertex within the cube it stands for;
// closed, but not guaranteed manifold where a cube is crossed by two sheets. Used for planning,
// where S_obj is ray cast thousands of times per Alg. 1 pass.
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
  // Vertex k stands for the crossings sources[first[k]] … sources[first[k + 1] − 1]
  // (one each for marching tetrahedra; the crossings of its cube for surface nets).
  std::vector<uint32_t> first;
  std::vector<EdgeVertex> sources;
};

struct ContourOptions {
  // contour(): the crossing edges of every sample found from a byte per sample's side in loops
  // the compiler vectorises (false: the plain per-sample loop, kept as the reference; the same
  // output bit for bit).
  bool vectorised = true;
};

// Both parallel over both cores; output is deterministic (independent of scheduling).
ContourResult contour(const ScalarGrid& grid, const ContourOptions& options = {});
ContourResult surfaceNets(const ScalarGrid& grid);

}  // namespace inhand
