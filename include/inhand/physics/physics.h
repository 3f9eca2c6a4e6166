#pragma once
// Rigid-body physics for the simulator's manipulation (MuJoCo 2.2): the true object as a free
// body with mass and inertia from its closed mesh, colliding through a convex decomposition of
// it; the robot's hand (the tip link and every link below it in the URDF) as a free body welded
// to a kinematic target that follows the arm, its finger joints driven by force-limited position
// servos; the table. Only the simulator uses it (nothing in the scan reads its state).
#include <memory>
#include <string>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/core/options.h"
#include "inhand/geometry/convex_decomposition.h"
#include "inhand/robot/robot_model.h"

namespace inhand {

struct PhysicsOptions {
  // true: every pick-up, motion with the object in the hand and put-down is simulated (MuJoCo);
  // false: the kinematic simulator (the object moves rigidly with the hand; whether a grasp
  // holds is SimOptions::check_hold's static test). Off in this struct; on in a scan's config
  // (ScanConfig), so that `inhand scan` simulates physics unless told otherwise.
  bool enabled = false;
  double density_kg_m3 = 300;  // the object's density (of the solid its closed mesh encloses)
  double mass_kg = 0;          // > 0: the object's mass, whatever its volume
  // MuJoCo's step, and the time constant of every contact's soft constraint (solref; at least
  // twice the step, MuJoCo's floor). A held object walks along the fingers' contacts as the load
  // on them turns, well inside the friction cone, by an amount that shrinks with the time
  // constant (docs/physics.md: 2.1 mm over nine turns of the palm at 5 ms, 0.7 mm at 2 ms).
  // The table's contacts have their own (docs/physics.md: at 5 ms three more first candidates
  // hold, table-level pinches among them, while fewer whole scans reach 97 % coverage).
  double timestep_s = 0.001;
  double contact_timeconst_s = 0.002;
  double table_contact_timeconst_s = 0.002;
  // The hand (BarrettHand BH8-280 figures, Barrett's support wiki): each finger pushes with at
  // most this force at its tip (load limit 2 kg per finger); open to closed in this time
  // (finger_close_time_s); worm-driven joints that do not backdrive: a closed finger holds its
  // position up to hold_force_factor times the driving force.
  double finger_force_n = 20;
  // The fingers first close with this force until each has met something (so that the first to
  // arrive does not push the object off the others), then squeeze with finger_force_n.
  double touch_force_n = 2;
  double finger_close_time_s = 1.0;
  double hold_force_factor = 20;
  // TorqueSwitch: once a finger's driven (proximal) joint stalls, its coupled (distal) joints
  // close on at this multiple of the driven joint's rate (BH8-280: 125 / 93.75 reductions).
  double breakaway_rate = 125.0 / 93.75;
  // The table-level pinch: when the hand's lowest point starts within this of the table top as
  // the fingers close, the arm lowers the palm as they close so that the lowest point stays
  // where it started (the fingertips sweep along the table rather than rising with the curling
  // fingers: they meet a thin body at its middle or below), by at most 3 cm. 0: off.
  double table_sweep_m = 0.005;
  // The arm's motions: each trajectory segment speeds up and slows down over at most this long
  // (a trapezoidal profile at the joints' speed limits), m/s² at the palm stay those of an arm.
  double ramp_s = 0.3;
  // After a put-down or a drop the object settles for at most this long (s).
  double settle_s = 2.0;
  // MuJoCo's no-slip solver passes per step (opt.noslip_iterations): soft contacts let a body
  // resting in static friction creep; this pass removes that drift. 0: off.
  int noslip_iterations = 10;
  // Rows of MuJoCo's constraint buffer to begin with (njmax; contacts: a quarter as many). MuJoCo
  // 2.2 sizes its buffers once, and its A·R matrix holds rows² numbers (6000 rows: 288 MB,
  // zeroed when a world starts); a step that fills them doubles both and is taken again, so a
  // full buffer never drops a contact. Whole scans of six of the test set's many-piece objects
  // (ring, bowl, cup, mug, pitcher, drill) needed at most 703 (the ring, 174 contacts).
  int constraint_rows = 1024;
  ConvexDecompositionOptions decomposition;

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.boolean("enabled", o.enabled,
              "simulate every manipulation in MuJoCo (off: the kinematic simulator, the object "
              "moves rigidly with the hand; `inhand scan --physics`)");
    v.num("density_kg_m3", o.density_kg_m3, "the object's density, kg/m³",
          Range::openClosed(0, 30000));
    v.num("mass_kg", o.mass_kg, "the object's mass (0: from the density), kg",
          Range::closed(0, 100));
    v.num("timestep_s", o.timestep_s, "MuJoCo's time step, s", Range::closed(1e-4, 0.01));
    v.num("contact_timeconst_s", o.contact_timeconst_s,
          "contacts' soft-constraint time constant (at least 2 timestep_s; stiffer: less creep), s",
          Range::closed(2e-4, 0.1));
    v.num("table_contact_timeconst_s", o.table_contact_timeconst_s,
          "the table's contacts' time constant (at least 2 timestep_s), s",
          Range::closed(2e-4, 0.1));
    v.num("finger_force_n", o.finger_force_n, "each finger's force limit at its tip, N",
          Range::openClosed(0, 1000));
    v.num("touch_force_n", o.touch_force_n,
          "fingers close with this force (at most finger_force_n) until each meets something, "
          "then squeeze, N",
          Range::openClosed(0, 1000));
    v.num("finger_close_time_s", o.finger_close_time_s, "fingers open to closed, s",
          Range::openClosed(0.05, 10));
    v.num("hold_force_factor", o.hold_force_factor,
          "a closed finger resists this multiple of its drive force (worm drive)",
          Range::closed(1, 1000));
    v.num("breakaway_rate", o.breakaway_rate,
          "TorqueSwitch: coupled joints' rate after the driven joint stalls, relative to it",
          Range::closed(0, 10));
    v.num("table_sweep_m", o.table_sweep_m,
          "a hand closing this near the table top is lowered as its fingertips rise, m",
          Range::closed(0, 0.05));
    v.num("ramp_s", o.ramp_s, "each motion segment speeds up and slows down over this long, s",
          Range::closed(0, 2));
    v.num("settle_s", o.settle_s, "longest wait for the object to come to rest, s",
          Range::closed(0, 20));
    v.integer("noslip_iterations", o.noslip_iterations,
              "MuJoCo's no-slip solver passes per step (0: off; soft contacts creep)",
              Range::closed(0, 100));
    v.integer("constraint_rows", o.constraint_rows,
              "rows of MuJoCo's constraint buffer to begin with (contacts: a quarter; both "
              "double whenever a step fills them)",
              Range::closed(16, 100000));
    ConvexDecompositionOptions::fields(v, o.decomposition, "decomposition_");
  }
  std::string validate() const;
};

