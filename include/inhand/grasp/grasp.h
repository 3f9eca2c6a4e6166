#pragma once
// Grasp candidates on a model of the object resting on the table, their stability, and (for
// re-grasps, paper §IV, §V-B) their ranking by what Alg. 1 could still see with the hand there.
// The same generator makes the first grasp, on the model the table-top frames give (the observed
// surface, closed over what it hides), and every re-grasp, on the model so far.
//
// Candidates (BarrettHand-style hands: a palm and closing fingers, optional spread):
//   - approach directions spread over the sphere, palm rolls about each, spread settings and
//     preshapes (how far the fingers are already closed as the hand comes in), the palm axis
//     through the model's centre; then the edge poses and the pinch poses (below);
//   - the preshaped hand comes along the approach until any link first touches the model or the
//     table (GraspApproach::kFirstContact, the default), or the palm face is slid until it
//     touches the nearest surface sample inside its footprint (kPalm; samples: the vertices
//     of the model's triangles, plus a lattice of half a contact cell on larger triangles);
//     the hand first comes to the model alone, and where it would then reach below the table
//     top, the palm rises along the table normal (while its axis stays on the model) and comes
//     in again stopping at model or table: a hand coming straight down stops with its
//     fingertips on the table;
//   - fingers closed from the preshape until contact with the model or the table
//     (robot::FingerCloser); a finger stopped by the table touches nothing;
//   - kept when at least two links touch the model, the grasp is force closure (below), the
//     hand on the object resting on the table stays above the table top, and the arm reaches
//     it and the lift pose (IK, collision).
//
// Stability: robot/wrench.h (Ferrari–Canny ε on the model's surface samples near the closed
// hand, Coulomb friction μ); ε > 0 means force closure.
#include <optional>
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/point_cloud.h"
#include "inhand/grasp/hold_test.h"
#include "inhand/mesh/extract.h"
#include "inhand/planning/view_selection.h"
#include "inhand/robot/wrench.h"

