// Tracking the hand in depth frames: the correction that ICP finds against frames rendered with
// a known arm error, and frames it must refuse.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "inhand/core/error.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/planning/view_selection.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/scan/scan.h"
#include "inhand/scan/session.h"
#include "inhand/sensor/render.h"
#include "inhand/sim/sim_world.h"
#include "test_util.h"

using namespace inhand;

namespace {
using test::wam;

// The coffee can held at the default grasp, presented to the camera at the planner's pose, with
// arm error `error_m`.
struct Scene {
  TriangleMesh can = loadObject("builtin:coffee_can");
  std::pair<Iso3, JointVector> grasp = defaultGrasp(wam(), can);
  SimWorld world;
  explicit Scene(double error_m, uint64_t seed = 1)
      : world(wam(), can, grasp.first, DepthCameraOptions{}, NoiseModelOptions{},
              opts(error_m, seed)) {
    world.q = grasp.second;
    ViewPlanner planner(wam(), DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{});
    world.T_B_C = planner.cameraPose(0.7);
    // A view of the can from the side, reached by IK.
    const Vec3 centre = grasp.first * Vec3(0, 0, wam().graspOffset());
    Aabb box;
    box.extend(centre - Vec3::Constant(0.07));
    box.extend(centre + Vec3::Constant(0.07));
    const auto c =
        planner.reach({Vec3(1, 0.3, -0.2).normalized()}, centre, box, {grasp.first, world.q})[0];
    if (c) world.q = wam().withArm(world.q, c->arm);
  }
  static SimOptions opts(double e, uint64_t seed) {
    SimOptions o;
    o.arm_error_m = e;
    o.seed = seed;
    return o;
  }
  // The palm's true and reported poses in the camera frame.
  Iso3 trueT_C_palm() const { return world.T_B_C.inverse() * wam().tipPose(world.trueJoints()); }
  Iso3 reportedT_C_palm() const { return world.T_B_C.inverse() * wam().tipPose(world.q); }
};

std::vector<SurfacePoint> handPoints(const JointVector& q) {
  return evenSurfaceSamples(HandGeometry(wam(), q, Iso3::Identity()).mesh(), 0.004);
}
}  // namespace

// The chamfer distance over a window is the whole image's wherever it is shorter than the
// window's margin around the pixel (an independent answer: the brute-force chamfer distance, the
// least of max(|du|, |dv|) + (√2 − 1) min(|du|, |dv|) over the image's zeros).
TEST(Tracking, ChamferDistanceInAWindowIsTheImagesNearItsPixels) {
  const int w = 120, h = 90;
  std::vector<uint8_t> zero(size_t(w * h), 0);
  uint32_t state = 7;
  for (uint8_t& z : zero) {
    state = state * 1664525u + 1013904223u;
    z = (state >> 24) < 3;  // about 1 % of the pixels
  }
  const std::vector<float> whole = chamferDistance(zero, w, PixelRect{0, 0, w, h});
  const PixelRect window{30, 20, 95, 70};
  const std::vector<float> part = chamferDistance(zero, w, window);
  int compared = 0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      double best = 1e9;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (zero[size_t(y * w + x)]) {
            const int a = std::abs(x - u), b = std::abs(y - v);
            best = std::min(best, std::max(a, b) + (std::sqrt(2.0) - 1) * std::min(a, b));
          }
      ASSERT_NEAR(whole[size_t(v * w + u)], best, 1e-4) << u << " " << v;
      if (u < window.u0 || u >= window.u1 || v < window.v0 || v >= window.v1) continue;
      const int margin =
          std::min({u - window.u0, window.u1 - 1 - u, v - window.v0, window.v1 - 1 - v});
      const float d = part[size_t((v - window.v0) * (window.u1 - window.u0) + (u - window.u0))];
      if (best < margin) {
        EXPECT_FLOAT_EQ(d, whole[size_t(v * w + u)]) << u << " " << v;
        ++compared;
      } else {
        EXPECT_GE(d, whole[size_t(v * w + u)] - 1e-4) << u << " " << v;  // never shorter
      }
    }
  EXPECT_GT(compared, 1000);
}

TEST(Tracking, RecoversTheArmErrorFromTheHandInTheFrame) {
  for (double error : {0.0, 0.01, 0.02, 0.03}) {
    Scene s(error, 3);
    const DepthImage d = s.world.render();
    TrackingOptions o;
    o.enabled = true;
    const TrackResult r =
        alignToDepth(d, DepthCameraOptions{}.intrinsics, handPoints(s.world.q), {}, {},
                     s.reportedT_C_palm(), {Iso3::Identity()},
                     axialSigma(NoiseModelOptions{}, s.reportedT_C_palm().translation().z(), 0), o);
    const double before =
        (s.reportedT_C_palm().translation() - s.trueT_C_palm().translation()).norm();
    const Iso3 tracked = r.correction * s.reportedT_C_palm();
    const double after = (tracked.translation() - s.trueT_C_palm().translation()).norm();
    EXPECT_TRUE(r.ok) << error << ": " << r.reason;
    std::printf(
        "arm error %.0f mm: palm %.1f mm off, %.2f mm after tracking (%d points, rms %.2f mm)\n",
        error * 1000, before * 1000, after * 1000, r.inliers, r.rms_m * 1000);
    EXPECT_LT(after, 0.003) << "arm error " << error << " m: palm " << before * 1000 << " mm off, "
                            << after * 1000 << " mm after tracking, " << r.inliers
                            << " points, rms " << r.rms_m * 1000 << " mm";
  }
}

