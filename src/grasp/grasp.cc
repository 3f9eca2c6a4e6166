#include "inhand/grasp/grasp.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <optional>
#include <random>
#include <tuple>

#include "inhand/core/error.h"
#include "inhand/core/internal/fast_math.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/geometry/primitives.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/ik.h"
#include "inhand/robot/wrench.h"

namespace inhand {

const char* graspApproachName(GraspApproach a) { return enumName(kGraspApproachNames, a); }

bool parseGraspApproach(const std::string& name, GraspApproach* a) {
  return enumFromName(kGraspApproachNames, name, a);
}

std::string GraspOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (spreads.empty()) return "spreads must not be empty";
  if (preshapes.empty()) return "preshapes must not be empty";
  if (std::string p = hold.validate(); !p.empty()) return "hold." + p;
  return {};
}

bool clearLineFromCamera(const RobotModel& robot, const JointVector& q, const Vec3& target_B,
                         double short_m, bool past_hand) {
  std::vector<Iso3> L_inv = robot.linkPoses(q);  // base to each link
  for (Iso3& T : L_inv) T = T.inverse();
  std::vector<char> skip(L_inv.size(), 0);
  if (past_hand)
    for (const int i : robot.handLinks()) skip[size_t(i)] = 1;
  const Vec3 cam = robot.camera().panTilt_B;
  const double len = (target_B - cam).norm();
  const Vec3 dir = (target_B - cam) / std::max(len, 1e-9);
  for (double t = 0.05; t < len - short_m; t += 0.01) {
    const Vec3 p = cam + t * dir;
    for (size_t i = 0; i < L_inv.size(); ++i) {
      if (skip[i]) continue;
      const Vec3 p_link = L_inv[i] * p;
      for (const Primitive& prim : robot.links()[i].collision)
        if (prim.contains(p_link)) return false;
    }
  }
  return true;
}

bool heldInView(const RobotModel& robot, const JointVector& q) {
  return clearLineFromCamera(robot, q, robot.tipPose(q) * Vec3(0, 0, robot.graspOffset()), 0.15,
                             false);
}

double liftPathDeviation(const RobotModel& robot, const JointVector& q, const JointVector& q_lift) {
  const Vec3 offset(0, 0, robot.graspOffset());
  const Iso3 start = robot.tipPose(q);
  const Vec3 a = start * offset, b = robot.tipPose(q_lift) * offset;
  const Vec3 ab = b - a;
  const double len2 = std::max(ab.squaredNorm(), 1e-12);
  double worst = 0;
  for (int s = 1; s <= 20; ++s) {
    const Iso3 T = robot.tipPose(q + (q_lift - q) * (s / 20.0));
    const Vec3 p = T * offset;
    const double t = std::clamp((p - a).dot(ab) / len2, 0.0, 1.0);
    const double turn = Eigen::AngleAxisd(T.linear() * start.linear().transpose()).angle();
    worst = std::max(worst, (p - (a + t * ab)).norm() + 0.1 * turn);
  }
  return worst;
}

namespace {

// Pick and lift configurations for palm poses T_B_palm[k] with the hand joints hands[k]: IK to
// the pick pose (seeded from q_now, `restarts` random restarts), then to the same pose lift_m
// higher, seeded from the pick; both free of table and base. nullopt where either fails. With
// `straight` the lift is solved in five steps up, each seeded from the last, and kept only where
// the move to it rises straight (liftPathDeviation). With `inView` a lift that hides the held
// object from the camera (heldInView) is solved again from up to 12 seeds near the pick's (σ 0.4
// rad per joint), the first in view, rising straight, whose joints lie within 1 rad of the pick's
// kept (else the first).
struct PickLift {
  JointVector q, q_lift;
};
struct LiftRule {
  double lift_m = 0;
  bool straight = false, inView = false;
};
std::vector<std::optional<PickLift>> pickAndLift(const RobotModel& robot,
                                                 const std::vector<Iso3>& T_B_palm,
                                                 const std::vector<JointVector>& hands,
                                                 const JointVector& q_now, const LiftRule& rule,
                                                 int restarts, uint64_t seed) {
  IkOptions ik;
  ik.random_restarts = restarts;
  const auto sols = solveIkBatch(robot, T_B_palm, robot.arm(q_now), seed, ik);
  CollisionChecker checker(robot);
  IkSolver lift(robot, ik);
  IkOptions local = ik;
  local.random_restarts = 0;
  IkSolver stepper(robot, local);
  Rng rng = makeRng(seed + 4);
  const Iso3 up(Eigen::Translation3d(0, 0, rule.lift_m));
  auto rises = [&](const JointVector& q, const JointVector& ql) {
    return !rule.straight || liftPathDeviation(robot, q, ql) <= GraspOptions::kMaxLiftDeviation;
  };
  std::vector<std::optional<PickLift>> out(T_B_palm.size());
  for (size_t k = 0; k < T_B_palm.size(); ++k) {
    if (!sols[k]) continue;
    JointVector q = robot.withArm(hands[k], *sols[k]);
    if (checker.inCollision(q)) continue;
    std::optional<Eigen::VectorXd> lifted = *sols[k];
    if (rule.straight) {
      for (int s = 1; s <= 5 && lifted; ++s)
        lifted = stepper.solve(Eigen::Translation3d(0, 0, rule.lift_m * s / 5) * T_B_palm[k],
                               *lifted, nullptr);
    }
    if (!rule.straight || !lifted) lifted = lift.solve(up * T_B_palm[k], *sols[k], &rng);
    if (!lifted) continue;
    JointVector ql = robot.withArm(hands[k], *lifted);
    if (checker.inCollision(ql) || !rises(q, ql)) continue;
    if (rule.inView && !heldInView(robot, ql)) {
      std::normal_distribution<double> jitter(0.0, 0.4);
      for (int t = 0; t < 12; ++t) {
        Eigen::VectorXd start = *sols[k];
        for (int j = 0; j < start.size(); ++j) start[j] += jitter(rng);
        const auto other = lift.solve(up * T_B_palm[k], start, &rng);
        if (!other || (*other - *sols[k]).cwiseAbs().maxCoeff() > 1.0) continue;
        const JointVector qo = robot.withArm(hands[k], *other);
        if (checker.inCollision(qo) || !heldInView(robot, qo) ||
            liftPathDeviation(robot, q, qo) > GraspOptions::kMaxLiftDeviation)
          continue;
        ql = qo;
        break;
      }
    }
    out[k] = PickLift{q, ql};
  }
  return out;
}
}  // namespace

