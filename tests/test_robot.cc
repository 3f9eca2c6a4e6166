#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <random>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/geometry/primitives.h"
#include "inhand/planning/view_quality.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/ik.h"
#include "inhand/robot/reachability.h"
#include "inhand/robot/wrench.h"
#include "test_util.h"

using namespace inhand;

namespace {

const fs::path kWam = fs::path(INHAND_SOURCE_DIR) / "data/robots/wam_barretthand.json";
const fs::path kArm6 = fs::path(INHAND_SOURCE_DIR) / "tests/data/arm6_gripper.json";

const RobotModel& wam() {
  static RobotModel m = RobotModel::load(kWam);
  return m;
}
const RobotModel& arm6() {
  static RobotModel m = RobotModel::load(kArm6);
  return m;
}

struct Dh {
  double alpha, a, d;
};
// Independent forward kinematics from a standard DH table: T = Π Rz(θ) Tz(d) Tx(a) Rx(α),
// written out as the textbook matrix. Returns the frames 1..n (origin frame 0 at `T_B_0`).
std::vector<Mat4> dhFrames(const std::vector<Dh>& table, const Eigen::VectorXd& q,
                           const Mat4& T_B_0) {
  std::vector<Mat4> out;
  Mat4 T = T_B_0;
  for (size_t i = 0; i < table.size(); ++i) {
    double ct = std::cos(q[i]), st = std::sin(q[i]), ca = std::cos(table[i].alpha),
           sa = std::sin(table[i].alpha);
    Mat4 A;
    A << ct, -st * ca, st * sa, table[i].a * ct,  //
        st, ct * ca, -ct * sa, table[i].a * st,   //
        0, sa, ca, table[i].d,                    //
        0, 0, 0, 1;
    T = T * A;
    out.push_back(T);
  }
  return out;
}

const std::vector<Dh> kWamDh = {
    {-M_PI / 2, 0, 0},   {M_PI / 2, 0, 0}, {-M_PI / 2, 0.045, 0.55}, {M_PI / 2, -0.045, 0},
    {-M_PI / 2, 0, 0.3}, {M_PI / 2, 0, 0}, {-M_PI / 2, 0, 0.0609}};
const std::vector<Dh> kArm6Dh = {{M_PI / 2, 0, 0.089159}, {0, -0.425, 0},          {0, -0.39225, 0},
                                 {M_PI / 2, 0, 0.10915},  {-M_PI / 2, 0, 0.09465}, {0, 0, 0.0823}};

Eigen::VectorXd randomArm(const RobotModel& m, Rng& rng) {
  std::uniform_real_distribution<double> U(0, 1);
  Eigen::VectorXd lo = m.armLower(), hi = m.armUpper(), q(m.armDof());
  for (int i = 0; i < q.size(); ++i) q[i] = lo[i] + U(rng) * (hi[i] - lo[i]);
  return q;
}

// Checks the model's FK against the DH table: the frame of DH row i is the child frame of the
// link named `frames[i]` (link i+1 in the URDF, or the final DH link).
void checkFkAgainstDh(const RobotModel& m, const std::vector<Dh>& dh,
                      const std::vector<std::string>& frames, double base_z) {
  Rng rng = makeRng(21);
  Mat4 T0 = Mat4::Identity();
  T0(2, 3) = base_z;
  IkSolver ik(m);
  for (int n = 0; n < 2000; ++n) {
    Eigen::VectorXd arm = randomArm(m, rng);
    JointVector q = m.withArm(m.home(), arm);
    std::vector<Iso3> T = m.linkPoses(q);
    std::vector<Mat4> ref = dhFrames(dh, arm, T0);
    for (size_t i = 0; i < frames.size(); ++i) {
      int li = m.linkIndex(frames[i]);
      ASSERT_GE(li, 0) << frames[i];
      ASSERT_LT((T[li].translation() - ref[i].topRightCorner<3, 1>()).norm(), 1e-9)
          << frames[i] << " at sample " << n;
    }
    // The last DH frame agrees in orientation too.
    int last = m.linkIndex(frames.back());
    ASSERT_LT((T[last].linear() - ref.back().topLeftCorner<3, 3>()).cwiseAbs().maxCoeff(), 1e-9);
    // KDL's chain FK (used by IK) agrees with the tree FK.
    auto [dp, dr] = poseError(ik.fk(arm), m.tipPose(q));
    ASSERT_LT(dp, 1e-9);
    ASSERT_LT(dr, 1e-9);
    // So does the compiled chain the damped-least-squares IK iterates on.
    std::tie(dp, dr) = poseError(ik.compiledFk(arm), m.tipPose(q));
    ASSERT_LT(dp, 1e-9);
    ASSERT_LT(dr, 1e-9);
  }
}

// Returns the number solved.
int checkIkRoundTrip(const RobotModel& m, int samples, double minSuccess,
                     IkMethod method = IkMethod::kDampedLeastSquares) {
  Rng rng = makeRng(99);
  std::vector<Eigen::VectorXd> truth;
  std::vector<Iso3> targets;
  IkSolver fk(m);
  for (int n = 0; n < samples; ++n) {
    truth.push_back(randomArm(m, rng));
    targets.push_back(fk.fk(truth.back()));
  }
  IkOptions o;
  o.method = method;
  auto sols = solveIkBatch(m, targets, m.arm(m.home()), 5, o);
  int ok = 0;
  for (int n = 0; n < samples; ++n) {
    if (!sols[n]) continue;
    ++ok;
    const Eigen::VectorXd& q = *sols[n];
    EXPECT_TRUE(m.withinLimits(m.withArm(m.home(), q)));
    auto [dp, dr] = poseError(fk.fk(q), targets[n]);
    EXPECT_LE(dp, 1e-5);
    EXPECT_LE(dr, 1e-4);
  }
  EXPECT_GE(double(ok) / samples, minSuccess) << ok << " of " << samples;
  return ok;
}

}  // namespace

TEST(Robot, WamLoadsWithDesignFigures) {
  const RobotModel& m = wam();
  EXPECT_EQ(m.armDof(), 7);
  Eigen::VectorXd lo(7), hi(7), v(7);
  lo << -2.6, -2.0, -2.8, -0.9, -4.76, -1.6, -3.0;
  hi << 2.6, 2.0, 2.8, 3.1, 1.24, 1.6, 3.0;
  v << 1.571, 1.047, 2.094, 2.094, 4.189, 4.189, 1.047;
  EXPECT_EQ(m.armLower(), lo);
  EXPECT_EQ(m.armUpper(), hi);
  EXPECT_EQ(m.armVelocity(), v);
  EXPECT_EQ(m.fingers().size(), 3u);
  EXPECT_GE(m.spreadVariable(), 0);
}

TEST(Robot, WamForwardKinematicsMatchesDhTable) {
  checkFkAgainstDh(
      wam(), kWamDh,
      {"wam_link2", "wam_link3", "wam_link4", "wam_link5", "wam_link6", "wam_link7", "wam_dh7"},
      0.346);
}