namespace inhand {

// How a candidate's open hand comes to the object along its approach.
enum class GraspApproach {
  // The palm slides until its face touches the model; the preshaped fingers may start inside
  // the object, and the hand-aware update then empties the object where they are. Kept for
  // comparison.
  kPalm,
  // The whole preshaped hand comes in from outside until any link, palm or finger, touches the
  // model or the table: it never starts inside the object (physically valid; the default).
  kFirstContact,
};
inline constexpr EnumNames<GraspApproach, 2> kGraspApproachNames = {
    {GraspApproach::kPalm, "palm"}, {GraspApproach::kFirstContact, "first_contact"}};
const char* graspApproachName(GraspApproach a);  // palm, first_contact
bool parseGraspApproach(const std::string& name, GraspApproach* a);

struct GraspOptions {
  GraspApproach approach = GraspApproach::kFirstContact;
  int approaches = 64;               // approach directions over the sphere
  int rolls = 4;                     // palm rolls about each approach (over 180°)
  std::vector<double> spreads{0.0};  // spread joint values tried (hands with a spread joint)
  // Preshapes: each finger this fraction of the way from open to closed as the hand comes in
  // (BarrettHand: 0 flat fingers, 0.25 ≈ 35°, 0.45 ≈ 63°, 0.6 ≈ 84° flexion, fingertips down).
  std::vector<double> preshapes{0.0, 0.25, 0.45, 0.6};
  // Edge poses (hands with a spread joint), at each of these spreads: palm z along ± each of the
  // model's principal axes, palm y along another, palm x either way along the third (24 poses),
  // the palm axis moved along palm x until the model ends `edge_inset_m` beyond it. At 90° the
  // BarrettHand's fingers 1 and 2 face each other 150 mm apart at their flexion joints, while
  // finger 3 closes over the edge.
  std::vector<double> edge_spreads{M_PI / 2};
  double edge_inset_m = 0.005;
  // Pinch poses: the hand straight down onto the model's footprint, palm x across each side of
  // its least-area rectangle on the table, fingertips preshaped to straddle the model just wider
  // than it (8 and 20 mm each side), coming down beside it to the table and closing on it low;
  // and the same over the footprint's narrow parts (a handle, a ring's rim, a hammer's head: runs
  // of the footprint along its principal axes at least 10 mm narrower than the whole; the 12
  // nearest the model's centre).
  bool pinch_poses = true;
  // Two-finger pinch poses (hands with a spread joint and three fingers or more), with the pinch
  // poses: the spread at `two_finger_spread`, where the first two fingers face each other (the
  // BarrettHand's fingers 1 and 2 at 90°), every other finger left open out of the way
  // (RobotModel::closingFingers), palm y across each side of the footprint, the two fingertips
  // preshaped 3, 6 and 10 mm wider than the model on each side. Their end faces then meet a thin
  // body lying on the table at its middle or below it (with PhysicsOptions::table_sweep_m): the
  // grasp that lifts a pen or a marker, where three fingers closing from both sides meet it
  // above its middle with their inclined distal links.
  bool two_finger_pinch = true;
  double two_finger_spread = M_PI / 2;
  double friction = 0.5;          // μ at each contact
  int cone_edges = 8;             // friction-cone linearisation
  int wrench_directions = 1000;   // directions sampled for ε
  double contact_m = 0.003;       // model vertices this close to the hand are in contact
  double contact_cell_m = 0.01;   // contact pooling cell, m
  double min_epsilon = 1e-4;      // ε below this: not a stable grasp
  double stability_weight = 0.0;  // score = quality + weight·ε
  // Failed pick-ups per grasp before the scan gives up on that grasp (first grasp:
  // pick_up_failed; a re-grasp: regrasp_failed, with the model of the grasps so far).
  int max_failed_pick_ups = 3;
  int max_candidates = 50;  // ranked at most (the most stable first)
  HoldTestOptions hold;     // the candidates tried in physics on the model (grasp/hold_test.h)
  double lift_m = 0.15;     // the object is lifted this far after the pick
  // The lift's arm pose solved in five steps up from the pick, each seeded from the last and
  // without random restarts, and kept only where the joint-space move to it rises straight
  // (liftPathDeviation ≤ kMaxLiftDeviation; else the candidate is unreachable). Without it the
  // lift is one IK solve seeded from the pick, whose random restarts may put the arm on another
  // branch: the move there swings the held object up to a metre (on a 20 × 8 × 12 cm box's
  // lifts, 32 of 449 stray more than 2 cm), which the kinematic simulator's held object does
  // not feel and physics does. Off in this struct; a scan's config turns it on with sim.physics.
  bool lift_straight = false;
  static constexpr double kMaxLiftDeviation = 0.02;
  // The lift's arm pose re-solved (up to 12 seeds near the pick's, every joint within 1 rad of
  // it) where an arm link lies on the line from the camera to the held object: the 7-DOF arm's
  // elbow is free, and a forearm in front of the hand (inside the sensor's minimum range it
  // returns no depth) hides the object that the check after the lift looks for. A re-solved
  // lift is kept only where its move rises straight (as for lift_straight). Off in this struct;
  // a scan's config turns it on with sim.physics.
  bool lift_in_view = false;
  // After the lift the hand holds still settle_s and the camera looks again from where it took
  // the lift's frame: more than settle_changed of the object's pixels at another depth, it is
  // sliding out of a grasp that does not hold (0 s: no second look). Off in this struct, as
  // TrackingOptions::in_hand is: the kinematic simulator's grasps hold where they close; a
  // scan's config turns it on with sim.physics (kSettleSeconds), and a real robot wants it.
  static constexpr double kSettleSeconds = 0.5;
  double settle_s = 0;
  double settle_changed = 0.2;
  // The approach's search for the nearest model sample in the hand's footprint four samples at a
  // time in AVX2 where the CPU has it (false: one at a time). The same candidates either way.
  bool vectorised = true;