namespace {

// A candidate pose: the palm's orientation in O (palm z into the object), the spread, whether it
// is an edge pose, the preshape (fraction of the fingers' closing range at the approach), and
// where its palm axis passes (the model's centre plus `offset`).
struct Pose {
  Mat3 R;
  double spread;
  bool edge;
  double preshape = 0;
  bool pinch = false;
  bool two_finger = false;  // fingers past the first two left open (closingFingers)
  Vec3 offset = Vec3::Zero();
  // A known grasp made again (graspsFromSet): the hand as it comes in, and a point of its palm
  // axis in O (instead of the model's centre plus `offset`).
  JointVector hand = JointVector();
  std::optional<Vec3> axis_O = std::nullopt;
};

// The hand as pose ps comes in: every finger preshaped, or for a two-finger pinch the first two
// preshaped and the others open (they then stay open: RobotModel::closingFingers).
JointVector poseHand(const RobotModel& robot, double spread, double preshape, bool two_finger) {
  JointVector q = robot.preshapedHand(spread, preshape);
  if (two_finger && preshape > 0) {
    for (size_t k = 2; k < robot.fingers().size(); ++k)
      q[robot.fingers()[k].variable] = robot.fingers()[k].open;
    robot.applyCouplings(&q);
  }
  return q;
}
JointVector poseHand(const RobotModel& robot, const Pose& ps) {
  if (ps.hand.size() > 0) return ps.hand;
  return poseHand(robot, ps.spread, ps.preshape, ps.two_finger);
}

// How far apart the open hand's lowest points (those within 5 mm of the farthest along palm z:
// the fingertips of a preshaped hand) lie along palm x, at `spread` and preshape `f`; for a
// two-finger pinch, the gap between those on either side of the palm axis along palm y (between
// the two fingertips' inner faces).
double tipGap(const RobotModel& robot, double spread, double f, bool two_finger = false) {
  const TriangleMesh hand =
      HandGeometry(robot, poseHand(robot, spread, f, two_finger), Iso3::Identity()).mesh();
  double zmax = -std::numeric_limits<double>::infinity();
  for (const Vec3f& v : hand.vertices) zmax = std::max(zmax, double(v.z()));
  const double inf = std::numeric_limits<double>::infinity();
  double x0 = inf, x1 = -inf, yPlus = inf, yMinus = -inf;
  for (const Vec3f& v : hand.vertices)
    if (v.z() > zmax - 0.005) {
      x0 = std::min(x0, double(v.x()));
      x1 = std::max(x1, double(v.x()));
      if (v.y() > 0) yPlus = std::min(yPlus, double(v.y()));
      if (v.y() < 0) yMinus = std::max(yMinus, double(v.y()));
    }
  if (two_finger) return std::isfinite(yPlus) && std::isfinite(yMinus) ? yPlus - yMinus : -1.0;
  return x1 - x0;
}

// The fingertips' gap at preshapes from f0 to f1 in steps of df, while it narrows (further on,
// other parts of the curled fingers are the lowest). With `narrowest_run`, the run of preshapes
// over which it narrows to its least value instead (before that run, other parts of the fingers
// may be the lowest).
std::vector<std::pair<double, double>> tipGaps(const RobotModel& robot, double spread,
                                               bool two_finger, double f0, double f1, double df,
                                               bool narrowest_run = false) {
  std::vector<std::pair<double, double>> gaps;
  for (double f = f0; f <= f1 + 1e-9; f += df) {
    const double gap = tipGap(robot, spread, f, two_finger);
    if (gap < 0 || (!narrowest_run && !gaps.empty() && gap > gaps.back().second)) break;
    gaps.push_back({f, gap});
  }
  if (narrowest_run && !gaps.empty()) {
    size_t end = 0;
    for (size_t k = 1; k < gaps.size(); ++k)
      if (gaps[k].second < gaps[end].second) end = k;
    size_t begin = end;
    while (begin > 0 && gaps[begin - 1].second > gaps[begin].second) --begin;
    gaps = std::vector<std::pair<double, double>>(gaps.begin() + long(begin),
                                                  gaps.begin() + long(end) + 1);
  }
  return gaps;
}

// The most closed preshape whose gap is at least `needed`, or -1.
double preshapeForGap(const std::vector<std::pair<double, double>>& gaps, double needed) {
  double best = -1;
  for (const auto& [f, gap] : gaps)
    if (gap >= needed) best = f;
  return best;
}

// The open hand's fingertip gaps the pinch poses choose their preshapes from (tipGaps): one
// list per spread of o.spreads, and the two-finger pinch's (empty without one). Computed once per
// generation: each entry is a hand mesh built and measured.
struct PinchGaps {
  std::vector<std::vector<std::pair<double, double>>> spreads;
  std::vector<std::pair<double, double>> two_finger;
};

bool hasTwoFingerPinch(const RobotModel& robot, const GraspOptions& o) {
  return o.two_finger_pinch && robot.spreadVariable() >= 0 && robot.fingers().size() >= 3;
}

PinchGaps pinchGaps(const RobotModel& robot, const GraspOptions& o) {
  PinchGaps g;
  for (double s : o.spreads) g.spreads.push_back(tipGaps(robot, s, false, 0.2, 0.9, 0.025));
  if (hasTwoFingerPinch(robot, o))
    g.two_finger = tipGaps(robot, o.two_finger_spread, true, 0.2, 0.95, 0.01, true);
  return g;
}

// Pinch poses: the hand straight down the table normal onto the model's footprint (the axis
// through the centre of its least-area rectangle on the table), palm x across each of the
// rectangle's sides either way, at each spread, with the preshape whose fingertips straddle the
// model's width across palm x by 8 mm and by 20 mm on each side. The fingertips then come down
// beside the model to the table (or onto it, on a tall model) and close on it low: the grasp of
// a pen, a remote or a box lying flat, which the approaches spread over the sphere catch only
// when one happens to line up with the model.
void addPinchPoses(const RobotModel& robot, const std::vector<Vec3>& points, const Vec3& centre,
                   const Vec3& up, const GraspOptions& o, const PinchGaps& g,
                   std::vector<Pose>* poses) {
  const PrincipalAxes A = principalAxesUpright(points, up, 0.0);
  Vec3 mid = centre;
  std::vector<std::pair<Vec3, double>> sides;  // (horizontal axis, the model's width along it)
  for (int k = 0; k < 3; ++k) {
    const Vec3 a = A.axes.col(k);
    if (std::abs(a.dot(up)) > 0.5) continue;
    mid += (0.5 * (A.min[k] + A.max[k]) + (A.centroid - centre).dot(a)) * a;
    sides.push_back({a, A.max[k] - A.min[k]});
  }
  for (size_t k = 0; k < o.spreads.size(); ++k) {
    const double s = o.spreads[k];
    const auto& gaps = g.spreads[k];
    for (const auto& [a, width] : sides)
      for (double margin : {0.008, 0.020}) {
        const double best = preshapeForGap(gaps, width + 2 * margin);
        if (best < 0) continue;
        for (double sx : {1.0, -1.0}) {
          Mat3 R;
          R.col(2) = -up;
          R.col(0) = sx * a;
          R.col(1) = R.col(2).cross(R.col(0));
          Pose ps{R, s, false, best};
          ps.pinch = true;
          ps.offset = mid - centre;
          poses->push_back(ps);
        }
      }
  }
  // Two-finger pinches: palm y across the side; the window of preshapes that meet a thin body
  // at its middle is narrow (the fingertips rise as they close), hence the fine steps.
  if (!hasTwoFingerPinch(robot, o)) return;
  const auto& gaps = g.two_finger;
  for (const auto& [a, width] : sides)
    for (double margin : {0.003, 0.006, 0.010}) {
      const double best = preshapeForGap(gaps, width + 2 * margin);
      if (best < 0) continue;
      Mat3 R;
      R.col(2) = -up;
      R.col(1) = a;
      R.col(0) = R.col(1).cross(R.col(2));
      Pose ps{R, o.two_finger_spread, false, best};
      ps.pinch = true;
      ps.two_finger = true;
      ps.offset = mid - centre;
      poses->push_back(ps);
    }
}

// A narrow part of the footprint: its middle (in the plane's coordinates) and width along `dir`.
struct FootprintPart {
  Eigen::Vector2d middle, dir;
  double width;
};

// The narrow parts of a footprint, which a pinch can straddle where it cannot straddle the
// whole: the footprint (`points` in the plane's coordinates, on a grid of `cell` metres, each
// point's cell and its neighbours filled) is crossed from seeds every 4 cells along each
// coordinate axis (the footprint's principal axes); the run of filled cells through a seed,
// within a strip `strip_m` wide (a fingertip's width) and bridging gaps narrower than `gap_m`
// (no finger fits between), is a part when it is at most `max_width` wide and at least 10 mm
// narrower than the footprint along that axis. Parts of the same direction whose middles lie
// within 8 mm are one. The `count` nearest to `centre2` are returned, nearest first.
std::vector<FootprintPart> footprintParts(const std::vector<Eigen::Vector2d>& points,
                                          const Eigen::Vector2d& centre2, double max_width,
                                          int count) {
  const double cell = 0.003, strip_m = 0.012, gap_m = 0.012;
  Eigen::Vector2d lo = points.front(), hi = points.front();
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  lo -= Eigen::Vector2d::Constant(2 * cell);
  const int nx = int((hi.x() - lo.x()) / cell) + 4, ny = int((hi.y() - lo.y()) / cell) + 4;
  std::vector<uint8_t> grid(size_t(nx) * size_t(ny), 0);
  for (const auto& p : points) {
    const int i = int((p.x() - lo.x()) / cell), j = int((p.y() - lo.y()) / cell);
    for (int di = -1; di <= 1; ++di)
      for (int dj = -1; dj <= 1; ++dj) grid[size_t(j + dj) * size_t(nx) + size_t(i + di)] = 1;
  }
  auto filled = [&](const Eigen::Vector2d& q) {
    const int i = int(std::floor((q.x() - lo.x()) / cell)),
              j = int(std::floor((q.y() - lo.y()) / cell));
    return i >= 0 && j >= 0 && i < nx && j < ny && grid[size_t(j) * size_t(nx) + size_t(i)];
  };
  // Filled anywhere across the strip at q.
  auto solid = [&](const Eigen::Vector2d& q, const Eigen::Vector2d& across) {
    for (double t = -0.5 * strip_m; t <= 0.5 * strip_m + 1e-9; t += cell)
      if (filled(q + t * across)) return true;
    return false;
  };
  std::vector<FootprintPart> parts;
  for (int a = 0; a < 2; ++a) {
    const Eigen::Vector2d d = Eigen::Vector2d::Unit(a), e = Eigen::Vector2d::Unit(1 - a);
    const double extent = hi[a] - lo[a] - 2 * cell;
    for (int j = 0; j < ny; j += 4)
      for (int i = 0; i < nx; i += 4) {
        if (!grid[size_t(j) * size_t(nx) + size_t(i)]) continue;
        const Eigen::Vector2d seed = lo + cell * Eigen::Vector2d(i + 0.5, j + 0.5);
        double ends[2] = {0, 0};
        for (int side = 0; side < 2; ++side) {
          const double sgn = side == 0 ? 1 : -1;
          double last = 0;
          for (double t = cell; t - last < gap_m && t < max_width + gap_m; t += cell)
            if (solid(seed + sgn * t * d, e)) last = t;
          ends[side] = sgn * last;
        }
        const double width = ends[0] - ends[1] + cell;
        if (width > max_width || width > extent - 0.010) continue;
        const Eigen::Vector2d middle = seed + 0.5 * (ends[0] + ends[1]) * d;
        const bool known = std::any_of(parts.begin(), parts.end(), [&](const FootprintPart& p) {
          return p.dir == d && (p.middle - middle).norm() < 0.008;
        });
        if (!known) parts.push_back({middle, d, width});
      }
  }
  std::stable_sort(parts.begin(), parts.end(), [&](const FootprintPart& x, const FootprintPart& y) {
    return (x.middle - centre2).norm() < (y.middle - centre2).norm();
  });
  if (int(parts.size()) > count) parts.resize(size_t(count));
  return parts;
}

// Pinch poses on the footprint's narrow parts (footprintParts, the 12 nearest the centre): a ring's
// rim, a hammer's handle or head, a mug's handle, which the pinch across the whole footprint cannot
// span or spans far from the mass. As addPinchPoses, with the palm axis over the part's middle and
// palm x (palm y for the two-finger pinch) across it.
void addPartPinchPoses(const std::vector<Vec3>& points, const Vec3& centre, const Vec3& up,
                       const GraspOptions& o, const PinchGaps& g, std::vector<Pose>* poses) {
  if (points.size() < 3) return;
  const PrincipalAxes A = principalAxesUpright(points, up, 0.0);
  std::vector<Vec3> across;  // the footprint's two principal axes
  for (int k = 0; k < 3; ++k)
    if (std::abs(A.axes.col(k).dot(up)) <= 0.5) across.push_back(A.axes.col(k));
  if (across.size() != 2) return;
  const Vec3 a0 = across[0], a1 = across[1];
  std::vector<Eigen::Vector2d> flat;
  for (const Vec3& p : points) flat.push_back({p.dot(a0), p.dot(a1)});
  const Eigen::Vector2d centre2(centre.dot(a0), centre.dot(a1));
  auto poseOver = [&](const FootprintPart& part, const Vec3& x_dir, double spread, double f) {
    Mat3 R;
    R.col(2) = -up;
    R.col(0) = x_dir;
    R.col(1) = R.col(2).cross(R.col(0));
    Pose ps{R, spread, false, f};
    ps.pinch = true;
    ps.offset = (part.middle.x() - centre2.x()) * a0 + (part.middle.y() - centre2.y()) * a1;
    return ps;
  };
  for (size_t k = 0; k < o.spreads.size(); ++k) {
    const double s = o.spreads[k];
    const auto& gaps = g.spreads[k];
    if (gaps.empty()) continue;
    for (const FootprintPart& part : footprintParts(flat, centre2, gaps.front().second - 0.016, 12))
      for (double margin : {0.008, 0.020}) {
        const double best = preshapeForGap(gaps, part.width + 2 * margin);
        if (best < 0) continue;
        const Vec3 d = part.dir.x() * a0 + part.dir.y() * a1;
        for (double sx : {1.0, -1.0}) poses->push_back(poseOver(part, sx * d, s, best));
      }
  }
  const auto& gaps = g.two_finger;
  if (gaps.empty()) return;
  for (const FootprintPart& part : footprintParts(flat, centre2, gaps.front().second - 0.006, 12))
    for (double margin : {0.003, 0.006, 0.010}) {
      const double best = preshapeForGap(gaps, part.width + 2 * margin);
      if (best < 0) continue;
      const Vec3 d = part.dir.x() * a0 + part.dir.y() * a1;
      // Palm y across the part: palm x = y × z with z = −up.
      Pose ps = poseOver(part, d.cross(-up), o.two_finger_spread, best);
      ps.two_finger = true;
      poses->push_back(ps);
    }
}

// Every (approach, roll, spread, preshape) pose with the palm axis through the centre; then the
// edge poses, aligned with the model's principal axes (palm z along ± one axis, palm y along
// another, palm x either way along the third: the hand is not symmetric there); then the pinch
// poses (addPinchPoses on `footprint`, else the samples; `up`: the table normal in O).
std::vector<Pose> candidatePoses(const RobotModel& robot, const std::vector<SurfacePoint>& samples,
                                 const Vec3& centre, const Vec3& up, const GraspOptions& o,
                                 const std::vector<Vec3>* footprint) {
  std::vector<Pose> poses;
  for (const Vec3& d : fibonacciSphere(o.approaches))
    for (int r = 0; r < o.rolls; ++r) {
      const Mat3 R = cameraPoseInObject(centre, -d, 1.0, M_PI * r / o.rolls).linear();
      for (double s : o.spreads)
        for (double f : o.preshapes) poses.push_back({R, s, false, f});
    }
  if (robot.spreadVariable() >= 0 && !o.edge_spreads.empty()) {
    std::vector<Vec3> points;
    for (const SurfacePoint& sm : samples) points.push_back(sm.p);
    const Mat3 A = principalAxes(points).axes;
    for (int z = 0; z < 3; ++z)
      for (double sz : {1.0, -1.0})
        for (int y = 0; y < 3; ++y) {
          if (y == z) continue;
          for (double sy : {1.0, -1.0}) {
            Mat3 R;
            R.col(2) = sz * A.col(z);
            R.col(1) = sy * A.col(y);
            R.col(0) = R.col(1).cross(R.col(2));
            for (double s : o.edge_spreads)
              for (double f : o.preshapes) poses.push_back({R, s, true, f});
          }
        }
  }
  if (o.pinch_poses) {
    std::vector<Vec3> points;
    if (footprint && !footprint->empty())
      points = *footprint;
    else
      for (const SurfacePoint& sm : samples) points.push_back(sm.p);
    const PinchGaps gaps = pinchGaps(robot, o);
    addPinchPoses(robot, points, centre, up, o, gaps, &poses);
    addPartPinchPoses(points, centre, up, o, gaps, &poses);
  }
  return poses;
}

GraspPoseRecord poseRecord(const Pose& ps) {
  GraspPoseRecord rec;
  rec.approach_O = ps.R.col(2);
  const Vec3 ref = ps.R.col(2).unitOrthogonal();
  rec.roll_rad = std::atan2(ref.cross(ps.R.col(0)).dot(ps.R.col(2)), ref.dot(ps.R.col(0)));
  rec.spread = ps.spread;
  rec.preshape = ps.preshape;
  rec.edge = ps.edge;
  rec.pinch = ps.pinch;
  rec.two_finger = ps.two_finger;
  rec.result = "no_contact";
  return rec;
}

// The lowest point (base z) of the hand at q with the palm at T_B_palm.
double handLowestZ(const RobotModel& robot, const JointVector& q, const Iso3& T_B_palm) {
  double lowest = std::numeric_limits<double>::infinity();
  for (const Vec3f& v : HandGeometry(robot, q, T_B_palm).mesh().vertices)
    lowest = std::min(lowest, double(v.z()));
  return lowest;
}

// The samples' coordinates one array per axis, for nearestInFootprint.
struct SampleArrays {
  std::vector<double> x, y, z;
};

// The least z of the samples p' = Rᵀ(p − origin) (from sample `first` on) whose (x, y) lie in
// [x0, x1] × [y0, y1] (+inf when none does). Each coordinate as Eigen's Rᵀ·v computes it,
// (R0i·dx + R1i·dy) + R2i·dz.
double nearestInFootprint(const SampleArrays& s, const Mat3& R, const Vec3& origin, double x0,
                          double x1, double y0, double y1, size_t first = 0) {
  double nearest = std::numeric_limits<double>::infinity();
  const double ox = origin.x(), oy = origin.y(), oz = origin.z();
  for (size_t i = first; i < s.x.size(); ++i) {
    const double dx = s.x[i] - ox, dy = s.y[i] - oy, dz = s.z[i] - oz;
    const double px = R(0, 0) * dx + R(1, 0) * dy + R(2, 0) * dz;
    const double py = R(0, 1) * dx + R(1, 1) * dy + R(2, 1) * dz;
    if (px < x0 || px > x1 || py < y0 || py > y1) continue;
    nearest = std::min(nearest, R(0, 2) * dx + R(1, 2) * dy + R(2, 2) * dz);
  }
  return nearest;
}

#if INHAND_FAST_MATH_AVX2
// nearestInFootprint four samples at a time (the same operations per sample, no FMA; the least of
// the same values).
__attribute__((target("avx2"))) double nearestInFootprintFour(const SampleArrays& s, const Mat3& R,
                                                              const Vec3& origin, double x0,
                                                              double x1, double y0, double y1) {
  const size_t n = s.x.size(), n4 = n / 4 * 4;
  const __m256d ox = _mm256_set1_pd(origin.x()), oy = _mm256_set1_pd(origin.y()),
                oz = _mm256_set1_pd(origin.z());
  __m256d r[3][3];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) r[a][b] = _mm256_set1_pd(R(a, b));
  const __m256d vx0 = _mm256_set1_pd(x0), vx1 = _mm256_set1_pd(x1), vy0 = _mm256_set1_pd(y0),
                vy1 = _mm256_set1_pd(y1),
                inf = _mm256_set1_pd(std::numeric_limits<double>::infinity());
  __m256d best = inf;
  for (size_t i = 0; i < n4; i += 4) {
    const __m256d dx = _mm256_sub_pd(_mm256_loadu_pd(s.x.data() + i), ox);
    const __m256d dy = _mm256_sub_pd(_mm256_loadu_pd(s.y.data() + i), oy);
    const __m256d dz = _mm256_sub_pd(_mm256_loadu_pd(s.z.data() + i), oz);
    __m256d c[3];
    for (int k = 0; k < 3; ++k)
      c[k] = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(r[0][k], dx), _mm256_mul_pd(r[1][k], dy)),
                           _mm256_mul_pd(r[2][k], dz));
    const __m256d px = c[0], py = c[1];
    // Outside: px < x0 or px > x1 or ... (a NaN compares false both ways and counts as inside, as
    // in the scalar test; both minimums then pass over it).
    const __m256d outside = _mm256_or_pd(
        _mm256_or_pd(_mm256_cmp_pd(px, vx0, _CMP_LT_OQ), _mm256_cmp_pd(px, vx1, _CMP_GT_OQ)),
        _mm256_or_pd(_mm256_cmp_pd(py, vy0, _CMP_LT_OQ), _mm256_cmp_pd(py, vy1, _CMP_GT_OQ)));
    if (_mm256_movemask_pd(outside) == 0xF) continue;
    const __m256d pz = _mm256_blendv_pd(c[2], inf, outside);
    best = _mm256_min_pd(pz, best);
  }
  alignas(32) double lanes[4];
  _mm256_store_pd(lanes, best);
  const double nearest = std::min(std::min(lanes[0], lanes[1]), std::min(lanes[2], lanes[3]));
  return std::min(nearest, nearestInFootprint(s, R, origin, x0, x1, y0, y1, n4));
}
#endif