TEST(Robot, SecondRobotForwardKinematicsMatchesItsDhTable) {
  checkFkAgainstDh(arm6(), kArm6Dh,
                   {"arm_link2", "arm_link3", "arm_link4", "arm_link5", "arm_link6", "arm_dh6"},
                   0.0);
}

TEST(Robot, WamIkRoundTripTenThousand) { checkIkRoundTrip(wam(), 10000, 0.99); }

TEST(Robot, SecondRobotIkRoundTrip) { checkIkRoundTrip(arm6(), 3000, 0.99); }

// Our damped-least-squares solver against KDL's LMA (the reference) on the same targets: it
// solves at least as many.
TEST(Robot, DampedLeastSquaresSolvesWhatKdlSolves) {
  for (const RobotModel* m : {&wam(), &arm6()}) {
    const int kdl = checkIkRoundTrip(*m, 400, 0.98, IkMethod::kKdlLma);
    const int dls = checkIkRoundTrip(*m, 400, 0.98, IkMethod::kDampedLeastSquares);
    EXPECT_GE(dls, kdl);
  }
}

TEST(Robot, IkReportsUnreachableAsNoSolution) {
  for (IkMethod method : {IkMethod::kDampedLeastSquares, IkMethod::kKdlLma}) {
    IkOptions o;
    o.method = method;
    IkSolver ik(wam(), o);
    Rng rng = makeRng(1);
    Iso3 far = Iso3(Eigen::Translation3d(3.0, 0, 0.5));
    EXPECT_FALSE(ik.solve(far, wam().arm(wam().home()), &rng));
  }
}

TEST(Robot, TrajectoryTimeIsSlowestJoint) {
  const RobotModel& m = wam();
  Eigen::VectorXd a = Eigen::VectorXd::Zero(7), b = a;
  b[0] = 1.571;  // 1 s at 1.571 rad/s
  b[6] = 0.5;    // 0.478 s at 1.047 rad/s
  EXPECT_NEAR(trajectoryTime(m, a, b), 1.0, 1e-12);
  b[6] = 2.094;  // 2 s
  EXPECT_NEAR(trajectoryTime(m, a, b), 2.0, 1e-12);
}

TEST(Robot, CouplingsFollowTheirLeaders) {
  const RobotModel& m = wam();
  JointVector q = m.home();
  q[m.variableIndex("bh_j12")] = 1.2;
  q[m.variableIndex("bh_j11")] = 0.4;
  m.applyCouplings(&q);
  EXPECT_NEAR(q[m.variableIndex("bh_j13")], 1.2 / 3 + 42 * M_PI / 180, 1e-12);
  EXPECT_NEAR(q[m.variableIndex("bh_j21")], 0.4, 1e-12);
}

namespace {
// Brute-force point-in-closed-mesh by ray parity (Möller–Trumbore over every triangle).
bool bruteInside(const TriangleMesh& mesh, const Vec3& p) {
  const Vec3 dir = Vec3(0.31, 0.47, 0.83).normalized();
  int crossings = 0;
  for (const Tri& f : mesh.triangles) {
    Vec3 a = mesh.vertices[f[0]].cast<double>(), e1 = mesh.vertices[f[1]].cast<double>() - a,
         e2 = mesh.vertices[f[2]].cast<double>() - a;
    Vec3 h = dir.cross(e2);
    double det = e1.dot(h);
    if (std::abs(det) < 1e-14) continue;
    Vec3 s = p - a;
    double u = s.dot(h) / det;
    Vec3 qv = s.cross(e1);
    double v = dir.dot(qv) / det;
    if (u < 0 || v < 0 || u + v > 1) continue;
    if (e2.dot(qv) / det > 0) ++crossings;
  }
  return crossings & 1;
}

void checkInsideAgainstBruteForce(const RobotModel& m, const JointVector& q) {
  Iso3 T_F_palm = lookAt(Vec3(0.1, 0.2, 0.3), Vec3::Zero());
  HandGeometry hand(m, q, T_F_palm);
  std::vector<TriangleMesh> linkMeshes;
  for (size_t k = 0; k < m.handLinks().size(); ++k)
    for (const Primitive& p : m.links()[m.handLinks()[k]].collision)
      linkMeshes.push_back(transformed(p.toMesh(), hand.linkPoses()[k]));
  Aabb box = hand.mesh().bounds();
  Rng rng = makeRng(8);
  std::uniform_real_distribution<double> U(0, 1);
  int inside = 0, compared = 0;
  for (int n = 0; n < 20000; ++n) {
    Vec3 p = box.min + box.size().cwiseProduct(Vec3(U(rng), U(rng), U(rng)));
    // The palm cylinder's mesh is a 32-gon: skip points within 0.5 mm of its curved side.
    Vec3 p_palm = T_F_palm.inverse() * p;
    if (m.name() == "wam_barretthand" &&
        std::abs(std::hypot(p_palm.x(), p_palm.y()) - 0.0445) < 5e-4)
      continue;
    bool brute = false;
    for (const TriangleMesh& lm : linkMeshes) brute = brute || bruteInside(lm, p);
    ASSERT_EQ(hand.contains(p), brute) << p.transpose();
    inside += brute;
    ++compared;
  }
  EXPECT_GT(inside, 200);
  EXPECT_GT(compared, 15000);
}
}  // namespace

TEST(Hand, InsideTestAgreesWithBruteForce) {
  JointVector q = wam().home();
  q[wam().variableIndex("bh_j12")] = 0.8;
  q[wam().variableIndex("bh_j22")] = 1.4;
  q[wam().variableIndex("bh_j11")] = 0.6;
  checkInsideAgainstBruteForce(wam(), q);
  checkInsideAgainstBruteForce(arm6(), arm6().home());
}

TEST(Hand, MeshIsInTheRequestedFrame) {
  const RobotModel& m = wam();
  Iso3 T = Iso3(Eigen::Translation3d(1, 2, 3));
  Aabb b = HandGeometry(m, m.home(), T).mesh().bounds();
  // Palm (Ø 89 × 76 mm) plus flat fingers whose distal links rise 42° to z ≈ 117 mm.
  EXPECT_NEAR(b.min.z(), 3.0, 1e-6);
  EXPECT_GT(b.max.z(), 3.0 + 0.11);
  EXPECT_GT(b.max.x() - b.min.x(), 0.3);
  EXPECT_NEAR(b.center().x(), 1.0, 0.03);
  // bounds() (each primitive's box) holds the mesh, at a turned pose and a preshape too.
  T.linear() = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  for (const JointVector& q : {m.home(), m.preshapedHand(1.2, 0.5)}) {
    const Aabb mesh = HandGeometry(m, q, T).mesh().bounds(), prims = HandGeometry(m, q, T).bounds();
    EXPECT_TRUE((prims.min.array() <= mesh.min.array() + 1e-6).all());
    EXPECT_TRUE((prims.max.array() >= mesh.max.array() - 1e-6).all());
  }
}

