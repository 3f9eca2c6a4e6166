#include "inhand/scan/scan.h"

#include <tbb/parallel_invoke.h>

#include <chrono>
#include <optional>

#include "inhand/core/error.h"
#include "inhand/core/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/raster.h"
#include "inhand/robot/collision.h"
#include "inhand/scan/session.h"

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

std::string FrameChecks::validate() const {
  if (!(min_valid_fraction >= 0 && min_valid_fraction < 1))
    return "min_valid_fraction must be in [0, 1)";
  if (!(max_path_deviation_rad >= 0)) return "max_path_deviation_rad must be >= 0";
  if (!(min_support >= 0 && min_support <= 1)) return "min_support must be in [0, 1]";
  if (min_points < 1) return "min_points must be >= 1";
  if (lost_after < 1) return "lost_after must be >= 1";
  if (!(max_free_space_fraction > 0 && max_free_space_fraction <= 1))
    return "max_free_space_fraction must be in (0, 1]";
  return {};
}

std::string ScanOptions::validate() const {
  if (!(voxel_m > 0 && voxel_m < 0.05)) return "voxel_m must be in (0, 0.05) m";
  if (std::string p = checks.validate(); !p.empty()) return "checks." + p;
  if (!(volume_size_m > 10 * voxel_m && volume_size_m < 2))
    return "volume_size_m must be in (10 voxels, 2 m)";
  if (!(t_hand_m >= 0)) return "t_hand_m must be >= 0";
  if (initial_views < 0) return "initial_views must be >= 0";
  if (max_views < 0) return "max_views must be >= 0";
  if (planning_stride < 1 || planning_stride > 4) return "planning_stride must be in 1..4";
  if (carve_radius_px < 0 || carve_radius_px > 10) return "carve_radius_px must be in 0..10";
  if (!(edge_jump_m >= 0 && edge_jump_m < 1)) return "edge_jump_m must be in [0, 1) m";
  if (!(volume_budget.truncation_m >= 0 && volume_budget.truncation_m < 0.1))
    return "truncation_m must be in [0, 0.1) m (0: 4 voxels)";
  if (volume_budget.truncation_m > 0 && volume_budget.truncation_m < voxel_m)
    return "truncation_m must be at least one voxel (voxel_m)";
  if (!(volume_budget.band_sigmas >= 0 && volume_budget.band_sigmas <= 100))
    return "band_sigmas must be in [0, 100]";
  std::string p = planner.validate();
  if (!p.empty()) return "planner." + p;
  p = mesh.validate();
  if (!p.empty()) return "mesh." + p;
  p = tracking.validate();
  if (!p.empty()) return "tracking." + p;
  return {};
}

namespace {
using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}
}  // namespace

DepthImage robotDepthImage(const RobotOccluders& robotScenes, const JointVector& q,
                           const Iso3& T_B_C, const DepthCameraOptions& camera, bool with_table,
                           const PixelRect& region) {
  const CameraIntrinsics& K = camera.intrinsics;
  DepthImage out(K.width, K.height);
  const PixelRect window{std::max(0, region.u0), std::max(0, region.v0),
                         std::min(K.width, region.u1), std::min(K.height, region.v1)};
  if (window.empty()) return out;
  thread_local DepthRaster perThread;
  DepthRaster& raster = perThread;  // (inside the parallel loop below, the caller's)
  raster.reset(PinholeProjection{K.fx, K.fy, K.cx, K.cy},
               RasterWindow{window.u0, window.u1 - 1, window.v0, window.v1 - 1, 1});
  const Iso3 T_C_B = T_B_C.inverse();
  std::vector<RayScene::PlacedMesh> meshes;
  std::vector<uint8_t> solid;
  for (const Occluder& o : robotScenes.at(q, Iso3::Identity(), with_table)) {
    o.scene->collectMeshes(T_C_B * o.T_O_scene, &meshes);
    solid.resize(meshes.size(), o.solid);
  }
  // Triangle ids run on from mesh to mesh (the id is the index into `normal`); each triangle's
  // normal in the camera frame.
  std::vector<size_t> firstId(meshes.size() + 1, 0);
  for (size_t k = 0; k < meshes.size(); ++k)
    firstId[k + 1] = firstId[k] + meshes[k].mesh->triangles.size();
  std::vector<Vec3> normal(firstId.back());
  // The normals on the other core while this one rasterises.
  tbb::parallel_invoke(
      [&] {
        for (size_t k = 0; k < meshes.size(); ++k) {
          const RayScene::PlacedMesh& m = meshes[k];
          // Back faces of a closed link may go when the camera is outside its box.
          const bool inside = m.bounds->contains(m.T.inverse().translation());
          raster.draw(*m.mesh, m.T, int(firstId[k]), solid[k] && !inside, 0, m.bounds);
        }
      },
      [&] {
        for (size_t k = 0; k < meshes.size(); ++k) {
          const RayScene::PlacedMesh& m = meshes[k];
          Vec3* out = normal.data() + firstId[k];
          for (const Tri& t : m.mesh->triangles) {
            const Vec3 a = m.T * m.mesh->vertices[size_t(t[0])].cast<double>();
            const Vec3 b = m.T * m.mesh->vertices[size_t(t[1])].cast<double>();
            const Vec3 c = m.T * m.mesh->vertices[size_t(t[2])].cast<double>();
            *out++ = (b - a).cross(c - a);
          }
        }
      });
  const double cosLimit = std::cos(89 * M_PI / 180);
  parallelFor(window.v0, window.v1, [&](int v) {
    for (int u = window.u0; u < window.u1; ++u) {
      const int s = raster.index(u, v), id = raster.id(s);
      if (id < 0) continue;
      const double z = 1.0 / double(raster.inverseDepth(s));
      if (z < camera.min_range_m || z > camera.max_range_m) continue;
      const Vec3 dir = K.rayZ1(u, v);
      const Vec3& n = normal[size_t(id)];
      const double nn = n.squaredNorm() * dir.squaredNorm();
      if (!(nn > 0) || std::abs(n.dot(dir)) < cosLimit * std::sqrt(nn)) continue;
      out.depth_m[size_t(v) * K.width + size_t(u)] = float(z);
    }
  });
  return out;
}