// Brings one pose's hand to the model and closes it: what generateGrasps does per pose, with
// what it shares across poses.
class PoseCloser {
 public:
  PoseCloser(const RobotModel& robot, const TriangleMesh& mesh, const Iso3& T_B_O,
             const GraspOptions& o, const std::vector<SurfacePoint>& samples,
             const std::vector<Pose>& poses)
      : PoseCloser(robot, mesh, T_B_O, o, samples, poses, closers(robot, mesh, T_B_O)) {}

 private:
  // The two closers' collision hierarchies (model with table, model alone), one per core.
  static std::vector<FingerCloser> closers(const RobotModel& robot, const TriangleMesh& mesh,
                                           const Iso3& T_B_O) {
    std::vector<std::optional<FingerCloser>> built(2);
    parallelForThreads(0, 2, [&](int i) {
      built[size_t(i)].emplace(robot, i == 0 ? withTable(mesh, robot, T_B_O) : mesh);
    });
    return {*built[0], *built[1]};
  }
  PoseCloser(const RobotModel& robot, const TriangleMesh& mesh, const Iso3& T_B_O,
             const GraspOptions& o, const std::vector<SurfacePoint>& samples,
             const std::vector<Pose>& poses, const std::vector<FingerCloser>& closers)
      : robot_(robot),
        T_B_O_(T_B_O),
        o_(o),
        samples_(samples),
        grid_(samples, o.contact_cell_m),
        centre_(mesh.bounds().center()),
        up_(T_B_O.linear().transpose() * Vec3::UnitZ()),
        closer_(closers[0]),
        modelCloser_(closers[1]) {
    // Palm face (top of the palm geometry along palm z) and footprint.
    for (const Primitive& p : robot.links()[robot.tipLink()].collision) {
      const Aabb b = p.toMesh().bounds();
      palm_.extend(b.min);
      palm_.extend(b.max);
    }
    for (const SurfacePoint& sm : samples_) rho_ = std::max(rho_, (sm.p - centre_).norm());
    for (const SurfacePoint& sm : samples_) {
      arrays_.x.push_back(sm.p.x());
      arrays_.y.push_back(sm.p.y());
      arrays_.z.push_back(sm.p.z());
    }
    // The preshaped hand's bounding box in the palm frame, per (spread, preshape).
    for (const Pose& ps : poses)
      if (!openHandBox_.count(boxKey(ps)))
        openHandBox_[boxKey(ps)] =
            HandGeometry(robot_, poseHand(robot_, ps), Iso3::Identity()).mesh().bounds();
  }

