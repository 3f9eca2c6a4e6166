#include "inhand/grasp/hold_test.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>

#include "inhand/core/enum_names.h"
#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/grasp/grasp.h"
#include "inhand/robot/collision.h"

namespace inhand {

namespace {
const EnumNames<HoldFailure, 5> kHoldFailures = {{HoldFailure::kNone, ""},
                                                 {HoldFailure::kNotTouching, "not_touching"},
                                                 {HoldFailure::kDroppedInLift, "dropped_in_lift"},
                                                 {HoldFailure::kDroppedInTurn, "dropped_in_turn"},
                                                 {HoldFailure::kSlipped, "slipped"}};
}  // namespace

const char* holdFailureName(HoldFailure f) { return enumName(kHoldFailures, f); }
bool parseHoldFailure(const std::string& name, HoldFailure* out) {
  return enumFromName(kHoldFailures, name, out);
}

std::string HoldTestOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (max_tested < max_candidates) return "max_tested must be >= max_candidates";
  return {};
}

std::vector<ConvexPiece> modelPiecesAboveTable(const TriangleMesh& model_O, const Iso3& T_B_O,
                                               const RobotModel& robot,
                                               const std::vector<Plane>* keep_O,
                                               const ConvexDecompositionOptions& options) {
  // The table top in frame O: n·x ≥ d above it (a millimetre up: the model's surface where it
  // meets the top is a voxel's width of guess).
  const Vec3 n = T_B_O.linear().transpose() * Vec3::UnitZ();
  const double d = robot.table().topZ() + 0.001 - T_B_O.translation().z();
  std::vector<ConvexPiece> out;
  for (const ConvexPiece& p : convexDecomposition(model_O, options)) {
    std::optional<ConvexPiece> c = clipPiece(p, n, d);
    for (size_t k = 0; keep_O && k < keep_O->size() && c; ++k)
      c = clipPiece(*c, (*keep_O)[k].n, -(*keep_O)[k].d);
    if (c) out.push_back(std::move(*c));
  }
  return out;
}

int holdStage(HoldFailure failure) {
  switch (failure) {
    case HoldFailure::kNone:
      return 4;
    case HoldFailure::kSlipped:
      return 3;
    case HoldFailure::kDroppedInTurn:
      return 2;
    case HoldFailure::kDroppedInLift:
      return 1;
    case HoldFailure::kNotTouching:
      break;
  }
  return 0;
}

namespace {
// The palm's pose s ∈ [0, 1] of the way along a motion with a trapezoidal speed profile (a
// quarter of the time speeding up, a quarter slowing down).
double trapezoid(double s) {
  const double r = 0.25, v = 1 / (1 - r);
  if (s < r) return 0.5 * v * s * s / r;
  if (s > 1 - r) return 1 - 0.5 * v * (1 - s) * (1 - s) / r;
  return v * (s - 0.5 * r);
}

// Moves the palm from `from` toward `to` over `seconds` (trapezoidal, 20 ms segments), rotating
// about the point `pivot_B`; false as soon as the object has touched no part of the hand for
// 0.1 s.
bool movePalmHolding(PhysicsWorld& w, const Iso3& from, const Vec3& lift,
                     const Eigen::AngleAxisd& turn, const Vec3& pivot_B, double seconds) {
  const int n = std::max(1, int(std::lround(seconds / 0.02)));
  double untouched = 0;
  for (int k = 1; k <= n; ++k) {
    const double f = trapezoid(double(k) / n);
    const Mat3 R = Eigen::AngleAxisd(f * turn.angle(), turn.axis()).toRotationMatrix();
    Iso3 T = Iso3::Identity();
    T.linear() = R * from.linear();
    T.translation() = pivot_B + R * (from.translation() - pivot_B) + f * lift;
    w.movePalm(T, seconds / n);
    untouched = w.objectTouchesHand() ? 0.0 : untouched + seconds / n;
    if (untouched >= 0.1 - 1e-9) return false;
  }
  return true;
}
}  // namespace

Vec3 holdTurnAxis(const Iso3& T_B_palm) {
  Vec3 axis = Vec3::UnitZ().cross(T_B_palm.linear().col(2));
  if (axis.norm() < std::sin(3 * M_PI / 180)) {
    axis = T_B_palm.linear().col(0);
    axis.z() = 0;
  }
  return axis.normalized();
}

PhysicsOptions holdTrialPhysics(const HoldTestOptions& o) {
  PhysicsOptions po;
  po.density_kg_m3 = o.density_kg_m3;
  po.noslip_iterations = o.noslip_iterations;
  po.timestep_s = 0.002;
  po.contact_timeconst_s = 0.005;
  po.table_contact_timeconst_s = 0.005;
  return po;
}