namespace {
bool boxContains(const Vec3& p, const Vec3& c, const Vec3& size, double tol = 0) {
  return ((p - c).cwiseAbs().array() < 0.5 * size.array() - tol).all();
}
// After closing, no finger geometry penetrates the object; a little further closed, it does.
template <typename Inside>
void checkClosing(const RobotModel& m, const JointVector& q0, const TriangleMesh& object,
                  Inside objectContains, int expectContacts) {
  ClosingResult r = closeFingers(m, q0, Iso3::Identity(), object, 0.01, 1e-5);
  int contacts = 0;
  for (size_t i = 0; i < r.fingers.size(); ++i) {
    const FingerInfo& f = m.fingers()[i];
    const FingerClosing& fc = r.fingers[i];
    if (!fc.contact) continue;
    ++contacts;
    std::string why;
    auto penetrates = [&](double v) {
      JointVector q = r.q;
      q[f.variable] = v;
      m.applyCouplings(&q);
      HandGeometry hand(m, q, Iso3::Identity());
      // Dense samples of both surfaces (a barycentric grid on every triangle), so that
      // edge-on-edge contacts are seen too.
      auto samples = [](const TriangleMesh& mesh, int n, auto&& fn) {
        for (const Tri& t : mesh.triangles)
          for (int i = 0; i <= n; ++i)
            for (int j = 0; i + j <= n; ++j) {
              double a = double(i) / n, b = double(j) / n;
              Vec3 p = (1 - a - b) * mesh.vertices[t[0]].cast<double>() +
                       a * mesh.vertices[t[1]].cast<double>() +
                       b * mesh.vertices[t[2]].cast<double>();
              if (fn(p)) return true;
            }
        return false;
      };
      if (samples(hand.mesh(), 24, objectContains)) {
        why = "a point of the hand's surface is inside the object";
        return true;
      }
      const Vec3 centre = object.bounds().center();  // shrink by 0.01 %: touching is not inside
      if (samples(object, object.triangles.size() > 100 ? 6 : 24,
                  [&](const Vec3& p) { return hand.contains(centre + 0.9999 * (p - centre)); })) {
        why = "a point of the object's surface is inside the hand";
        return true;
      }
      return false;
    };
    double further = fc.value + (f.closed > f.open ? 1 : -1) * 0.03;
    EXPECT_FALSE(penetrates(fc.value)) << "finger " << i << " at " << fc.value << ": " << why;
    EXPECT_TRUE(penetrates(further)) << "finger " << i;
  }
  EXPECT_EQ(contacts, expectContacts);
}
}  // namespace

TEST(Hand, BarrettFingersStopAtContactOnBoxAndCylinder) {
  const RobotModel& m = wam();
  // Box between the fingers, below the inward-bent distal links of the open hand.
  // (Above the knuckles, which end 20 mm over the palm, and clear of the open hand.)
  const Vec3 c(0, 0, 0.14), size(0.04, 0.09, 0.05);
  TriangleMesh box = transformed(makeBox(size), Iso3(Eigen::Translation3d(c)));
  checkClosing(
      m, m.home(), box, [&](const Vec3& p) { return boxContains(p, c, size, 1e-5); }, 3);
  // Cylinder (Ø 50 mm, axis along y) between the fingers.
  TriangleMesh cyl = makeCylinder(0.025, 0.12, 128);
  Iso3 T = Iso3(Eigen::Translation3d(0, 0, 0.14)) * Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX());
  cyl = transformed(cyl, T);
  checkClosing(
      m, m.home(), cyl,
      [&](const Vec3& p) {
        Vec3 l = T.inverse() * p;
        return std::hypot(l.x(), l.y()) < 0.025 * std::cos(M_PI / 128) - 1e-5 &&
               std::abs(l.z()) < 0.06;
      },
      3);
  // Nothing between the fingers: they close fully without contact.
  TriangleMesh far =
      transformed(makeBox(Vec3(0.02, 0.02, 0.02)), Iso3(Eigen::Translation3d(1, 1, 1)));
  ClosingResult r = closeFingers(m, m.home(), Iso3::Identity(), far);
  for (const FingerClosing& fc : r.fingers) {
    EXPECT_FALSE(fc.contact);
    EXPECT_NEAR(fc.value, 2.443460952792061, 1e-12);
  }
}

// The approach to first contact: the open hand moving along its palm axis towards a wall wider
// than the hand stops where its most advanced point (a mesh vertex of the hand: the links are
// boxes and a cylinder) reaches the wall, within the bisection tolerance; the hand is free there
// and touches 1 mm further. Touching at the start gives nullopt, nothing in the way max_travel.
TEST(Hand, FreeTravelStopsAtTheFirstContactOfAnyLink) {
  const RobotModel& m = wam();
  JointVector open = m.home();
  m.applyCouplings(&open);
  double tip = -1;
  for (const Vec3f& v : HandGeometry(m, open, Iso3::Identity()).mesh().vertices)
    tip = std::max(tip, double(v.z()));
  EXPECT_GT(tip, 0.11);  // the flat fingers' distal links rise beyond the palm face (z = 0.076)
  // A wall 0.5 m ahead of the palm, facing it.
  const double d = 0.5;
  const TriangleMesh wall =
      transformed(makeBox(Vec3(0.4, 0.4, 0.02)), Iso3(Eigen::Translation3d(0, 0, d + 0.01)));
  const FingerCloser closer(m, wall);
  const std::optional<double> travel =
      closer.freeTravel(open, Iso3::Identity(), Vec3::UnitZ(), 1.0, 0.01, 1e-4);
  ASSERT_TRUE(travel.has_value());
  EXPECT_NEAR(*travel, d - tip, 2e-4);
  Iso3 at = Iso3(Eigen::Translation3d(0, 0, *travel));
  EXPECT_FALSE(closer.handTouches(open, at));
  at.translation().z() += 0.001;
  EXPECT_TRUE(closer.handTouches(open, at));
  EXPECT_FALSE(closer.freeTravel(open, at, Vec3::UnitZ(), 1.0).has_value());
  // Moving away: nothing in the way.
  EXPECT_DOUBLE_EQ(*closer.freeTravel(open, Iso3::Identity(), -Vec3::UnitZ(), 0.3), 0.3);
}

