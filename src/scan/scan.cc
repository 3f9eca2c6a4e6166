#include "inhand/scan/scan.h"

#include <chrono>
#include <optional>

#include "inhand/core/error.h"
#include "inhand/core/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/robot/collision.h"
#include "inhand/sensor/render.h"

namespace inhand {

std::string handModeName(HandMode m) {
  switch (m) {
    case HandMode::kNaive:
      return "naive";
    case HandMode::kCarveOnly:
      return "carve";
    case HandMode::kCarveAndEmpty:
      return "carve-empty";
  }
  return "?";
}

bool parseHandMode(const std::string& s, HandMode* out) {
  for (HandMode m : {HandMode::kNaive, HandMode::kCarveOnly, HandMode::kCarveAndEmpty})
    if (s == handModeName(m)) {
      *out = m;
      return true;
    }
  return false;
}

std::string ScanOptions::validate() const {
  if (!(voxel_m > 0 && voxel_m < 0.05)) return "voxel_m must be in (0, 0.05) m";
  if (!(volume_size_m > 10 * voxel_m && volume_size_m < 2))
    return "volume_size_m must be in (10 voxels, 2 m)";
  if (!(t_hand_m >= 0)) return "t_hand_m must be >= 0";
  if (initial_views < 0) return "initial_views must be >= 0";
  if (max_views < 0) return "max_views must be >= 0";
  if (planning_stride < 1 || planning_stride > 4) return "planning_stride must be in 1..4";
  if (carve_radius_px < 0 || carve_radius_px > 10) return "carve_radius_px must be in 0..10";
  std::string p = planner.validate();
  if (!p.empty()) return "planner." + p;
  p = mesh.validate();
  if (!p.empty()) return "mesh." + p;
  return {};
}

namespace {
using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}
}  // namespace