 public:
  // The candidate of pose i (index `pose`), or nullopt with rec.result saying why.
  std::optional<GraspCandidate> operator()(const Pose& ps, int pose, GraspPoseRecord& rec) const {
    Iso3 T = Iso3::Identity();
    T.linear() = ps.R;
    const JointVector q = poseHand(robot_, ps);
    // Edge poses: the palm axis moves along palm x until the model's extent along it ends
    // `edge_inset_m` beyond the axis, so that fingers 1 and 2 (across palm y at a 90° spread)
    // straddle the object near its edge and finger 3 closes over that edge.
    Vec3 origin = ps.axis_O ? *ps.axis_O : centre_ + ps.offset;
    if (ps.edge) origin += (extent(ps.R.col(0)) - o_.edge_inset_m) * ps.R.col(0);
    // The hand first comes to the model alone: where it then reaches below the table top, the
    // palm rises along the table normal until it clears it (by 3 mm) and comes in again, now
    // stopping at the model or the table. Rising moves the palm axis off the model's centre by
    // its part across the approach: allowed while the axis stays 1 cm inside the model's extent
    // that way. A hand coming straight down keeps its axis: its fingertips stop at the table and
    // close from there (the table-level pinch of a short object).
    if (!approach(ps, q, origin, modelCloser_, &T)) return std::nullopt;
    const double rise = robot_.table().topZ() + 0.003 - handLowestZ(robot_, q, T_B_O_ * T);
    if (rise > 0) {
      const Vec3 across = rise * (up_ - up_.dot(ps.R.col(2)) * ps.R.col(2));
      if (across.norm() > 1e-9 && across.norm() > extent(across.normalized()) - 0.01) {
        rec.result = "table";
        return std::nullopt;
      }
      origin += rise * up_;
    }
    if (!approach(ps, q, origin, closer_, &T)) {
      rec.result = "table";
      return std::nullopt;
    }
    // 0.06 rad steps: the fingertip moves 9 mm per step, less than a link is thick (20 mm).
    // A finger stopped by the table short of the model lifts the hand off it (5 mm steps).
    auto [closed, Tc] = closeOffTheTable(closer_, modelCloser_, q, T, 0.005, 0.03, 0.06);
    GraspCandidate c;
    c.T_O_palm = Tc;
    c.q = closed.q;
    c.q_open = q;
    c.pose = pose;
    c.pinch = ps.pinch;
    // Contacts: model surface samples near the closed hand (a finger stopped by the table
    // touches nothing).
    HandContacts hc = handContacts(robot_, c.q, Tc, grid_, o_.contact_m, o_.contact_cell_m);
    c.contacts = std::move(hc.contacts);
    c.links_in_contact = hc.fingers_touching + int(hc.palm_touching);
    c.palm_contact = hc.palm_touching;
    if (c.links_in_contact < 2) {
      rec.result = "fewer_than_two_links";
      return std::nullopt;
    }
    c.epsilon = forceClosureEpsilon(c.contacts, centre_, rho_, o_.friction, o_.cone_edges,
                                    o_.wrench_directions);
    rec.epsilon = c.epsilon;
    return c;
  }

