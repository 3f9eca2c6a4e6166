// Re-grasping: stability metric, candidate generation, ranking by what Alg. 1 can still see.
#include <gtest/gtest.h>

#include "inhand/core/pose.h"
#include "inhand/geometry/primitives.h"
#include "inhand/grasp/grasp.h"
#include "inhand/robot/collision.h"
#include "test_util.h"

using namespace inhand;

namespace {
double eps(const std::vector<Contact>& c, double mu) {
  return forceClosureEpsilon(c, Vec3::Zero(), 0.1, mu, 8, 2000);
}
}  // namespace

TEST(ForceClosure, OpposingContactsCloseAndOneSidedOnesDoNot) {
  // Two contacts on +x, one on −x (outward normals), a box 10 cm across.
  std::vector<Contact> opposing{{Vec3(0.05, 0, 0.03), Vec3::UnitX()},
                                {Vec3(0.05, 0, -0.03), Vec3::UnitX()},
                                {Vec3(-0.05, 0, 0), -Vec3::UnitX()}};
  EXPECT_GT(eps(opposing, 0.5), 0.01);
  // More friction, larger cones: a larger ball fits in the wrench hull.
  EXPECT_GT(eps(opposing, 1.0), eps(opposing, 0.5));
  // All on one face: nothing can pull the object towards that face.
  std::vector<Contact> oneSide{{Vec3(0.05, 0.02, 0.03), Vec3::UnitX()},
                               {Vec3(0.05, -0.02, -0.03), Vec3::UnitX()},
                               {Vec3(0.05, 0.03, -0.02), Vec3::UnitX()}};
  EXPECT_LE(eps(oneSide, 0.5), 0.0);
  // Two point contacts cannot resist a twist about the line through them.
  std::vector<Contact> pair{{Vec3(0.05, 0, 0), Vec3::UnitX()}, {Vec3(-0.05, 0, 0), -Vec3::UnitX()}};
  EXPECT_LE(eps(pair, 0.5), 1e-9);
  EXPECT_LT(eps({}, 0.5), 0.0);
}

namespace {
// A 6 × 10 × 16 cm box whose faces are observed (σ² = 1e-7 m²) except +x, still unknown
// (σ = 5 cm).
ObjectModel boxSeenExceptPlusX() {
  return test::unweldedModel(makeBox(Vec3(0.06, 0.10, 0.16)),
                             [](const Vec3& n) { return n.x() > 0.9 ? 0.05f * 0.05f : 1e-7f; });
}

GraspCandidate palmOn(const Vec3& outward, const ObjectModel& model) {
  const RobotModel& r = test::wam();
  double palmHeight = 0;
  for (const Primitive& p : r.links()[r.tipLink()].collision)
    palmHeight = std::max(palmHeight, p.toMesh().bounds().max.z());
  GraspCandidate c;
  c.T_O_palm = cameraPoseInObject(Vec3::Zero(), -outward, 1.0, M_PI / 2);
  c.T_O_palm.translation() = (0.03 + palmHeight + 0.002) * outward;
  JointVector q = r.home();
  for (const FingerInfo& f : r.fingers()) q[f.variable] = f.open;
  r.applyCouplings(&q);
  c.q = closeFingers(r, q, c.T_O_palm, model.mesh).q;
  c.q_lift = c.q;
  return c;
}
}  // namespace

// Fig. 6: a grasp whose palm covers the still-unknown face ranks below one that leaves it
// visible.
TEST(GraspRanking, GraspCoveringTheUnknownFaceRanksLower) {
  ObjectModel model = boxSeenExceptPlusX();
  std::vector<GraspCandidate> cands{palmOn(Vec3::UnitX(), model), palmOn(-Vec3::UnitX(), model)};
  ViewPlannerOptions coarse;
  coarse.directions = 64;
  coarse.rolls = 4;
  coarse.quality.pixel_stride = 4;
  ViewPlanner planner(test::wam(), DepthCameraOptions{}, NoiseModelOptions{}, coarse);
  rankGrasps(planner, model, GraspOptions{}, &cands);
  ASSERT_EQ(cands.size(), 2u);
  // The palm on −x (z pointing +x into the object) comes first.
  EXPECT_GT(cands[0].T_O_palm.linear().col(2).x(), 0.9);
  EXPECT_GT(cands[0].quality, 1.5 * cands[1].quality);
  EXPECT_GT(cands[0].reachable_views, 0);
}

TEST(GraspGeneration, CandidatesAreStableClearOfTheTableAndReachable) {
  const RobotModel& r = test::wam();
  ObjectModel model = boxSeenExceptPlusX();
  const Iso3 T_B_O(Eigen::Translation3d(r.camera().lookAt_B.x(), r.camera().lookAt_B.y(),
                                        r.table().topZ() + 0.08));
  GraspOptions o;
  o.approaches = 24;
  o.rolls = 2;
  GraspGeneration g = generateGrasps(r, model.mesh, T_B_O, r.home(), o);
  EXPECT_EQ(g.tried, 48);
  ASSERT_GT(g.candidates.size(), 3u);
  CollisionChecker checker(r);
  for (size_t k = 0; k < g.candidates.size(); ++k) {
    const GraspCandidate& c = g.candidates[k];
    EXPECT_GE(c.epsilon, o.min_epsilon);
    EXPECT_GE(c.links_in_contact, 2);
    if (k > 0) {
      EXPECT_LE(c.epsilon, g.candidates[k - 1].epsilon);  // most stable first
    }
    // The arm puts the palm where the grasp says, free of table and base, and the hand stays
    // above the table top.
    EXPECT_LT((r.tipPose(c.q).translation() - (T_B_O * c.T_O_palm).translation()).norm(), 1e-3);
    EXPECT_FALSE(checker.inCollision(c.q));
    for (const Vec3f& v : HandGeometry(r, c.q, T_B_O * c.T_O_palm).mesh().vertices)
      EXPECT_GT(v.z(), r.table().topZ());
    // Lifted: the same palm orientation, lift_m higher.
    Vec3 up = r.tipPose(c.q_lift).translation() - r.tipPose(c.q).translation();
    EXPECT_NEAR(up.z(), o.lift_m, 1e-3);
  }
  EXPECT_LE(g.stable, g.touching);
  EXPECT_LE(g.table_free, g.stable);
  GraspOptions bad = o;
  bad.friction = 0;
  EXPECT_THROW(generateGrasps(r, model.mesh, T_B_O, r.home(), bad), std::runtime_error);
}
