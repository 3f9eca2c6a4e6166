#pragma once
// Indexed triangle mesh in metres. Vertices are float (what Embree consumes); triangles are
// counter-clockwise seen from outside, so face normals point out of closed meshes.
#include <array>
#include <string>
#include <vector>

#include "inhand/core/types.h"

namespace inhand {

using Tri = Eigen::Vector3i;

struct Aabb {
  Vec3 min = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 max = Vec3::Constant(-std::numeric_limits<double>::infinity());
  void extend(const Vec3& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  bool empty() const { return !(min.array() <= max.array()).all(); }
  Vec3 center() const { return 0.5 * (min + max); }
  // p inside or on the boundary.
  bool contains(const Vec3& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
  Vec3 size() const { return max - min; }
  // Corner k of 8: bit 0 picks max.x, bit 1 max.y, bit 2 max.z.
  Vec3 corner(int k) const {
    return Vec3((k & 1) ? max.x() : min.x(), (k & 2) ? max.y() : min.y(),
                (k & 4) ? max.z() : min.z());
  }
};

struct TriangleMesh {
  std::vector<Vec3f> vertices;
  std::vector<Tri> triangles;

  bool empty() const { return triangles.empty(); }
  Aabb bounds() const;
  double area() const;
  // Signed enclosed volume (positive for a closed, outward-oriented mesh).
  double signedVolume() const;
  Vec3 faceNormal(int tri) const;  // unit; zero for degenerate triangles
  double triangleArea(int tri) const;
  // Appends another mesh (indices shifted).
  void append(const TriangleMesh& other);
  // Every undirected edge used by exactly two triangles, in opposite directions.
  bool isClosed() const;
  // Every directed edge is used as often as its reverse: the triangles bound a region (edges
  // where surfaces touch may be shared by four), as contouring a scalar field gives. Weaker
  // than isClosed, which also asks for a manifold.
  bool isWatertight() const;
  // Number of edges used by only one triangle.
  int boundaryEdgeCount() const;
};

TriangleMesh transformed(const TriangleMesh& mesh, const Iso3& T);

// Area-weighted vertex normals (unit; +z where every triangle around is degenerate).
std::vector<Vec3f> vertexNormals(const TriangleMesh& mesh);

// Merges vertices with identical coordinates (after rounding to `tolerance_m`), drops triangles
// that become degenerate. STL files come unwelded; this makes them indexed. `kept_triangles`
// receives the old index of each triangle kept, `vertex_remap` each old vertex's new index.
TriangleMesh welded(const TriangleMesh& mesh, double tolerance_m = 1e-7,
                    std::vector<int>* kept_triangles = nullptr,
                    std::vector<int>* vertex_remap = nullptr);

// The mesh with fewer triangles by vertex clustering: vertices in one cube of `cell_m` (a grid
// through the origin) become one, at their mean; triangles that become degenerate or repeat
// another (the same three vertices, either orientation) are dropped. Shape error at most about
// a cell; the topology may change where parts are thinner than a cell.
TriangleMesh clustered(const TriangleMesh& mesh, double cell_m);
// clustered() at the smallest cell (from the mean edge length, growing by 25 % a step) that
// leaves at most `max_triangles`; the mesh itself when it has no more than that.
TriangleMesh simplifiedTo(const TriangleMesh& mesh, size_t max_triangles);

// The mesh without the vertices no triangle uses (the triangles renumbered, in order): what a
// mesh cut out of a bigger one keeps, so that its bounds and samples are its triangles'.
TriangleMesh withoutUnusedVertices(const TriangleMesh& mesh);

// The mesh with each hole (a loop of edges only one triangle uses) closed by a fan of triangles
// about the loop's centroid, facing the same way as the triangles around it: a scanned mesh open
// where its scanner could not see (the Stanford bunny's base) as the solid object it stands for,
// so that a simulated camera cannot look into it. `loops_closed` receives how many holes were
// closed. A closed mesh comes back unchanged.
TriangleMesh withHolesClosed(const TriangleMesh& mesh, int* loops_closed = nullptr);

// Points on the surface with outward normals: every vertex (area-weighted face normals), plus a
// lattice of about `spacing_m` on triangles larger than that (so coarse meshes are covered too).
struct SurfacePoint {
  Vec3 p, n;
  double var = 0;  // the point's own surface variance, m² (a scanned model's; 0: exact)
};
std::vector<SurfacePoint> surfaceSamples(const TriangleMesh& mesh, double spacing_m);

// Points on the surface about `spacing_m` apart whatever the triangles' shapes and sizes (long
// slivers and fine tessellations alike): triangles split along their longest edge until no edge
// is longer than `spacing_m`, the pieces' centroids kept one per cube of that size and normal
// direction (six, by the normal's dominant axis, so that both sides of a thin part stay), each
// with its triangle's outward normal. In mesh order: the same points for the same mesh.
std::vector<SurfacePoint> evenSurfaceSamples(const TriangleMesh& mesh, double spacing_m);

// The mesh with every edge longer than max_edge_m split at its middle until none is (red-green
// refinement: a triangle with one, two or three split edges becomes two, three or four, so that
// neighbours stay joined and the orientation is kept); the surface is unchanged. `flags` (optional,
// one per vertex) is extended: a new vertex is flagged when both ends of its edge are.
TriangleMesh subdivided(const TriangleMesh& mesh, double max_edge_m,
                        std::vector<uint8_t>* flags = nullptr);

// Checks indices and finite coordinates; returns an empty string when valid, else the problem.
std::string validateMesh(const TriangleMesh& mesh);

}  // namespace inhand