// A held scan of the cracker box with 2 cm of arm error, driven frame by frame: the palm the
// session fuses with against the simulator's true palm, every fused frame; and a frame without
// the hand in view is refused, not fused.
TEST(Tracking, FollowsTheHandThroughAScanWithTwoCentimetresOfArmError) {
  const TriangleMesh box = loadObject("builtin:cracker_box");
  auto [T_O_palm, q] = defaultGrasp(wam(), box);
  SimOptions so;
  so.arm_error_m = 0.02;
  so.frame_subsample = 4;
  SimWorld world(wam(), box, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, so);
  world.q = q;
  SimRobot robot(&world);
  SimSensor sensor(&world, DepthCameraOptions{});
  ScanOptions o;
  o.voxel_m = 0.003;
  o.planner.directions = 120;
  o.planner.rolls = 4;
  o.max_views = 3;
  o.tracking.enabled = true;
  const MultiGraspOptions multi;
  ScanSession s(wam(), DepthCameraOptions{}, NoiseModelOptions{}, o, multi,
                T_O_palm * Vec3(0, 0, wam().graspOffset()));
  s.beginGrasp(T_O_palm, robot.joints());
  // The camera turned away from the hand: nothing to align, the frame is refused.
  sensor.setPose(lookAt(wam().camera().panTilt_B, wam().camera().panTilt_B + Vec3(0, 3, 0)));
  const FrameReport away = s.addFrame(sensor.capture(), robot.joints(), sensor.pose());
  EXPECT_FALSE(away.fused);
  EXPECT_EQ(away.refusal, FrameRefusal::kTracking) << away.rejected;
  EXPECT_EQ(away.tracking_refusal, TrackRefusal::kTooFewPoints) << away.rejected;
  EXPECT_EQ(s.summary().frames, 0);
  EXPECT_EQ(s.summary().frames_rejected, 1);
  std::vector<double> before, after;
  sensor.setPose(s.cameraPose());
  while (auto v = s.nextView(robot.joints())) {
    robot.execute(v->waypoints, [&](const JointVector& qq) {
      const FrameReport r = s.addFrame(sensor.capture(), qq, sensor.pose());
      if (!r.fused) return;
      const Vec3 truth =
          (sensor.pose().inverse() * wam().tipPose(world.trueJoints())).translation();
      after.push_back(((r.T_B_C.inverse() * wam().tipPose(qq)).translation() - truth).norm());
      before.push_back(
          ((sensor.pose().inverse() * wam().tipPose(qq)).translation() - truth).norm());
    });
    s.finishView();
  }
  ASSERT_GE(after.size(), 20u);
  std::sort(before.begin(), before.end());
  std::sort(after.begin(), after.end());
  const double medianBefore = before[before.size() / 2], medianAfter = after[after.size() / 2];
  const double p90 = after[after.size() * 9 / 10];
  std::printf(
      "%zu frames fused (%d refused): palm error median %.1f mm reported, %.2f mm tracked, "
      "90th percentile %.2f mm\n",
      after.size(), s.summary().frames_rejected, medianBefore * 1000, medianAfter * 1000,
      p90 * 1000);
  // A checkpoint keeps the refused frames' count (and the last error, to start from).
  test::TempDir dir;
  s.save(dir.path() / "t.inhand");
  const ScanSession back = ScanSession::load(dir.path() / "t.inhand", wam(), DepthCameraOptions{},
                                             NoiseModelOptions{}, o, multi);
  EXPECT_EQ(back.summary().frames_rejected, s.summary().frames_rejected);
  EXPECT_GT(medianBefore, 0.01);
  EXPECT_LT(medianAfter, 0.0015);
  EXPECT_LT(p90, 0.004);
}

// With SimOptions::grasp_error the arm's error displaces the grasp itself: the pick-up reports
// the grasp its joints imply, the object sits in the hand elsewhere; without it the two agree.
TEST(Tracking, ThePickUpReportsTheGraspTheJointsImply) {
  const TriangleMesh can = loadObject("builtin:coffee_can");
  for (bool graspError : {false, true}) {
    SimOptions so;
    so.arm_error_m = 0.02;
    so.grasp_error = graspError;
    so.pick_up_first_contact = false;  // the palm backed off the object: the same as planned
    auto [T_O_palm, q] = defaultGrasp(wam(), can);
    SimWorld world(wam(), can, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, so);
    SimRobot robot(&world);
    world.held = false;
    const std::optional<Iso3> reported = robot.pickUp(T_O_palm, q);
    ASSERT_TRUE(reported.has_value());
    const double apart = (reported->translation() - world.T_O_palm.translation()).norm();
    if (!graspError) {
      EXPECT_LT(apart, 1e-12);
      continue;
    }
    // The palm in the object frame is off by the arm's error at the pick configuration: the
    // true palm pose relative to the reported one, as forward kinematics gives it.
    const Iso3 delta = wam().tipPose(q).inverse() * wam().tipPose(world.trueJoints());
    EXPECT_GT(apart, 0.01);
    EXPECT_NEAR(apart, delta.translation().norm(), 0.01);
  }
}

namespace {
// The robot's depth casting an Embree ray per pixel through its links (and with `table` its
// table): noise-free, every angle below 89°, no projector shadows.
DepthImage rayCastRobot(const RobotOccluders& scenes, const JointVector& q, const Iso3& T_B_C,
                        bool table) {
  RayScene robotScene;
  for (const Occluder& o : scenes.at(q, Iso3::Identity(), table))
    robotScene.addInstance(*o.scene, o.T_O_scene);
  robotScene.commit();
  DepthCameraOptions cam;
  cam.max_incidence_deg = 89;
  cam.max_projector_incidence_deg = 89;
  cam.projector_C = Vec3(1e-6, 0, 0);
  RenderOptions exact;
  exact.noise = false;
  exact.projector_shadows = false;
  return renderDepth(robotScene, T_B_C, cam, NoiseModelOptions{}, exact);
}
}  // namespace

