#pragma once
// Alg. 1 (SelectView): candidate viewing directions spread over the sphere at least t_θ from
// every used view; the object's centre on the optical axis at range 0.7 m (other ranges only where
// no IK solution exists there); rolls about the viewing direction swept and the roll with the
// lowest trajectory time kept; quality by eq. 9 with the robot (hand, wrist, forearm, …) at that
// candidate's IK solution as occluder; score = q − α_cost·cost; views with q < t_q do not count.
// By default coarse to fine: every candidate's q at every 4th pixel, the best few again at full
// resolution (see ViewPlannerOptions::refine; refine = 0 is the paper's exhaustive pass).
//
// Camera placement: the camera stays on its pan-tilt unit aimed at one presentation point, at the
// view range from the unit towards the config's look_at point; the arm turns the object in front
// of it. Pan/tilt are not searched jointly with roll.
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "inhand/planning/view_quality.h"
#include "inhand/planning/volumetric.h"
#include "inhand/robot/ik.h"

namespace inhand {

// How a candidate view is scored. inhand's own is eq. 9; the others are the baselines of
// `inhand eval`, run through the same candidates, IK, costs and robot occluders.
enum class ViewMetric {
  kInformationGain,   // eq. 9 (quality.integrand picks eq. 9 or the unknown-area integrand)
  kRandom,            // a uniformly random reachable view: quality drawn from U(0, 1)
  kUnobservedVoxels,  // Isler et al. 2016 (see volumetric.h), needs the volume
  kRearSideEntropy,   // Isler et al. 2016 (see volumetric.h), needs the volume
};

// When a view counts and when the planner is done (§III-B's t_q).
enum class StopRule {
  // t_q and α_cost scale with the surface area A of S_obj (eq. 9 is an area integral, nats·m²):
  // a view counts when its eq. 9 gain is at least t_q_relative·A, and α_cost = α_relative·A, so
  // an object scaled by s stops after the same views. Every planner stops on this rule: a
  // baseline still chooses by its own metric, among the same candidates, but the pass ends when
  // no reachable view's eq. 9 gain reaches the threshold.
  kRelative,
  // The paper's absolute t_q and α_cost; a baseline stops on its own threshold in its own units.
  kAbsolute,
};
inline constexpr EnumNames<StopRule, 2> kStopRuleNames = {{StopRule::kRelative, "relative"},
                                                          {StopRule::kAbsolute, "absolute"}};

struct ViewPlannerOptions {
  ViewMetric metric = ViewMetric::kInformationGain;
  VolumetricOptions volumetric;  // for the volumetric metrics
  int directions = 500;          // candidate directions on the unit sphere
  double min_angle_deg = 10.0;   // t_θ: minimum angle to every used view
  double range_m = 0.7;          // preferred camera-to-object-centre distance
  std::vector<double> fallback_ranges_m{0.6, 0.8, 0.9};  // tried only where range_m has no IK
  int rolls = 8;                                         // rolls swept about the viewing direction
  double alpha_cost = 0.0005;  // α_cost: quality units per second of trajectory
  double t_q = 0.005;          // t_q: minimum quality of a view that counts (absolute rule)
  StopRule stop = StopRule::kRelative;
  // Relative rule: t_q = t_q_relative·A(S_obj) and α_cost = alpha_cost_relative·A(S_obj).
  // 0.036 nats is what eq. 9 gives for 1% of the surface seen for the first time (σ 5 cm before,
  // the sensor's σ at 0.7 m after: ½ ln(1 + 0.05²/0.00137²) = 3.6 nats per m²); α keeps the
  // paper's ratio t_q/α_cost = 10 s of trajectory.
  double t_q_relative = 0.036;
  double alpha_cost_relative = 0.0036;
  bool use_cost = true;          // false: score = q (ablation)
  bool hand_occlusion = true;    // false: no robot occluders, no t_hand rule (ablation)
  bool check_collisions = true;  // reject candidates whose arm, hand or object hit table/base
  int ik_restarts = 1;           // random restarts per IK target after the seeded attempt
  IkMethod ik_solver = IkMethod::kDampedLeastSquares;  // dls (ours) or kdl_lma (the reference)
  uint64_t seed = 1;                                   // IK restarts
  // Coarse to fine (eq. 9 only): every reachable candidate is first scored at every
  // `prescreen_stride`-th pixel in u and v; the `refine` best by that score are scored again at
  // quality.pixel_stride and the view is chosen among them (when none of them counts, the next
  // `refine` whose coarse quality is at least t_q/2, and so on). refine = 0, or a prescreen
  // stride not coarser than quality.pixel_stride: every candidate at quality.pixel_stride (the
  // paper's exhaustive pass).
  int prescreen_stride = 4;
  int refine = 32;
  ViewQualityOptions quality;