std::vector<uint8_t> robotPixelMask(const DepthImage& depth, const Iso3& T_B_C,
                                    const JointVector& q, const RobotOccluders& robotScenes,
                                    const DepthCameraOptions& camera,
                                    const NoiseModelOptions& noise, double t_hand_m, int radius_px,
                                    bool with_table) {
  RayScene robotScene;
  for (const Occluder& o : robotScenes.at(q, Iso3::Identity(), with_table))
    robotScene.addInstance(*o.scene, o.T_O_scene);
  robotScene.commit();
  RenderOptions exact;
  exact.noise = false;
  DepthCameraOptions cam = camera;
  cam.max_incidence_deg = 89;
  cam.max_projector_incidence_deg = 89;
  cam.projector_C = Vec3(1e-6, 0, 0);
  DepthImage robotDepth = renderDepth(robotScene, T_B_C, cam, noise, exact);
  // A measurement is the robot's when the robot's rendered surface lies within t_hand of it at
  // that pixel or within radius_px of it: the sensor's lateral noise moves returns across the
  // robot's silhouette by a pixel or two.
  std::vector<uint8_t> mask(depth.depth_m.size(), 0);
  const int W = depth.width, H = depth.height, R = radius_px;
  parallelFor(0, H, [&](int v) {
    for (int u = 0; u < W; ++u) {
      const float d = depth.depth_m[size_t(v) * W + u];
      if (!(d > 0)) continue;
      bool robot = false;
      for (int dv = -R; dv <= R && !robot; ++dv)
        for (int du = -R; du <= R && !robot; ++du) {
          const int uu = u + du, vv = v + dv;
          if (uu < 0 || vv < 0 || uu >= W || vv >= H || du * du + dv * dv > R * R) continue;
          const float rd = robotDepth.depth_m[size_t(vv) * W + uu];
          robot = rd > 0 && std::abs(d - rd) < t_hand_m;
        }
      mask[size_t(v) * W + u] = robot;
    }
  });
  return mask;
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
                           TsdfVolume* sharedVolume, const Aabb& object_box_O) {
  const auto t0 = Clock::now();
  std::string problem = options.validate();
  if (!problem.empty()) throw Error("scan options: " + problem);
  auto log = [&](const std::string& s) {
    if (progress.log) progress.log(s);
  };
  const RobotModel& m = robot.model();
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  ScanResult result;

  std::optional<TsdfVolume> ownVolume;
  if (!sharedVolume) ownVolume.emplace(makeScanVolume(centre_O, options));
  TsdfVolume& volume = sharedVolume ? *sharedVolume : *ownVolume;

  ViewPlanner planner(m, sensor.camera(), noise, options.planner);
  sensor.setPose(planner.cameraPose(options.planner.range_m));
  const HandGeometry hand(m, robot.joints(), T_O_palm);
  auto nearHand = std::make_shared<NearHandGrid>(hand, options.planner.quality.t_hand_m,
                                                 options.planner.quality.near_hand_cell_m);
  // Fig. 3 (c): voxels inside the robot are empty. The paper marks the hand; we mark every link
  // (the wrist and forearm too), at each frame's joint state: nothing of the object can be there.
  std::vector<Aabb> linkBox(m.links().size());
  for (size_t li = 0; li < m.links().size(); ++li)
    for (const Primitive& p : m.links()[li].collision) {
      Aabb b = p.toMesh().bounds();
      linkBox[li].extend(b.min);
      linkBox[li].extend(b.max);
    }
  auto emptyInsideRobot = [&](const JointVector& q, const Iso3& T_O_B) {
    std::vector<Iso3> T = m.linkPoses(q);
    for (size_t li = 0; li < m.links().size(); ++li) {
      if (m.links()[li].collision.empty()) continue;
      const Iso3 T_O_link = T_O_B * T[li];
      Aabb b;  // the link's box in O
      for (int c = 0; c < 8; ++c) b.extend(T_O_link * linkBox[li].corner(c));
      Vec3 lo = ((b.min - volume.origin()) / volume.voxelSize()).array().ceil();
      Vec3 hi = ((b.max - volume.origin()) / volume.voxelSize()).array().floor();
      lo = lo.cwiseMax(Vec3::Zero());
      hi = hi.cwiseMin((volume.dims().cast<double>().array() - 1).matrix());
      if ((lo.array() > hi.array()).any()) continue;
      const Iso3 T_link_O = T_O_link.inverse();
      parallelFor(int(lo.z()), int(hi.z()) + 1, [&](int z) {
        for (int y = int(lo.y()); y <= int(hi.y()); ++y)
          for (int x = int(lo.x()); x <= int(hi.x()); ++x) {
            Vec3 p = T_link_O * volume.point(x, y, z);
            for (const Primitive& prim : m.links()[li].collision)
              if (prim.contains(p)) {
                size_t i = volume.index(x, y, z);
                // Measurements win over the hand model: a voxel the sensor saw behind the
                // object's surface stays (a finger closed on the model can overlap the object).
                if (volume.state(i) == VoxelState::kObserved && volume.distance(i) < 0) break;
                volume.states()[i] = uint8_t(VoxelState::kEmpty);
                volume.sumW()[i] = 0;
                volume.sumWD()[i] = 0;
                break;
              }
          }
      });
    }
  };
  const RobotOccluders robotScenes(m);

  // Fuses the sensor's current frame with the pose the robot reports.
  auto fuse = [&](const JointVector& q) {
    const auto tf = Clock::now();
    DepthImage depth = sensor.capture();
    const Iso3 T_B_C = sensor.pose();
    const Iso3 T_O_B = T_O_palm * m.tipPose(q).inverse();
    const Iso3 T_O_C = T_O_B * T_B_C;
    std::vector<uint8_t> carve;
    if (options.hand_mode != HandMode::kNaive)  // the robot's own surfaces only carve (§IV)
      carve = robotPixelMask(depth, T_B_C, q, robotScenes, sensor.camera(), noise, options.t_hand_m,
                             options.carve_radius_px);
    integrate(depth, T_O_C, K, measurementSigma(depth, K, noise), &volume,
              carve.empty() ? nullptr : &carve);
    if (options.hand_mode == HandMode::kCarveAndEmpty) emptyInsideRobot(q, T_O_B);
    ++result.frames;
    result.fusion_s += secondsSince(tf);
  };
  auto moveTo = [&](const ViewCandidate& c) {
    const int before = result.frames;
    JointVector q0 = robot.joints();
    robot.execute({q0, m.withArm(q0, c.arm)}, fuse);
    return result.frames - before;
  };

  std::vector<Vec3> used;
  // The simple initial trajectory: a few directions spread over the sphere.
  if (options.initial_views > 0) {
    Aabb guess = object_box_O;
    if (guess.empty()) {
      guess.extend(centre_O - Vec3::Constant(0.05));
      guess.extend(centre_O + Vec3::Constant(0.05));
    }
    for (const Vec3& dir : fibonacciSphere(options.initial_views)) {
      // The views are taken one after the other: each move, from where the arm is, must keep
      // it clear of the object in the hand (a forearm swinging through it would also empty its
      // inside in the model).
      const GraspState g{T_O_palm, robot.joints()};
      const std::optional<ViewCandidate> c = planner.reach({dir}, centre_O, guess, g, true)[0];
      if (!c) {
        log("initial view skipped: no collision-free move there");
        continue;
      }
      ViewRecord rec;
      rec.initial = true;
      rec.dir_O = c->dir_O;
      rec.T_O_C = c->T_O_C;
      rec.cost_s = trajectoryTime(m, m.arm(robot.joints()), c->arm);
      rec.frames = moveTo(*c);
      ObjectModel model = extractModel(volume, options.mesh);
      rec.mean_entropy = model.meanEntropy();
      rec.observed_fraction = model.observedAreaFraction();
      if (progress.coverage) rec.coverage = progress.coverage(model);
      used.push_back(c->dir_O);
      result.views.push_back(rec);
      log("initial view " + std::to_string(result.views.size()) + ": " +
          std::to_string(rec.frames) + " frames, mean entropy " + std::to_string(rec.mean_entropy));
    }
  }

  result.termination = "max_views";
  MeshOptions planningMesh = options.mesh;
  planningMesh.stride = options.planning_stride;
  planningMesh.method = options.planning_method;
  for (int v = 0; v < options.max_views; ++v) {
    ObjectModel model = extractModel(volume, planningMesh);
    const auto tp = Clock::now();
    ViewSelection sel =
        planner.select(model, GraspState{T_O_palm, robot.joints()}, used, nearHand, &volume);
    result.planning_s += secondsSince(tp);
    result.view_evaluations += sel.evaluated;
    result.view_refinements += sel.refined;
    if (!sel.best) {
      result.termination = sel.reachable == 0 ? "no_reachable_view" : "no_view_above_threshold";
      log("no view reaches t_q (" + std::to_string(sel.evaluated) + " candidates): done");
      break;
    }
    const ViewCandidate& c = *sel.best;
    ViewRecord rec;
    rec.dir_O = c.dir_O;
    rec.T_O_C = c.T_O_C;
    rec.quality = c.quality;
    rec.cost_s = c.cost_s;
    rec.score = c.score;
    rec.candidates = sel.evaluated;
    rec.planning_s = sel.total_s;
    rec.frames = moveTo(c);
    ObjectModel after = extractModel(volume, options.mesh);
    rec.mean_entropy = after.meanEntropy();
    rec.observed_fraction = after.observedAreaFraction();
    if (progress.coverage) rec.coverage = progress.coverage(after);
    used.push_back(c.dir_O);
    result.views.push_back(rec);
    char line[240];
    std::snprintf(line, sizeof(line),
                  "view %d: quality %.4f, cost %.2f s, %d candidates, %d at full resolution (%.2f "
                  "s: IK %.2f, quality %.2f), %d frames, mean entropy %.3f",
                  v + 1, rec.quality, rec.cost_s, rec.candidates, sel.refined, rec.planning_s,
                  sel.ik_s, sel.quality_s, rec.frames, rec.mean_entropy);
    log(line);
  }
  result.model = extractModel(volume, options.mesh);
  result.planning_model = extractModel(volume, planningMesh);
  result.total_s = secondsSince(t0);
  return result;
}

}  // namespace inhand
