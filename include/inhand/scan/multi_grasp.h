#pragma once
// The autonomous multi-grasp scan (paper §IV, §V-B): scan with the current grasp until no view
// reaches t_q, put the object down, generate grasp candidates on the model so far, rank them by
// the best view Alg. 1 finds with the hand there, pick the object up with the best one, and go
// on, the model kept in the object frame throughout, until no candidate grasp promises a view
// above t_q or a grasp limit.
#include <optional>

#include "inhand/grasp/grasp.h"
#include "inhand/scan/scan.h"

namespace inhand {

// The table-top stage (paper §V): the object starts on the table, unknown.
struct TableTopOptions {
  int frames = 3;              // depth frames taken of it there (fused; the table hides the bottom)
  double aim_height_m = 0.05;  // the camera aims this far above the rest pose's origin, m
  double search_radius_m = 0.25;  // object points lie within this of the rest pose (horizontal), m
  double above_table_m = 0.008;   // … and at least this far above the fitted table plane, m
  double cluster_cell_m = 0.01;   // the object is the largest cluster at this linking cell, m
  int min_points = 200;           // fewer object points than this: object_not_found
  PlaneFitOptions plane;          // RANSAC of the table plane
  std::string validate() const;
};

// One pick-up attempt: the candidate tried and what became of it.
struct PickAttempt {
  // picked (it held after the lift), no_contact (the hand met nothing), empty_hand (the fingers
  // closed on nothing), dropped (the lift's frame did not show it in the hand)
  std::string outcome;
  int rank = 0;          // the candidate's place in the ranking it was tried from (0: the first)
  int pose = -1;         // its index among the poses generated (GraspCandidate::pose)
  int hold_test = -1;    // the hold test's verdict on the model: 1 held, 0 not, -1 untested
  int hold_margin = -1;  // … and with its margin (GraspCandidate::hold_margin)
  // Where it failed the hold test (HoldTrial::failure: dropped_in_lift, dropped_in_turn,
  // slipped, not_touching; empty when it held or was not tested).
  std::string hold_failure;
  bool palm_contact = false;  // enveloping (the palm touches) or fingertips only
  double epsilon = 0;         // its force-closure ε
  // After the lift: how far the object sat in the hand from the planned grasp (−1: not seen).
  double shift_m = -1;
};
Json attemptsJson(const std::vector<PickAttempt>& attempts);
// Throws Error on a malformed list; a list of outcome strings (older checkpoints) is read too.
std::vector<PickAttempt> attemptsFrom(const Json& j);
int countOutcome(const std::vector<PickAttempt>& attempts, const std::string& outcome);

// What the table-top stage saw and chose.
struct TableTopRecord {
  int frames = 0;
  int points = 0;         // measured points near the rest pose
  int table_inliers = 0;  // of those, on the fitted plane
  int object_points = 0;  // above it
  Plane table_O;          // the fitted table plane, frame O
  PrincipalAxes axes;     // of the object points, frame O
  // First-grasp candidates (generateGrasps on the table-top model): poses tried, those whose
  // closed hand touches with two links or more, of those force closure, clear of the table, and
  // reachable; then the pick-up attempts in order (picked, no_contact, empty_hand, dropped).
  int tried = 0, touching = 0, stable = 0, table_free = 0, reachable = 0;
  std::vector<GraspPoseRecord> poses;     // every pose tried and what became of it
  double volume_size_m = 0, voxel_m = 0;  // the volume as fitted to the object
  std::vector<PickAttempt> attempts;
  double seconds = 0;
};

struct MultiGraspOptions {
  int max_grasps = 3;  // grasps in all (1: the single-grasp scan)
  TableTopOptions table_top;
  GraspOptions grasp;
  // Alg. 1 as used to rank grasp candidates: coarser than the view planner's (fewer directions
  // and rolls, every 4th pixel), since it runs once per candidate.
  ViewPlannerOptions ranking = defaultRankingPlanner();
  int keep_ranked = 12;  // candidates kept per grasp in its record (for the report)
  static ViewPlannerOptions defaultRankingPlanner();
  std::string validate() const;
};

// A ranked candidate as the report shows it.
struct RankedGrasp {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;  // hand closed to contact
  double quality = 0, epsilon = 0;
};

struct GraspRecord {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;  // the robot's joints when the grasp's views began (hand as it holds the object)
  int candidates = 0;  // ranked candidates this grasp was chosen from (0: the first grasp)
  int tried = 0;       // candidate poses tried
  double quality = 0;  // its best view quality when ranked
  double t_q = 0;      // the threshold that quality passed (relative rule: scaled by the area)
  double model_area_m2 = 0;                         // of the planning model it was ranked on
  double epsilon = 0;                               // its stability (Ferrari–Canny ε)
  int views = 0;                                    // views taken with it
  Termination termination = Termination::kRunning;  // why its views ended
  double hole_area_m2 = 0;  // σ = 5 cm (unknown) area of the model after its views
  double mean_entropy = 0;  // of the model after its views
  double generation_s = 0, ranking_s = 0;
  std::vector<RankedGrasp> ranked;    // the best candidates it was chosen from, best first
  std::vector<PickAttempt> attempts;  // pick-up attempts, the last the one that held
  ObjectModel model;                  // the model after its views (at the planning stride)
};

struct MultiGraspResult {
  ScanResult scan;  // views of all grasps, model, timings; termination of the whole scan
  std::vector<GraspRecord> grasps;
  // The grasp planning that led to no further grasp (no candidate above t_q, none reachable or
  // none picked up): its time is in no GraspRecord.
  double unused_generation_s = 0, unused_ranking_s = 0;
  // The attempts of a re-grasp that never held (regrasp_failed, object_lost): no GraspRecord
  // carries them.
  std::vector<PickAttempt> failed_regrasp_attempts;
  // After each put-down, the residual (RMS, m) of the model registered where the object rests.
  std::vector<double> refind_residuals_m;
  std::optional<TableTopRecord> table_top;  // when the scan began with the object on the table
};

// `T_O_palm` and the robot's state: the first grasp (the robot holds the object); `T_B_O_rest`:
// where the object rests on the table between grasps (frame O kept).
MultiGraspResult scanMultiGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm,
                                const Vec3& centre_O, const Iso3& T_B_O_rest,
                                const ScanOptions& options, const MultiGraspOptions& multi,
                                const NoiseModelOptions& noise, const ScanProgress& progress = {});

// The whole autonomous scan (§V): the object rests on the table at T_B_O_rest (its frame O is the
// model's frame; nothing of its shape is known). The camera takes table_top.frames of it; the
// table plane is fitted (RANSAC) and the points above it near the rest pose are the object; the
// volume is centred on them and the frames are fused (table and robot pixels only carve); the
// first grasp comes from generateGrasps on the model those frames give (the observed surface,
// closed over what it hides); the robot picks the object up with the first candidate that holds
// (by what it observes after the lift) and the multi-grasp scan goes on as scanMultiGrasp.
// Terminations of its own: object_not_found, object_too_large_for_volume,
// object_too_large_for_hand, no_reachable_grasp, pick_up_failed (the model so far is returned with
// each).
MultiGraspResult scanFromTable(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_B_O_rest,
                               const ScanOptions& options, const MultiGraspOptions& multi,
                               const NoiseModelOptions& noise, const ScanProgress& progress = {});

}  // namespace inhand