// robotDepthImage (the robot's links rasterised) against renderDepth casting a ray per pixel
// through the same links: the same pixels covered but for a few on silhouette edges, the same
// depth to float rounding (Embree intersects in single precision: within 1e-5 of the depth); for
// two arm configurations holding the object up to the camera, with and without the table, a
// window past the image's edges (clipped to it) and one inside it.
TEST(Tracking, RobotDepthImageIsTheRayCastRobot) {
  const TriangleMesh mesh = loadObject("builtin:cracker_box");
  auto [T_O_palm, q] = defaultGrasp(wam(), mesh);
  const RobotOccluders scenes(wam());
  ViewPlanner planner(wam(), DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{});
  const Iso3 T_B_C = planner.cameraPose(0.7);
  // The object held up to the camera from two sides: the hand and the arm in view.
  const Vec3 centre = T_O_palm * Vec3(0, 0, wam().graspOffset());
  Aabb box;
  box.extend(centre - Vec3::Constant(0.1));
  box.extend(centre + Vec3::Constant(0.1));
  std::vector<JointVector> configs;
  for (const Vec3& d : {Vec3(1, 0.3, -0.2), Vec3(-0.3, 1, 0.4)}) {
    const auto c = planner.reach({d.normalized()}, centre, box, {T_O_palm, q})[0];
    ASSERT_TRUE(c.has_value());
    configs.push_back(wam().withArm(q, c->arm));
  }
  int covered = 0;
  for (const JointVector& qq : configs)
    for (bool table : {true, false})
      for (bool whole : {true, false}) {
        const PixelRect window =
            whole ? PixelRect{-5, -5, 700, 500} : PixelRect{150, 100, 500, 400};
        const DepthImage cast = rayCastRobot(scenes, qq, T_B_C, table);
        const DepthImage raster =
            robotDepthImage(scenes, qq, T_B_C, DepthCameraOptions{}, table, window);
        int both = 0, onlyOne = 0, outside = 0;
        for (int v = 0; v < 480; ++v)
          for (int u = 0; u < 640; ++u) {
            const float a = cast.at(u, v), b = raster.at(u, v);
            if (u < window.u0 || u >= window.u1 || v < window.v0 || v >= window.v1) {
              outside += b != 0.f;
              continue;
            }
            if ((a > 0) != (b > 0)) {
              ++onlyOne;
              continue;
            }
            if (!(a > 0)) continue;
            ++both;
            EXPECT_NEAR(a, b, 1e-5 * a) << u << " " << v;
          }
        EXPECT_EQ(outside, 0);
        EXPECT_LE(onlyOne, both / 500 + 5) << "table " << table << ", whole " << whole;
        EXPECT_GT(both, table ? 20000 : 2000);
        covered += both;
      }
  EXPECT_GT(covered, 100000);
}

// robotPixelMask against its rule pixel by pixel: a measurement is the robot's when the robot's
// rendered surface (noise-free, every angle below 89°, no projector shadows) at a pixel within
// radius_px lies within t_hand of it; for several radii, the whole image and a region.
TEST(Tracking, RobotPixelMaskFollowsItsRuleAtEveryPixel) {
  const TriangleMesh mesh = loadObject("builtin:cracker_box");
  auto [T_O_palm, q] = defaultGrasp(wam(), mesh);
  SimWorld world(wam(), mesh, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, SimOptions{});
  world.q = q;
  world.T_B_C = ViewPlanner(wam(), DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{})
                    .cameraPose(0.7);
  const DepthImage d = world.render();
  const RobotOccluders scenes(wam());
  const DepthImage rd = rayCastRobot(scenes, world.q, world.T_B_C, true);
  const int W = d.width, H = d.height;
  const double t_hand = 0.01;
  for (int R : {0, 1, 2, 3})
    for (bool whole : {true, false}) {
      const PixelRect region{150, 100, 500, 400};
      const std::vector<uint8_t> mask =
          robotPixelMask(d, world.T_B_C, world.q, scenes, DepthCameraOptions{}, t_hand, R,
                         /*with_table=*/true, whole ? nullptr : &region);
      int robot = 0, other = 0, differ = 0;
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          bool want = false;
          const float z = d.at(u, v);
          const bool inside =
              whole || (u >= region.u0 && u < region.u1 && v >= region.v0 && v < region.v1);
          for (int dv = -R; dv <= R && z > 0 && inside; ++dv)
            for (int du = -R; du <= R; ++du) {
              const int uu = u + du, vv = v + dv;
              if (uu < 0 || vv < 0 || uu >= W || vv >= H || du * du + dv * dv > R * R) continue;
              want |= rd.at(uu, vv) > 0 && std::abs(z - rd.at(uu, vv)) < t_hand;
            }
          differ += bool(mask[size_t(v) * W + u]) != want;
          (want ? robot : other) += z > 0;
        }
      EXPECT_EQ(differ, 0) << "radius " << R << (whole ? ", whole image" : ", region");
      EXPECT_GT(robot, 2000) << R;
      EXPECT_GT(other, 20000) << R;
    }
}