 private:
  // How far the model reaches from its centre along the unit direction d.
  double extent(const Vec3& d) const {
    double e = -std::numeric_limits<double>::infinity();
    for (const SurfacePoint& sm : samples_) e = std::max(e, (sm.p - centre_).dot(d));
    return e;
  }

  static TriangleMesh withTable(const TriangleMesh& mesh, const RobotModel& robot,
                                const Iso3& T_B_O) {
    TriangleMesh obstacles = mesh;
    obstacles.append(tableMeshInObject(robot, T_B_O));
    return obstacles;
  }

  // Brings the preshaped hand (palm orientation ps.R, its axis through `origin`) to the model
  // along palm z: kFirstContact, from outside until any link touches what `closer` holds (the
  // model, or the model and the table; the travel starts where the open hand's box first reaches a
  // sample inside its footprint: nothing can touch earlier); kPalm, until the palm face touches the
  // nearest sample in its footprint. False when nothing is met or the hand starts in contact.
  bool approach(const Pose& ps, const JointVector& q, const Vec3& origin,
                const FingerCloser& closer, Iso3* T) const {
    const Mat3& R = ps.R;
    const bool firstContact = o_.approach == GraspApproach::kFirstContact;
    const Aabb box = firstContact ? openHandBox_.at(boxKey(ps)) : palm_;
    const double margin = firstContact ? 0.005 : 0.0;
    const double x0 = box.min.x() - margin, x1 = box.max.x() + margin, y0 = box.min.y() - margin,
                 y1 = box.max.y() + margin;
#if INHAND_FAST_MATH_AVX2
    const double nearest = o_.vectorised && fastMathAvx2()
                               ? nearestInFootprintFour(arrays_, R, origin, x0, x1, y0, y1)
                               : nearestInFootprint(arrays_, R, origin, x0, x1, y0, y1);
#else
    const double nearest = nearestInFootprint(arrays_, R, origin, x0, x1, y0, y1);
#endif
    if (!std::isfinite(nearest)) return false;
    if (!firstContact) {
      T->translation() = origin + R * Vec3(0, 0, nearest - palm_.max.z() - 0.002);
      return true;
    }
    const double start = box.max.z() - nearest + 0.01, travelMax = 2 * rho_ + 0.02;
    T->translation() = origin - start * R.col(2);
    const std::optional<double> travel = closer.freeTravel(q, *T, R.col(2), travelMax);
    if (!travel || *travel >= travelMax) return false;
    T->translation() += *travel * R.col(2);
    return true;
  }

