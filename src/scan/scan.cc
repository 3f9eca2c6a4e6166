#include "inhand/scan/scan.h"

#include <tbb/parallel_invoke.h>

#include <chrono>
#include <optional>

#include "inhand/core/clock.h"
#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/internal/raster.h"
#include "inhand/robot/collision.h"
#include "inhand/scan/session.h"

namespace inhand {

std::string handModeName(HandMode m) { return enumName(kHandModeNames, m); }

bool parseHandMode(const std::string& s, HandMode* out) {
  return enumFromName(kHandModeNames, s, out);
}

namespace {
constexpr std::pair<Termination, const char*> kTerminationNames[] = {
    {Termination::kRunning, "running"},
    {Termination::kNoViewAboveThreshold, "no_view_above_threshold"},
    {Termination::kMaxViews, "max_views"},
    {Termination::kNoReachableView, "no_reachable_view"},
    {Termination::kMaxGrasps, "max_grasps"},
    {Termination::kRegraspUnsupported, "regrasp_unsupported"},
    {Termination::kNoReachableGrasp, "no_reachable_grasp"},
    {Termination::kNoGraspAboveThreshold, "no_grasp_above_threshold"},
    {Termination::kPickUpFailed, "pick_up_failed"},
    {Termination::kRegraspFailed, "regrasp_failed"},
    {Termination::kObjectOutOfView, "object_out_of_view"},
    {Termination::kObjectNotFound, "object_not_found"},
    {Termination::kObjectTooLargeForHand, "object_too_large_for_hand"},
    {Termination::kObjectTooLargeForVolume, "object_too_large_for_volume"},
    {Termination::kNoStableGrasp, "no_stable_grasp"},
    {Termination::kInterrupted, "interrupted"},
    {Termination::kObjectLost, "object_lost"},
};
}  // namespace

Json slipsJson(const std::vector<SlipRecord>& slips) {
  Json out = Json::array();
  for (const SlipRecord& e : slips)
    out.push_back({{"grasp", e.grasp},
                   {"view", e.view},
                   {"moved_mm", 1000 * e.moved_m},
                   {"turned_deg", e.turned_rad * 180 / M_PI},
                   {"frames_not_fused", e.frames},
                   {"settled", e.settled}});
  return out;
}

std::vector<SlipRecord> slipsFrom(const Json& j) {
  if (!j.is_array()) throw Error("slips: not a list");
  std::vector<SlipRecord> out;
  for (const Json& e : j) {
    SlipRecord r;
    r.grasp = e.at("grasp").get<int>();
    r.view = e.at("view").get<int>();
    r.moved_m = e.at("moved_mm").get<double>() / 1000;
    r.turned_rad = e.at("turned_deg").get<double>() * M_PI / 180;
    r.frames = e.at("frames_not_fused").get<int>();
    r.settled = e.at("settled").get<bool>();
    out.push_back(r);
  }
  return out;
}

std::string terminationName(Termination t) {
  for (const auto& [value, name] : kTerminationNames)
    if (value == t) return name;
  return "?";
}

bool parseTermination(const std::string& s, Termination* out) {
  for (const auto& [value, name] : kTerminationNames)
    if (s == name) {
      *out = value;
      return true;
    }
  return false;
}

std::string FrameChecks::validate() const { return checkOptionRanges(*this); }

std::string ScanOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (!(volume_size_m > 10 * voxel_m)) return "volume_size_m must be over 10 voxels (voxel_m)";
  if (volume_budget.truncation_m > 0 && volume_budget.truncation_m < voxel_m)
    return "truncation_m must be at least one voxel (voxel_m)";
  if (std::string p = planner.validate(); !p.empty()) return "planner." + p;
  if (std::string p = tracking.validate(); !p.empty()) return "tracking." + p;
  return {};
}

TsdfVolume makeScanVolume(const Vec3& centre_O, const ScanOptions& options) {
  Aabb box;
  box.extend(centre_O - Vec3::Constant(0.5 * options.volume_size_m));
  box.extend(centre_O + Vec3::Constant(0.5 * options.volume_size_m));
  VolumeOptions vo = options.volume_budget;
  vo.voxel_size_m = options.voxel_m;
  return TsdfVolume(box, vo);
}

ScanResult scanSingleGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm,
                           const Vec3& centre_O, const ScanOptions& options,
                           const NoiseModelOptions& noise, const ScanProgress& progress,
                           const Aabb& object_box_O) {
  const auto t0 = Clock::now();
  MultiGraspOptions one;
  one.max_grasps = 1;
  ScanSession session(robot.model(), sensor.camera(), noise, options, one, centre_O);
  session.setProgress(progress);
  session.beginGrasp(T_O_palm, robot.joints(), object_box_O);
  ScanResult result;
  result.termination = runGraspViews(session, robot, sensor);
  result.views = session.views();
  session.summary().copyTo(&result);
  result.model = session.model();
  result.planning_model = session.planningModel();
  result.total_s = secondsSince(t0);
  return result;
}

Termination runGraspViews(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                          const std::function<void()>& after_view) {
  const ScanProgress& progress = session.progress();
  sensor.setPose(session.cameraPose());
  while (!progress.stopRequested()) {
    const std::optional<PlannedView> view = session.nextView(robot.joints());
    if (!view) return session.summary().termination;
    bool stopped = false;
    auto lost = [&] { return session.summary().termination == Termination::kObjectLost; };
    robot.execute(view->waypoints, [&](const JointVector& q) {
      // Once stopped, the rest of the motion is not fused (a real driver's arm finishes or is
      // halted by its own controller); nor once the object is no longer in the hand.
      if (stopped || (stopped = progress.stopRequested()) || lost()) return;
      const DepthImage depth = sensor.capture();
      if (sensor.camera().colour.enabled) session.setColourOfNextFrame(sensor.captureColour());
      session.addFrame(depth, q, sensor.pose());
    });
    session.finishView();
    if (lost()) return Termination::kObjectLost;
    if (stopped) break;
    // At rest at the view's end: the arm's torques weigh the object (robots that report them).
    if (const std::optional<TorqueSamples> rest =
            torquesAtRest(robot, session.options().torque_readings))
      session.addJointTorques(robot.joints(), *rest);
    if (after_view) after_view();
  }
  session.finish(Termination::kInterrupted, "interrupted by the caller");
  return Termination::kInterrupted;
}

}  // namespace inhand
