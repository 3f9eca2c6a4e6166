// Tracking the hand in depth frames: the correction that ICP finds against frames rendered with
// a known arm error, and frames it must refuse.
#include <gtest/gtest.h>

#include <algorithm>

#include "inhand/core/pose.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/planning/view_selection.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/scan/session.h"
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
  return surfaceSamples(HandGeometry(wam(), q, Iso3::Identity()).mesh(), 0.004);
}
}  // namespace

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
  EXPECT_NE(away.rejected.find("too few points"), std::string::npos) << away.rejected;
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
  EXPECT_GT(medianBefore, 0.015);
  EXPECT_LT(medianAfter, 0.0015);
  EXPECT_LT(p90, 0.004);
}