std::vector<uint8_t> robotPixelMask(const DepthImage& depth, const Iso3& T_B_C,
                                    const JointVector& q, const RobotOccluders& robotScenes,
                                    const DepthCameraOptions& camera, double t_hand_m,
                                    int radius_px, bool with_table, const PixelRect* region) {
  const int W = depth.width, H = depth.height, R = radius_px;
  const PixelRect r = region ? PixelRect{std::max(0, region->u0), std::max(0, region->v0),
                                         std::min(W, region->u1), std::min(H, region->v1)}
                             : PixelRect{0, 0, W, H};
  std::vector<uint8_t> mask(depth.depth_m.size(), 0);
  if (r.empty()) return mask;
  const DepthImage robotDepth = robotDepthImage(robotScenes, q, T_B_C, camera, with_table,
                                                PixelRect{r.u0 - R, r.v0 - R, r.u1 + R, r.v1 + R});
  // A measurement is the robot's when the robot's rendered surface lies within t_hand of it at
  // that pixel or within radius_px of it: the sensor's lateral noise moves returns across the
  // robot's silhouette by a pixel or two. Pixels with no robot surface in the (2R + 1)² square
  // around them cannot be (a separable dilation of where the robot is, rows then columns).
  std::vector<uint8_t> rowNear(depth.depth_m.size(), 0), near(depth.depth_m.size(), 0);
  const int rv0 = std::max(0, r.v0 - R), rv1 = std::min(H, r.v1 + R);
  parallelFor(rv0, rv1, [&](int v) {
    const float* rd = &robotDepth.depth_m[size_t(v) * W];
    uint8_t* out = &rowNear[size_t(v) * W];
    // The last column up to u + R where the robot is: it is within R of u when not before u − R.
    int last = r.u0 - R - 1, next = std::max(0, r.u0 - R);
    for (int u = r.u0; u < r.u1; ++u) {
      for (const int end = std::min(W - 1, u + R); next <= end; ++next)
        if (rd[next] > 0) last = next;
      out[u] = last >= u - R;
    }
  });
  // (Raw row pointers: a store through a vector's uint8_t element may alias the vector itself,
  // which kept these loops from being vectorised.)
  parallelFor(r.v0, r.v1, [&](int v) {
    uint8_t* out = near.data() + size_t(v) * W;
    for (int vv = std::max(0, v - R); vv <= std::min(H - 1, v + R); ++vv) {
      const uint8_t* in = rowNear.data() + size_t(vv) * W;
      for (int u = r.u0; u < r.u1; ++u) out[u] |= in[u];
    }
  });
  const float* robotZ = robotDepth.depth_m.data();
  parallelFor(r.v0, r.v1, [&](int v) {
    const float* z = depth.depth_m.data() + size_t(v) * W;
    const uint8_t* isNear = near.data() + size_t(v) * W;
    uint8_t* out = mask.data() + size_t(v) * W;
    for (int u = r.u0; u < r.u1; ++u) {
      const float d = z[u];
      if (!(d > 0) || !isNear[u]) continue;
      // The pixel itself first (most pixels near the robot are on it), then the whole disk.
      const float rd0 = robotZ[size_t(v) * W + u];
      bool robot = rd0 > 0 && std::abs(d - rd0) < t_hand_m;
      for (int dv = -R; dv <= R && !robot; ++dv)
        for (int du = -R; du <= R && !robot; ++du) {
          const int uu = u + du, vv = v + dv;
          if (uu < 0 || vv < 0 || uu >= W || vv >= H || du * du + dv * dv > R * R) continue;
          const float rd = robotZ[size_t(vv) * W + uu];
          robot = rd > 0 && std::abs(d - rd) < t_hand_m;
        }
      out[u] = robot;
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
      session.addFrame(depth, q, sensor.pose());
    });
    session.finishView();
    if (lost()) return Termination::kObjectLost;
    if (stopped) break;
    if (after_view) after_view();
  }
  session.finish(Termination::kInterrupted, "interrupted by the caller");
  return Termination::kInterrupted;
}

}  // namespace inhand