  // The options' rows (core/options.h); `vectorised` is a test switch, not an option.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.choice("approach", o.approach, kGraspApproachNames,
             "how the open hand comes in: palm slides to contact, or the whole hand to first "
             "contact");
    v.integer("approaches", o.approaches, "approach directions over the sphere", Range::atLeast(1));
    v.integer("max_failed_pick_ups", o.max_failed_pick_ups,
              "failed pick-ups per grasp before the scan gives up on it", Range::closed(1, 1000));
    v.integer("rolls", o.rolls, "palm rolls about each approach (over 180°)", Range::atLeast(1));
    v.numbers("spreads", o.spreads, "spread joint values tried (at least one)");
    v.numbers("preshapes", o.preshapes,
              "fingers this fraction of the way closed as the hand comes in (at least one)",
              Range::closedOpen(0, 1));
    v.numbers("edge_spreads", o.edge_spreads, "edge poses at each of these spreads");
    v.num("edge_inset_m", o.edge_inset_m, "edge poses: the model ends this far beyond the palm, m",
          Range::closedOpen(0, 0.05));
    v.boolean("pinch_poses", o.pinch_poses,
              "pinch poses: straight down, fingertips straddling the model's footprint");
    v.boolean("two_finger_pinch", o.two_finger_pinch,
              "two-finger pinch poses: the first two fingers facing, the others left open");
    v.num("two_finger_spread", o.two_finger_spread,
          "the spread at which the first two fingers face each other, rad");
    v.num("friction", o.friction, "μ at each contact (stability)", Range::openClosed(0, 2));
    v.integer("cone_edges", o.cone_edges, "friction-cone linearisation", Range::closed(3, 64));
    v.integer("wrench_directions", o.wrench_directions, "directions sampled for ε",
              Range::atLeast(12));
    v.num("contact_m", o.contact_m, "model points this close to the hand are in contact, m",
          Range::open(0, 0.05));
    v.num("contact_cell_m", o.contact_cell_m, "contact pooling cell, m", Range::above(0));
    v.num("min_epsilon", o.min_epsilon, "ε below this: not a stable grasp", Range::atLeast(0));
    v.num("stability_weight", o.stability_weight, "ranking score = quality + weight · ε",
          Range::atLeast(0));
    v.integer("max_candidates", o.max_candidates, "ranked at most (the most stable first)",
              Range::atLeast(1));
    v.num("lift_m", o.lift_m, "the object is lifted this far after the pick, m",
          Range::closedOpen(0, 1));
    v.boolean("lift_straight", o.lift_straight,
              "the lift solved in steps up from the pick and kept only where the arm's move "
              "rises straight (default: as sim.physics.enabled, unless given)");
    v.boolean("lift_in_view", o.lift_in_view,
              "the lift's arm pose re-solved where an arm link hides the held object from the "
              "camera (default: as sim.physics.enabled, unless given)");
    v.num("settle_s", o.settle_s,
          "after the lift the hand holds still this long and a second frame looks again (0: "
          "no second look; default: 0.5 with sim.physics on, 0 with it off, unless given), s",
          Range::closed(0, 10));
    v.num("settle_changed", o.settle_changed,
          "… more than this fraction of the object's pixels at another depth: it is sliding out, "
          "the grasp did not hold",
          Range::open(0, 1));
    v.object("hold", "the hold test: candidates closed, lifted and turned on the model in physics",
             [&](auto& h) { HoldTestOptions::fields(h, o.hold); });
  }
  std::string validate() const;
};

struct GraspCandidate {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;              // hand joints closed to contact (arm part: the pick IK solution)
  JointVector q_open;         // the hand as it comes in (preshape; arm part as q)
  int pose = -1;              // its index in GraspGeneration::poses
  bool pinch = false;         // a pinch pose (GraspPoseRecord::pinch)
  JointVector q_lift;         // the same grasp with the object lifted `lift_m` off the table
  int links_in_contact = 0;   // fingers touching, plus one when the palm touches
  bool palm_contact = false;  // the palm touches (an enveloping grasp; else fingertips only)
  std::vector<Contact> contacts;
  double epsilon = 0;       // stability
  double quality = 0;       // best view quality Alg. 1 finds with the hand there
  double score = 0;         // quality + stability_weight·ε
  int reachable_views = 0;  // views Alg. 1 could reach with this grasp
  int hold = -1;            // the hold test: 1 held, 0 did not, -1 not tested
  HoldFailure hold_failure = HoldFailure::kNone;  // why it did not (HoldTrial::failure)
  int hold_margin = -1;      // held also with the test's margin (1), not (0), not tried (-1)
  int hold_robust = -1;      // held also with the model moved by the pose tolerance (1), not (0)
  int hold_unseen = -1;      // held also from where the unseen space stops the hand (1), not (0)
  double hold_close_m = -1;  // the hold test: how far its close pushed the model (-1 untested)
  // … and the grasp where its close left the model (HoldTrial::T_O_palm_closed).
  std::optional<Iso3> T_O_palm_closed;
};

