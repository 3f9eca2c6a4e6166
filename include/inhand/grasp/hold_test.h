#pragma once
// Grasps chosen to hold. Force closure (ε) says a grasp could resist some wrench; whether the
// hand holds this object depends on what ε leaves out: the object's weight against the fingers'
// force limits, the arm's accelerations, the fingers pushing the object as they close one after
// another, and the turns that present the object to the camera. The hold test closes each
// candidate on the planner's model of the object in physics (physics/physics.h: the hand's force
// limits and TorqueSwitch, the model's convex pieces above the table top, its weight at an assumed
// density), lifts it as the arm lifts, turns it, and sees whether the model stays in the hand.
// The model is what the scan knows (the observed surface, closed over what it hides), never the
// true object.
#include <optional>
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/convex_decomposition.h"
#include "inhand/geometry/point_cloud.h"
#include "inhand/physics/physics.h"
#include "inhand/robot/robot_model.h"

namespace inhand {

struct GraspCandidate;

struct HoldTestOptions {
  bool enabled = true;
  int max_candidates = 12;  // the first this many candidates (in their order) are tested
  // … and while fewer than enough_held of them hold the model, the next as many, up to this many
  // in all (enough_held 3, the scan's budget of failed pick-ups, was measured on the physics set
  // and not kept: docs/physics.md).
  int max_tested = 48;
  int enough_held = 1;
  // Assumed: the model's mass is its volume times this (the simulator's default density too).
  double density_kg_m3 = 300;
  double lift_m = 0.10;  // the lift, straight up over lift_s
  double lift_s = 1.0;
  // Then the palm turns by turn_rad about a horizontal axis over turn_s (the views turn the
  // object: gravity pulls at the grasp from another side) and holds still for 0.3 s.
  double turn_rad = M_PI / 2;
  double turn_s = 1.0;
  double max_slip_m = 0.01;  // the model moved farther than this in the hand: it did not hold
  // The margin: the candidates that held are tried again on the model this many times as heavy,
  // with this fraction of the friction; those that hold then too go first (1 and 1: no margin).
  double margin_mass = 2.0;
  double margin_friction = 0.7;
  // Within each of those groups (held with the margin, held without), the candidates whose close
  // pushed the model at most this far go first, and only they count toward enough_held: a close
  // that shoves the object centimetres across the table before the fingers hold it ends where the
  // unseen surface and the table's friction put it, which the model does not know. 0: not used.
  double max_close_push_m = 0.02;
  // Where the object lies is known to the registration's error: the candidates that held are
  // tried again, in order, with the model moved this far each way across the table (four trials,
  // the hand where it was); the first that holds in all goes first. At most robust_checked
  // candidates are tried so. 0: not tried.
  double pose_tolerance_m = 0;
  int robust_checked = 4;
  // The model's pieces (at most 64; coarser hulls bulge beside thin and flat models, where a pinch
  // then starts inside them and closes over the model).
  ConvexDecompositionOptions decomposition{64, 64, 0.02};
  // MuJoCo's no-slip pass in the trials (PhysicsOptions::noslip_iterations). 0: soft contacts, a
  // model that creeps more than max_slip_m in the trial counts as not holding.
  int noslip_iterations = 0;

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.boolean("enabled", o.enabled, "test the candidates; those that hold go first");
    v.integer("max_candidates", o.max_candidates, "the first this many are tested",
              Range::atLeast(1));
    v.integer("max_tested", o.max_tested,
              "… and while fewer than enough_held hold the model, the next as many, up to this "
              "many (at least max_candidates)",
              Range::atLeast(1));
    v.integer("enough_held", o.enough_held,
              "batches are tested until this many candidates hold the model", Range::atLeast(1));
    v.num("density_kg_m3", o.density_kg_m3,
          "assumed: the model's mass is its volume times this, kg/m³", Range::open(0, 30000));
    v.num("lift_m", o.lift_m, "lifted this far straight up, m", Range::closedOpen(0, 1));
    v.num("lift_s", o.lift_s, "… over this long, s", Range::openClosed(0, 10));
    v.num("turn_rad", o.turn_rad, "then turned this far about a horizontal axis, rad",
          Range::closed(-M_PI, M_PI));
    v.num("turn_s", o.turn_s, "… over this long, s", Range::openClosed(0, 10));
    v.num("max_slip_m", o.max_slip_m, "moved farther in the hand: it did not hold, m",
          Range::open(0, 0.2));
    v.num("margin_mass", o.margin_mass,
          "those that held, tried this many times as heavy: those that hold go first",
          Range::closed(1, 20));
    v.num("margin_friction", o.margin_friction, "… with this fraction of the friction",
          Range::openClosed(0, 1));
    v.num("max_close_push_m", o.max_close_push_m,
          "… and in each group, the ones whose close pushed the model at most this far go "
          "first; only they count toward enough_held (0: not used), m",
          Range::closedOpen(0, 1));
    v.num("pose_tolerance_m", o.pose_tolerance_m,
          "those that held, tried with the model moved this far each way across the table: the "
          "first that holds in all goes first (0: not tried), m",
          Range::closedOpen(0, 0.05));
    v.integer("robust_checked", o.robust_checked, "… at most this many of them, in their order",
              Range::atLeast(1));
    ConvexDecompositionOptions::fields(v, o.decomposition, "decomposition_");
    v.integer("noslip_iterations", o.noslip_iterations,
              "MuJoCo's no-slip passes per step in the trials (0: off; soft contacts creep)",
              Range::closed(0, 100));
  }
  std::string validate() const;
};

