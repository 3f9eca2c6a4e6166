#pragma once
// Mass properties of a closed mesh, and its decomposition into convex pieces for a physics
// engine that collides convex shapes only (MuJoCo collides every mesh geom by its hull).
#include <optional>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

// The solid a closed, outward-oriented mesh encloses, at unit density (kg/m³ = 1): its volume
// (m³), centre of mass and inertia tensor about the centre of mass (kg·m² per kg/m³), by the
// divergence theorem over the tetrahedra the triangles span with a point (exact for a closed
// mesh). Multiply volume and inertia by a density for kilograms.
struct ConvexPiece;
struct MassProperties {
  double volume_m3 = 0;
  Vec3 com = Vec3::Zero();
  Mat3 inertia_com = Mat3::Zero();
};
MassProperties massProperties(const TriangleMesh& closed);
// The solid as the union of convex pieces that do not overlap (each the solid its hull
// encloses): volumes and centres added, inertias about the common centre of mass (parallel
// axis theorem).
MassProperties massProperties(const std::vector<ConvexPiece>& pieces);

// The volume a convex hull encloses (m³).
double hullVolume(const ConvexHull& hull);

struct ConvexDecompositionOptions {
  int resolution = 64;       // voxels along the mesh's longest side (the solid's volume per box)
  int max_pieces = 128;      // at most this many pieces
  double max_excess = 0.03;  // stop once the hulls exceed the solid by this fraction of its volume

  // Rows keyed `prefix` + name ("decomposition_resolution" where an owner flattens them).
  template <class V, class S>
  static void fields(V& v, S& o, const std::string& prefix = "") {
    v.integer(prefix + "resolution", o.resolution,
              "voxels along the object's longest side for its convex decomposition",
              Range::closed(4, 512));
    v.integer(prefix + "max_pieces", o.max_pieces, "at most this many convex pieces",
              Range::closed(1, 1024));
    v.num(prefix + "max_excess", o.max_excess,
          "the pieces' hulls exceed the solid by at most this fraction of its volume",
          Range::closedOpen(0, 1));
  }
  std::string validate() const;
};

struct ConvexPiece {
  ConvexHull hull;       // the piece's hull (vertices and outward triangles), mesh frame
  double volume_m3 = 0;  // the hull's volume
};

// The solid split into pieces by axis-aligned cuts (each piece the hull of the solid's part in a
// box of a binary space partition; boxes apart, so the hulls' volumes add up): the piece whose
// hull exceeds its part of the solid most (hull volume − the box's solid voxels) is cut next,
// along the axis and at the quarter that leaves the least excess, until the excess is at most
// max_excess of the solid's volume or max_pieces are reached. A piece's hull is that of the
// mesh's triangles clipped to its box and of the box's corners inside the solid, so a convex part
// comes out exact. Deterministic. The mesh must be closed (a hollow cup, ring or clamp needs its
// walls as a closed solid); an empty result for an empty mesh.
std::vector<ConvexPiece> convexDecomposition(const TriangleMesh& closed,
                                             const ConvexDecompositionOptions& options = {});

// The part of a convex piece where n·x ≥ d (n a unit vector): the hull of its vertices on that
// side and of its edges' crossings of the plane. nullopt when less than 1e-9 m³ is left.
std::optional<ConvexPiece> clipPiece(const ConvexPiece& piece, const Vec3& n, double d);

}  // namespace inhand