  const RobotModel& robot_;
  Iso3 T_B_O_;
  const GraspOptions& o_;
  std::vector<SurfacePoint> samples_;
  SampleArrays arrays_;  // the same samples' coordinates, for the approach
  SampleGrid grid_;      // the same samples, for the contacts near the closed hand
  Vec3 centre_, up_;
  double rho_ = 0;
  Aabb palm_;
  FingerCloser closer_, modelCloser_;
  // The open hand's joint values.
  using BoxKey = std::vector<double>;
  BoxKey boxKey(const Pose& ps) const {
    const JointVector q = poseHand(robot_, ps);
    return BoxKey(q.data(), q.data() + q.size());
  }
  std::map<BoxKey, Aabb> openHandBox_;
};

}  // namespace

namespace {
// Two closed grasps the same to within 1 mm and 1° of palm pose and 0.01 rad at every finger.
bool sameGrasp(const RobotModel& robot, const GraspCandidate& a, const GraspCandidate& b) {
  if ((a.T_O_palm.translation() - b.T_O_palm.translation()).norm() > 0.001) return false;
  if (rotationBetween(a.T_O_palm, b.T_O_palm) > M_PI / 180) return false;
  for (const FingerInfo& f : robot.fingers())
    if (std::abs(a.q[f.variable] - b.q[f.variable]) > 0.01) return false;
  const int s = robot.spreadVariable();
  return s < 0 || std::abs(a.q[s] - b.q[s]) <= 0.01;
}
}  // namespace