HoldTrial tryHold(PhysicsWorld& world, const Iso3& T_B_O, const Iso3& T_O_palm,
                  const JointVector& q_open, const JointVector& q_closed,
                  const HoldTestOptions& o) {
  HoldTrial t;
  t.lift_kg = world.mass_kg();
  const Iso3 T_B_palm = T_B_O * T_O_palm;
  world.reset(T_B_O, T_B_palm, q_open);
  const Vec3 rested = world.objectPose().translation();
  world.closeHand(q_closed);
  t.close_moved_m = (world.objectPose().translation() - rested).norm();
  if (!world.objectTouchesHand()) {
    t.failure = HoldFailure::kNotTouching;
    return t;
  }
  t.T_O_palm_closed = world.objectPose().inverse() * world.palmPose();
  const Iso3 grip = world.palmPose().inverse() * world.objectPose();
  auto slip = [&] {
    const Iso3 now = world.palmPose().inverse() * world.objectPose();
    return (now.translation() - grip.translation()).norm();
  };
  const Iso3 start = world.palmPose();
  if (!movePalmHolding(world, start, Vec3(0, 0, o.lift_m), Eigen::AngleAxisd(0, Vec3::UnitX()),
                       start.translation(), o.lift_s)) {
    t.failure = HoldFailure::kDroppedInLift;
    t.slip_m = slip();
    return t;
  }
  // The turn (gravity then pulls along the approach or across it), through the object's centre.
  const Iso3 lifted = world.palmPose();
  if (!movePalmHolding(world, lifted, Vec3::Zero(),
                       Eigen::AngleAxisd(o.turn_rad, holdTurnAxis(lifted)),
                       world.objectPose().translation(), o.turn_s)) {
    t.failure = HoldFailure::kDroppedInTurn;
    t.slip_m = slip();
    return t;
  }
  world.movePalm(world.palmPose(), 0.3);
  t.slip_m = slip();
  t.held = world.objectTouchesHand() && t.slip_m <= o.max_slip_m;
  if (!t.held)
    t.failure = world.objectTouchesHand() ? HoldFailure::kSlipped : HoldFailure::kDroppedInTurn;
  return t;
}

namespace {
// preferHoldingUnseen: a hand the unseen space stops less than this short of its plan is where
// the hold test tried it (freeTravel's bisection and the model's own surface are within it).
constexpr double kUnseenStop_m = 0.002;
// … and the hand comes in from this far back along its approach.
constexpr double kUnseenFrom_m = 0.15;

// The first of the h candidates that held (in their order, at most o.robust_checked) that holds
// too with the model moved o.pose_tolerance_m each way across the table, moved to the front.
void robustFirst(const RobotModel& robot, const std::vector<ConvexPiece>& pieces, const Iso3& T_B_O,
                 double friction, const PhysicsOptions& po, const HoldTestOptions& o,
                 std::vector<GraspCandidate>* candidates, int h) {
  const double d = o.pose_tolerance_m;
  const std::array<Vec3, 4> shifts{Vec3(d, 0, 0), Vec3(-d, 0, 0), Vec3(0, d, 0), Vec3(0, -d, 0)};
  const int workers = std::max(1, std::min(threadCount(), int(shifts.size())));
  for (int i = 0; i < std::min(h, o.robust_checked); ++i) {
    GraspCandidate& c = (*candidates)[size_t(i)];
    const Iso3 T_B_palm = T_B_O * c.T_O_palm;
    std::array<uint8_t, 4> held{};
    parallelFor(0, workers, [&](int w) {
      PhysicsWorld world(robot, pieces, friction, po);
      for (size_t k = size_t(w); k < shifts.size(); k += size_t(workers)) {
        const Iso3 T = Eigen::Translation3d(shifts[k]) * T_B_O;
        held[k] = tryHold(world, T, T.inverse() * T_B_palm, c.q_open, c.q, o).held;
      }
    });
    c.hold_robust = std::all_of(held.begin(), held.end(), [](uint8_t x) { return x != 0; });
    if (c.hold_robust == 1) {
      std::rotate(candidates->begin(), candidates->begin() + i, candidates->begin() + i + 1);
      return;
    }
  }
}
}  // namespace

double rankByHold(const RobotModel& robot, const TriangleMesh& model_O, const Iso3& T_B_O,
                  const std::vector<Plane>* keep_O, double friction, const HoldTestOptions& o,
                  std::vector<GraspCandidate>* candidates) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!o.enabled || candidates->empty() || model_O.empty()) return 0;
  if (std::string p = o.validate(); !p.empty()) throw Error("hold test options: " + p);
  const std::vector<ConvexPiece> pieces =
      modelPiecesAboveTable(model_O, T_B_O, robot, keep_O, o.decomposition);
  const double s = rankByHold(robot, pieces, T_B_O, friction, o, candidates);
  return s > 0 ? std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() : 0;
}