namespace {
// A built-in object held by the default grasp, turned to face the camera (0.7 m away) from one
// side: the frame `d`, the robot's pixels `robot`, the object's true pose in the camera
// `trueT_C_O`; its mesh's vertices as occluders.
struct HeldInView {
  TriangleMesh mesh;
  DepthImage d;
  std::vector<uint8_t> robot;
  Iso3 trueT_C_O;
  std::vector<Vec3> occluders;
  explicit HeldInView(const char* name) : mesh(loadObject(name)) {
    auto [T_O_palm, q] = defaultGrasp(wam(), mesh);
    SimWorld world(wam(), mesh, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, SimOptions{});
    world.q = q;
    ViewPlanner planner(wam(), DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{});
    world.T_B_C = planner.cameraPose(0.7);
    const Vec3 centre = T_O_palm * Vec3(0, 0, wam().graspOffset());
    Aabb box;
    box.extend(centre - Vec3::Constant(0.1));
    box.extend(centre + Vec3::Constant(0.1));
    const auto c =
        planner.reach({Vec3(1, 0.3, -0.2).normalized()}, centre, box, {T_O_palm, world.q})[0];
    if (!c) throw Error(std::string("HeldInView: no view of ") + name);
    world.q = wam().withArm(world.q, c->arm);
    d = world.render();
    robot = robotPixelMask(d, world.T_B_C, world.q, RobotOccluders(wam()), DepthCameraOptions{},
                           0.01, 2, /*with_table=*/false);
    trueT_C_O = world.T_B_C.inverse() * world.objectPose();
    for (const Vec3f& v : mesh.vertices) occluders.push_back(v.cast<double>());
  }
  // The object's surface where pose `found_T_C_O` puts it, against the true surface (a turn
  // about a symmetry axis changes nothing there): the largest distance of its samples.
  double worstSurfaceError(const Iso3& found_T_C_O) const {
    const TriangleDistanceIndex truth(mesh);
    const Iso3 error = trueT_C_O.inverse() * found_T_C_O;  // object frame
    double worst = 0;
    for (const SurfacePoint& sp : surfaceSamples(mesh, 0.005))
      worst = std::max(worst, truth.distance(error * sp.p));
    return worst;
  }
};
}  // namespace

// The object's pose in the hand recovered from one frame of it held: the true mesh's surface as
// the model, started from the grasp off by a known offset (across the line of sight and in
// depth, and a few degrees), the robot's pixels masked.
TEST(Tracking, RecoversTheObjectsPoseInTheHand) {
  for (const char* name : {"builtin:coffee_can", "builtin:cracker_box"}) {
    const HeldInView h(name);
    const TriangleMesh& mesh = h.mesh;
    const DepthImage& d = h.d;
    const std::vector<uint8_t>& robot = h.robot;
    const Iso3& trueT_C_O = h.trueT_C_O;
    // Believed: 15 mm and 10 mm across the line of sight, 8 mm in depth, 3 degrees about the
    // object's centre (its frame's origin).
    Iso3 believed = trueT_C_O;
    believed.linear() = Eigen::AngleAxisd(0.05, Vec3(1, 2, 0.5).normalized()).toRotationMatrix() *
                        trueT_C_O.linear();
    believed.translation() += Vec3(0.015, -0.010, 0.008);
    const std::vector<Vec3>& occluders = h.occluders;
    TrackingOptions o;
    o.enabled = true;
    const TrackResult r = alignBodyToDepth(
        d, robot, DepthCameraOptions{}.intrinsics, surfaceSamples(mesh, 0.004), occluders, believed,
        axialSigma(NoiseModelOptions{}, believed.translation().z(), 0), o, UncoveredPull::kOff,
        NoDepthPixels::kUnknown);
    EXPECT_TRUE(r.ok) << name << ": " << r.reason;
    const Iso3 found = r.correction * believed;
    // The surface's worst sample against the true surface, and the mesh's vertices moved by the
    // pose error (which a turn about a symmetry axis does change).
    const double worst = h.worstSurfaceError(found);
    const Iso3 error = trueT_C_O.inverse() * found;  // object frame
    double worstVertex = 0;
    for (const Vec3f& v : mesh.vertices)
      worstVertex = std::max(worstVertex, (error * v.cast<double>() - v.cast<double>()).norm());
    std::printf(
        "%s: %d points, rms %.2f mm, surface up to %.2f mm off, vertices up to %.2f "
        "mm (started %.1f mm off)\n",
        name, r.inliers, 1000 * r.rms_m, 1000 * worst, 1000 * worstVertex,
        1000 * (believed.translation() - trueT_C_O.translation()).norm());
    // One frame, 20 mm and 3 degrees off to start: the whole surface within 2.5 mm (0.8-1.6 mm;
    // 2.9-3.4 mm with pixels without depth outside the outline, NoDepthPixels::kOutside; without
    // the outline term, projective pairs alone stop 6-11 mm off here).
    EXPECT_LT(worst, 0.0025) << name;
  }
}

