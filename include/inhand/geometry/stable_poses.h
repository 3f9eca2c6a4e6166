#pragma once
// Resting poses of a rigid object on a plane (quasi-static): the object comes to rest on a face
// of its convex hull. Each hull facet (coplanar hull triangles merged) gets the solid angle it
// subtends at the centre of mass, over 4π, as the probability that the object lands on it. A
// facet whose plane does not contain the centre of mass's projection inside it is unstable: the
// object rolls over the edge the projection lies beyond, onto the next facet, which inherits its
// probability. Adjacent stable facets whose planes lie equally far from the centre of mass
// (within 1 % or 1 mm) and within 15° of each other are one pose (a cylinder's side). The centre
// of mass is that of the solid the mesh encloses (uniform density), or of its hull when the mesh
// is not closed.
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

struct ConvexHull {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 3>> triangles;  // outward (counter-clockwise seen from outside)
};
// The convex hull of the points (incremental; coplanar and duplicate points dropped).
ConvexHull convexHull(const std::vector<Vec3>& points);

struct StablePose {
  Vec3 down_O;             // outward normal of the face it rests on (points into the table)
  double probability = 0;  // quasi-static probability of coming to rest on it
  double height_m = 0;     // the centre of mass above the table
  Mat3 R_B_O;              // an orientation resting on it: R_B_O · down_O = −z
};

// Stable poses, most probable first (probabilities sum to 1).
std::vector<StablePose> stablePoses(const TriangleMesh& mesh);

// Centre of mass of the solid the mesh encloses (uniform density); the vertex mean when the
// enclosed volume is negligible.
Vec3 centreOfMass(const TriangleMesh& mesh);

}  // namespace inhand