// The box links' separating-axis test (TriangleBoxIndex) closes the fingers and approaches as
// the FCL mesh–mesh reference does: random palm poses about a sphere and a thin plate (thousands
// of triangles, the fingers coming from every side), every finger's stop and every approach.
TEST(Closing, BoxLinkTestClosesAsTheMeshReferenceDoes) {
  const RobotModel& m = wam();
  TriangleMesh object = makeSphere(0.06, 4);
  object.append(
      transformed(makeBox(Vec3(0.004, 0.16, 0.12)), Iso3(Eigen::Translation3d(0.0, 0.0, 0.09))));
  const FingerCloser fast(m, object), reference(m, object, /*reference=*/true);
  Rng rng = makeRng(21);
  std::normal_distribution<double> N(0, 1);
  std::uniform_real_distribution<double> U(0, 1);
  int contacts = 0, travels = 0, fingers = 0, same = 0;
  double worst = 0;
  for (int i = 0; i < 60; ++i) {
    // The palm 0.15-0.25 m from the centre, facing it, turned about its axis at random.
    const Vec3 dir = Vec3(N(rng), N(rng), N(rng)).normalized();
    Iso3 T = Iso3::Identity();
    T.linear() = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), -dir).toRotationMatrix() *
                 Eigen::AngleAxisd(2 * M_PI * U(rng), Vec3::UnitZ());
    T.translation() = (0.15 + 0.1 * U(rng)) * dir;
    const JointVector q = m.preshapedHand(U(rng) * M_PI, 0.0);
    const std::optional<double> a = fast.freeTravel(q, T, -dir, 0.3, 0.01, 1e-4),
                                b = reference.freeTravel(q, T, -dir, 0.3, 0.01, 1e-4);
    ASSERT_EQ(a.has_value(), b.has_value()) << "pose " << i;
    if (!a) continue;
    EXPECT_NEAR(*a, *b, 1e-4) << "pose " << i;
    travels += *a < 0.3;
    T.translation() -= *a * dir;
    const ClosingResult ca = fast.close(q, T, 0.06, 1e-4), cb = reference.close(q, T, 0.06, 1e-4);
    for (size_t k = 0; k < ca.fingers.size(); ++k) {
      ++fingers;
      ASSERT_EQ(ca.fingers[k].contact, cb.fingers[k].contact) << "pose " << i << " finger " << k;
      contacts += ca.fingers[k].contact;
      const double d = std::abs(ca.fingers[k].value - cb.fingers[k].value);
      worst = std::max(worst, d);
      same += d <= 1e-4;
    }
  }
  EXPECT_GT(travels, 40);
  EXPECT_GT(contacts, 60);
  EXPECT_GE(same, fingers - 2);  // a bisection may turn the other way at a grazing contact
  EXPECT_LT(worst, 0.06);
}

// The BH8-280's fingertips from the manufacturer's DH table (Craig: T = RotX(α) TransX(a) RotZ(θ)
// TransZ(d) per row), computed here without the URDF: joint 1 a = r·Aw, d = Dw, θ = r·Θ1 − j·π/2
// (r = −1, 1, 0 and j = 1, 1, −1 for fingers 1, 2, 3); joint 2 a = A1, α = π/2, θ = Θ2; joint 3
// a = A2, θ = Θ3 + Φ3; joint 4 a = A3, α = −π/2, d = D3. Our palm frame is the DH palm frame turned
// −90° about z (x towards finger 3). URDF FK must agree to 0.5 mm over spreads and flexions.
namespace {
Vec3 dhFingertip(int finger, double spread, double flex) {
  const double Aw = 0.025, A1 = 0.05, A2 = 0.07, A3 = 0.05, Dw = 0.076, D3 = 0.0095;
  const double Phi3 = 42 * M_PI / 180;
  const double r = finger == 1 ? -1 : finger == 2 ? 1 : 0, j = finger == 3 ? -1 : 1;
  auto row = [](double alpha, double a, double theta, double d) {
    return Iso3(Eigen::AngleAxisd(alpha, Vec3::UnitX())) * Eigen::Translation3d(a, 0, 0) *
           Eigen::AngleAxisd(theta, Vec3::UnitZ()) * Eigen::Translation3d(0, 0, d);
  };
  const Iso3 T = row(0, r * Aw, r * spread - j * M_PI / 2, Dw) * row(M_PI / 2, A1, flex, 0) *
                 row(0, A2, flex / 3 + Phi3, 0) * row(-M_PI / 2, A3, 0, D3);
  const Iso3 dhToPalm(Eigen::AngleAxisd(-M_PI / 2, Vec3::UnitZ()));
  return dhToPalm * T.translation();
}
}  // namespace

TEST(Hand, FingertipsMatchTheManufacturersDhTable) {
  const RobotModel& m = wam();
  const int palm = m.tipLink();
  for (double spread : {0.0, 0.4, M_PI / 2, 2.5, M_PI})
    for (double flex : {0.0, 0.3, 1.0, M_PI / 2, 2.0, 2.443460952792061}) {
      JointVector q = m.home();
      q[m.spreadVariable()] = spread;
      for (const char* j : {"bh_j12", "bh_j22", "bh_j32"}) q[m.variableIndex(j)] = flex;
      m.applyCouplings(&q);
      const std::vector<Iso3> T = m.linkPoses(q);
      for (int finger = 1; finger <= 3; ++finger) {
        const int distal = m.linkIndex("bh_f" + std::to_string(finger) + "_distal");
        ASSERT_GE(distal, 0);
        // DH frame 4 in the distal link's frame (the URDF's link frames are the DH frames).
        const Vec3 tip = T[palm].inverse() * T[distal] * Vec3(0.05, 0.0095, 0);
        EXPECT_LT((tip - dhFingertip(finger, spread, flex)).norm(), 5e-4)
            << "finger " << finger << " spread " << spread << " flex " << flex << ": "
            << tip.transpose() << " vs " << dhFingertip(finger, spread, flex).transpose();
      }
    }
  // Flexion 0 lays the finger flat in the palm plane, pointing outward: finger 3's medial link
  // runs along +x at the height of the flexion axes (Dw = 76 mm).
  const Vec3 flat = dhFingertip(3, 0, 0);
  EXPECT_GT(flat.x(), 0.15);
  EXPECT_NEAR(flat.y(), 0.0, 1e-12);
}

// The open hand's aperture: flat fingers put finger 3's tip and fingers 1 and 2's tips
// 2·(A1 + A2 + A3 cos Φ3 − D3 sin Φ3) = 301.6 mm apart along palm x; the flexion axes stand
// 100 mm apart at spread 0 and fingers 1 and 2's 150 mm apart at 90°, so a slab 120 mm wide
// passes between the open fingers down to the knuckles (10 mm above the palm face), and at
// spread 90° one 120 mm wide across palm y too (ending 40 mm along palm x, short of finger 3).
TEST(Hand, OpenHandApertureEnvelopsObjectsOverOneHundredMillimetres) {
  const RobotModel& m = wam();
  const double Phi3 = 42 * M_PI / 180;
  const double expected = 2 * (0.05 + 0.07 + 0.05 * std::cos(Phi3) - 0.0095 * std::sin(Phi3));
  // Fingertips of the URDF's open hand (flexion 0, spread 0), DH frame 4 in the distal links.
  const std::vector<Iso3> T = m.linkPoses(m.openHand(0.0));
  auto tip = [&](int finger) {
    const int distal = m.linkIndex("bh_f" + std::to_string(finger) + "_distal");
    return Vec3(T[m.tipLink()].inverse() * T[distal] * Vec3(0.05, 0.0095, 0));
  };
  EXPECT_NEAR(tip(3).x() - tip(1).x(), expected, 1e-6);
  EXPECT_NEAR(tip(3).x() - tip(2).x(), expected, 1e-6);
  EXPECT_NEAR(m.palmFaceZ(), 0.076, 1e-8);
  const double reach = openHandReach(m);
  const double tipZ = m.palmFaceZ() + reach;
  EXPECT_NEAR(openHandDepth(m, 0, 0.120), tipZ - 0.086, 5e-4);
  EXPECT_NEAR(openHandDepth(m, 1, 0.120, M_PI / 2, 0.04), tipZ - 0.086, 5e-4);
  // Wider than the flexion axes: the slab lands on the finger roots.
  EXPECT_LT(openHandDepth(m, 0, 0.28), tipZ - 0.086 - 0.005);
  EXPECT_THROW(openHandDepth(m, 2, 0.01), std::runtime_error);
}