// A pixel without depth tells nothing of where a held object is: a depth camera returns none at
// grazing incidence (a can's top face seen edge-on) and in its projector's shadow, both at the
// object's edges. The held object of HeldInView with the upper third of its pixels' depths
// dropped (set to 0), the body aligned from its true pose as the in-hand registration aligns it
// (the uncovered pull, NoDepthPixels::kUnknown): its surface stays within 3 mm of the truth
// (1.4-1.5 mm). With such pixels outside the outline (kOutside, the table's rule) the body's
// points that project there are pulled out of them: the box ends 49 mm off, seen through, the
// can 6 mm off with a residual over the bound.
TEST(Tracking, PixelsWithoutDepthDoNotPullAHeldBodysOutline) {
  for (const char* name : {"builtin:coffee_can", "builtin:cracker_box"}) {
    HeldInView h(name);
    // The object's box in the image and its depths, from its mesh at the true pose.
    const CameraIntrinsics& K = DepthCameraOptions{}.intrinsics;
    double v0 = 1e9, v1 = -1e9, u0 = 1e9, u1 = -1e9, z0 = 1e9, z1 = 0;
    for (const Vec3f& v : h.mesh.vertices) {
      const Vec3 x = h.trueT_C_O * v.cast<double>();
      const Vec2 uv = K.project(x);
      u0 = std::min(u0, uv.x());
      u1 = std::max(u1, uv.x());
      v0 = std::min(v0, uv.y());
      v1 = std::max(v1, uv.y());
      z0 = std::min(z0, x.z());
      z1 = std::max(z1, x.z());
    }
    int dropped = 0;
    for (int v = std::max(0, int(v0)); v <= std::min(h.d.height - 1, int(v0 + (v1 - v0) / 3)); ++v)
      for (int u = std::max(0, int(u0)); u <= std::min(h.d.width - 1, int(u1)); ++u) {
        float& z = h.d.depth_m[size_t(v) * size_t(h.d.width) + size_t(u)];
        if (z >= z0 - 0.005 && z <= z1 + 0.005 &&
            !h.robot[size_t(v) * size_t(h.d.width) + size_t(u)]) {
          z = 0;
          ++dropped;
        }
      }
    EXPECT_GT(dropped, 500) << name;
    TrackingOptions o;
    o.enabled = true;
    for (NoDepthPixels rule : {NoDepthPixels::kUnknown, NoDepthPixels::kOutside}) {
      const TrackResult r =
          alignBodyToDepth(h.d, h.robot, K, surfaceSamples(h.mesh, 0.004), h.occluders, h.trueT_C_O,
                           axialSigma(NoiseModelOptions{}, h.trueT_C_O.translation().z(), 0), o,
                           UncoveredPull::kAfterConverging, rule);
      const double worst = h.worstSurfaceError(r.correction * h.trueT_C_O);
      const bool unknown = rule == NoDepthPixels::kUnknown;
      std::printf("%s, %s: %d pixels dropped, the surface up to %.2f mm off (%s)\n", name,
                  unknown ? "unknown" : "outside", dropped, 1000 * worst,
                  r.ok ? "ok" : r.reason.c_str());
      if (unknown) {
        EXPECT_TRUE(r.ok) << name << ": " << r.reason;
        EXPECT_LT(worst, 0.003) << name;
      } else {
        EXPECT_TRUE(!r.ok || worst > 0.003) << name;
      }
    }
  }
}

// The arm's error does not jump between frames; a wrong alignment does. With the hand in view
// and an exact arm, a frame whose reported camera pose is 3 cm off (the alignment finds the palm
// 3 cm off) is refused as a jump from the last tracked frame; the same offset in the next frame
// confirms it (fused); coming back at once is a jump again, refused, then confirmed.
TEST(Tracking, AJumpOfTheArmsErrorIsFusedOnlyWhenTheNextFrameConfirmsIt) {
  const TriangleMesh box = loadObject("builtin:cracker_box");
  auto [T_O_palm, q] = defaultGrasp(wam(), box);
  SimWorld world(wam(), box, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, SimOptions{});
  world.q = q;
  SimRobot robot(&world);
  SimSensor sensor(&world, DepthCameraOptions{});
  ScanOptions o;
  o.voxel_m = 0.003;
  o.tracking.enabled = true;
  o.tracking.slip_check = false;
  const MultiGraspOptions multi;
  ScanSession s(wam(), DepthCameraOptions{}, NoiseModelOptions{}, o, multi,
                T_O_palm * Vec3(0, 0, wam().graspOffset()));
  s.beginGrasp(T_O_palm, robot.joints());
  sensor.setPose(s.cameraPose());
  // The hand shown to the camera: the first view's pose.
  const std::optional<PlannedView> view = s.nextView(robot.joints());
  ASSERT_TRUE(view.has_value());
  robot.execute(view->waypoints, [](const JointVector&) {});
  Iso3 off = sensor.pose();
  off.translation() += Vec3(0.03, 0, 0);
  const JointVector qq = robot.joints();
  std::vector<FrameReport> r;
  for (const Iso3& reported : {sensor.pose(), off, off, sensor.pose(), sensor.pose()})
    r.push_back(s.addFrame(sensor.capture(), qq, reported));
  EXPECT_TRUE(r[0].fused) << r[0].rejected;
  EXPECT_FALSE(r[1].fused);
  EXPECT_EQ(r[1].refusal, FrameRefusal::kTracking);
  EXPECT_NE(r[1].rejected.find("from the last frame's"), std::string::npos) << r[1].rejected;
  EXPECT_TRUE(r[2].fused) << r[2].rejected;
  EXPECT_FALSE(r[3].fused);
  EXPECT_NE(r[3].rejected.find("from the last frame's"), std::string::npos) << r[3].rejected;
  EXPECT_TRUE(r[4].fused) << r[4].rejected;
  // Each fused frame with the camera where it truly was (the alignment's correction).
  for (int k : {0, 2, 4})
    EXPECT_LT((r[size_t(k)].T_B_C.translation() - sensor.pose().translation()).norm(), 0.003) << k;
  // Off: every one fused.
  o.tracking.max_jump_m = 0;
  ScanSession all(wam(), DepthCameraOptions{}, NoiseModelOptions{}, o, multi,
                  T_O_palm * Vec3(0, 0, wam().graspOffset()));
  all.beginGrasp(T_O_palm, q);
  ASSERT_TRUE(all.nextView(q).has_value());
  for (const Iso3& reported : {sensor.pose(), off, off, sensor.pose()})
    EXPECT_TRUE(all.addFrame(sensor.capture(), qq, reported).fused);
}

