#pragma once
// Grasp wrench space: contacts of a closed hand on an object, and the Ferrari–Canny ε.
//
// Contacts are the object's surface samples within `contact_m` of the closed hand, pooled into
// cells of `contact_cell_m` (one point contact per cell, at the mean point and normal). Each is a
// point contact with Coulomb friction μ, its cone linearised by `cone_edges` unit forces. Their
// wrenches (force, torque/ρ about `centre_O`, ρ a length that makes torques comparable to
// forces) span a convex hull; ε is the radius of the largest origin-centred ball inside it,
// estimated as the least support value over `directions` fixed unit directions in R⁶ (an upper
// bound that tightens with more directions). ε > 0: force closure, so the grasp resists any
// external wrench (gravity in every orientation, accelerations) given enough grip force.
#include <vector>

#include "inhand/geometry/triangle_mesh.h"
#include "inhand/robot/collision.h"

namespace inhand {

struct Contact {
  Vec3 p_O;       // contact point (object frame)
  Vec3 normal_O;  // outward surface normal there
};

// ε as described above (≤ 0: not force closure; -1 without contacts).
double forceClosureEpsilon(const std::vector<Contact>& contacts, const Vec3& centre_O, double rho,
                           double friction, int cone_edges, int directions);

// forceClosureEpsilon's plain form: every wrench of every direction (the reference the pruned one
// is tested against; the same value to the bit).
double forceClosureEpsilonReference(const std::vector<Contact>& contacts, const Vec3& centre_O,
                                    double rho, double friction, int cone_edges, int directions);

struct HandContacts {
  std::vector<Contact> contacts;  // pooled per cell
  int fingers_touching = 0;       // fingers with a sample near one of their links
  bool palm_touching = false;     // a sample within contact_m of the palm face
};

// Contacts of the hand at joints q, palm at T_O_palm, on the surface samples (frame O): every
// sample measured against the hand (the reference of the grid version below).
HandContacts handContacts(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                          const std::vector<SurfacePoint>& samples, double contact_m,
                          double contact_cell_m);

// Surface samples bucketed in a uniform grid over their bounds (at most 64 cells a side), for
// finding those near a box without visiting the others.
class SampleGrid {
 public:
  SampleGrid(std::vector<SurfacePoint> samples, double cell_m);
  const std::vector<SurfacePoint>& samples() const { return samples_; }
  // Appends the indices of the samples in the cells `box` overlaps (every sample in `box`, and
  // some near it), in ascending order within each cell.
  void near(const Aabb& box, std::vector<int>* out) const;

 private:
  std::vector<SurfacePoint> samples_;
  Vec3 origin_ = Vec3::Zero();
  double cell_ = 1;
  Eigen::Vector3i dims_ = Eigen::Vector3i::Ones();
  std::vector<int> start_, index_;  // cell c's samples: index_[start_[c] .. start_[c + 1])
};

// The same contacts, measuring only the samples in the grid cells that each hand primitive's
// box, grown by contact_m, overlaps (no other sample can be within contact_m), in the samples'
// order: equal to the reference's, sums included.
HandContacts handContacts(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                          const SampleGrid& samples, double contact_m, double contact_cell_m);

}  // namespace inhand