// How far a grasp got in the hold test when it did not hold (grasp/hold_test.h), in the order
// of how far: the fingers closed and touched nothing, it fell in the lift, it fell in the turn,
// it stayed in the hand but moved too far.
enum class HoldFailure { kNone, kNotTouching, kDroppedInLift, kDroppedInTurn, kSlipped };
// "", "not_touching", "dropped_in_lift", "dropped_in_turn", "slipped" (summary.json's names).
const char* holdFailureName(HoldFailure f);
// The name back (false: not one of them; "" is kNone).
bool parseHoldFailure(const std::string& name, HoldFailure* out);

struct HoldTrial {
  bool held = false;         // still in the hand, moved at most max_slip_m
  double slip_m = 0;         // how far the model moved in the hand (its centre, from the close)
  double lift_kg = 0;        // the model's mass
  double close_moved_m = 0;  // how far the close pushed the model (its centre)
  // The grasp (the palm in the model's frame) where the close left it, when it touched.
  std::optional<Iso3> T_O_palm_closed;
  HoldFailure failure = HoldFailure::kNone;
};

// How far a trial got: 4 held, 3 slipped (in the hand, moved too far), 2 dropped in the turn,
// 1 dropped in the lift, 0 not touching after the close.
int holdStage(HoldFailure failure);

// The closed model (frame O) resting at T_B_O, as convex pieces of its part above the robot's
// table top (the unobserved space below the top is not the object) and, when `keep_O` is given,
// inside those half-spaces (where the object may lie; Plane::distance ≥ 0 inside).
std::vector<ConvexPiece> modelPiecesAboveTable(const TriangleMesh& model_O, const Iso3& T_B_O,
                                               const RobotModel& robot,
                                               const std::vector<Plane>* keep_O,
                                               const ConvexDecompositionOptions& options);

// The physics the trials run in: the model's mass at options.density_kg_m3, its no-slip passes
// options.noslip_iterations, a 2 ms step and 5 ms contacts (a coarser step than the simulator's,
// twice as fast; what the trials' verdicts were measured with: docs/physics.md).
PhysicsOptions holdTrialPhysics(const HoldTestOptions& options);

// The axis the trial turns a lifted grasp about (base frame, unit): horizontal, across the palm's
// approach; for a palm within 3° of vertical (a grasp from above, tilted a little by the close),
// its own x made horizontal, so that the axis does not swing with a fraction of a degree's tilt.
Vec3 holdTurnAxis(const Iso3& T_B_palm);