namespace {
// The poses' hands brought to `mesh` resting at T_B_O and closed (PoseCloser, on both cores), kept
// as candidates (in the poses' order) when force closure with ε ≥ min_epsilon, above the table
// top (fingers stop at the table top when they close: 1 mm tolerance) and reachable at the table
// (IK to the palm pose and the lift, arm and hand free of table and base); out.poses says why
// not. `distinct`: preshapes that close to the same grasp (the same palm pose, the same finger
// joints) are one candidate, the first.
std::vector<GraspCandidate> closeAndKeep(const RobotModel& robot, const TriangleMesh& mesh,
                                         const Iso3& T_B_O, const JointVector& q_now,
                                         const GraspOptions& o,
                                         const std::vector<SurfacePoint>& samples,
                                         const std::vector<Pose>& poses, bool distinct,
                                         GraspGeneration& out) {
  out.tried = int(poses.size());
  for (const Pose& ps : poses) out.poses.push_back(poseRecord(ps));
  const PoseCloser close(robot, mesh, T_B_O, o, samples, poses);
  std::vector<std::optional<GraspCandidate>> found(poses.size());
  parallelFor(0, int(poses.size()), [&](int i) { found[i] = close(poses[i], i, out.poses[i]); });
  std::vector<GraspCandidate> kept;
  for (size_t i = 0; i < found.size(); ++i) {
    auto& f = found[i];
    if (!f) continue;
    ++out.touching;
    if (f->epsilon < o.min_epsilon) {
      out.poses[i].result = "not_force_closure";
      continue;
    }
    ++out.stable;
    if (handLowestZ(robot, f->q, T_B_O * f->T_O_palm) < robot.table().topZ() - 0.001) {
      out.poses[i].result = "hand_in_table";
      continue;
    }
    ++out.table_free;
    const bool same =
        distinct && std::any_of(kept.begin(), kept.end(),
                                [&](const GraspCandidate& k) { return sameGrasp(robot, k, *f); });
    if (same) {
      out.poses[i].result = "duplicate";
      continue;
    }
    kept.push_back(std::move(*f));
  }
  std::vector<Iso3> targets;
  std::vector<JointVector> hands;
  for (const GraspCandidate& c : kept) {
    targets.push_back(T_B_O * c.T_O_palm);
    hands.push_back(c.q);
  }
  const auto reach =
      pickAndLift(robot, targets, hands, q_now, {o.lift_m, o.lift_straight, o.lift_in_view}, 2, 7);
  std::vector<GraspCandidate> candidates;
  for (size_t k = 0; k < kept.size(); ++k) {
    if (!reach[k]) {
      out.poses[kept[k].pose].result = "unreachable";
      continue;
    }
    out.poses[kept[k].pose].result = "kept";
    kept[k].q = reach[k]->q;
    kept[k].q_lift = reach[k]->q_lift;
    kept[k].q_open = robot.withArm(kept[k].q_open, robot.arm(reach[k]->q));
    candidates.push_back(std::move(kept[k]));
  }
  return candidates;
}

// The options checked; the model's vertices that triangles use (a model cut out of a bigger one
// keeps others: they would be samples, contacts and bounds of surface that is not there), and its
// surface samples with outward normals (vertices, plus a lattice on large triangles).
std::pair<TriangleMesh, std::vector<SurfacePoint>> graspSurface(const RobotModel& robot,
                                                                const TriangleMesh& model,
                                                                const GraspOptions& o) {
  if (std::string p = o.validate(); !p.empty()) throw Error("grasp options: " + p);
  INHAND_CHECK(!robot.fingers().empty(), "the hand has no fingers to grasp with");
  TriangleMesh mesh = withoutUnusedVertices(model);
  std::vector<SurfacePoint> samples = surfaceSamples(mesh, 0.5 * o.contact_cell_m);
  return {std::move(mesh), std::move(samples)};
}
}  // namespace

