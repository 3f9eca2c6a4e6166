#pragma once
// Collision checks with FCL: the arm, the hand and a held object against the table and the
// robot's own static base, at a configuration or along a joint-space path. Self-collision between
// arm links is not checked (links adjacent to the base are listed in the config and skipped
// against it).
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "inhand/robot/robot_model.h"

namespace inhand {

class CollisionChecker {
 public:
  explicit CollisionChecker(const RobotModel& model);
  ~CollisionChecker();
  CollisionChecker(CollisionChecker&&) noexcept;

  // Attaches an object (mesh in its own frame O) rigidly to the tip at T_tip_O.
  void setHeldObject(const TriangleMesh& mesh_O, const Iso3& T_tip_O);
  void clearHeldObject();

  // True when something collides at q; `what` (optional) says which pair. Thread-safe.
  bool inCollision(const JointVector& q, std::string* what = nullptr) const;
  // Checks straight-line joint-space motion a → b at steps of at most `step_rad` per joint.
  bool pathFree(const JointVector& a, const JointVector& b, double step_rad = 0.02,
                std::string* what = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Hand geometry (S_hand of Alg. 1) at given hand joint values (the arm part of q is ignored),
// placed by the palm pose T_F_palm in any frame F.
class HandGeometry {
 public:
  HandGeometry(const RobotModel& model, const JointVector& q, const Iso3& T_F_palm);
  // All hand links' collision geometry as one mesh in F (closed pieces, may overlap).
  TriangleMesh mesh() const;
  // Whether p_F lies inside any hand link's geometry (exact for boxes, cylinders, spheres).
  bool contains(const Vec3& p_F) const;
  // Signed distance (m) from p_F to the hand: negative inside. Exact for boxes, cylinders and
  // spheres; mesh links give 0 inside and +infinity outside. `nearest` (optional) receives the
  // model's index of the nearest link.
  double distance(const Vec3& p_F, int* nearest = nullptr) const;
  // distance() where it is at most `limit` (the same value and nearest link), +infinity beyond
  // it: only the primitives whose box in F, grown by `limit`, holds p_F are measured.
  double distanceWithin(const Vec3& p_F, double limit, int* nearest = nullptr) const;
  // Link poses T_F_link of the hand links, in handLinks() order.
  const std::vector<Iso3>& linkPoses() const { return T_F_link_; }
  // A box in F holding every link's geometry (the union of each primitive's box: the exact
  // primitives, not their tessellation in mesh()), without building a mesh.
  Aabb bounds() const;
  // Each primitive's box in F, per hand link (handLinks() order) and primitive: the boxes
  // distanceWithin tests a point against.
  const std::vector<std::vector<Aabb>>& primitiveBoxes() const { return boxes_F_; }

 private:
  const RobotModel* model_;
  std::vector<Iso3> T_F_link_;
  // Their inverses, and each link's primitives' T_geom_link, computed once (distance() is the
  // grasp search's innermost call).
  std::vector<Iso3> T_link_F_;
  std::vector<std::vector<Iso3>> T_geom_link_;
  // Each primitive's bounding box in F, per link and primitive (distanceWithin).
  std::vector<std::vector<Aabb>> boxes_F_;
  double primitiveDistance(const Primitive& p, const Vec3& p_geom, const Vec3& p_link) const;
};

struct FingerClosing {
  double value = 0;      // the finger joint's value where it stopped
  bool contact = false;  // stopped by touching the object (else it reached `closed`)
  // How many of the closing's steps were free of contact before it touched (all of them when it
  // did not; -1 when it touched where it started).
  int free_steps = -1;
};

struct ClosingResult {
  JointVector q;  // q with the finger joints (and their couplings) at the stopping values
  std::vector<FingerClosing> fingers;  // one per RobotModel::fingers()
};

// Closes each finger from its value in q (clamped to [open, closed]: the open hand, or a
// preshape) towards `closed` until its links touch the object
// (mesh in frame O; palm at T_O_palm), refining the contact by bisection to `tolerance` (rad or
// m). Other hand joints (spread) are taken from q.
ClosingResult closeFingers(const RobotModel& model, const JointVector& q, const Iso3& T_O_palm,
                           const TriangleMesh& object_O, double step = 0.02,
                           double tolerance = 1e-4);

// The same with the object's and fingers' collision structures built once, for many grasps on
// one object; close() is const and thread-safe. Box links meet the object's triangles by the
// separating-axis test (TriangleBoxIndex), other links as triangle meshes in FCL; `reference`:
// every link through FCL (what tests compare with). The two differ only where an object
// triangle lies wholly inside a link's box, which the box test counts as touching.
class FingerCloser {
 public:
  FingerCloser(const RobotModel& model, const TriangleMesh& object_O, bool reference = false);
  const RobotModel& model() const { return *model_; }
  // With `free_from` (a closing of the same q, pose and step against a superset of this object,
  // e.g. the object and the table), the steps it found free are not checked again: they are free
  // of this object too (the same result, fewer collision checks).
  ClosingResult close(const JointVector& q, const Iso3& T_O_palm, double step = 0.02,
                      double tolerance = 1e-4, const ClosingResult* free_from = nullptr) const;
  // Whether any hand link (palm included) at q, palm at T_O_palm, touches the object's surface.
  // (A link wholly inside the object does not touch it: approach from outside.)
  bool handTouches(const JointVector& q, const Iso3& T_O_palm) const;
  // The approach to first contact: how far the whole hand at q can move from T_O_palm along the
  // unit direction dir_O before any link touches the object, stepping `step` and bisecting to
  // `tolerance` (m); `max_travel` when nothing is touched on the way, nullopt when the hand
  // touches the object at T_O_palm already. `step` must be below the thinnest link and object
  // wall for no contact to be stepped over.
  std::optional<double> freeTravel(const JointVector& q, const Iso3& T_O_palm, const Vec3& dir_O,
                                   double max_travel, double step = 0.01,
                                   double tolerance = 5e-4) const;

 private:
  struct Geometry;
  const RobotModel* model_;
  std::shared_ptr<const Geometry> geometry_;
};

// Closing on an object that rests on a table, as a hand with fingertip force sensing would: the
// fingers close against object and table (`both`); where one stops on the table short of where
// the object alone (`object`) would stop it, the palm backs off along its axis by `step_m` and
// the fingers close again from the preshape, up to `max_backoff_m`. Short, flat objects are
// then gripped with the fingertips skimming the table. Returns the closing and the palm pose.
std::pair<ClosingResult, Iso3> closeOffTheTable(const FingerCloser& both,
                                                const FingerCloser& object, const JointVector& q,
                                                const Iso3& T_O_palm, double step_m = 0.005,
                                                double max_backoff_m = 0.03,
                                                double closing_step = 0.06);

// How far objects of a given width get into the open hand (fingers at their `open` values, other
// joints at home): a slab `width_m` wide across palm x (axis 0) or palm y (axis 1), unbounded
// along the other palm axis, meets the hand coming along palm z until any link first touches
// (FingerCloser::freeTravel). Returns the depth from the fingertips' level down to where the slab
// stops: the hand's whole reach beyond the palm for a slab that slips between the fingers to the
// palm, about 0 for one that lands on the fingertips. `spread`: the spread joint's value (hands
// with one). With a finite `edge_x_m` the slab ends at palm x = edge_x_m (an object's edge held
// with the palm axis just inside it, as in the edge grasps), else it is unbounded along x too.
double openHandDepth(const RobotModel& model, int axis, double width_m, double spread = 0,
                     double edge_x_m = std::numeric_limits<double>::infinity());
// How far the open hand reaches beyond its palm link along palm z.
double openHandReach(const RobotModel& model);

// The robot's table as a box mesh in frame O, for an object resting at T_B_O.
TriangleMesh tableMeshInObject(const RobotModel& robot, const Iso3& T_B_O);

}  // namespace inhand
