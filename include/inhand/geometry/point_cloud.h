#pragma once
// Point-cloud primitives for the table-top stage (paper §V): the table plane by RANSAC, and the
// principal axes of the points above it.
#include <cstdint>
#include <optional>
#include <vector>

#include "inhand/core/types.h"

namespace inhand {

// n · p + d = 0, n a unit normal.
struct Plane {
  Vec3 n = Vec3::UnitZ();
  double d = 0;
  double distance(const Vec3& p) const { return n.dot(p) + d; }  // signed, along n
};

struct PlaneFitOptions {
  double inlier_m = 0.004;  // a point within this of the plane supports it
  int iterations = 300;     // RANSAC hypotheses (three points each)
  uint64_t seed = 1;        // for the hypotheses
  Vec3 expected_normal = Vec3::UnitZ();
  double max_tilt_deg = 25;  // hypotheses whose normal is farther from expected_normal lose
  // Where the plane is expected (a robot's table, from its config): hypotheses through points
  // farther than `max_offset_m` from it, or tilted more than `max_expected_tilt_deg` from
  // expected_normal, lose (a plane through the table and the foot of a large object's face
  // can otherwise collect more inliers than the little table left in view). Without it, the largest
  // plane wins (a large object's top face can outnumber the table's visible points).
  std::optional<Plane> expected_plane;
  double max_offset_m = 0.05;
  double max_expected_tilt_deg = 5;
};

struct PlaneFit {
  Plane plane;  // least-squares refit on the inliers; n oriented towards expected_normal
  int inliers = 0;
};

// RANSAC over three-point hypotheses, then a least-squares refit (smallest principal axis of the
// inliers). nullopt when fewer than 3 points or no hypothesis within the tilt limit.
std::optional<PlaneFit> fitPlaneRansac(const std::vector<Vec3>& points,
                                       const PlaneFitOptions& options = {});

// The points of the largest Euclidean cluster: points are linked when they share a cell of size
// `cell_m` or lie in neighbouring cells (26-connected), so clusters are separated by gaps of
// more than about two cells. Removes the stray returns that would stretch the principal extents.
std::vector<Vec3> largestCluster(const std::vector<Vec3>& points, double cell_m);

struct PrincipalAxes {
  Vec3 centroid = Vec3::Zero();
  Mat3 axes = Mat3::Identity();   // columns: unit axes, largest variance first (right-handed)
  Vec3 variances = Vec3::Zero();  // along each axis, m², descending
  Vec3 min = Vec3::Zero(), max = Vec3::Zero();  // extent of the points along each axis
};

// Principal axes of the points (the eigenvectors of their covariance); throws on no points.
PrincipalAxes principalAxes(const std::vector<Vec3>& points);

// Principal axes of an object resting on a plane with normal `up`: one axis is `up`, the other
// two are the principal axes of the points projected onto the plane, turned (within ±45°) to
// the least-area rectangle around those projections. Axes are ordered by the
// points' extent along them, largest first (a camera sees one side of the object, which tilts
// free principal axes; resting objects have a vertical axis of symmetry more often than not).
// Extents (and the rectangle) leave out the `trim` fraction of points at each end: depth noise
// on faces seen at a slant scatters a few points millimetres beyond them.
PrincipalAxes principalAxesUpright(const std::vector<Vec3>& points, const Vec3& up,
                                   double trim = 0.01);

}  // namespace inhand
