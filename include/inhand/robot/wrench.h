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

struct HandContacts {
  std::vector<Contact> contacts;  // pooled per cell
  int fingers_touching = 0;       // fingers with a sample near one of their links
  bool palm_touching = false;     // a sample within contact_m of the palm face
};

// Contacts of the hand at joints q, palm at T_O_palm, on the surface samples (frame O).
HandContacts handContacts(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                          const std::vector<SurfacePoint>& samples, double contact_m,
                          double contact_cell_m);

}  // namespace inhand
