// `inhand regrasp-test`: the loop closed on an asset (docs/asset.md): in a fresh simulated world
// with the true object on the table in a pose of the user's choosing, the robot finds it with the
// asset alone, picks a grasp from the asset's grasp set and lifts it with physics; the simulator's
// truth then says whether it was found where it is and whether it is in the hand.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "commands.h"
#include "inhand/config/scan_config.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/driver/simulated_scan.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/scan/regrasp.h"
#include "inhand/sim/sim_world.h"

namespace inhand::app {

namespace {

// The grasps of an asset's set that worked, in the order a robot tries them: those a scan tried
// that held the object, then those that held the model in the hold test with its margin, then
// without. `index`: each one's place in grasps.json.
std::vector<KnownGrasp> workingGrasps(const Json& grasps, const RobotModel& robot,
                                      const std::string& file, std::vector<int>* index) {
  std::vector<KnownGrasp> out;
  for (const char* wanted : {"held", "held_with_margin", "ranked_held"})
    for (size_t i = 0; i < grasps.size(); ++i) {
      const Json& g = grasps[i];
      const std::string where = file + ": grasp " + std::to_string(i);
      try {
        const std::string source = g.at("source").get<std::string>();
        const std::string outcome = g.at("outcome").get<std::string>();
        const std::string w = wanted;
        const bool take = w == "held" ? source == "tried" && outcome == "held"
                          : w == "held_with_margin"
                              ? source == "ranked" && outcome == "held_with_margin"
                              : source == "ranked" && outcome == "held";
        if (!take) continue;
        KnownGrasp k;
        k.T_O_palm = isoFrom(g.at("T_O_palm"));
        k.hand = robot.withFingersOpen(robot.home());
        for (const auto& joint : g.at("preshape").items()) {
          const int v = robot.variableIndex(joint.key());
          if (v < 0) throw Error(where + ": joint \"" + joint.key() + "\" is not the robot's");
          k.hand[v] = joint.value().get<double>();
        }
        out.push_back(k);
        index->push_back(int(i));
      } catch (const Json::exception& e) {
        throw Error(where + ": " + e.what());
      }
    }
  return out;
}

// How far `found` puts the object from `truth` (both T_B_O): its centre's distance, the rotation
// between them, and ADD-S, the mean distance from the true surface moved by the error to the true
// surface (2000 points): a turn that leaves the surface where it was (a can about its axis)
// costs nothing there. adds_3deg_m: the ADD-S of a 3° turn about the centre about that axis of O
// where it is largest (what a 3° error can move this object's surface by).
struct PoseError {
  double centre_m = 0, rotation_rad = 0, adds_m = 0, adds_3deg_m = 0;
  // Within 3 mm and 3°, or within 3 mm and the surface moved no more than by a 3° turn (the
  // rest of the turn is the object's symmetry).
  bool within() const {
    return centre_m <= 0.003 && (rotation_rad <= 3 * M_PI / 180 || adds_m <= adds_3deg_m);
  }
};
PoseError poseError(const TriangleMesh& object, const Iso3& truth, const Iso3& found) {
  PoseError e;
  const Vec3 c = object.bounds().center();
  e.centre_m = (found * c - truth * c).norm();
  e.rotation_rad = rotationBetween(truth, found);
  const TriangleDistanceIndex index(object);
  const std::vector<Vec3> points = sampleSurfaceUniform(object, 2000, 7);
  auto adds = [&](const Iso3& moved) {
    double sum = 0;
    for (const Vec3& p : points) sum += index.distance(moved * p);
    return sum / double(std::max<size_t>(1, points.size()));
  };
  e.adds_m = adds(truth.inverse() * found);
  for (int a = 0; a < 3; ++a)
    e.adds_3deg_m = std::max(e.adds_3deg_m, adds(Eigen::Translation3d(c) *
                                                 Eigen::AngleAxisd(3 * M_PI / 180, Vec3::Unit(a)) *
                                                 Eigen::Translation3d(-c)));
  return e;
}

// The scan options for a regrasp-test (the config file's, physics on whatever it says) and the
// command line checked.
ScanConfig regraspConfig(const RegraspArgs& args) {
  ScanConfig o;
  const Json config = args.config.empty() ? Json() : readJsonFile(args.config);
  if (!args.config.empty()) readScanConfig(config, args.config, &o);
  if (!args.robot.empty()) o.robot = args.robot;
  if (o.robot.empty()) o.robot = defaultRobotConfig();
  o.sim.seed = args.seed;
  // The pick-up and the lift in physics, with what physics implies where the config is silent.
  setPhysics(true, config, &o);
  if (std::string p = o.validate(); !p.empty()) throw Error(p);
  if (!(std::isfinite(args.heading_deg) && std::abs(args.heading_deg) <= 360))
    throw Error("--heading: must be degrees in [-360, 360]");
  if (!(std::isfinite(args.scale) && args.scale > 0))
    throw Error("--scale: must be a positive number");
  const fs::path out = args.out;
  if (!out.empty() && out.has_parent_path() && !fs::is_directory(out.parent_path()))
    throw Error("--out: " + out.parent_path().string() + " is not a directory");
  return o;
}

// The true object (closed, scaled), with o->sim.R_B_O_rest set to its --rest-pose turned by
// --heading about the vertical.
TriangleMesh trueObject(const RegraspArgs& args, ScanConfig* o) {
  TriangleMesh object = withHolesClosed(loadSimulatedObject(args.object, false).mesh);
  if (args.scale != 1)
    for (Vec3f& v : object.vertices) v *= float(args.scale);
  const std::vector<StablePose> poses = stablePoses(object);
  if (args.rest_pose < 0 || args.rest_pose >= int(poses.size()))
    throw Error("--rest-pose: " + args.object + " has " + std::to_string(poses.size()) +
                " stable poses (0.." + std::to_string(int(poses.size()) - 1) + "), not " +
                std::to_string(args.rest_pose));
  o->sim.R_B_O_rest = Eigen::AngleAxisd(args.heading_deg * M_PI / 180, Vec3::UnitZ()) *
                      poses[size_t(args.rest_pose)].R_B_O;
  return object;
}

}  // namespace

int runRegraspTest(const RegraspArgs& args) {
  ScanConfig o = regraspConfig(args);
  const LoadedAsset asset = readAsset(args.asset);
  const RobotModel model = RobotModel::load(o.robot);
  std::vector<int> index;
  KnownObject known;
  known.grasps =
      workingGrasps(asset.grasps, model, (fs::path(args.asset) / "grasps.json").string(), &index);
  known.model_O.mesh = asset.model_O;
  known.model_O.observed = asset.observed;
  known.mass_kg = asset.mass_kg;
  known.com_O = asset.com_O;
  const TriangleMesh object = trueObject(args, &o);
  DepthCameraOptions camera;
  NoiseModelOptions noise;
  SimWorld world(model, object, defaultGrasp(model, object).first, camera, noise, o.sim);
  world.held = false;
  world.q = model.home();
  SimRobot robot(&world);
  SimSensor sensor(&world, camera);
  const Iso3 truth = world.tablePose;
  RegraspOptions ro;
  ro.scan = o.scan;
  ro.table_top = o.multi.table_top;
  ro.grasp = o.multi.grasp;
  ro.noise = noise;
  const RegraspResult r =
      pickUpKnownObject(robot, sensor, known, model.camera().lookAt_B, ro,
                        [](const std::string& s) { std::printf("regrasp-test: %s\n", s.c_str()); });

  // The truth: where the object is, whether it rose with the hand.
  const double rose = world.objectPose().translation().z() - truth.translation().z();
  const bool held = world.held && rose > 0.5 * ro.grasp.lift_m;
  auto setIndex = [&](int k) { return k >= 0 ? Json(index[size_t(k)]) : Json(); };
  Json report = {{"asset", args.asset},
                 {"object", args.object},
                 {"rest_pose", args.rest_pose},
                 {"heading_deg", args.heading_deg},
                 {"seed", args.seed},
                 {"set", r.set},
                 {"working_grasps", known.grasps.size()},
                 {"made_here", r.made},
                 {"held_in_hold_test", r.held_in_test},
                 {"chosen", setIndex(r.chosen)},
                 {"robot_says_lifted", r.lifted},
                 {"weighed_kg", r.weighed_kg},
                 {"asset_mass_kg", asset.mass_kg},
                 {"failure", r.failure},
                 {"held", held},
                 {"rose_m", rose},
                 {"find_s", r.find_s},
                 {"plan_s", r.plan_s},
                 {"pick_s", r.pick_s},
                 {"working_grasps_here", Json::array()}};
  for (size_t k = 0; k < r.generation.poses.size() && k < index.size(); ++k)
    report["working_grasps_here"].push_back(
        {{"grasp", index[k]}, {"result", r.generation.poses[k].result}});
  if (r.T_B_O) {
    const PoseError e = poseError(object, truth, *r.T_B_O);
    report["found"] = {
        {"T_B_O", isoJson(*r.T_B_O)},   {"T_B_O_true", isoJson(truth)},
        {"centre_error_m", e.centre_m}, {"rotation_error_deg", e.rotation_rad * 180 / M_PI},
        {"adds_m", e.adds_m},           {"adds_3deg_m", e.adds_3deg_m},
        {"support", r.support},         {"within_3mm_3deg", e.within()}};
    std::printf("regrasp-test: found %.1f mm and %.1f° from the truth (ADD-S %.2f mm): %s\n",
                1000 * e.centre_m, e.rotation_rad * 180 / M_PI, 1000 * e.adds_m,
                e.within() ? "within 3 mm / 3°" : "not within 3 mm / 3°");
  }
  std::printf(
      "regrasp-test: %s (grasp %s of the asset's set; %d of %zu working grasps made here; "
      "%.1f + %.1f + %.1f s)\n",
      held ? "HELD: the object rose with the hand" : "NOT HELD",
      (r.chosen >= 0 ? setIndex(r.chosen).dump() : std::string("none")).c_str(), r.made,
      known.grasps.size(), r.find_s, r.plan_s, r.pick_s);
  if (!args.out.empty()) writeTextAtomically(args.out, report.dump(1) + "\n");
  return held ? 0 : 4;
}

}  // namespace inhand::app