namespace {
// A noiseless frame from the camera's origin of `body` at T_C_body and a finger (a box of
// `finger_size` at finger_at, in the camera frame), the finger's pixels hidden (the robot's).
struct FingerFrame {
  DepthImage depth;
  std::vector<uint8_t> hidden;
};
FingerFrame frameWithFinger(const TriangleMesh& body, const Iso3& T_C_body, const Vec3& finger_size,
                            const Vec3& finger_at) {
  RayScene scene;
  scene.addMesh(body, T_C_body);
  Iso3 T_C_finger = Iso3::Identity();
  T_C_finger.translation() = finger_at;
  const int finger = scene.addMesh(makeBox(finger_size), T_C_finger);
  scene.commit();
  RenderOptions ro;
  ro.noise = false;
  std::vector<int> geometry;
  FingerFrame f;
  f.depth = renderDepth(scene, Iso3::Identity(), DepthCameraOptions{}, NoiseModelOptions{}, ro,
                        &geometry);
  f.hidden.assign(geometry.size(), 0);
  for (size_t i = 0; i < geometry.size(); ++i) f.hidden[i] = geometry[i] == finger;
  return f;
}
// A body's pose in the camera frame: 60 cm ahead, turned 0.9 rad about the camera's x axis.
Iso3 tiltedAtSixtyCentimetres() {
  Iso3 T = Iso3::Identity();
  T.linear() = Eigen::AngleAxisd(-0.9, Vec3::UnitX()).toRotationMatrix();
  T.translation() = Vec3(0, 0, 0.6);
  return T;
}
}  // namespace

// A pen (12 × 140 mm) seen side on at 60 cm, its right end behind a finger (the robot's pixels,
// hidden), the body believed 8 mm to the right along its axis: the believed right end projects
// onto the finger, so the outline term has nothing to pull, and the sides fit anywhere along the
// axis; only the frame's left end, which the believed body does not cover, says where it is.
TEST(Tracking, ABodyShortOfTheFramesOutlineIsPulledAlongIt) {
  const TriangleMesh pen = makeCylinder(0.006, 0.14);  // along its z axis, centred
  Iso3 trueT_C_P = Iso3::Identity();
  trueT_C_P.linear() = Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()).toRotationMatrix();  // z to x
  trueT_C_P.translation() = Vec3(0, 0, 0.6);
  const DepthCameraOptions camera;
  const auto [d, hidden] =
      frameWithFinger(pen, trueT_C_P, Vec3(0.04, 0.04, 0.01), Vec3(0.06, 0, 0.55));
  // A model's points as a scan's are: its surface every 1.5 mm (rings along the axis, discs at
  // the ends), outward normals; the same points hide what lies behind them.
  std::vector<SurfacePoint> points;
  for (double z = -0.07; z <= 0.0701; z += 0.0015)
    for (int k = 0; k < 25; ++k) {
      const Vec3 n(std::cos(2 * M_PI * k / 25), std::sin(2 * M_PI * k / 25), 0);
      points.push_back({0.006 * n + Vec3(0, 0, z), n});
    }
  for (double r = 0.0015; r < 0.006; r += 0.0015)
    for (int k = 0; k < int(2 * M_PI * r / 0.0015); ++k) {
      const double a = 2 * M_PI * k / int(2 * M_PI * r / 0.0015);
      for (double end : {-0.07, 0.07})
        points.push_back(
            {Vec3(r * std::cos(a), r * std::sin(a), end), Vec3(0, 0, end > 0 ? 1 : -1)});
    }
  std::vector<Vec3> occluders;
  for (const SurfacePoint& sp : points) occluders.push_back(sp.p);
  Iso3 believed = trueT_C_P;
  believed.translation().x() += 0.008;
  TrackingOptions o;
  const TrackResult r = alignBodyToDepth(d, hidden, camera.intrinsics, points, occluders, believed,
                                         0.001, o, UncoveredPull::kAfterConverging);
  ASSERT_TRUE(r.ok) << r.reason;
  const Iso3 found = r.correction * believed;
  const Vec3 off = found.translation() - trueT_C_P.translation();
  std::printf("along the axis %.2f mm, across %.2f mm\n", 1000 * off.x(),
              1000 * off.tail<2>().norm());
  // Within 4 mm along the axis (8.3 mm without the uncovered pixels' pull; the pull stops where
  // the frame's end pixels lie within 1.5 point spacings of the body's end, 2.25 mm here), and
  // across it within 0.5 mm.
  EXPECT_LT(std::abs(off.x()), 0.004);
  EXPECT_LT(off.tail<2>().norm(), 0.0005);
}

// A flat bar the closing fingers pushed 13 mm in the hand and turned 6°, one end behind a
// finger, found from where the hand planned to hold it with the uncovered pixels' pull (which
// refines from where the alignment converged without it): without the pull 12.1 mm off along the
// bar, nothing drawing it along; with it 3.8 mm (the pull stops within 1.5 point spacings).
TEST(Tracking, AHeldBodyACentimetreOffIsFoundWithTheUncoveredPull) {
  const TriangleMesh bar = makeBox(Vec3(0.18, 0.04, 0.015));
  const Iso3 trueT_C_B = tiltedAtSixtyCentimetres();
  const DepthCameraOptions camera;
  const auto [d, hidden] =
      frameWithFinger(bar, trueT_C_B, Vec3(0.04, 0.05, 0.012), Vec3(0.085, 0, 0.56));
  // The bar's surface about 1.5 mm apart, outward normals.
  const std::vector<SurfacePoint> points = evenSurfaceSamples(bar, 0.0015);
  std::vector<Vec3> occluders;
  for (const SurfacePoint& sp : points) occluders.push_back(sp.p);
  Iso3 believed = trueT_C_B;
  believed.translation() += Vec3(0.012, -0.005, 0.003);
  believed.linear() = Eigen::AngleAxisd(-0.1, Vec3::UnitZ()).toRotationMatrix() * believed.linear();
  TrackingOptions o;
  const TrackResult r = alignBodyToDepth(d, hidden, camera.intrinsics, points, occluders, believed,
                                         0.001, o, UncoveredPull::kAfterConverging);
  ASSERT_TRUE(r.ok) << r.reason;
  const Iso3 found = r.correction * believed;
  const double off = (found.translation() - trueT_C_B.translation()).norm();
  const double turn = Eigen::AngleAxisd(found.linear() * trueT_C_B.linear().transpose()).angle();
  std::printf("found %.2f mm, %.2f deg from the truth\n", 1000 * off, turn * 180 / M_PI);
  EXPECT_LT(off, 0.006);
  EXPECT_LT(turn, 0.01);
}