// The spread joint swings fingers 1 and 2 outward around the palm, as on the real hand: at 0
// both face finger 3 across the palm (flexion joints 50 mm behind the centre), at 90° they face
// each other across palm y (flexion joints 75 mm either side), at 180° both sit beside finger 3.
// They never cross the palm's centre line.
TEST(Hand, SpreadSwingsFingersOneAndTwoOutwardAroundThePalm) {
  const RobotModel& m = wam();
  const int palm = m.tipLink();
  const int f1 = m.linkIndex("bh_f1_medial"), f2 = m.linkIndex("bh_f2_medial");
  ASSERT_GE(f1, 0);
  ASSERT_GE(f2, 0);
  auto flexJoints = [&](double spread) {
    JointVector q = m.home();
    q[m.spreadVariable()] = spread;
    m.applyCouplings(&q);
    const std::vector<Iso3> T = m.linkPoses(q);
    const Iso3 T_palm_B = T[palm].inverse();
    return std::make_pair(Vec3(T_palm_B * T[f1].translation()),
                          Vec3(T_palm_B * T[f2].translation()));
  };
  auto [a0, b0] = flexJoints(0.0);
  EXPECT_LT((a0 - Vec3(-0.05, 0.025, 0.076)).norm(), 1e-9) << a0.transpose();
  EXPECT_LT((b0 - Vec3(-0.05, -0.025, 0.076)).norm(), 1e-9) << b0.transpose();
  auto [a90, b90] = flexJoints(M_PI / 2);
  EXPECT_LT((a90 - Vec3(0, 0.075, 0.076)).norm(), 1e-9) << a90.transpose();
  EXPECT_LT((b90 - Vec3(0, -0.075, 0.076)).norm(), 1e-9) << b90.transpose();
  auto [a180, b180] = flexJoints(M_PI);
  EXPECT_LT((a180 - Vec3(0.05, 0.025, 0.076)).norm(), 1e-9) << a180.transpose();
  EXPECT_LT((b180 - Vec3(0.05, -0.025, 0.076)).norm(), 1e-9) << b180.transpose();
  for (int k = 0; k <= 18; ++k) {
    auto [a, b] = flexJoints(M_PI * k / 18);
    EXPECT_GT(a.y(), 0.02) << k;
    EXPECT_LT(b.y(), -0.02) << k;
  }
}

TEST(Hand, ParallelJawStopsAtContact) {
  const RobotModel& m = arm6();
  const Vec3 c(0, 0, 0.07), size(0.03, 0.04, 0.03);
  TriangleMesh box = transformed(makeBox(size), Iso3(Eigen::Translation3d(c)));
  checkClosing(
      m, m.home(), box, [&](const Vec3& p) { return boxContains(p, c, size, 1e-5); }, 1);
  ClosingResult r = closeFingers(m, m.home(), Iso3::Identity(), box, 0.002, 1e-6);
  EXPECT_NEAR(r.fingers[0].value, 0.02, 1e-5);  // jaws stop at the box's 40 mm width
}

// A preshape with the first two fingers partly closed and the third at its open value (a
// two-finger pinch): the third stays open as the others close; every finger closes from a
// preshape with all of them open, or all partly closed.
TEST(Hand, AFingerLeftOpenInAPinchPreshapeStaysOpen) {
  const RobotModel& m = wam();
  JointVector q = m.preshapedHand(M_PI / 2, 0.5);
  const FingerInfo& third = m.fingers()[2];
  q[third.variable] = third.open;
  m.applyCouplings(&q);
  EXPECT_EQ(m.closingFingers(q), (std::vector<bool>{true, true, false}));
  EXPECT_EQ(m.closingFingers(m.preshapedHand(0.0, 0.0)), (std::vector<bool>{true, true, true}));
  EXPECT_EQ(m.closingFingers(m.preshapedHand(0.0, 0.4)), (std::vector<bool>{true, true, true}));
  const TriangleMesh far =
      transformed(makeBox(Vec3(0.01, 0.01, 0.01)), Iso3(Eigen::Translation3d(Vec3(5, 5, 5))));
  const ClosingResult r = closeFingers(m, q, Iso3::Identity(), far);
  EXPECT_EQ(r.q[third.variable], third.open);
  EXPECT_EQ(r.q[m.fingers()[0].variable], m.fingers()[0].closed);
  EXPECT_EQ(r.q[m.fingers()[1].variable], m.fingers()[1].closed);
}

TEST(Collision, TableAndBaseAreDetected) {
  const RobotModel& m = wam();
  CollisionChecker checker(m);
  std::string what;
  EXPECT_FALSE(checker.inCollision(m.home(), &what)) << what;
  // Shoulder pitched forward and down, elbow straight: the arm goes into the table.
  JointVector down = m.home();
  down[m.variableIndex("wam_j2")] = 1.9;
  down[m.variableIndex("wam_j4")] = 0.0;
  EXPECT_TRUE(checker.inCollision(down, &what));
  EXPECT_NE(what.find("table"), std::string::npos) << what;
  EXPECT_FALSE(checker.pathFree(m.home(), down, 0.02, &what));
  // Palm facing down 0.25 m above the table's centre: free. A held object hanging from the hand
  // that reaches 1 cm into the table collides; one that stops 1 cm above it does not.
  const double top = m.table().topZ();
  Iso3 T_B_palm = Iso3(Eigen::Translation3d(m.table().center_B.x() - 0.1, 0, top + 0.25)) *
                  Eigen::AngleAxisd(M_PI, Vec3::UnitX());
  IkSolver ik(m);
  Rng rng = makeRng(3);
  auto arm = ik.solve(T_B_palm, m.arm(m.home()), &rng);
  ASSERT_TRUE(arm);
  JointVector low = m.withArm(m.home(), *arm);
  ASSERT_FALSE(checker.inCollision(low, &what)) << what;
  for (double reach : {0.01, -0.01}) {
    double z0 = top + 0.15, z1 = top - reach;  // from 10 cm below the palm down to z1
    Vec3 centre(T_B_palm.translation().x(), 0, 0.5 * (z0 + z1));
    checker.setHeldObject(makeBox(Vec3(0.03, 0.03, z0 - z1)),
                          T_B_palm.inverse() * Iso3(Eigen::Translation3d(centre)));
    EXPECT_EQ(checker.inCollision(low, &what), reach > 0) << what;
    if (reach > 0) {
      EXPECT_NE(what.find("held object"), std::string::npos) << what;
    }
  }
  checker.clearHeldObject();
  EXPECT_FALSE(checker.inCollision(low));
}