  // The options' rows (core/options.h); metric and seed are set by the caller.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.integer("directions", o.directions, "candidate directions on the unit sphere (Alg. 1)",
              Range::atLeast(1));
    v.num("min_angle_deg", o.min_angle_deg, "t_θ: minimum angle to every used view, degrees",
          Range::closedOpen(0, 180));
    v.num("range_m", o.range_m, "preferred camera-to-object-centre distance, m", Range::above(0));
    v.numbers("fallback_ranges_m", o.fallback_ranges_m,
              "ranges tried only where range_m has no IK solution, m", Range::above(0));
    v.integer("rolls", o.rolls, "rolls swept about each viewing direction", Range::atLeast(1));
    v.num("alpha_cost", o.alpha_cost,
          "α_cost: score = quality − α_cost · trajectory seconds (absolute rule)",
          Range::atLeast(0));
    v.choice("stop", o.stop, kStopRuleNames,
             "relative: t_q and α_cost scale with S_obj's surface area, every planner stops when "
             "no view's eq. 9 gain reaches t_q; absolute: the paper's t_q and α_cost, each planner "
             "on its own threshold");
    v.num("t_q", o.t_q, "t_q: minimum quality of a view that counts (absolute rule)",
          Range::atLeast(0));
    v.num("t_q_relative", o.t_q_relative,
          "relative rule: t_q = this · S_obj's area, nats per m² (0.036: 1% of the surface seen "
          "for the first time)",
          Range::atLeast(0));
    v.num("alpha_cost_relative", o.alpha_cost_relative,
          "relative rule: α_cost = this · S_obj's area, per second", Range::atLeast(0));
    v.boolean("use_cost", o.use_cost, "false: score = quality (ablation)");
    v.boolean("hand_occlusion", o.hand_occlusion,
              "false: no robot occluders, no t_hand rule (ablation)");
    v.boolean("check_collisions", o.check_collisions,
              "reject candidates whose arm, hand or object hit the table or base");
    v.integer("ik_restarts", o.ik_restarts, "random IK restarts after the seeded attempt",
              Range::atLeast(0));
    v.choice("ik_solver", o.ik_solver, kIkMethodNames, "IK: damped least squares or KDL's LMA");
    v.integer("prescreen_stride", o.prescreen_stride,
              "coarse pass: every n-th pixel for every reachable candidate", Range::closed(1, 16));
    v.integer("refine", o.refine, "the best this many by the coarse pass are scored in full",
              Range::atLeast(0));
    v.object("quality", "eq. 9", [&](auto& q) { ViewQualityOptions::fields(q, o.quality); });
    v.object("volumetric", "the volumetric baselines (Isler et al. 2016)",
             [&](auto& q) { VolumetricOptions::fields(q, o.volumetric); });
  }
  std::string validate() const;
};

struct ViewCandidate {
  Vec3 dir_O = Vec3::UnitZ();  // viewing direction in the object frame (camera → object)
  double range_m = 0, roll_rad = 0;
  Iso3 T_O_C = Iso3::Identity();  // camera pose in the object frame
  Iso3 T_B_O = Iso3::Identity();  // object pose in the base frame there
  Eigen::VectorXd arm;            // IK solution
  double cost_s = 0, quality = 0, score = 0;
  // eq. 9 at full resolution (nats·m²): `quality` for ig; for a baseline under the relative rule
  // its eq. 9 gain as well; NaN where not evaluated.
  double gain = std::numeric_limits<double>::quiet_NaN();
  int pixel_stride = 1;  // the stride `quality` was evaluated at
};

struct ViewSelection {
  std::optional<ViewCandidate> best;  // none: no reachable view reaches t_q
  double t_q = 0;                     // the threshold the pass used (in eq. 9 units, nats·m²,
                                      // under the relative rule)
  int directions = 0;                 // after the t_θ filter
  int reachable = 0;                  // with an IK solution (and collision-free)
  int evaluated = 0;                  // candidates scored (eq. 9, coarse or full)
  int refined = 0;                    // of those, scored again at full resolution
  double ik_s = 0, quality_s = 0, total_s = 0;
  std::vector<ViewCandidate> candidates;  // every evaluated candidate
};