// The same pull where the frame shows something at the body's depths that the robot's mask
// missed (a finger beside the bar's end, not hidden), with the background behind: the uncovered
// finger pixels draw the bar towards them, its other end then over the background that the camera
// sees through. The refinement is not kept where the frame contradicts it more than the alignment
// without it (more points seen through, fewer paired): the bar stays where it is.
TEST(Tracking, TheUncoveredPullIsNotKeptWhereTheFrameContradictsIt) {
  const TriangleMesh bar = makeBox(Vec3(0.18, 0.04, 0.015));
  Iso3 trueT_C_B = Iso3::Identity();
  trueT_C_B.linear() = Eigen::AngleAxisd(-0.5, Vec3::UnitX()).toRotationMatrix();
  trueT_C_B.translation() = Vec3(0, 0, 0.6);
  RayScene scene;
  scene.addMesh(bar, trueT_C_B);
  Iso3 T_C_finger = trueT_C_B;
  T_C_finger.translation() += trueT_C_B.linear() * Vec3(0.105, 0, 0);
  scene.addMesh(makeBox(Vec3(0.03, 0.03, 0.015)), T_C_finger);
  Iso3 T_C_wall = Iso3::Identity();
  T_C_wall.translation() = Vec3(0, 0, 0.75);
  scene.addMesh(makeBox(Vec3(1, 1, 0.01)), T_C_wall);
  scene.commit();
  RenderOptions ro;
  ro.noise = false;
  const DepthCameraOptions camera;
  const DepthImage d =
      renderDepth(scene, Iso3::Identity(), camera, NoiseModelOptions{}, ro, nullptr);
  const std::vector<SurfacePoint> points = evenSurfaceSamples(bar, 0.0015);
  std::vector<Vec3> occluders;
  for (const SurfacePoint& sp : points) occluders.push_back(sp.p);
  Iso3 believed = trueT_C_B;
  believed.translation() += trueT_C_B.linear() * Vec3(-0.002, 0.001, 0);
  TrackingOptions o;
  const TrackResult r = alignBodyToDepth(d, {}, camera.intrinsics, points, occluders, believed,
                                         0.001, o, UncoveredPull::kAfterConverging);
  ASSERT_TRUE(r.ok) << r.reason;
  const Iso3 found = r.correction * believed;
  const double off = (found.translation() - trueT_C_B.translation()).norm();
  std::printf("found %.2f mm from the truth, %d points seen through\n", 1000 * off, r.see_through);
  EXPECT_LT(off, 0.0015);
}

// A model known only to millimetres (a thin object's first model, from the table-top frames:
// its points scattered 1.5 mm along their normals) leaves a residual that the sensor's noise
// alone does not explain. With its points' own variances (SurfacePoint::var) the alignment
// expects that residual and keeps the frame; without them it refuses it. The pose it finds is
// the bar's, within what the scatter allows.
TEST(Tracking, AModelKnownToMillimetresIsAlignedWithTheResidualItsVarianceExplains) {
  const TriangleMesh bar = makeBox(Vec3(0.18, 0.04, 0.015));
  const Iso3 trueT_C_B = tiltedAtSixtyCentimetres();
  const DepthCameraOptions camera;
  const auto [d, hidden] =
      frameWithFinger(bar, trueT_C_B, Vec3(0.02, 0.02, 0.01), Vec3(0.2, 0.2, 0.5));
  const double scatter = 0.0015;
  std::mt19937 rng(7);
  std::normal_distribution<double> gauss(0, scatter);
  std::vector<SurfacePoint> points = evenSurfaceSamples(bar, 0.002);
  for (SurfacePoint& sp : points) sp.p += gauss(rng) * sp.n;
  std::vector<Vec3> occluders;
  for (const SurfacePoint& sp : points) occluders.push_back(sp.p);
  Iso3 believed = trueT_C_B;
  believed.translation() += Vec3(0.003, -0.002, 0.002);
  TrackingOptions o;
  const double sigma = 0.001;
  const TrackResult exact = alignBodyToDepth(d, hidden, camera.intrinsics, points, occluders,
                                             believed, sigma, o, UncoveredPull::kAfterConverging);
  std::printf("without the model's variance: %s, residual %.2f mm\n",
              exact.ok ? "kept" : exact.reason.c_str(), 1000 * exact.rms_m);
  EXPECT_FALSE(exact.ok);
  EXPECT_EQ(exact.refusal, TrackRefusal::kResidual);
  for (SurfacePoint& sp : points) sp.var = scatter * scatter;
  const TrackResult r = alignBodyToDepth(d, hidden, camera.intrinsics, points, occluders, believed,
                                         sigma, o, UncoveredPull::kAfterConverging);
  ASSERT_TRUE(r.ok) << r.reason;
  // The residual is the scatter's, within a fifth (the frame is rendered without noise): an
  // independent check of the kept alignment, whose gate (1.2 × √(σ² + scatter²), 2.16 mm) lies
  // well above it.
  std::printf("kept with the model's variance: residual %.2f mm\n", 1000 * r.rms_m);
  EXPECT_GT(r.rms_m, 0.8 * scatter);
  EXPECT_LT(r.rms_m, 1.2 * scatter);
  const Iso3 found = r.correction * believed;
  const double off = (found.translation() - trueT_C_B.translation()).norm();
  const double turn = Eigen::AngleAxisd(found.linear() * trueT_C_B.linear().transpose()).angle();
  std::printf("found %.2f mm, %.2f deg from the truth\n", 1000 * off, turn * 180 / M_PI);
  EXPECT_LT(off, 0.001);
  EXPECT_LT(turn, 0.01);
}

