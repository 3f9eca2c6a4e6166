#pragma once
// The autonomous multi-grasp scan (paper §IV, §V-B): scan with the current grasp until no view
// reaches t_q, put the object down, generate grasp candidates on the model so far, rank them by
// the best view Alg. 1 finds with the hand there, pick the object up with the best one, and go
// on, the model kept in the object frame throughout, until no candidate grasp promises a view
// above t_q or a grasp limit.
#include "inhand/grasp/grasp.h"
#include "inhand/scan/scan.h"

namespace inhand {

struct MultiGraspOptions {
  int max_grasps = 3;  // grasps in all (1: the single-grasp scan)
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
  int candidates = 0;       // ranked candidates this grasp was chosen from (0: the first grasp)
  int tried = 0;            // candidate poses tried
  double quality = 0;       // its best view quality when ranked
  double epsilon = 0;       // its stability (Ferrari–Canny ε)
  int views = 0;            // views taken with it
  std::string termination;  // why its views ended
  double hole_area_m2 = 0;  // σ = 5 cm (unknown) area of the model after its views
  double mean_entropy = 0;  // of the model after its views
  double generation_s = 0, ranking_s = 0;
  std::vector<RankedGrasp> ranked;  // the best candidates it was chosen from, best first
  ObjectModel model;                // the model after its views (at the planning stride)
};

struct MultiGraspResult {
  ScanResult scan;  // views of all grasps, model, timings; termination of the whole scan
  std::vector<GraspRecord> grasps;
};

// `T_O_palm` and the robot's state: the first grasp (the robot holds the object); `T_B_O_rest`:
// where the object rests on the table between grasps (frame O kept).
MultiGraspResult scanMultiGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm,
                                const Vec3& centre_O, const Iso3& T_B_O_rest,
                                const ScanOptions& options, const MultiGraspOptions& multi,
                                const NoiseModelOptions& noise, const ScanProgress& progress = {});

}  // namespace inhand