// What the planner needs to know about the grasp: where the palm is on the object, and the robot's
// current joints (hand joints included).
struct GraspState {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;
};

// The named planners of `--planner`: ig (inhand, eq. 9), ig-no-hand (no robot occlusion
// reasoning), ig-no-cost (α_cost = 0), random, area, unobserved-voxels, rear-side-entropy.
std::vector<std::string> plannerNames();
// Sets metric, integrand, use_cost, hand_occlusion and the stopping threshold t_q of `name` on
// `options` (other fields kept). False for an unknown name. Thresholds (a view counts only at or
// above): ig 0.005 (the paper's t_q); area 2 cm² of unknown surface; unobserved-voxels 300 voxels;
// rear-side-entropy 5000 bits; random 0 (it ends at the view budget).
bool applyPlannerName(const std::string& name, ViewPlannerOptions* options);

// The threshold and the cost weight for a model of surface area `area_m2` (the relative rule
// scales them with it; the absolute one returns t_q and alpha_cost).
double viewThreshold(const ViewPlannerOptions& options, double area_m2);
double costWeight(const ViewPlannerOptions& options, double area_m2);

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
  // With `path_free` the straight joint-space move there from grasp.q must be free too.
  std::vector<std::optional<ViewCandidate>> reach(const std::vector<Vec3>& dirs_O,
                                                  const Vec3& centre_O, const Aabb& object_box_O,
                                                  const GraspState& grasp,
                                                  bool path_free = false) const;

  // Alg. 1. `used_dirs_O`: directions of views already taken (object frame). `near_hand`: the
  // grasp's near-hand grid (shared across passes of one grasp).
  // `volume`: the fused volume, needed by the volumetric metrics only.
  ViewSelection select(const ObjectModel& S_obj, const GraspState& grasp,
                       const std::vector<Vec3>& used_dirs_O,
                       std::shared_ptr<const NearHandGrid> near_hand,
                       const TsdfVolume* volume = nullptr) const;

  // The same with S_obj already prepared (its BVH built once for many passes, e.g. one per
  // grasp candidate); `scene` must have been made with this planner's camera, noise and quality
  // options. Its near-hand grid is replaced by `near_hand`.
  ViewSelection select(ViewQualityScene& scene, const GraspState& grasp,
                       const std::vector<Vec3>& used_dirs_O,
                       std::shared_ptr<const NearHandGrid> near_hand,
                       const TsdfVolume* volume = nullptr) const;
  // A ViewQualityScene of S_obj for this planner.
  ViewQualityScene qualityScene(const ObjectModel& S_obj) const;

  // An upper bound on the quality any grasp can promise under this planner (what rankGrasps
  // gives a candidate: its best view's quality, used directions none): the best eq. 9 quality of
  // S_obj over every direction, roll and range, with neither the robot nor the near-hand rule,
  // at each pixel stride select() scores at. A grasp's views have the same camera poses in the
  // object's frame, and per pixel the robot can only take a non-negative term away (it hides
  // S_obj or the projector, or marks the surface near the hand). Reachability is not asked.
  // +infinity for the metrics that are not such sums (random, the volumetric ones). Replaces
  // the scene's near-hand grid with none. `view_bounds` (optional) receives the per-view bounds
  // it took the largest of (viewBoundsWithoutHand), for rankGrasps.
  double graspQualityBound(ViewQualityScene& scene,
                           std::vector<double>* view_bounds = nullptr) const;
  // The bound of each view: eq. 9 with no hand for every (direction, range, roll) in reach()'s
  // order (index (direction · ranges + range) · rolls + roll), the largest over the strides
  // select() may score at. Empty for metrics other than eq. 9 or an empty model.
  std::vector<double> viewBoundsWithoutHand(ViewQualityScene& scene) const;
  // What rankGrasps takes from select() for a grasp, the best quality among its reachable views
  // (used directions none), found by scoring the views in decreasing order of `bounds`
  // (viewBoundsWithoutHand) until none left can beat the best found: the same maximum, with
  // most views never scored. `reachable`: how many directions have a view. nullopt where
  // select() would score otherwise (not eq. 9, coarse to fine, bounds of another shape).
  std::optional<double> bestViewQuality(ViewQualityScene& scene, const GraspState& grasp,
                                        std::shared_ptr<const NearHandGrid> near_hand,
                                        const std::vector<double>& bounds, int* reachable) const;

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