class PhysicsWorld {
 public:
  // `object_O`: the true object's closed mesh in its frame O; `friction`: μ at every contact.
  // Throws Error when MuJoCo refuses the model (the message names the part).
  PhysicsWorld(const RobotModel& model, const TriangleMesh& object_O, double friction,
               const PhysicsOptions& options);
  // The object as convex pieces already made (frame O; they must not overlap): its solid is their
  // union, its mass and inertia theirs.
  PhysicsWorld(const RobotModel& model, std::vector<ConvexPiece> pieces, double friction,
               const PhysicsOptions& options);
  ~PhysicsWorld();
  // How often a step filled MuJoCo's buffers and they were doubled (PhysicsOptions::
  // constraint_rows).
  int buffersGrown() const;
  PhysicsWorld(const PhysicsWorld&) = delete;
  PhysicsWorld& operator=(const PhysicsWorld&) = delete;

  double mass_kg() const;
  int pieces() const;              // convex pieces the object collides through
  double piecesVolume_m3() const;  // their hulls' volume
  const std::vector<ConvexPiece>& decomposition() const;

  // Puts the object at T_B_O at rest, the hand's palm at T_B_palm with the hand joints of q (an
  // open preshape), both at rest.
  void reset(const Iso3& T_B_O, const Iso3& T_B_palm, const JointVector& q);
  // Closes every finger from where it is toward its `closed` value with the TorqueSwitch until
  // each joint stalls on something or reaches its limit (at most twice finger_close_time_s),
  // pressing with touch_force_n; then squeezes with finger_force_n for 0.2 s and locks them.
  // Returns q with the hand joints as they ended.
  JointVector closeHand(const JointVector& q);
  // Opens the fingers to their open values over finger_close_time_s (the palm held).
  void openHand();
  // The palm moves to T_B_palm over `duration_s`, linearly (position and orientation), physics
  // stepping along: the object moves only as contacts and gravity move it.
  void movePalm(const Iso3& T_B_palm, double duration_s);
  // Puts the object at T_B_O, at rest (an injected slip).
  void moveObject(const Iso3& T_B_O);
  // Steps with the palm held until the object is at rest (at most `max_s`).
  void settle(double max_s);

  Iso3 objectPose() const;     // T_B_O
  Iso3 palmPose() const;       // T_B_palm as simulated (it trails its target by the weld's give)
  double objectSpeed() const;  // m/s of its centre of mass
  bool objectTouchesHand() const;
  bool objectTouchesTable() const;
  bool handTouchesTable() const;  // any hand link
  // The object's contacts now: where (base frame), the normal pointing into the object, and what
  // it touches (a hand link's index into RobotModel::links(), or -1 for the table).
  struct Contact {
    Vec3 p_B;
    Vec3 normal_B;
    int link;
  };
  std::vector<Contact> objectContacts() const;
  JointVector handJoints(const JointVector& q) const;  // q with the hand joints as simulated
  // Each hand link's pose as simulated (link index into RobotModel::links(), T_B_link).
  std::vector<std::pair<int, Iso3>> handLinkPoses() const;
  // The whole dynamic state (positions, velocities, servo targets and limits, the solver's warm
  // start), for checkpoints: setState(state()) continues exactly as without the break.
  Json state() const;
  void setState(const Json& state);  // throws Error on a state of another model
  double simulated_s() const;        // physics time stepped so far, s
  // Steps MuJoCo found unstable (bad accelerations): each undone (the state before it, at rest).
  int unstableSteps() const;
  double wall_s() const;  // computation spent stepping, s

  struct Impl;  // MuJoCo's model and data (physics.cc)

 private:
  void build(const RobotModel& model, std::vector<ConvexPiece> pieces, const MassProperties& mp,
             double friction, const PhysicsOptions& options);
  std::unique_ptr<Impl> impl_;
};

}  // namespace inhand