bool liftShowsHand(const RobotModel& robot, const JointVector& q) {
  return heldInView(robot, q) &&
         clearLineFromCamera(robot, q, robot.tipPose(q).translation(), 0.05, true);
}

void liftInViewFirst(const RobotModel& robot, std::vector<GraspCandidate>::iterator first,
                     std::vector<GraspCandidate>::iterator last) {
  std::stable_partition(first, last, [&robot](const GraspCandidate& c) {
    return c.q_lift.size() == 0 || liftShowsHand(robot, c.q_lift);
  });
}

double rankByHold(const RobotModel& robot, const std::vector<ConvexPiece>& pieces,
                  const Iso3& T_B_O, double friction, const HoldTestOptions& o,
                  std::vector<GraspCandidate>* candidates, bool lift_in_view_first) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!o.enabled || candidates->empty() || pieces.empty()) return 0;
  if (std::string p = o.validate(); !p.empty()) throw Error("hold test options: " + p);
  const PhysicsOptions po = holdTrialPhysics(o);
  // Batches of max_candidates in their order until enough_held hold (or max_tested are tried).
  // One world per core, each trying every other candidate of the batch from a fresh reset.
  const int total = std::min(o.max_tested, int(candidates->size()));
  int n = 0;  // tested so far
  int heldCount = 0;
  while (n < total && heldCount < o.enough_held) {
    const int begin = n, end = std::min(total, n + o.max_candidates);
    const int workers = std::max(1, std::min(threadCount(), end - begin));
    std::vector<HoldTrial> trials(size_t(end - begin), HoldTrial{});
    // Each core takes the next candidate not yet taken (a trial that drops the model early is
    // short); a trial's outcome does not depend on the world that ran it (reset restores all
    // that a trial changes).
    std::atomic<int> next{begin};
    parallelForThreads(0, workers, [&](int) {
      PhysicsWorld world(robot, pieces, friction, po);
      for (int i = next++; i < end; i = next++) {
        const GraspCandidate& c = (*candidates)[size_t(i)];
        trials[size_t(i - begin)] = tryHold(world, T_B_O, c.T_O_palm, c.q_open, c.q, o);
      }
    });
    for (int i = begin; i < end; ++i) {
      GraspCandidate& c = (*candidates)[size_t(i)];
      c.hold = trials[size_t(i - begin)].held ? 1 : 0;
      c.hold_failure = trials[size_t(i - begin)].failure;
      c.hold_close_m = trials[size_t(i - begin)].close_moved_m;
      c.T_O_palm_closed = trials[size_t(i - begin)].T_O_palm_closed;
      heldCount += c.hold == 1 && (o.max_close_push_m <= 0 || c.hold_close_m <= o.max_close_push_m);
    }
    n = end;
  }
  const auto held = std::stable_partition(candidates->begin(), candidates->begin() + n,
                                          [](const GraspCandidate& c) { return c.hold == 1; });
  // Those that did not hold, by how far they got: still in the hand but moved, dropped in the
  // turn, dropped in the lift, not touching after the close.
  std::stable_sort(held, candidates->begin() + n,
                   [](const GraspCandidate& a, const GraspCandidate& b) {
                     return holdStage(a.hold_failure) > holdStage(b.hold_failure);
                   });
  // The margin: those that held tried again on a model margin_mass times as heavy with
  // margin_friction of the friction (the object's true weight and friction are not known); those
  // that hold that too go first.
  const int h = int(held - candidates->begin());
  if (h > 0 && (o.margin_mass != 1 || o.margin_friction != 1)) {
    PhysicsOptions heavy = po;
    heavy.density_kg_m3 *= o.margin_mass;
    std::vector<uint8_t> margin(size_t(h), 0);
    const int workers = std::max(1, std::min(threadCount(), h));
    std::atomic<int> next{0};
    parallelForThreads(0, workers, [&](int) {
      PhysicsWorld world(robot, pieces, friction * o.margin_friction, heavy);
      for (int i = next++; i < h; i = next++) {
        const GraspCandidate& c = (*candidates)[size_t(i)];
        margin[size_t(i)] = tryHold(world, T_B_O, c.T_O_palm, c.q_open, c.q, o).held;
      }
    });
    for (int i = 0; i < h; ++i) (*candidates)[size_t(i)].hold_margin = margin[size_t(i)];
  }
  // Held with the margin first; within each group, those whose close pushed the model little.
  const double push = o.max_close_push_m;
  if (lift_in_view_first) liftInViewFirst(robot, candidates->begin(), held);
  std::stable_sort(
      candidates->begin(), held, [push](const GraspCandidate& a, const GraspCandidate& b) {
        auto key = [push](const GraspCandidate& c) {
          return 2 * int(c.hold_margin == 1) + int(push <= 0 || c.hold_close_m <= push);
        };
        return key(a) > key(b);
      });
  if (h > 0 && o.pose_tolerance_m > 0)
    robustFirst(robot, pieces, T_B_O, friction, po, o, candidates, h);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double preferHoldingUnseen(const RobotModel& robot, const std::vector<ConvexPiece>& pieces,
                           const TriangleMesh& unseen_O, const Iso3& T_B_O, double friction,
                           const HoldTestOptions& o, int checked,
                           std::vector<GraspCandidate>* candidates) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<int> tried;  // indices of the first `checked` that held
  for (int i = 0; i < int(candidates->size()) && int(tried.size()) < checked; ++i)
    if ((*candidates)[size_t(i)].hold == 1) tried.push_back(i);
  if (!o.enabled || tried.empty() || unseen_O.empty() || pieces.empty()) return 0;
  // Where the unseen space stops each hand on its way in: from kUnseenFrom_m back along its
  // approach, the open hand's free travel toward the plan.
  const FingerCloser closer(robot, unseen_O);
  std::vector<double> shortBy(tried.size(), 0);
  parallelFor(0, int(tried.size()), [&](int k) {
    const GraspCandidate& c = (*candidates)[size_t(tried[size_t(k)])];
    const Vec3 a = c.T_O_palm.linear().col(2);
    Iso3 from = c.T_O_palm;
    from.translation() -= kUnseenFrom_m * a;
    const std::optional<double> travel = closer.freeTravel(c.q_open, from, a, kUnseenFrom_m);
    shortBy[size_t(k)] = travel ? kUnseenFrom_m - *travel : kUnseenFrom_m;
  });
  // The hold test's trial from there, on the model (a hand stopped where planned: its verdict
  // stands).
  std::vector<uint8_t> held(tried.size(), 1);
  const PhysicsOptions po = holdTrialPhysics(o);
  const int workers = std::max(1, std::min(threadCount(), int(tried.size())));
  std::atomic<int> next{0};
  parallelForThreads(0, workers, [&](int) {
    std::optional<PhysicsWorld> world;
    for (int k = next++; k < int(tried.size()); k = next++) {
      if (shortBy[size_t(k)] < kUnseenStop_m) continue;
      const GraspCandidate& c = (*candidates)[size_t(tried[size_t(k)])];
      Iso3 stopped = c.T_O_palm;
      stopped.translation() -= shortBy[size_t(k)] * c.T_O_palm.linear().col(2);
      if (!world) world.emplace(robot, pieces, friction, po);
      held[size_t(k)] = tryHold(*world, T_B_O, stopped, c.q_open, c.q, o).held;
    }
  });
  for (size_t k = 0; k < tried.size(); ++k) (*candidates)[size_t(tried[k])].hold_unseen = held[k];
  // Not ahead of a candidate that held with the margin when it did not (a pinch the unseen space
  // would stop short may well hold the true object, and the margin says more about the weight).
  const int margin = (*candidates)[size_t(tried[0])].hold_margin;
  for (size_t k = 0; k < tried.size(); ++k)
    if (held[k] && (*candidates)[size_t(tried[k])].hold_margin >= margin) {
      const auto at = candidates->begin() + tried[k];
      std::rotate(candidates->begin(), at, at + 1);
      break;
    }
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string holdLine(const std::vector<GraspCandidate>& candidates, double seconds) {
  int tested = 0, held = 0;
  for (const GraspCandidate& c : candidates) {
    tested += c.hold >= 0;
    held += c.hold == 1;
  }
  if (tested == 0) return "hold test: no candidate tested";
  char line[120];
  std::snprintf(line, sizeof line, "hold test: %d of %d candidates held the model (%.2f s)", held,
                tested, seconds);
  return line;
}

std::string unseenHoldLine(const std::vector<GraspCandidate>& candidates, double seconds) {
  int tried = 0, held = 0;
  for (const GraspCandidate& c : candidates) {
    tried += c.hold_unseen >= 0;
    held += c.hold_unseen == 1;
  }
  if (tried == 0) return "";
  char line[120];
  std::snprintf(line, sizeof line,
                "hold test with each hand where the unseen space stops it: %d of %d held (%.2f s)",
                held, tried, seconds);
  return line;
}

}  // namespace inhand