GraspGeneration generateGrasps(const RobotModel& robot, const TriangleMesh& model,
                               const Iso3& T_B_O, const JointVector& q_now, const GraspOptions& o,
                               const std::vector<Vec3>* footprint_O) {
  const auto t0 = std::chrono::steady_clock::now();
  GraspGeneration out;
  const auto [mesh, samples] = graspSurface(robot, model, o);
  if (mesh.empty()) return out;
  const std::vector<Pose> poses =
      candidatePoses(robot, samples, mesh.bounds().center(),
                     T_B_O.linear().transpose() * Vec3::UnitZ(), o, footprint_O);
  out.candidates = closeAndKeep(robot, mesh, T_B_O, q_now, o, samples, poses, true, out);
  std::stable_sort(
      out.candidates.begin(), out.candidates.end(),
      [](const GraspCandidate& a, const GraspCandidate& b) { return a.epsilon > b.epsilon; });
  for (size_t k = o.max_candidates; k < out.candidates.size(); ++k)
    out.poses[out.candidates[k].pose].result = "beyond_max_candidates";
  if (int(out.candidates.size()) > o.max_candidates) out.candidates.resize(o.max_candidates);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

GraspGeneration graspsFromSet(const RobotModel& robot, const TriangleMesh& model, const Iso3& T_B_O,
                              const JointVector& q_now, const std::vector<KnownGrasp>& set,
                              const GraspOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  GraspGeneration out;
  const auto [mesh, samples] = graspSurface(robot, model, o);
  if (mesh.empty()) return out;
  std::vector<Pose> poses;
  const int s = robot.spreadVariable();
  for (const KnownGrasp& g : set) {
    if (g.hand.size() != robot.variableCount())
      throw Error("graspsFromSet: a grasp's hand has " + std::to_string(g.hand.size()) +
                  " joint values, the robot " + std::to_string(robot.variableCount()));
    Pose ps{g.T_O_palm.linear(), s >= 0 ? g.hand[s] : 0.0, false};
    ps.hand = g.hand;
    robot.applyCouplings(&ps.hand);
    ps.axis_O = g.T_O_palm.translation();
    poses.push_back(ps);
  }
  out.candidates = closeAndKeep(robot, mesh, T_B_O, q_now, o, samples, poses, false, out);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

double rankGrasps(const ViewPlanner& planner, const ObjectModel& S_obj, const GraspOptions& o,
                  std::vector<GraspCandidate>* candidates, bool reference,
                  const std::vector<double>* view_bounds) {
  const auto t0 = std::chrono::steady_clock::now();
  const ViewQualityOptions& qo = planner.options().quality;
  ViewQualityScene scene = planner.qualityScene(S_obj);  // S_obj's BVH once for all candidates
  const Aabb region = S_obj.mesh.bounds();  // near-hand cells only where S_obj can be hit
  // Each view's quality with no hand bounds it with any hand: views are scored best bound first
  // until no other can beat the best found (bestViewQuality); the reference scores every view.
  const std::vector<double> bounds = reference     ? std::vector<double>()
                                     : view_bounds ? *view_bounds
                                                   : planner.viewBoundsWithoutHand(scene);
  for (GraspCandidate& c : *candidates) {
    HandGeometry hand(planner.model(), c.q, c.T_O_palm);
    auto nearHand = std::make_shared<NearHandGrid>(hand, qo.t_hand_m, qo.near_hand_cell_m, &region);
    const GraspState grasp{c.T_O_palm, c.q_lift};
    int reachable = 0;
    const std::optional<double> best =
        bounds.empty() ? std::nullopt
                       : planner.bestViewQuality(scene, grasp, nearHand, bounds, &reachable);
    if (best) {
      c.reachable_views = reachable;
      c.quality = *best;
    } else {
      ViewSelection sel = planner.select(scene, grasp, {}, nearHand);
      c.reachable_views = sel.reachable;
      c.quality = 0;
      for (const ViewCandidate& v : sel.candidates) c.quality = std::max(c.quality, v.quality);
    }
    c.score = c.quality + o.stability_weight * c.epsilon;
  }
  std::stable_sort(
      candidates->begin(), candidates->end(),
      [](const GraspCandidate& a, const GraspCandidate& b) { return a.score > b.score; });
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace inhand