// The simulated arm's error: none at 0; the palm's median error where objects are presented
// (drift and noise off) the knob's distance; gravity's part follows the configuration; drift is
// slow (a frame moves it by far less than a minute does); the noise is new every frame; a saved
// state continues with the same error.
TEST(Tracking, TheSimulatedArmErrorHasItsParts) {
  const TriangleMesh can = loadObject("builtin:coffee_can");
  const auto grasp = defaultGrasp(wam(), can);
  auto world = [&](double error, double gravity, double drift, double noise) {
    SimOptions o;
    o.arm_error_m = error;
    o.arm_error_gravity = gravity;
    o.arm_error_drift = drift;
    o.arm_error_noise = noise;
    o.seed = 5;
    return SimWorld(wam(), can, grasp.first, DepthCameraOptions{}, NoiseModelOptions{}, o);
  };
  const JointVector home = wam().home();
  auto palmOff = [&](const SimWorld& w, const JointVector& q) {
    return (wam().tipPose(q + w.jointErrorAt(q)).translation() - wam().tipPose(q).translation())
        .norm();
  };
  EXPECT_EQ(world(0, 0.5, 0.2, 0.02).jointErrorAt(home).norm(), 0.0);
  // The knob: the palm's median error where objects are presented.
  const std::vector<JointVector> shown = presentationConfigurations(wam());
  ASSERT_GE(shown.size(), 8u);
  for (const JointVector& q : shown)  // they present the palm at the camera's nominal point
    EXPECT_LT((wam().tipPose(q) * Vec3(0, 0, wam().graspOffset()) - wam().camera().lookAt_B).norm(),
              1e-4);
  for (double g : {0.0, 0.5, 2.0}) {
    const SimWorld w = world(0.02, g, 0, 0);
    std::vector<double> off;
    for (const JointVector& q : shown) off.push_back(palmOff(w, q));
    std::nth_element(off.begin(), off.begin() + long(off.size() / 2), off.end());
    EXPECT_NEAR(off[off.size() / 2], 0.02, 1e-6) << g;
  }
  // Gravity: the arm turned at the shoulder (joint 2) changes the sag, not the fixed part.
  JointVector q2 = home;
  q2[wam().armVariables()[1]] += 0.6;
  const SimWorld fixed = world(0.02, 0, 0, 0), sag = world(0.02, 1.0, 0, 0);
  EXPECT_NEAR((fixed.jointErrorAt(q2) - fixed.jointErrorAt(home)).norm(), 0.0, 1e-12);
  const JointVector sagChange = sag.jointErrorAt(q2) - sag.jointErrorAt(home);
  EXPECT_GT(sagChange.norm(), 0.1 * sag.jointError.norm());
  // Its direction is gravity's torque change (the torques themselves are checked against the
  // potential energy's slope in Robot.GravityTorquesAreTheSlopeOfThePotentialEnergy).
  const JointVector dtau = wam().gravityTorques(q2) - wam().gravityTorques(home);
  JointVector dtauArm = JointVector::Zero(dtau.size());
  for (int v : wam().armVariables()) dtauArm[v] = dtau[v];
  EXPECT_GT(sagChange.normalized().dot(dtauArm.normalized()), 0.999);
  // Drift: one frame against a minute (1800 frames at 30 Hz).
  SimWorld drifting = world(0.02, 0, 1.0, 0);
  auto atFrame = [](SimWorld& w, int f) {  // as if frame f were the last rendered
    Json st = w.state();
    st["frame"] = f + 1;
    w.setState(st);
  };
  std::vector<JointVector> e;
  for (int f : {0, 1, 1801}) {
    atFrame(drifting, f);
    e.push_back(drifting.jointErrorAt(home));
  }
  const double frameStep = (e[1] - e[0]).norm(), minute = (e[2] - e[0]).norm();
  EXPECT_GT(minute, 0.2 * drifting.jointError.norm());
  EXPECT_LT(frameStep, 0.01 * minute);
  // Noise: new every frame, its RMS over the arm's joints the fraction of the fixed part.
  SimWorld noisy = world(0.02, 0, 0, 0.5);
  double sq = 0;
  const int frames = 200;
  for (int f = 0; f < frames; ++f) {
    atFrame(noisy, f);
    sq += (noisy.jointErrorAt(home) - noisy.jointError).squaredNorm();
  }
  EXPECT_NEAR(std::sqrt(sq / frames), 0.5 * noisy.jointError.norm(),
              0.15 * 0.5 * noisy.jointError.norm());
  // A saved state continues with the same error: every part on, 137 frames in, a fresh world
  // given the state has the error the original has.
  SimWorld original = world(0.02, 0.5, 0.2, 0.02);
  atFrame(original, 137);
  SimWorld resumed = world(0.02, 0.5, 0.2, 0.02);
  resumed.setState(original.state());
  EXPECT_EQ((resumed.jointErrorAt(q2) - original.jointErrorAt(q2)).norm(), 0.0);
  EXPECT_GT((resumed.jointErrorAt(q2) - world(0.02, 0.5, 0.2, 0.02).jointErrorAt(q2)).norm(), 0.0);
}