// What became of one candidate pose.
struct GraspPoseRecord {
  Vec3 approach_O = Vec3::Zero();  // palm z (the direction the hand moves in), frame O
  double roll_rad = 0;             // palm x about it, from the approach's reference direction
  double spread = 0, preshape = 0;
  bool edge = false;
  bool pinch = false;       // a pinch pose (GraspOptions::pinch_poses)
  bool two_finger = false;  // a two-finger pinch (GraspOptions::two_finger_pinch)
  double epsilon = 0;       // when the closed hand touched with two links or more
  // kept, no_contact (the hand met nothing or started in contact), table (the hand cannot clear
  // the table), fewer_than_two_links, not_force_closure, hand_in_table, unreachable, or
  // beyond_max_candidates; duplicate: its closed hand is an earlier pose's (the same palm pose
  // and finger joints from another preshape)
  std::string result;
};

// Whether no robot link lies on the line from the camera's pan-tilt centre to the held object
// (graspOffset in front of the palm) at q, sampled every centimetre from 5 cm out to 15 cm short of
// the object (the hand holding it is not counted) (GraspOptions::lift_in_view).
bool heldInView(const RobotModel& robot, const JointVector& q);
// Whether no link of the robot at q (none but the hand's with `past_hand`) lies on the line from
// the camera's pan-tilt centre to target_B, sampled every centimetre from 5 cm out to short_m
// short of it (heldInView: the grasp point, 15 cm short, every link).
bool clearLineFromCamera(const RobotModel& robot, const JointVector& q, const Vec3& target_B,
                         double short_m, bool past_hand);

// How far the joint-space move from q to q_lift (straight in joint space, as the robot executes
// it) strays from the straight line between its ends, at 20 steps: the held object's point
// (graspOffset in front of the palm) off the line, plus 0.1 m times the palm's turn from its
// orientation at q (a point of the object 10 cm from the palm swings by about that), m.
double liftPathDeviation(const RobotModel& robot, const JointVector& q, const JointVector& q_lift);

struct GraspGeneration {
  std::vector<GraspCandidate> candidates;  // stable, table-free, reachable; best ε first
  std::vector<GraspPoseRecord> poses;      // every pose tried, in generation order
  int tried = 0;                           // (approach, roll, spread) poses tried
  int touching = 0;                        // with ≥ 2 links in contact
  int stable = 0;                          // of those, force closure with ε ≥ min_epsilon
  int table_free = 0;                      // of those, hand clear of the table
  double seconds = 0;
};

// Candidates on `model_O` (the current S_obj) with the object resting on the table at T_B_O;
// `q_now` gives the arm's current state (IK seed). `footprint_O`: points of the object as
// measured, from which the pinch poses take its footprint on the table (a model's hole-filled
// surface, such as the table hidden behind a thin object, widens it); else the model's surface.
GraspGeneration generateGrasps(const RobotModel& robot, const TriangleMesh& model_O,
                               const Iso3& T_B_O, const JointVector& q_now,
                               const GraspOptions& options,
                               const std::vector<Vec3>* footprint_O = nullptr);

// A grasp known to work on the object (an asset's grasp set), in its frame O: the palm's pose and
// the hand as it comes in (every variable; the arm's are not used).
struct KnownGrasp {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector hand;
};

// The grasps of `set` made again on `model_O` resting at T_B_O, each as generateGrasps makes a
// candidate: the palm's orientation and axis as the set has them, the hand as it comes in, brought
// along its axis from outside until it first touches the model or the table, closed, kept when
// force closure, clear of the table and reachable (GraspGeneration::poses, one per grasp of the
// set, says why not). The candidates in the set's order; `pose` is the grasp's index in `set`.
// Throws Error when a grasp's hand is not the robot's.
GraspGeneration graspsFromSet(const RobotModel& robot, const TriangleMesh& model_O,
                              const Iso3& T_B_O, const JointVector& q_now,
                              const std::vector<KnownGrasp>& set, const GraspOptions& options);

// Fills quality, reachable_views and score of each candidate by one Alg. 1 pass of `planner`
// over S_obj with the hand at that grasp (usually a coarse planner: fewer directions, rolls and
// a pixel stride), and sorts them best first. Returns the seconds spent. A candidate's quality is
// its best reachable view's; views are scored in decreasing order of their quality with no hand
// (an upper bound) until none left can beat the best (ViewPlanner::bestViewQuality), or, with
// `reference`, every view through ViewPlanner::select: the same qualities. `view_bounds`: the
// planner's viewBoundsWithoutHand of S_obj when already computed (else computed here).
double rankGrasps(const ViewPlanner& planner, const ObjectModel& S_obj, const GraspOptions& options,
                  std::vector<GraspCandidate>* candidates, bool reference = false,
                  const std::vector<double>* view_bounds = nullptr);

}  // namespace inhand