// One candidate on the model `world` holds (its object put at T_B_O, the palm at the candidate's
// pose, the fingers open as they come in): closed, lifted, turned.
HoldTrial tryHold(PhysicsWorld& world, const Iso3& T_B_O, const Iso3& T_O_palm,
                  const JointVector& q_open, const JointVector& q_closed,
                  const HoldTestOptions& options);

// Tests the first max_candidates candidates on the model (in parallel; the next as many while
// none holds, up to max_tested), records each one's outcome (keep_O: as for
// modelPiecesAboveTable; GraspCandidate::hold: 1 held, 0 not, -1 not tested) and moves those
// that held ahead of those that did not among the tested, those that held with the margin first
// (GraspCandidate::hold_margin), those that did not by how far they got (holdStage); each group
// in its order; then, with options.pose_tolerance_m, the first that held that also holds with the
// model moved by the tolerance (GraspCandidate::hold_robust) ahead of all. `friction`: μ the
// planner assumes.
// Returns the seconds it took. Nothing happens with options.enabled false.
double rankByHold(const RobotModel& robot, const TriangleMesh& model_O, const Iso3& T_B_O,
                  const std::vector<Plane>* keep_O, double friction, const HoldTestOptions& options,
                  std::vector<GraspCandidate>* candidates);
// The same on the model's pieces (modelPiecesAboveTable) already made. With
// `lift_in_view_first` (the first grasp's), among those that held alike (the same margin and
// push groups) the candidates whose lift shows the hand go first (liftInViewFirst).
double rankByHold(const RobotModel& robot, const std::vector<ConvexPiece>& pieces,
                  const Iso3& T_B_O, double friction, const HoldTestOptions& options,
                  std::vector<GraspCandidate>* candidates, bool lift_in_view_first = false);

// Whether the held object is in the camera's view at q (heldInView) and so is the palm: no link
// but the hand's on the line from the camera's pan-tilt centre to the palm's origin, sampled
// every centimetre from 5 cm out to 5 cm short of it.
bool liftShowsHand(const RobotModel& robot, const JointVector& q);

// Moves the candidates of [first, last) whose lift shows the hand (liftShowsHand at q_lift; one
// without q_lift counts as showing it) ahead of the others, each group in its order. After the
// lift the camera looks at the hand: where the arm hides it, tracking has too few of the hand's
// points to align and the pick-up is judged failed whether or not the object is held (a cup
// held up behind the upper arm, nearer the camera than its 0.5 m range). Not for re-grasps:
// their order within a hold group is the coverage ranking (eq. 9), and putting lifts in view
// first there cost coverage on the test set's thin objects (the marker 99.5 -> 88.6 %).
void liftInViewFirst(const RobotModel& robot, std::vector<GraspCandidate>::iterator first,
                     std::vector<GraspCandidate>::iterator last);

// The first grasp's model keeps the space the camera did not see only beneath measured surface
// (TableTopOptions::under_measured_only): where the object bulges past what the camera saw, the
// true surface lies beyond the model, a finger planned there meets it, and the guarded move stops
// the hand short of the plan. Of the first `checked` candidates that held (hold == 1, in their
// order), each is brought in along its approach against `unseen_O` (the model with all the
// unseen space kept: the camera's shadow, up to the table); one stopped more than 2 mm short of
// its plan is tried again from there on the model's `pieces` (what rankByHold tested). The first
// that holds so (or stopped where planned), and held with the margin where the first of them did,
// is moved to the front; every one checked records GraspCandidate::hold_unseen. Returns the seconds
// it took (0 with checked 0 or nothing held).
double preferHoldingUnseen(const RobotModel& robot, const std::vector<ConvexPiece>& pieces,
                           const TriangleMesh& unseen_O, const Iso3& T_B_O, double friction,
                           const HoldTestOptions& options, int checked,
                           std::vector<GraspCandidate>* candidates);

// "hold test: H of N candidates held the model (S s)" (N: those tested), or "" when none was.
std::string holdLine(const std::vector<GraspCandidate>& candidates, double seconds);
// "hold test with each hand where the unseen space stops it: H of N held (S s)" (N: those
// checked), or "" when none was.
std::string unseenHoldLine(const std::vector<GraspCandidate>& candidates, double seconds);

}  // namespace inhand
