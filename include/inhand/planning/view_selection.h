#pragma once
// Alg. 1 (SelectView): candidate viewing directions spread over the sphere at least t_θ from
// every used view; the object's centre on the optical axis at range 0.7 m (other ranges only where
// no IK solution exists there); rolls about the viewing direction swept and the roll with the
// lowest trajectory time kept; quality by eq. 9 with the robot (hand, wrist, forearm, …) at that
// candidate's IK solution as occluder; score = q − α_cost·cost; views with q < t_q do not count.
//
// Camera placement: the camera stays on its pan-tilt unit aimed at one presentation point, at the
// view range from the unit towards the config's look_at point; the arm turns the object in front
// of it. Pan/tilt are not searched jointly with roll.
#include <optional>
#include <string>
#include <vector>

#include "inhand/planning/view_quality.h"
#include "inhand/robot/ik.h"

namespace inhand {

struct ViewPlannerOptions {
  int directions = 500;         // candidate directions on the unit sphere
  double min_angle_deg = 10.0;  // t_θ: minimum angle to every used view
  double range_m = 0.7;         // preferred camera-to-object-centre distance
  std::vector<double> fallback_ranges_m{0.6, 0.8, 0.9};  // tried only where range_m has no IK
  int rolls = 8;                                         // rolls swept about the viewing direction
  double alpha_cost = 0.0005;    // α_cost: quality units per second of trajectory
  double t_q = 0.005;            // t_q: minimum quality of a view that counts
  bool use_cost = true;          // false: score = q (ablation)
  bool hand_occlusion = true;    // false: eq. 9 without the robot as occluder (ablation)
  bool check_collisions = true;  // reject candidates whose arm, hand or object hit table/base
  int ik_restarts = 1;           // random restarts per IK target after the seeded attempt
  uint64_t seed = 1;             // IK restarts
  ViewQualityOptions quality;
  std::string validate() const;
};

struct ViewCandidate {
  Vec3 dir_O = Vec3::UnitZ();  // viewing direction in the object frame (camera → object)
  double range_m = 0, roll_rad = 0;
  Iso3 T_O_C = Iso3::Identity();  // camera pose in the object frame
  Iso3 T_B_O = Iso3::Identity();  // object pose in the base frame there
  Eigen::VectorXd arm;            // IK solution
  double cost_s = 0, quality = 0, score = 0;
};

struct ViewSelection {
  std::optional<ViewCandidate> best;  // none: no reachable view reaches t_q
  int directions = 0;                 // after the t_θ filter
  int reachable = 0;                  // with an IK solution (and collision-free)
  int evaluated = 0;                  // quality evaluations (eq. 9)
  double ik_s = 0, quality_s = 0, total_s = 0;
  std::vector<ViewCandidate> candidates;  // every evaluated candidate
};

// What the planner needs to know about the grasp: where the palm is on the object, and the robot's
// current joints (hand joints included).
struct GraspState {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;
};

class ViewPlanner {
 public:
  ViewPlanner(const RobotModel& model, const DepthCameraOptions& camera,
              const NoiseModelOptions& noise, const ViewPlannerOptions& options);

  // Camera pose in the base frame (fixed by the presentation point and the view range).
  Iso3 cameraPose(double range_m) const;
  // Object pose in the base frame that puts the camera at T_O_C relative to the object.
  Iso3 objectPoseFor(const Iso3& T_O_C, double range_m) const;

  // Line 7 of Alg. 1 for each direction: the cheapest collision-free (range, roll) with an IK
  // solution, or nullopt. `object_box_O`: the held object's current bounds (for collisions).
  std::vector<std::optional<ViewCandidate>> reach(const std::vector<Vec3>& dirs_O,
                                                  const Vec3& centre_O, const Aabb& object_box_O,
                                                  const GraspState& grasp) const;

  // Alg. 1. `used_dirs_O`: directions of views already taken (object frame). `near_hand`: the
  // grasp's near-hand grid (shared across passes of one grasp).
  ViewSelection select(const ObjectModel& S_obj, const GraspState& grasp,
                       const std::vector<Vec3>& used_dirs_O,
                       std::shared_ptr<const NearHandGrid> near_hand) const;

  // The same with S_obj already prepared (its BVH built once for many passes, e.g. one per
  // grasp candidate); `scene` must have been made with this planner's camera, noise and quality
  // options. Its near-hand grid is replaced by `near_hand`.
  ViewSelection select(ViewQualityScene& scene, const GraspState& grasp,
                       const std::vector<Vec3>& used_dirs_O,
                       std::shared_ptr<const NearHandGrid> near_hand) const;
  // A ViewQualityScene of S_obj for this planner.
  ViewQualityScene qualityScene(const ObjectModel& S_obj) const;

  const ViewPlannerOptions& options() const { return options_; }
  const RobotModel& model() const { return *model_; }

 private:
  const RobotModel* model_;
  DepthCameraOptions camera_;
  NoiseModelOptions noise_;
  ViewPlannerOptions options_;
  RobotOccluders occluders_;
};

}  // namespace inhand