TEST(Reachability, PresentationPoseShowsTheRequestedSide) {
  Rng rng = makeRng(4);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int n = 0; n < 100; ++n) {
    Vec3 obj(U(rng), U(rng), U(rng)), cam(U(rng), U(rng), U(rng) + 3),
        dir = Vec3(U(rng), U(rng), U(rng)).normalized();
    Iso3 T_B_palm = presentationPalmPose(obj, cam, dir, U(rng) * M_PI, 0.1);
    Iso3 T_B_O = T_B_palm * Iso3(Eigen::Translation3d(0, 0, 0.1));
    EXPECT_LT((T_B_O.translation() - obj).norm(), 1e-12);
    EXPECT_LT((T_B_O.linear() * dir - (obj - cam).normalized()).norm(), 1e-9);
  }
  ReachabilityOptions o;
  o.directions = 20;
  o.rolls = 4;
  o.grid = 2;
  auto cells = reachabilityMap(wam(), o);
  ASSERT_EQ(cells.size(), 4u);
  int reachable = 0;
  for (const auto& c : cells) reachable += c.reachable;
  EXPECT_GT(reachable, 0);
}

TEST(RobotConfig, ErrorsNameTheField) {
  test::TempDir dir;
  Json base = readJsonFile(kWam);
  base["urdf"] = (fs::path(INHAND_SOURCE_DIR) / "data/robots/wam_barretthand.urdf").string();
  auto expectError = [&](Json cfg, const std::string& needle) {
    writeTextAtomically(dir.path() / "r.json", cfg.dump());
    try {
      RobotModel::load(dir.path() / "r.json");
      ADD_FAILURE() << "no error, expected " << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  Json c = base;
  c["tip_link"] = "bh_plam";
  expectError(c, "tip_link: no link named 'bh_plam'");
  c = base;
  c["tip_link"] = "wam_base";
  c["base_link"] = "bh_palm";
  expectError(c, "does not connect");
  c = base;
  c["table"]["size_xyz"] = "big";
  expectError(c, "table.size_xyz");
  c = base;
  c["hand"]["fingers"][0]["joint"] = 3;
  expectError(c, "hand.fingers[0].joint: expected a string");
  c = base;
  c["colour"] = "red";
  expectError(c, "unknown field \"colour\"");
  c = base;
  c["camera"]["colour"]["intrinsics"]["fx"] = -1;
  expectError(c, "camera.colour.intrinsics");
  c = base;
  c["camera"]["colour"]["T_depth_colour"][0] = 2;
  expectError(c, "camera.colour.T_depth_colour: not a rigid transform");
  c = base;
  c["camera"]["colour"]["offset"] = 1;
  expectError(c, "camera.colour: unknown field \"offset\"");
  c = base;
  c["urdf"] = (dir.path() / "missing.urdf").string();
  expectError(c, "missing.urdf");
  std::ofstream(dir.path() / "bad.urdf")
      << "<robot name='x'><link name='a'/><joint name='j' type='revolute'>";
  c = base;
  c["urdf"] = (dir.path() / "bad.urdf").string();
  expectError(c, "malformed URDF");
}

// The colour camera comes from the robot config: the shipped WAM's Kinect-class camera, and
// another's intrinsics and offset as given.
TEST(RobotConfig, ColourCameraFromTheConfig) {
  const ColourCameraOptions& shipped = wam().camera().colour;
  EXPECT_EQ(shipped.intrinsics.width, 640);
  EXPECT_DOUBLE_EQ(shipped.intrinsics.fx, 530.0);
  EXPECT_LT((shipped.T_D_RGB.translation() - Vec3(0.025, 0, 0)).norm(), 1e-12);
  EXPECT_FALSE(shipped.enabled);         // the scan turns it on (sim.colour.enabled)
  EXPECT_TRUE(shipped.light_at_camera);  // as the simulator's lamp
  test::TempDir dir;
  Json c = readJsonFile(kWam);
  c["urdf"] = (fs::path(INHAND_SOURCE_DIR) / "data/robots/wam_barretthand.urdf").string();
  c["camera"]["colour"] = {
      {"intrinsics",
       {{"width", 1280}, {"height", 720}, {"fx", 910}, {"fy", 905}, {"cx", 640}, {"cy", 360}}},
      {"T_depth_colour", {0, -1, 0, -0.015, 1, 0, 0, 0.002, 0, 0, 1, 0.001, 0, 0, 0, 1}}};
  writeTextAtomically(dir.path() / "r.json", c.dump());
  const ColourCameraOptions got = RobotModel::load(dir.path() / "r.json").camera().colour;
  EXPECT_EQ(got.intrinsics.width, 1280);
  EXPECT_EQ(got.intrinsics.height, 720);
  EXPECT_DOUBLE_EQ(got.intrinsics.fy, 905.0);
  EXPECT_LT((got.T_D_RGB.translation() - Vec3(-0.015, 0.002, 0.001)).norm(), 1e-12);
  EXPECT_LT((got.T_D_RGB.linear() * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-12);
  EXPECT_FALSE(got.light_at_camera);  // left out: the room's light alone
  c["camera"]["colour"]["light_at_camera"] = "yes";
  writeTextAtomically(dir.path() / "r.json", c.dump());
  try {
    RobotModel::load(dir.path() / "r.json");
    ADD_FAILURE() << "a light_at_camera that is not a bool was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("camera.colour.light_at_camera"), std::string::npos)
        << e.what();
  }
}

namespace {
// Frame O: palm z (the approach) is +z; a table's face at z = 0.30 and a disc 15 mm thick, Ø 120
// mm on it: the table, the disc, and both in one mesh.
struct DiscOnTable {
  TriangleMesh table, disc, both;
};
DiscOnTable discOnTable() {
  DiscOnTable s;
  s.table = transformed(makeBox(Vec3(0.8, 0.8, 0.05)), Iso3(Eigen::Translation3d(0, 0, 0.325)));
  s.disc = transformed(makeCylinder(0.06, 0.015, 64), Iso3(Eigen::Translation3d(0, 0, 0.2925)));
  s.both = s.table;
  s.both.append(s.disc);
  return s;
}
}  // namespace

// A flat object on a table (a disc 15 mm thick, Ø 120 mm), the hand coming down on it with its
// fingers spread wider than the disc (preshape 25 %, 35° of flexion): the fingertips meet the
// table first; closing against object and table, they touch nothing of the disc; closeOffTheTable
// lifts the hand in 5 mm steps until the fingers close on the disc's rim, with the hand never in
// the table.
TEST(Hand, FingersStoppedByTheTableLiftTheHandUntilTheyGripAFlatObject) {
  const RobotModel& m = wam();
  const auto [table, disc, both] = discOnTable();
  const FingerCloser closeBoth(m, both), closeDisc(m, disc), closeTable(m, table);
  const JointVector q = m.preshapedHand(0.0, 0.25);
  const std::optional<double> travel =
      closeBoth.freeTravel(q, Iso3::Identity(), Vec3::UnitZ(), 0.5);
  ASSERT_TRUE(travel && *travel < 0.5);
  const Iso3 T(Eigen::Translation3d(0, 0, *travel));
  const std::vector<SurfacePoint> samples = surfaceSamples(disc, 0.003);
  // Plain closing: the table stops the fingertips before they reach the disc.
  const ClosingResult plain = closeBoth.close(q, T, 0.02, 1e-4);
  EXPECT_LT(handContacts(m, plain.q, T, samples, 0.003, 0.01).fingers_touching, 2);
  // Lifting off the table: the fingers grip the rim, and the hand is out of the table.
  const auto [closed, lifted] = closeOffTheTable(closeBoth, closeDisc, q, T, 0.005, 0.03, 0.02);
  const double lift = T.translation().z() - lifted.translation().z();
  EXPECT_GT(lift, 0.004);
  EXPECT_LE(lift, 0.03 + 1e-9);
  const HandContacts hc = handContacts(m, closed.q, lifted, samples, 0.003, 0.01);
  EXPECT_GE(hc.fingers_touching, 2);
  Iso3 clear = lifted;
  clear.translation().z() -= 0.001;  // within the bisection tolerance of touching
  EXPECT_FALSE(closeTable.handTouches(closed.q, clear));
  EXPECT_GT(forceClosureEpsilon(hc.contacts, Vec3(0, 0, 0.2925), 0.06, 0.5, 8, 1000), 0);
}

// The grid's query holds every sample in the box (against a scan of all of them), and contacts
// from the grid equal the reference's (every sample measured) at closed hands around a box and a
// sphere: the same contact points and normals to the bit, fingers and palm touching.
TEST(Hand, ContactsFromTheSampleGridEqualMeasuringEverySample) {
  const RobotModel& m = wam();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  int compared = 0, withContacts = 0;
  for (const TriangleMesh& mesh : {makeBox(Vec3(0.06, 0.1, 0.16)), makeSphere(0.05, 3)}) {
    const std::vector<SurfacePoint> samples = surfaceSamples(mesh, 0.005);
    const SampleGrid grid(samples, 0.01);
    for (int k = 0; k < 200; ++k) {
      const Vec3 c(0.1 * U(rng), 0.1 * U(rng), 0.1 * U(rng));
      const Aabb box{c - Vec3(0.01, 0.02, 0.03).cwiseAbs() * (1 + U(rng)),
                     c + Vec3(0.03, 0.01, 0.02) * (1 + U(rng))};
      std::vector<int> near;
      grid.near(box, &near);
      for (size_t i = 0; i < samples.size(); ++i)
        if (box.contains(samples[i].p)) {
          ASSERT_NE(std::find(near.begin(), near.end(), int(i)), near.end()) << k;
        }
    }
    const FingerCloser closer(m, mesh);
    for (int k = 0; k < 40; ++k) {
      const Vec3 dir = Vec3(U(rng), U(rng), U(rng)).normalized();
      Iso3 T = cameraPoseInObject(Vec3::Zero(), -dir, 0.0, M_PI * U(rng));
      const JointVector q = m.preshapedHand(0.0, 0.25 * (1 + U(rng)));
      const std::optional<double> travel = closer.freeTravel(
          q, Iso3(Eigen::Translation3d(-0.3 * T.linear().col(2))) * T, T.linear().col(2), 0.5);
      if (!travel) continue;
      T.translation() = (*travel - 0.3) * T.linear().col(2);
      const JointVector closed = closer.close(q, T, 0.02, 1e-4).q;
      for (double contact : {0.003, 0.01}) {
        const HandContacts a = handContacts(m, closed, T, samples, contact, 0.01);
        const HandContacts b = handContacts(m, closed, T, grid, contact, 0.01);
        ASSERT_EQ(a.contacts.size(), b.contacts.size()) << k;
        for (size_t i = 0; i < a.contacts.size(); ++i) {
          EXPECT_EQ(a.contacts[i].p_O, b.contacts[i].p_O) << k;
          EXPECT_EQ(a.contacts[i].normal_O, b.contacts[i].normal_O) << k;
        }
        EXPECT_EQ(a.fingers_touching, b.fingers_touching) << k;
        EXPECT_EQ(a.palm_touching, b.palm_touching) << k;
        ++compared;
        withContacts += !a.contacts.empty();
      }
    }
  }
  EXPECT_GT(compared, 100);
  EXPECT_GT(withContacts, 50);
}

// Closing against the object alone, told which steps a closing against object and table found
// free, gives what closing from scratch gives (finger values, contacts, free steps): the disc on
// the table above, the hand at heights from touching the table to well above it, several
// preshapes and spreads.
TEST(Hand, ClosingResumedFromASupersetsFreeStepsIsTheSame) {
  const RobotModel& m = wam();
  const auto [table, disc, both] = discOnTable();
  const FingerCloser closeBoth(m, both), closeDisc(m, disc);
  int resumed = 0, contacts = 0;
  for (double spread : {0.0, 0.5, 1.0})
    for (double preshape : {0.0, 0.25, 0.5}) {
      const JointVector q = m.preshapedHand(spread, preshape);
      const std::optional<double> travel =
          closeBoth.freeTravel(q, Iso3::Identity(), Vec3::UnitZ(), 0.5);
      ASSERT_TRUE(travel);
      for (double up : {0.0, 0.004, 0.01, 0.02, 0.04}) {
        const Iso3 T(Eigen::Translation3d(0, 0, *travel - up));
        const ClosingResult superset = closeBoth.close(q, T, 0.06, 1e-4);
        const ClosingResult fresh = closeDisc.close(q, T, 0.06, 1e-4);
        const ClosingResult resume = closeDisc.close(q, T, 0.06, 1e-4, &superset);
        EXPECT_EQ(resume.q, fresh.q);
        ASSERT_EQ(resume.fingers.size(), fresh.fingers.size());
        for (size_t k = 0; k < fresh.fingers.size(); ++k) {
          EXPECT_EQ(resume.fingers[k].value, fresh.fingers[k].value);
          EXPECT_EQ(resume.fingers[k].contact, fresh.fingers[k].contact);
          EXPECT_EQ(resume.fingers[k].free_steps, fresh.fingers[k].free_steps);
          resumed += superset.fingers[k].free_steps > 0;
          contacts += fresh.fingers[k].contact;
        }
      }
    }
  EXPECT_GT(resumed, 20);
  EXPECT_GT(contacts, 20);
}

// distanceWithin against distance: the same value and nearest link wherever the hand is within
// the limit, +infinity and no link beyond it; points around a half-closed hand, some inside it.
TEST(Hand, DistanceWithinALimitMatchesTheFullDistance) {
  const RobotModel& m = wam();
  const Iso3 T_F_palm = lookAt(Vec3(0.1, -0.05, 0.2), Vec3::Zero());
  const HandGeometry hand(m, m.preshapedHand(0.5, 0.5), T_F_palm);
  const Aabb box = hand.mesh().bounds();
  Rng rng = makeRng(17);
  std::uniform_real_distribution<double> U(0, 1);
  int within = 0, beyond = 0;
  for (int i = 0; i < 20000; ++i) {
    const Vec3 p = box.min - Vec3::Constant(0.01) +
                   (box.size() + Vec3::Constant(0.02)).cwiseProduct(Vec3(U(rng), U(rng), U(rng)));
    const double limit = i % 2 ? 0.003 : 0.01;
    int linkAll = -2, linkNear = -2;
    const double all = hand.distance(p, &linkAll), near = hand.distanceWithin(p, limit, &linkNear);
    if (all <= limit) {
      EXPECT_EQ(near, all) << p.transpose();
      EXPECT_EQ(linkNear, linkAll);
      ++within;
    } else {
      EXPECT_TRUE(std::isinf(near)) << p.transpose() << " " << all;
      EXPECT_EQ(linkNear, -1);
      ++beyond;
    }
  }
  EXPECT_GT(within, 500);
  EXPECT_GT(beyond, 5000);
}

// The arm's joint offsets recovered from the palm's error at one configuration carry that error
// to a configuration nearby (the pick-up after the lift, tracking.in_hand): 200 draws of offsets
// that put the palm 1-3 cm off, a random configuration and one up to 0.3 rad away per joint. The
// offsets reproduce the error they were solved from, and predict the other better than taking
// the error to be the same there.
TEST(Robot, ArmOffsetsFromThePalmsErrorCarryItToANearbyConfiguration) {
  const RobotModel& m = wam();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<double> same, carried;
  for (int draw = 0; draw < 200; ++draw) {
    JointVector q1 = m.home(), e = JointVector::Zero(m.variableCount());
    for (int v : m.armVariables()) {
      const JointInfo& j = m.variable(v);
      q1[v] = 0.5 * (j.lower + j.upper) + 0.4 * U(rng) * (j.upper - j.lower);
      e[v] = U(rng);
    }
    // Scaled so that the palm is 1-3 cm off at q1.
    const double want = 0.02 + 0.01 * U(rng);
    double s = 0.01;
    for (int it = 0; it < 20; ++it) {
      const double d = (m.tipPose(q1 + s * e).translation() - m.tipPose(q1).translation()).norm();
      if (d <= 0) break;
      s *= want / d;
    }
    e *= s;
    JointVector q2 = q1;
    for (int v : m.armVariables()) q2[v] += 0.3 * U(rng);
    const Iso3 error1 = m.tipPose(q1).inverse() * m.tipPose(q1 + e);
    const Iso3 error2 = m.tipPose(q2).inverse() * m.tipPose(q2 + e);
    const JointVector found = armOffsetsFromPalmError(m, q1, error1);
    const Iso3 back = m.tipPose(q1).inverse() * m.tipPose(q1 + found);
    // Within the damping's pull towards zero (far below tracking's own error).
    EXPECT_LT((back.translation() - error1.translation()).norm(), 3e-4);
    EXPECT_LT(Eigen::AngleAxisd(back.linear().transpose() * error1.linear()).angle(), 1e-3);
    const Iso3 predicted = m.tipPose(q2).inverse() * m.tipPose(q2 + found);
    same.push_back((error1.translation() - error2.translation()).norm());
    carried.push_back((predicted.translation() - error2.translation()).norm());
  }
  std::sort(same.begin(), same.end());
  std::sort(carried.begin(), carried.end());
  std::printf(
      "palm error at the second configuration: median %.2f mm off taken the same, %.2f mm "
      "carried by the offsets (90th percentile %.2f / %.2f mm)\n",
      1000 * same[100], 1000 * carried[100], 1000 * same[180], 1000 * carried[180]);
  EXPECT_LT(carried[100], 0.5 * same[100]);
}

// Gravity's generalised forces are the slope of the potential energy Σ −m g·c(q) (central
// differences of the links' centres of mass through forward kinematics), at random
// configurations; the WAM's base joint turns about the vertical and carries no torque.
TEST(Robot, GravityTorquesAreTheSlopeOfThePotentialEnergy) {
  const RobotModel& m = wam();
  const Vec3 g(0, 0, -9.81);
  auto potential = [&](const JointVector& q) {
    const std::vector<Iso3> T = m.linkPoses(q);
    double U = 0;
    for (size_t l = 0; l < m.links().size(); ++l)
      U -= m.links()[l].mass * g.dot(T[l] * m.links()[l].com);
    return U;
  };
  double total = 0;
  for (const LinkInfo& l : m.links()) total += l.mass;
  EXPECT_GT(total, 20.0);  // the WAM's links and the hand
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int draw = 0; draw < 20; ++draw) {
    JointVector q = m.home();
    for (int v : m.armVariables()) {
      const JointInfo& j = m.variable(v);
      q[v] = 0.5 * (j.lower + j.upper) + 0.45 * U(rng) * (j.upper - j.lower);
    }
    const JointVector tau = m.gravityTorques(q, g);
    const double h = 1e-6;
    for (int v : m.armVariables()) {
      JointVector a = q, b = q;
      a[v] += h;
      b[v] -= h;
      const double slope = -(potential(a) - potential(b)) / (2 * h);
      EXPECT_NEAR(tau[v], slope, 1e-5 + 1e-6 * std::abs(slope)) << "variable " << v;
    }
    EXPECT_NEAR(tau[m.armVariables()[0]], 0.0, 1e-9);
    EXPECT_GT(tau.norm(), 1.0);
  }
}

// A force at a point on the palm puts on each arm joint the work it does per unit of that joint's
// motion (virtual work): τ_j = f · ∂p/∂q_j, the derivative taken by central differences of the
// forward kinematics — an answer independent of the joint-axis formula.
TEST(Robot, PointForceTorquesAreTheVirtualWorkOfTheForce) {
  const RobotModel& m = test::wam();
  Rng rng = makeRng(11);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  const Vec3 p_palm(0.02, -0.03, 0.12);
  const Vec3 f(1.5, -0.7, -4.9);
  for (int trial = 0; trial < 5; ++trial) {
    JointVector q = m.home();
    for (int v : m.armVariables()) q[v] += u(rng);
    const Vec3 p_B = m.tipPose(q) * p_palm;
    const JointVector tau = m.pointForceTorques(q, m.tipLink(), p_B, f);
    for (int v : m.armVariables()) {
      const double h = 1e-6;
      JointVector a = q, b = q;
      a[v] += h;
      b[v] -= h;
      const double work = f.dot(m.tipPose(a) * p_palm - m.tipPose(b) * p_palm) / (2 * h);
      EXPECT_NEAR(tau[v], work, 1e-6) << "joint " << v;
    }
  }
}
