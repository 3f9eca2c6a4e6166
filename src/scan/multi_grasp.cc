#include "inhand/scan/multi_grasp.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>

#include "inhand/core/enum_names.h"
#include "inhand/core/error.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/robot/collision.h"
#include "inhand/scan/checkpoint.h"
#include "inhand/scan/registration.h"
#include "inhand/scan/session.h"
#include "inhand/scan/table_top.h"
#include "inhand/sensor/render.h"

namespace inhand {

ViewPlannerOptions MultiGraspOptions::defaultRankingPlanner() {
  ViewPlannerOptions o;
  o.directions = 48;
  o.rolls = 4;
  o.fallback_ranges_m = {};
  o.ik_restarts = 0;
  o.quality.pixel_stride = 4;
  o.quality.near_hand_cell_m = 0.005;
  return o;
}

std::string MultiGraspOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (std::string p = grasp.validate(); !p.empty()) return "grasp." + p;
  if (std::string p = ranking.validate(); !p.empty()) return "grasp.ranking." + p;
  return {};
}

namespace {
using Clock = std::chrono::steady_clock;

void validate(const ScanOptions& options, const MultiGraspOptions& multi) {
  std::string problem = options.validate();
  if (problem.empty()) problem = multi.validate();
  if (!problem.empty()) throw Error("scan options: " + problem);
}

// The object lifted but not where the grasp `T_O_palm` says: the model registered to the lift's
// frame `d` (robot pixels `mask`, camera at T_B_C as tracked, the robot at q) from that grasp,
// and, where that is not borne out, from where the frame's points near the hand say it moved
// (heldObjectStarts: closing the fingers may push it centimetres); never where the object would
// still rest on the table. The grasp where it was found and the fraction of `points_O` the frame
// bears out there, when more than half (from the grasp) or 80 % (from the search); else nullopt.
std::optional<std::pair<Iso3, double>> refindInHand(
    ScanSession& session, const DepthImage& d, const std::vector<uint8_t>& mask,
    const JointVector& q, const Iso3& T_B_C, const Iso3& T_O_palm,
    const std::vector<Vec3>& points_O, const CameraIntrinsics& K,
    const std::function<void(const std::string&)>& log) {
  const RobotModel& m = session.robot();
  const Iso3 T_B_palm = m.tipPose(q);
  // How far the frame bears the grasp out; -1 where it would leave the object on the table (its
  // lowest point within 2 cm of the top, or half the lift if less: the search can find the
  // object where it still rests beside the hand) or put it into the hand (pointsInsideHand, more
  // than the grasp it starts from does).
  const double lifted = std::min(0.02, 0.5 * session.multiOptions().grasp.lift_m);
  const int insideAtStart = pointsInsideHand(m, q, T_O_palm, points_O);
  auto supportOf = [&](const Iso3& T_O_palm_found) {
    if (pointsInsideHand(m, q, T_O_palm_found, points_O) >
        insideAtStart + std::max<int>(3, int(points_O.size()) / 100))
      return -1.0;
    const Iso3 T_B_O = T_B_palm * T_O_palm_found.inverse();
    std::vector<Vec3> held_B;
    double lowest = std::numeric_limits<double>::infinity();
    for (const Vec3& p : points_O) {
      held_B.push_back(T_B_O * p);
      lowest = std::min(lowest, held_B.back().z());
    }
    if (lowest < m.table().topZ() + lifted) return -1.0;
    return depthSupport(d, T_B_C, K, mask, held_B);
  };
  TrackResult reg;
  std::optional<Iso3> found = session.registerHeldObject(d, mask, q, T_B_C, T_O_palm, &reg);
  double support = found ? supportOf(*found) : -1;
  std::string why = reg.reason;
  // A pose the search finds away from the grasp must explain most of the object's points: a thin
  // or flat object fits many poses near the hand half-way (an L-bracket of 6 mm plate was found
  // 9-10 cm from its grasp, 68 % borne out, 6 cm from where it was, and every frame of the grasp
  // was fused 16 mm off).
  double needed = 0.5;
  if (!(support > 0.5)) {
    needed = 0.8;
    why += found ? "" : "; from the points near the hand: no fit";
    std::vector<uint8_t> hidden = mask;
    markBelow(d, T_B_C, K, m.table().topZ() + 0.005, &hidden);
    const Iso3 T_B_O = T_B_palm * T_O_palm.inverse();
    for (const auto& [T, r] : session.registerObjectAt(
             d, hidden, T_B_C,
             heldObjectStarts(d, hidden, T_B_C, K, m.table().topZ(), T_B_O, points_O),
             /*in_hand=*/true)) {
      if (!T) continue;
      const Iso3 T_O_palm_found = T->inverse() * T_B_palm;
      const double s = supportOf(T_O_palm_found);
      if (s > support) {
        support = s;
        found = T_O_palm_found;
      }
    }
  }
  if (!found) {
    log("the object not found in the hand: " + why);
    return std::nullopt;
  }
  if (support < 0) {
    log("the object not found in the hand: what fits is still on the table or inside the hand");
    return std::nullopt;
  }
  char line[160];
  std::snprintf(line, sizeof line,
                "the object found in the hand %.1f mm from the planned grasp (%d %% borne out)",
                1000 * (found->translation() - T_O_palm.translation()).norm(),
                int(std::lround(100 * std::max(0.0, support))));
  if (!(support > needed)) {
    log(line + std::string(": too little to trust"));
    return std::nullopt;
  }
  log(line);
  return std::make_pair(*found, support);
}

// The object found on the table again after it was put down or fell: a frame aimed where it is
// believed to lie (T_B_O_guess), the largest cluster above the table near there
// (findObjectOnTable), and the model so far registered to the frame from the believed pose and
// from each of the model's 6 most probable resting orientations at 12 headings over the
// cluster; the registration whose pose the frame bears out most, if more than 60 %. Logged as
// moved from T_B_O_believed where given (a place looked at other than the belief).
struct Refound {
  std::optional<Iso3> T_B_O;
  double support = -1, rms_m = 0;
  std::string reason;  // why not found
};

// The model at a registration whose surface lies no farther than this from the belief's is
// where the object was believed to be (the registration slid along what the frame cannot tell).
constexpr double kSameSurfaceM = 0.002;

// Of the registrations (each with the support the frame gives it), the one nearest where the
// object was believed to lie among those within 2 % of the most borne out (a symmetric object
// fits turned poses as well: the belief decides between them); found if borne out over 60 %.
// When the frame bears out the belief itself as well (`believed_support` within 2 %) and the
// chosen registration puts the model's surface where the belief does (`gapFromBelief` ≤
// kSameSurfaceM), the object did not move (a registration also slides along what the frame
// cannot tell apart, such as a can's turn about its axis), and the belief, which the fused model
// was built in, stays. The support alone does not tell: points hidden behind what the camera
// sees do not count, so a belief centimetres off can be borne out by the few points it has in
// view.
Refound nearestOfTheBest(const std::vector<Refound>& fits, const Iso3& T_B_O_guess,
                         double believed_support,
                         const std::function<double(const Iso3&)>& gapFromBelief) {
  double most = -1;
  for (const Refound& f : fits) most = std::max(most, f.support);
  auto away = [&](const Iso3& T) {
    return (T.translation() - T_B_O_guess.translation()).norm() +
           0.1 * rotationBetween(T_B_O_guess, T);
  };
  const Refound* best = nullptr;
  for (const Refound& f : fits)
    if (f.support >= most - 0.02 && (!best || away(*f.T_B_O) < away(*best->T_B_O))) best = &f;
  Refound out;
  if (!best) return out;
  out.support = best->support;
  out.rms_m = best->rms_m;
  if (best->support > 0.6)
    out.T_B_O = believed_support >= most - 0.02 && gapFromBelief(*best->T_B_O) <= kSameSurfaceM
                    ? T_B_O_guess
                    : *best->T_B_O;
  return out;
}

Refound refindOnTable(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                      const Iso3& T_B_O_guess, const ScanOptions& options,
                      const std::function<void(const std::string&)>& log,
                      const Iso3* T_B_O_believed = nullptr) {
  const RobotModel& m = robot.model();
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  Refound out;
  // The arm out of the camera's way first: home, the hand as it is.
  const JointVector home = m.withArm(robot.joints(), m.arm(m.home()));
  if (!robot.joints().isApprox(home, 1e-9))
    robot.execute({robot.joints(), home}, [](const JointVector&) {});
  const TableTopOptions& to = session.multiOptions().table_top;
  const std::optional<Iso3> aim =
      m.camera().aimAt(T_B_O_guess.translation() + Vec3(0, 0, to.aim_height_m));
  std::optional<DepthImage> frame;
  if (aim) {
    sensor.setPose(*aim);
    frame = captureUsable(sensor, options.checks);
  }
  if (!frame) {
    out.reason = "no usable frame of the table";
    return out;
  }
  const DepthImage& d = *frame;
  const RobotOccluders scenes(m);
  const std::vector<uint8_t> mask =
      robotPixelMask(d, *aim, robot.joints(), scenes, sensor.camera(), options.t_hand_m,
                     options.carve_radius_px, /*with_table=*/false);
  const TableTopObject object =
      findObjectOnTable({d}, {mask}, *aim, K, T_B_O_guess, m, options, to, nullptr, {});
  if (object.problem == Termination::kObjectNotFound) {
    out.reason = "no object on the table near where it was";
    return out;
  }
  Vec3 centre_B = Vec3::Zero();
  for (const Vec3& p : object.points_O) centre_B += T_B_O_guess * p;
  centre_B /= double(std::max<size_t>(1, object.points_O.size()));
  // The robot's pixels and the table's (at most 5 mm above its top) pair with nothing.
  std::vector<uint8_t> hidden = mask;
  markBelow(d, *aim, K, m.table().topZ() + 0.005, &hidden);
  // Starts: where it is believed to lie; resting on the table over the cluster.
  const ObjectModel model = session.planningModel();
  std::vector<Iso3> starts{T_B_O_guess};
  for (const Iso3& T : restingStarts(model.mesh, centre_B, aim->translation(), m.table().topZ()))
    starts.push_back(T);
  const std::vector<Vec3> known_O = observedVertices(model);
  // The best: nearestOfTheBest.
  auto supportAt = [&](const Iso3& T) {
    std::vector<Vec3> at_B;
    for (const Vec3& p : known_O) at_B.push_back(T * p);
    return depthSupport(d, *aim, K, hidden, at_B);
  };
  std::vector<Refound> fits;
  for (const auto& [T, r] : session.registerObjectAt(d, hidden, *aim, starts))
    if (T) fits.push_back({*T, supportAt(*T), r.rms_m, ""});
  const TriangleDistanceIndex surface_O(model.mesh);
  out = nearestOfTheBest(fits, T_B_O_guess, supportAt(T_B_O_guess), [&](const Iso3& T) {
    return surfaceGap(surface_O, known_O, T_B_O_guess, T);
  });
  if (!out.T_B_O) {
    out.reason = "the model does not fit what the camera sees there";
    return out;
  }
  const Iso3& believed = T_B_O_believed ? *T_B_O_believed : T_B_O_guess;
  char line[200];
  std::snprintf(line, sizeof line,
                "the object found on the table %.1f mm and %.1f° from where it was believed to "
                "lie (%d %% borne out, residual %.2f mm)",
                1000 * (out.T_B_O->translation() - believed.translation()).norm(),
                180 / M_PI * rotationBetween(believed, *out.T_B_O),
                int(std::lround(100 * out.support)), 1000 * out.rms_m);
  log(line);
  return out;
}

// The rest of the table top, looked over once the guesses missed: a grid of places whose search
// circles (radius r, TableTopOptions::search_radius_m) cover the table's top, a cell's diagonal
// the circle's diameter, nearest `guesses[0]` first; places within r/2 of a guess left out (the
// guess looked there). An object that rolled or slid away after a put-down or a drop lies
// somewhere on the table; off the table it is lost.
std::vector<Iso3> tableSweep(const RobotModel& m, const std::vector<Iso3>& guesses, double r) {
  std::vector<Iso3> out;
  if (guesses.empty() || r <= 0) return out;
  const TableInfo& t = m.table();
  const double cell = r * std::sqrt(2.0);
  const int nx = std::max(1, int(std::ceil(t.size.x() / cell)));
  const int ny = std::max(1, int(std::ceil(t.size.y() / cell)));
  const Vec3 from = guesses[0].translation();
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j) {
      const Vec3 at(t.center_B.x() + t.size.x() * ((i + 0.5) / nx - 0.5),
                    t.center_B.y() + t.size.y() * ((j + 0.5) / ny - 0.5), from.z());
      bool looked = false;
      for (const Iso3& g : guesses)
        looked = looked || (g.translation() - at).head<2>().norm() < 0.5 * r;
      if (looked) continue;
      Iso3 T = guesses[0];
      T.translation() = at;
      out.push_back(T);
    }
  std::stable_sort(out.begin(), out.end(), [&](const Iso3& a, const Iso3& b) {
    return (a.translation() - from).norm() < (b.translation() - from).norm();
  });
  return out;
}

// The object looked for where it is believed to lie, then at each further guess while not
// found there (beneath where the hand held it: it may have fallen from the hand, or been knocked
// there by a pick-up that failed), then over the rest of the table (tableSweep), each miss
// logged.
Refound refindAt(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                 const std::vector<Iso3>& guesses, const ScanOptions& options,
                 const std::function<void(const std::string&)>& log) {
  Refound found;
  for (size_t k = 0; k < guesses.size() && !found.T_B_O; ++k) {
    found = refindOnTable(session, robot, sensor, guesses[k], options, log);
    if (!found.T_B_O)
      log("the object not found " + std::string(k == 0 ? "there" : "at that guess") + ": " +
          found.reason + "; looking elsewhere");
  }
  if (found.T_B_O || session.progress().stopRequested()) return found;
  const std::vector<Iso3> sweep =
      tableSweep(robot.model(), guesses, session.multiOptions().table_top.search_radius_m);
  log("looking over the rest of the table (" + std::to_string(sweep.size()) + " places)");
  for (const Iso3& at : sweep) {
    const Refound f = refindOnTable(session, robot, sensor, at, options, log, &guesses[0]);
    if (f.T_B_O) return f;
  }
  found.reason =
      "not where it was believed to lie nor anywhere else the camera looked on the table";
  return found;
}

// The rest pose T_B_O_rest moved beneath where the hand at q holds the object (T_O_palm), its
// centre (of `c_O`) under the held one's: where an object that fell from the hand is looked for.
Iso3 beneathHand(const RobotModel& m, const JointVector& q, const Iso3& T_O_palm,
                 const Iso3& T_B_O_rest, const Vec3& c_O) {
  const Iso3 T_B_O_held = m.tipPose(q) * T_O_palm.inverse();
  Vec3 shift = T_B_O_held * c_O - T_B_O_rest * c_O;
  shift.z() = 0;
  return Eigen::Translation3d(shift) * T_B_O_rest;
}

// Picks the object up with the first candidate (in order) that the robot
// closes on, lifts, and by what it then observes holds. Fingers all closed to their limit mean
// an empty hand. After the lift the camera looks at the hand: the object's points (`points_O`,
// what the scan knows of its surface) carried by the hand as gripped must be borne out by the
// depth frame (depthSupport > 1/2), and where it rested they must not be. Each failure lets go
// and tries the next. Records every attempt.
// tracking.in_hand: the grasp the lift's frame `d` shows (camera at *aim as aimed, at `tracked`
// as tracked by `liftTrack`; the robot's pixels `mask`), from the planned candidate `c` and the
// grasp as the hand closed on it (`achieved`).
Iso3 graspInHand(ScanSession& session, const RobotModel& m, const JointVector& q,
                 const DepthImage& d, const std::vector<uint8_t>& mask, const Iso3& aim,
                 const Iso3& tracked, const TrackResult& liftTrack, const GraspCandidate& c,
                 const Iso3& achieved, const std::vector<Vec3>& points_O,
                 const TrackingOptions& options, const std::function<void(const std::string&)>& log,
                 bool* registered) {
  // Where the object sits in the hand: the arm's error where it grasped moved it from
  // where the joints say. The palm's error that tracking sees in the lift's frame, as
  // joint offsets (armOffsetsFromPalmError), gives the palm's error at the pick (the palm
  // was that far off when it met the object, which has not moved since); then the model
  // is registered with the frame from there.
  const Iso3 T_C_reported = aim.inverse() * m.tipPose(q);
  // Only an error the frame shows beyond its own noise is carried (an exact arm's lift
  // frame alone would move the object a millimetre or two for the rest of the grasp).
  const double palmSignificance =
      correctionSignificance(liftTrack, T_C_reported, options.pair_information);
  const Iso3 palmError = palmSignificance > options.in_hand_significance
                             ? Iso3(T_C_reported.inverse() * (tracked.inverse() * m.tipPose(q)))
                             : Iso3::Identity();
  // The joint offsets that explain it, then the palm's error they give at the pick.
  const JointVector e = armOffsetsFromPalmError(m, q, palmError);
  const Iso3 pickError = m.tipPose(c.q_open).inverse() * m.tipPose(c.q_open + e);
  // achieved = planned · motion (the guarded move, in the palm frame): the error enters
  // before it.
  const Iso3 carried = c.T_O_palm * pickError * (c.T_O_palm.inverse() * achieved);
  Iso3 grasp = carried;
  TrackResult reg;
  if (const std::optional<Iso3> T = session.registerHeldObject(d, mask, q, tracked, carried, &reg))
    grasp = *T;
  // The hand's links are where the joints say: a registration that puts the object's measured
  // surface into them is wrong, however well it fits the frame (a lying soup can's partial model
  // slid 7 mm into the palm along its axis, 11 % of its points over 3 mm deep, where the joints
  // had it within 0.6 mm).
  const int inside = pointsInsideHand(m, q, grasp, points_O);
  const int insideCarried = pointsInsideHand(m, q, carried, points_O);
  if (reg.ok && inside > insideCarried + std::max<int>(3, int(points_O.size()) / 100)) {
    char why[160];
    std::snprintf(why, sizeof why, "it puts %d of %zu points inside the hand, against %d", inside,
                  points_O.size(), insideCarried);
    reg.ok = false;
    reg.reason = why;
    grasp = carried;
  }
  *registered = reg.ok;
  char line[240];
  std::snprintf(line, sizeof line,
                "the object in the hand: %.1f mm from where the joints put it by the arm's "
                "error (significance %.0f), %.1f mm more by the model ",
                1000 * (carried.translation() - achieved.translation()).norm(), palmSignificance,
                1000 * (grasp.translation() - carried.translation()).norm());
  log(line + (reg.ok ? std::string("(registered)") : "(not registered: " + reg.reason + ")"));
  return grasp;
}

// A frame of the object held (its points `held_B` where the hand holds it): the camera aimed at
// them, the frame's camera pose as tracked (nullopt: tracking refused the frame, `track` says
// why) and the robot's pixels (seen from the tracked pose, else from the aim). No frame: nothing.
struct HeldFrame {
  DepthImage d;
  Iso3 aim;
  std::optional<Iso3> tracked;
  TrackResult track;
  std::vector<uint8_t> mask;
};
std::optional<HeldFrame> frameOfTheHeld(ScanSession& session, RobotInterface& robot,
                                        DepthSensor& sensor, const std::vector<Vec3>& held_B,
                                        const Iso3& T_O_palm, const ScanOptions& options,
                                        const RobotOccluders& scenes) {
  Aabb heldBox;
  for (const Vec3& p : held_B) heldBox.extend(p);
  const std::optional<Iso3> aim = robot.model().camera().aimAt(heldBox.center());
  if (!aim) return std::nullopt;
  sensor.setPose(*aim);
  std::optional<DepthImage> frame = captureUsable(sensor, options.checks);
  if (!frame) return std::nullopt;
  HeldFrame f{std::move(*frame), *aim, std::nullopt, {}, {}};
  // The camera pose relative to where the hand really is (options.tracking; the pose as
  // reported without it): the held points and the robot's pixels are seen from there.
  f.tracked = session.trackedCameraPose(f.d, robot.joints(), f.aim, T_O_palm, &f.track);
  f.mask = robotPixelMask(f.d, f.tracked ? *f.tracked : f.aim, robot.joints(), scenes,
                          sensor.camera(), options.t_hand_m, options.carve_radius_px,
                          /*with_table=*/false);
  return f;
}

// The lift's frame `f` (taken for the grasp `*achieved`, whose points are `held_B`) tracked with
// the grasp `pushed` instead: where the frame bears the object's points out more there, the frame's
// tracking, robot pixels, grasp and points become those of `pushed` (only where the frame bears
// `*achieved` out at most 90 %, and `pushed` at least 5 points more and more of the points in
// number). Whether it was taken.
bool pushedIfBorneOut(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                      const Iso3& pushed, const std::vector<Vec3>& points_O,
                      const ScanOptions& options, const RobotOccluders& scenes,
                      const std::function<void(const std::string&)>& log, HeldFrame* f,
                      std::optional<Iso3>* achieved, std::vector<Vec3>* held_B) {
  const RobotModel& m = robot.model();
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  const JointVector q = robot.joints();
  const double planned = f->tracked ? depthSupport(f->d, *f->tracked, K, f->mask, *held_B) : -1;
  if (planned > 0.9) return false;  // the grasp as the hand achieved it is borne out
  TrackResult track;
  const std::optional<Iso3> tracked = session.trackedCameraPose(f->d, q, f->aim, pushed, &track);
  if (!tracked) return false;
  std::vector<uint8_t> mask =
      robotPixelMask(f->d, *tracked, q, scenes, sensor.camera(), options.t_hand_m,
                     options.carve_radius_px, /*with_table=*/false);
  const Iso3 T_B_O = m.tipPose(q) * pushed.inverse();
  std::vector<Vec3> at_B;
  for (const Vec3& p : points_O) at_B.push_back(T_B_O * p);
  const double support = depthSupport(f->d, *tracked, K, mask, at_B);
  if (!(support > planned + 0.05)) return false;  // not clearly more
  // A share counts only the points whose pixels show something other than the robot: a pose that
  // puts the points behind the hand or the object's surface has few left, and those may all fit
  // (the ring's grasp as achieved: 83 % of 646; one 11 mm off: 100 % of 260). So the pushed grasp
  // must also bear out more points, both seen from the camera where the arm reports it (each
  // grasp's own tracking leans towards it), with either's robot pixels hidden.
  std::vector<uint8_t> hidden = mask;
  if (f->mask.size() == hidden.size())
    for (size_t i = 0; i < hidden.size(); ++i) hidden[i] = hidden[i] || f->mask[i];
  const int here = depthSupportCounts(f->d, f->aim, K, hidden, *held_B).support;
  const int there = depthSupportCounts(f->d, f->aim, K, hidden, at_B).support;
  if (there <= here) return false;
  char line[240];
  std::snprintf(
      line, sizeof line,
      "the object where the hold test's close pushed it, %.1f mm from the grasp: %d %% "
      "borne out (%s there), %d points against %d",
      1000 * (pushed.translation() - (*achieved)->translation()).norm(),
      int(std::lround(100 * support)),
      planned < 0 ? "none" : (std::to_string(int(std::lround(100 * planned))) + " %").c_str(),
      there, here);
  log(line);
  *achieved = pushed;
  f->tracked = tracked;
  f->track = track;
  f->mask = std::move(mask);
  *held_B = std::move(at_B);
  return true;
}

// A fraction borne out as a percentage; "none in view" when negative.
std::string percent(double f) {
  return f < 0 ? std::string("none in view") : std::to_string(int(std::lround(100 * f))) + " %";
}

// After the lift: how much of the object's points `points_O` the lift's frame bears out where the
// grasp holds it (`*achieved`, moved to where the frame shows it in the hand) and where it rested
// (T_B_O_rest); -1 where none is in view. The grasp where the hold test's close left the model
// (closing the fingers may push the object centimetres) is taken instead of `*achieved` where
// the frame bears it out more (pushedIfBorneOut).
struct LiftCheck {
  double inHand = -1, onTable = -1;
  std::optional<HeldFrame> frame;  // the lift's frame
  Aabb heldBox;                    // the object's points where the frame shows it in the hand
  bool registered = false;         // the grasp registered with the lift's frame
  bool pushed = false;             // the grasp where the hold test's close pushed the model
  // Taken where the hold test's close pushed the model (a prediction good to millimetres) and
  // not registered with the lift's frame (too few of its points in view there): the grasp's
  // first frames are to register it (ScanSession::confirmGraspOnNextFrames). A grasp as the hand
  // achieved it is not: registering the model so far, which lacks the faces the camera sees in
  // the hand, pulls it towards them (the remote's grasp, right, moved 5.7 mm).
  bool toConfirm() const { return pushed && !registered; }
  // Points where it rested that the camera saw through (against) and that bore it out, in the
  // lift's frame or, where none of them was in view there, in a frame aimed at where it rested.
  SupportCounts restCounts;
  // None of the object's points in view where the hand holds it (the arm or the hand hides
  // them, or tracking refused the frame), and where it rested at least kGoneFromRest of them seen
  // through and under 10 % borne out: the fingers (which did not close on nothing) hold it out of
  // the camera's sight. Its first in-hand frames confirm it (a hand found empty there ends the
  // grasp as object_lost).
  static constexpr int kGoneFromRest = 100;
  bool heldOutOfSight() const {
    return inHand < 0 && restCounts.against >= kGoneFromRest &&
           restCounts.support < 0.1 * (restCounts.support + restCounts.against);
  }
};

// Where the object rested (its points `rest_B`) seen with the arm where it is: the camera aimed
// at them, the robot's pixels hidden. Nothing counted without a usable frame.
SupportCounts restPlaceSeen(RobotInterface& robot, DepthSensor& sensor,
                            const std::vector<Vec3>& rest_B, const ScanOptions& options,
                            const RobotOccluders& scenes) {
  if (rest_B.empty()) return {};
  Aabb box;
  for (const Vec3& p : rest_B) box.extend(p);
  const std::optional<Iso3> aim = robot.model().camera().aimAt(box.center());
  if (!aim) return {};
  sensor.setPose(*aim);
  const std::optional<DepthImage> d = captureUsable(sensor, options.checks);
  if (!d) return {};
  const std::vector<uint8_t> mask =
      robotPixelMask(*d, *aim, robot.joints(), scenes, sensor.camera(), options.t_hand_m,
                     options.carve_radius_px, /*with_table=*/false);
  return depthSupportCounts(*d, *aim, sensor.camera().intrinsics, mask, rest_B);
}
LiftCheck checkAfterLift(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                         const GraspCandidate& c, const Iso3& T_B_O_rest,
                         const std::vector<Vec3>& points_O, const ScanOptions& options,
                         const RobotOccluders& scenes,
                         const std::function<void(const std::string&)>& log,
                         std::optional<Iso3>* achieved) {
  const RobotModel& m = robot.model();
  // Where the hand holds the object now, and where it rested: which does the camera see?
  const Iso3 T_B_O_held = m.tipPose(robot.joints()) * (*achieved)->inverse();
  std::vector<Vec3> held_B, rest_B_points;
  // Where it rested, only points well above the table tell (the table itself is near the
  // others' depth).
  const double tableTop = m.table().topZ();
  for (const Vec3& p : points_O) {
    held_B.push_back(T_B_O_held * p);
    const Vec3 r = T_B_O_rest * p;
    if (r.z() > tableTop + 0.015) rest_B_points.push_back(r);
  }
  LiftCheck out;
  std::optional<HeldFrame> f =
      frameOfTheHeld(session, robot, sensor, held_B, **achieved, options, scenes);
  if (!f) return out;
  const DepthImage& d = f->d;
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  // Where the hold test's close left the model, carried onto the grasp the hand achieved.
  std::optional<Iso3> pushed;
  if (c.T_O_palm_closed && c.hold_close_m > 0.002)
    pushed = **achieved * c.T_O_palm.inverse() * *c.T_O_palm_closed;
  if (pushed)
    out.pushed = pushedIfBorneOut(session, robot, sensor, *pushed, points_O, options, scenes, log,
                                  &*f, achieved, &held_B);
  const std::optional<Iso3>& tracked = f->tracked;
  if (!tracked) log("tracking refused the lift's frame: " + f->track.reason);
  if (tracked && options.tracking.enabled && options.tracking.in_hand) {
    const JointVector q = robot.joints();
    *achieved = graspInHand(session, m, q, d, f->mask, f->aim, *tracked, f->track, c, **achieved,
                            points_O, options.tracking, log, &out.registered);
    const Iso3 T_B_O = m.tipPose(q) * (*achieved)->inverse();
    for (size_t k = 0; k < points_O.size(); ++k) held_B[k] = T_B_O * points_O[k];
  }
  if (tracked) out.inHand = depthSupport(d, *tracked, K, f->mask, held_B);
  // Where it rested, seen again with the camera aimed there where the lift's frame showed none
  // of it nor of the object in the hand.
  out.restCounts = depthSupportCounts(d, f->aim, K, f->mask, rest_B_points);
  if (out.inHand < 0 && out.restCounts.support + out.restCounts.against == 0)
    out.restCounts = restPlaceSeen(robot, sensor, rest_B_points, options, scenes);
  if (const int n = out.restCounts.support + out.restCounts.against; n > 0)
    out.onTable = double(out.restCounts.support) / n;
  // Not all where the grasp says, and not where it rested: closing the fingers may have
  // moved it in the hand. Registered from the grasp, kept where the frame bears out more.
  if (tracked && !(out.inHand > 0.9) && !(out.onTable > 0.5))
    if (const auto found = refindInHand(session, d, f->mask, robot.joints(), *tracked, **achieved,
                                        points_O, K, log);
        found && found->second > out.inHand) {
      *achieved = found->first;
      out.inHand = found->second;
      out.registered = true;
    }
  const Iso3 T_B_O = m.tipPose(robot.joints()) * (*achieved)->inverse();
  for (const Vec3& p : points_O) out.heldBox.extend(T_B_O * p);
  out.frame = std::move(f);
  return out;
}

// After the lift's check passed: the hand holds still (GraspOptions::settle_s) and the camera
// takes a second frame from where it took the lift's. The pixels that showed the object then
// (not the robot's, their points within 1 cm of the object's box in the hand, above the table)
// show it now at the same depth, within 3 mm and three times the sensor's noise for two frames,
// unless it moved in the hand (pixels at the lift frame's depth edges left out). More than
// settle_changed of them changed: it is sliding out of a grasp that does not hold (false). Pixels
// without depth in either frame do not count. No registration: the frames are compared as they are
// (a registration's own scatter is 1–2 mm, and degrees about a symmetric object's axis).
bool stayedInHand(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                  const LiftCheck& lift, const ScanOptions& options,
                  const std::function<void(const std::string&)>& log) {
  const GraspOptions& g = session.multiOptions().grasp;
  robot.holdStill(g.settle_s);
  if (!lift.frame) return true;
  const HeldFrame& f = *lift.frame;
  sensor.setPose(f.aim);
  const std::optional<DepthImage> again = captureUsable(sensor, options.checks);
  if (!again || again->width != f.d.width || again->height != f.d.height) {
    log("after holding still: no usable frame to look again; the lift's frame stands");
    return true;
  }
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  const Iso3 T_B_C = f.tracked ? *f.tracked : f.aim;
  Aabb box = lift.heldBox;
  box.min -= Vec3::Constant(0.01);
  box.max += Vec3::Constant(0.01);
  box.min.z() = std::max(box.min.z(), robot.model().table().topZ() + 0.01);
  // A pixel at a depth edge of the lift's frame (a neighbour 1 cm nearer or farther, or without
  // depth) mixes two surfaces and flips between them with the noise: not counted.
  auto edge = [&](int u, int v) {
    const float d = f.d.at(u, v);
    for (const auto& [du, dv] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      const int x = u + du, y = v + dv;
      if (x < 0 || y < 0 || x >= f.d.width || y >= f.d.height) return true;
      const float n = f.d.at(x, y);
      if (!(n > 0) || std::abs(n - d) > 0.01f) return true;
    }
    return false;
  };
  int object = 0, changed = 0;
  for (int v = 0; v < f.d.height; ++v)
    for (int u = 0; u < f.d.width; ++u) {
      const size_t i = size_t(v) * size_t(f.d.width) + size_t(u);
      const double d1 = f.d.depth_m[i], d2 = again->depth_m[i];
      if (f.mask[i] || !(d1 > 0) || !(d2 > 0) || edge(u, v)) continue;
      if (!box.contains(T_B_C * (K.rayZ1(u, v) * d1))) continue;
      ++object;
      const double tol = 0.003 + 3 * std::sqrt(2.0) * axialSigma(session.noise(), d1, 0);
      changed += std::abs(d2 - d1) > tol;
    }
  const double fraction = object > 0 ? double(changed) / object : 0.0;
  char line[200];
  std::snprintf(line, sizeof line,
                "after holding still %.1f s: %d of %d pixels of the object in the hand changed "
                "depth (%d %%)",
                g.settle_s, changed, object, int(std::lround(100 * fraction)));
  log(line);
  return !(fraction > g.settle_changed);
}

// The record of trying candidate c, the rank-th of its ranking (its outcome still to come).
PickAttempt attemptOf(const GraspCandidate& c, int rank, const RobotModel& m) {
  PickAttempt a;
  a.T_O_palm = c.T_O_palm;
  a.preshape = m.handJointValues(c.q_open);
  a.closed = m.handJointValues(c.q);
  a.rank = rank;
  a.pose = c.pose;
  a.hold_test = c.hold;
  a.hold_margin = c.hold_margin;
  a.hold_unseen = c.hold_unseen;
  a.hold_close_m = c.hold_close_m;
  a.hold_failure = c.hold_failure;
  a.palm_contact = c.palm_contact;
  a.epsilon = c.epsilon;
  a.pinch = c.pinch;
  return a;
}

// In-hand frames that try to register a grasp the lift's frame did not.
constexpr int kConfirmFrames = 10;

struct PickUp {
  std::optional<Iso3> achieved;
  std::optional<GraspCandidate> picked;  // a copy: the candidates it came from may be gone
  std::vector<PickAttempt> attempts;     // per candidate tried
  // After a failed attempt the object was found elsewhere on the table (the candidates, planned
  // where it was, no longer apply), or not found at all.
  std::optional<Iso3> moved_to;
  bool lost = false;
};
// The candidates in turn, best ranked first, each tried at most once; a candidate that repeats
// a failed pick-up (those of this grasp before, `earlier`, and this call's) only once every other
// has been tried. At most grasp.max_failed_pick_ups failures in all, `earlier` included.
PickUp pickAndVerify(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                     const Iso3& T_B_O_rest, const std::vector<Vec3>& points_O,
                     const std::vector<GraspCandidate>& candidates, const ScanOptions& options,
                     const std::function<void(const std::string&)>& log,
                     const std::vector<PickAttempt>& earlier = {}) {
  const RobotModel& m = robot.model();
  const RobotOccluders scenes(m);
  PickUp out;
  const int budget = session.multiOptions().grasp.max_failed_pick_ups;
  const int used = int(earlier.size());
  std::vector<bool> done(candidates.size(), false);
  auto nextRank = [&]() -> std::optional<size_t> {
    std::vector<PickAttempt> failed = earlier;
    failed.insert(failed.end(), out.attempts.begin(), out.attempts.end());
    std::optional<size_t> repeat;
    for (size_t k = 0; k < candidates.size(); ++k) {
      if (done[k]) continue;
      if (!repeatsAFailedPickUp(candidates[k].T_O_palm, failed)) return k;
      if (!repeat) repeat = k;
    }
    return repeat;
  };
  // After a failed attempt that touched the object: is it still where it rested?
  auto stillThere = [&](const Iso3& T_O_palm_tried) {
    const Iso3 beneath = beneathHand(m, robot.joints(), T_O_palm_tried, T_B_O_rest,
                                     session.planningModel().mesh.bounds().center());
    const Refound f = refindAt(session, robot, sensor, {T_B_O_rest, beneath}, options, log);
    if (!f.T_B_O) {
      log("the object not found on the table: " + f.reason);
      out.lost = true;
      return false;
    }
    const double moved = (f.T_B_O->translation() - T_B_O_rest.translation()).norm();
    const double turned = rotationBetween(T_B_O_rest, *f.T_B_O);
    if (moved < 0.005 && turned < 0.05) return true;
    out.moved_to = f.T_B_O;
    return false;
  };
  for (std::optional<size_t> next = nextRank(); next; next = nextRank()) {
    const size_t rank = *next;
    done[rank] = true;
    const GraspCandidate& c = candidates[rank];
    if (session.progress().stopRequested()) break;
    if (used + int(out.attempts.size()) >= budget) {
      log("no pick-up held after " + std::to_string(budget) +
          " attempts (grasp.max_failed_pick_ups); giving up on this grasp");
      break;
    }
    PickAttempt attempt = attemptOf(c, int(rank), m);
    auto record = [&](PickOutcome outcome, std::string evidence) {
      attempt.outcome = outcome;
      attempt.at_s = session.elapsedSeconds();
      attempt.evidence = std::move(evidence);
      out.attempts.push_back(attempt);
    };
    std::optional<Iso3> achieved = robot.pickUp(c.T_O_palm, c.q_open);
    if (!achieved) {
      record(PickOutcome::kNoContact, "the robot's pick-up met nothing there");
      log("pick-up failed (the hand met nothing there); trying the next candidate");
      continue;
    }
    if (fingersClosedOnNothing(m, robot.joints())) {
      robot.putDown();
      record(PickOutcome::kEmptyHand, "the fingers closed to their limits");
      log("the fingers closed on nothing; trying the next candidate");
      if (!stillThere(c.T_O_palm)) break;
      continue;
    }
    robot.execute({robot.joints(), m.withArm(robot.joints(), m.arm(c.q_lift))},
                  [](const JointVector&) {});
    const LiftCheck lift = checkAfterLift(session, robot, sensor, c, T_B_O_rest, points_O, options,
                                          scenes, log, &achieved);
    const double inHand = lift.inHand, onTable = lift.onTable;
    attempt.lift_in_hand = inHand;
    attempt.lift_on_table = onTable;
    const std::string seen = "the object's points borne out in the hand " + percent(inHand) +
                             ", where it rested " + percent(onTable);
    log("after the lift: " + seen);
    if (inHand > 0.5) attempt.shift_m = (achieved->translation() - c.T_O_palm.translation()).norm();
    // Held out of the camera's sight: no second look (none of its pixels to compare).
    const bool unseen = lift.heldOutOfSight();
    const std::string unseenWhy = " (" + std::to_string(lift.restCounts.against) +
                                  " of its points where it rested seen through): held out of "
                                  "the camera's sight; its first frames in the hand confirm it";
    if (unseen) log("after the lift: the object" + unseenWhy);
    const bool dropped = !unseen && (!(inHand > 0.5) || onTable > 0.5);
    if (dropped || (!unseen && session.multiOptions().grasp.settle_s > 0 &&
                    !stayedInHand(session, robot, sensor, lift, options, log))) {
      robot.putDown();
      record(dropped ? PickOutcome::kDropped : PickOutcome::kSlid,
             dropped ? "after the lift: " + seen
                     : "after holding still the object's pixels in the hand changed depth");
      log(std::string(dropped ? "the grasp did not hold"
                              : "the object is sliding out of the grasp") +
          "; trying the next candidate");
      // Not seen where it rested: where is it?
      if (!(onTable > 0.5) && !stillThere(*achieved)) break;
      continue;
    }
    record(PickOutcome::kPicked, "after the lift: " + seen + (unseen ? unseenWhy : ""));
    if ((unseen || lift.toConfirm()) && options.tracking.enabled && options.tracking.in_hand)
      session.confirmGraspOnNextFrames(kConfirmFrames);
    out.achieved = achieved;
    out.picked = c;
    break;
  }
  return out;
}

// Where to look for the object after a grasp's put-down: where it rested, then beneath where
// the hand was when a frame last showed the object in it (it may have fallen unnoticed during
// the last frames); lost from the hand during the views, beneath the hand first.
std::vector<Iso3> placesToLook(const ScanSession& session, const RobotInterface& robot,
                               const Iso3& T_B_O_rest, bool lost) {
  const Iso3 beneath =
      beneathHand(robot.model(), session.lastSeenHeld().value_or(robot.joints()),
                  session.graspPose(), T_B_O_rest, session.planningModel().mesh.bounds().center());
  return lost ? std::vector<Iso3>{beneath, T_B_O_rest} : std::vector<Iso3>{T_B_O_rest, beneath};
}

// A grasp's record once its views ended (at `at_s`, seconds since the session began): the model
// then (at the planning stride: a quarter of the triangles), its views, how they ended.
GraspRecord graspEnded(GraspRecord rec, const ScanResult& all, int views, Termination ended,
                       double at_s) {
  rec.views_ended_at_s = at_s;
  rec.model = all.planning_model;
  rec.views = views;
  rec.termination = ended;
  rec.hole_area_m2 = all.model.holeArea();
  rec.mean_entropy = all.model.meanEntropy();
  return rec;
}

// The next grasp's record from the plan and the pick-up that achieved it.
GraspRecord graspPicked(const GraspPlan& plan, const PickUp& pick,
                        const std::vector<PickAttempt>& attempts, int keep_ranked) {
  GraspRecord next;
  next.T_O_palm = *pick.achieved;
  next.candidates = int(plan.candidates.size());
  next.tried = plan.generation.tried;
  next.quality = pick.picked->quality;
  next.t_q = plan.t_q;
  next.model_area_m2 = plan.model_area_m2;
  next.epsilon = pick.picked->epsilon;
  next.generation_s = plan.generation.seconds;
  next.ranking_s = plan.ranking_s;
  next.attempts = attempts;
  for (const GraspCandidate& c : plan.candidates) {
    if (int(next.ranked.size()) >= keep_ranked) break;
    next.ranked.push_back({c.T_O_palm, c.q, c.quality, c.epsilon});
  }
  return next;
}

// After a put-down: the object found again where it came to rest (T_B_O_rest updated), then
// the best candidate the robot manages to pick up and hold. Picked up: `next` describes the new
// grasp and nullopt is returned; else how the scan ends.
std::optional<Termination> regrasp(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                                   Iso3& T_B_O_rest, const std::vector<Iso3>& look_at,
                                   MultiGraspResult& out, GraspRecord& next,
                                   const std::function<void(const std::string&)>& log) {
  const ScanProgress& progress = session.progress();
  const ScanResult& all = out.scan;
  // Where the object came to rest (it may have tipped, or fallen during the views): the model
  // registered to a frame of the table, before any re-grasp is planned, looked for at each of
  // `look_at` in turn.
  const Refound found = refindAt(session, robot, sensor, look_at, session.options(), log);
  if (!found.T_B_O) {
    log("the object not found on the table: " + found.reason);
    return Termination::kObjectLost;
  }
  T_B_O_rest = *found.T_B_O;
  out.refind_residuals_m.push_back(found.rms_m);
  // The best candidate the robot manages to pick up and hold (a real hand may fail where the
  // model said it would not; the next one above t_q is tried). Lifted, not fused. Found
  // elsewhere after a failed attempt: planned again where it lies.
  const std::vector<Vec3> known_O = observedVertices(all.model);
  GraspPlan plan;
  PickUp pick;
  std::vector<PickAttempt> attempts;
  for (;;) {
    plan = session.planGrasps(T_B_O_rest, robot.joints());
    if (plan.above_threshold == 0) break;
    const std::vector<GraspCandidate> usable(plan.candidates.begin(),
                                             plan.candidates.begin() + plan.above_threshold);
    pick = pickAndVerify(session, robot, sensor, T_B_O_rest, known_O, usable, session.options(),
                         log, attempts);
    attempts.insert(attempts.end(), pick.attempts.begin(), pick.attempts.end());
    if (pick.achieved || !pick.moved_to || progress.stopRequested()) break;
    T_B_O_rest = *pick.moved_to;
  }
  if (plan.above_threshold == 0) {
    out.unused_generation_s += plan.generation.seconds;
    out.unused_ranking_s += plan.ranking_s;
    // No re-grasp can be made (none stable, clear of the table and reachable): the model of
    // the grasps so far stands, as when every re-grasp's pick-up failed.
    const Termination t = session.summary().termination;
    return t == Termination::kNoReachableGrasp ? Termination::kRegraspFailed : t;
  }
  if (!pick.achieved) {
    out.failed_regrasp_attempts = attempts;
    out.unused_generation_s += plan.generation.seconds;
    out.unused_ranking_s += plan.ranking_s;
    return progress.stopRequested() ? Termination::kInterrupted
           : pick.lost              ? Termination::kObjectLost
                                    : Termination::kRegraspFailed;
  }
  next = graspPicked(plan, pick, attempts, session.multiOptions().keep_ranked);
  return std::nullopt;
}

// The grasp loop from grasp `first` on (the robot holds the object at T_O_palm0), over
// `session`; `next` describes that grasp, `box_O` where the object is believed to lie for the
// first grasp's initial trajectory (empty: unknown). `resumed`: the grasp has begun already (a
// checkpoint), its views go on.
void runGrasps(RobotInterface& robot, DepthSensor& sensor, ScanSession& session,
               const Iso3& T_O_palm0, const Iso3& T_B_O_start, GraspRecord next,
               MultiGraspResult& out, const Aabb& box_O, const TableAnchor* anchor = nullptr,
               int first = 0, bool resumed = false) {
  Iso3 T_B_O_rest = T_B_O_start;  // where it rests on the table (re-found after each put-down)
  const MultiGraspOptions& multi = session.multiOptions();
  const ScanProgress& progress = session.progress();
  auto log = [&](const std::string& s) { session.log(s); };
  ScanResult& all = out.scan;
  Iso3 T_O_palm = T_O_palm0;
  // A resumed grasp's record keeps the grasp it was picked up with (the session's may have moved
  // since with a slip or creep).
  if (!resumed) next.T_O_palm = T_O_palm;
  for (int g = first;; ++g) {
    auto checkpoint = [&] {
      if (progress.checkpoint)
        progress.checkpoint({&session, &out, g, &next, T_B_O_rest, box_O, anchor});
    };
    if (progress.stopRequested()) {
      all.termination = Termination::kInterrupted;
      break;
    }
    if (!(resumed && g == first)) {
      log("grasp " + std::to_string(g + 1));
      next.q = robot.joints();
      session.beginGrasp(T_O_palm, robot.joints(), g == 0 ? box_O : Aabb());
      checkpoint();
    } else {
      log("grasp " + std::to_string(g + 1) + ", resumed after " +
          std::to_string(session.views().size()) + " views");
    }
    const std::vector<int>& viewGrasps = session.viewGrasps();  // the views of earlier grasps
    const auto viewsBefore = std::count_if(viewGrasps.begin(), viewGrasps.end(),
                                           [&](int vg) { return vg < session.graspIndex(); });
    const Termination ended = runGraspViews(session, robot, sensor, checkpoint);
    all.model = session.model();
    all.planning_model = session.planningModel();
    if (ended == Termination::kInterrupted) {
      all.termination = ended;
      break;
    }
    out.grasps.push_back(graspEnded(next, all, int(session.views().size() - viewsBefore), ended,
                                    session.elapsedSeconds()));
    char line[200];
    const GraspRecord& rec = out.grasps.back();
    std::snprintf(line, sizeof(line),
                  "grasp %d: %d views (%s), unknown area %.4f m², mean entropy %.3f", g + 1,
                  rec.views, terminationName(rec.termination).c_str(), rec.hole_area_m2,
                  rec.mean_entropy);
    log(line);
    if (ended == Termination::kNoReachableView && g == 0) {
      all.termination = Termination::kNoReachableView;
      break;
    }
    if (g + 1 >= multi.max_grasps) {
      // One grasp only: the scan ends as that grasp's views did.
      all.termination = multi.max_grasps == 1 ? ended : Termination::kMaxGrasps;
      break;
    }
    const std::vector<Iso3> lookAt =
        placesToLook(session, robot, T_B_O_rest, ended == Termination::kObjectLost);
    // Put down, then candidates on the model so far, ranked by eq. 9 with the hand there.
    if (!robot.putDown()) {
      all.termination = Termination::kRegraspUnsupported;
      break;
    }
    session.endGrasp();
    if (const std::optional<Termination> end =
            regrasp(session, robot, sensor, T_B_O_rest, lookAt, out, next, log)) {
      all.termination = *end;
      break;
    }
    T_O_palm = next.T_O_palm;
  }
  session.finish(all.termination);
  const ScanSession::Summary sum = session.summary();
  all.views = session.views();
  sum.copyTo(&all);
}
}  // namespace

namespace {
Json jointsByName(const std::vector<std::pair<std::string, double>>& joints) {
  Json out = Json::object();
  for (const auto& [name, value] : joints) out[name] = value;
  return out;
}
std::vector<std::pair<std::string, double>> jointsFromJson(const Json& j) {
  std::vector<std::pair<std::string, double>> out;
  for (const auto& [name, value] : j.items()) out.emplace_back(name, value.get<double>());
  return out;
}
}  // namespace

Json attemptsJson(const std::vector<PickAttempt>& attempts) {
  Json out = Json::array();
  for (const PickAttempt& a : attempts) {
    Json& e = out.emplace_back(
        Json{{"outcome", pickOutcomeName(a.outcome)},
             {"rank", a.rank},
             {"pose", a.pose},
             {"hold_test", a.hold_test < 0 ? Json() : Json(a.hold_test == 1)},
             {"hold_margin", a.hold_margin < 0 ? Json() : Json(a.hold_margin == 1)},
             {"hold_unseen", a.hold_unseen < 0 ? Json() : Json(a.hold_unseen == 1)},
             {"hold_close_push_mm", a.hold_close_m < 0 ? Json() : Json(1000 * a.hold_close_m)},
             {"hold_failure", a.hold_test == 0 ? Json(holdFailureName(a.hold_failure)) : Json()},
             {"kind", a.palm_contact ? "enveloping" : "fingertips"},
             {"pinch", a.pinch},
             {"epsilon", a.epsilon},
             {"shift_in_hand_mm", a.shift_m < 0 ? Json() : Json(1000 * a.shift_m)},
             {"at_s", a.at_s < 0 ? Json() : Json(a.at_s)},
             {"lift_in_hand", a.lift_in_hand < 0 ? Json() : Json(a.lift_in_hand)},
             {"lift_on_table", a.lift_on_table < 0 ? Json() : Json(a.lift_on_table)},
             {"evidence", a.evidence}});
    if (a.T_O_palm) {
      e["T_O_palm"] = isoJson(*a.T_O_palm);
      e["preshape"] = jointsByName(a.preshape);
      e["closed"] = jointsByName(a.closed);
    }
  }
  return out;
}

std::vector<PickAttempt> attemptsFrom(const Json& j) {
  if (!j.is_array()) throw Error("pick-up attempts: not a list");
  std::vector<PickAttempt> out;
  auto outcome = [](const Json& name) {
    PickOutcome o;
    if (!parsePickOutcome(name.get<std::string>(), &o))
      throw Error("pick-up attempts: unknown outcome \"" + name.get<std::string>() + "\"");
    return o;
  };
  for (const Json& e : j) {
    PickAttempt a;
    if (e.is_string()) {
      a.outcome = outcome(e);
    } else {
      a.outcome = outcome(e.at("outcome"));
      a.rank = e.at("rank").get<int>();
      a.pose = e.at("pose").get<int>();
      a.hold_test = e.at("hold_test").is_null() ? -1 : int(e.at("hold_test").get<bool>());
      const Json margin = e.value("hold_margin", Json());  // absent before the margin
      a.hold_margin = margin.is_null() ? -1 : int(margin.get<bool>());
      const Json unseen = e.value("hold_unseen", Json());  // absent before the unseen check
      a.hold_unseen = unseen.is_null() ? -1 : int(unseen.get<bool>());
      const Json push = e.value("hold_close_push_mm", Json());  // absent before it was recorded
      a.hold_close_m = push.is_number() ? push.get<double>() / 1000 : -1;
      const Json failure = e.value("hold_failure", Json());  // absent before it was recorded
      if (failure.is_string() && !parseHoldFailure(failure.get<std::string>(), &a.hold_failure))
        throw Error("pick-up attempts: unknown hold_failure \"" + failure.get<std::string>() +
                    "\"");
      a.palm_contact = e.at("kind").get<std::string>() == "enveloping";
      a.pinch = e.value("pinch", false);  // absent before it was recorded
      a.epsilon = e.at("epsilon").get<double>();
      a.shift_m =
          e.at("shift_in_hand_mm").is_null() ? -1.0 : e.at("shift_in_hand_mm").get<double>() / 1000;
      // Absent before they were recorded.
      auto orNone = [&](const char* key) {
        const Json v = e.value(key, Json());
        return v.is_number() ? v.get<double>() : -1.0;
      };
      a.at_s = orNone("at_s");
      a.lift_in_hand = orNone("lift_in_hand");
      a.lift_on_table = orNone("lift_on_table");
      a.evidence = e.value("evidence", std::string());
      if (e.contains("T_O_palm")) {  // absent before grasps were recorded with their poses
        a.T_O_palm = isoFrom(e.at("T_O_palm"));
        a.preshape = jointsFromJson(e.at("preshape"));
        a.closed = jointsFromJson(e.at("closed"));
      }
    }
    out.push_back(a);
  }
  return out;
}

namespace {
const EnumNames<PickOutcome, 5> kPickOutcomes = {{PickOutcome::kPicked, "picked"},
                                                 {PickOutcome::kNoContact, "no_contact"},
                                                 {PickOutcome::kEmptyHand, "empty_hand"},
                                                 {PickOutcome::kDropped, "dropped"},
                                                 {PickOutcome::kSlid, "slid"}};
}  // namespace

const char* pickOutcomeName(PickOutcome o) { return enumName(kPickOutcomes, o); }
bool parsePickOutcome(const std::string& name, PickOutcome* out) {
  return enumFromName(kPickOutcomes, name, out);
}

int countOutcome(const std::vector<PickAttempt>& attempts, PickOutcome outcome) {
  return int(std::count_if(attempts.begin(), attempts.end(),
                           [&](const PickAttempt& a) { return a.outcome == outcome; }));
}

std::string TableTopOptions::validate() const { return checkOptionRanges(*this); }

MultiGraspResult scanMultiGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm0,
                                const Vec3& centre_O, const Iso3& T_B_O_rest,
                                const ScanOptions& options, const MultiGraspOptions& multi,
                                const NoiseModelOptions& noise, const ScanProgress& progress) {
  const auto t0 = Clock::now();
  ScanSession session(robot.model(), sensor.camera(), noise, options, multi, centre_O);
  session.setProgress(progress);
  MultiGraspResult out;
  runGrasps(robot, sensor, session, T_O_palm0, T_B_O_rest, GraspRecord{}, out, Aabb());
  out.scan.total_s = std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

namespace {
// The table-top stage's frames of the object where it rests (the camera at T_B_C, the robot at
// q): the usable depth frames, each with its robot pixels (they only carve) and its colour.
struct TableFrames {
  std::vector<DepthImage> depth;
  std::vector<std::vector<uint8_t>> robotMask;
  std::vector<RgbImage> colour;
};
TableFrames captureOnTable(DepthSensor& sensor, const RobotModel& m, const Iso3& T_B_C,
                           const JointVector& q, const ScanOptions& options, int frames,
                           const std::function<void(const std::string&)>& log) {
  const RobotOccluders scenes(m);
  TableFrames out;
  for (int f = 0; f < frames; ++f) {
    std::optional<DepthImage> d = captureUsable(sensor, options.checks);
    if (!d) {
      log("table top: no usable depth frame from the sensor");
      continue;
    }
    out.depth.push_back(std::move(*d));
    out.colour.push_back(sensor.camera().colour.enabled ? sensor.captureColour() : RgbImage());
    out.robotMask.push_back(robotPixelMask(out.depth.back(), T_B_C, q, scenes, sensor.camera(),
                                           options.t_hand_m, options.carve_radius_px,
                                           /*with_table=*/false));
  }
  return out;
}

// The first grasp's record as the pick-up from the table left it (candidate `picked`).
GraspRecord firstGraspRecord(const GraspCandidate& picked, const TableTopRecord& tt) {
  GraspRecord rec;
  rec.epsilon = picked.epsilon;
  rec.attempts = tt.attempts;
  rec.candidates = tt.reachable;
  rec.tried = tt.tried;
  rec.generation_s = tt.seconds;
  return rec;
}

// The first frame as the model's anchor: the robot's pixels and the table's (at most 5 mm above
// its top) pair with nothing.
TableAnchor tableAnchor(const TableFrames& table, const Iso3& T_B_C, const CameraIntrinsics& K,
                        const Iso3& T_B_O, double table_top_z) {
  TableAnchor a{table.depth[0], table.robotMask[0], T_B_C, T_B_O};
  markBelow(a.depth, T_B_C, K, table_top_z + 0.005, &a.hidden);
  return a;
}

// The frames fused (the camera at T_B_C, the object at T_B_O): table pixels (on or below the
// plane table_O, up to above_table_m over it) and robot pixels only carve.
void fuseOnTable(ScanSession& session, TableFrames& table, const JointVector& q, const Iso3& T_B_C,
                 const Iso3& T_B_O, const Plane& table_O, double above_table_m) {
  const CameraIntrinsics& K = session.camera().intrinsics;
  const Iso3 T_O_C = T_B_O.inverse() * T_B_C;
  for (size_t f = 0; f < table.depth.size(); ++f) {
    std::vector<uint8_t> carve = tablePixels(table.depth[f], T_O_C, K, table_O, above_table_m);
    for (size_t i = 0; i < carve.size(); ++i) carve[i] |= table.robotMask[f][i];
    session.setColourOfNextFrame(std::move(table.colour[f]));
    session.addFrameOfObjectAt(table.depth[f], q, T_B_C, T_B_O, &carve,
                               /*carve_includes_robot=*/true);
  }
}

// The first grasp's candidate counts into the table-top record; the line that logs them.
std::string recordFirstGrasps(const GraspGeneration& first, TableTopRecord* tt) {
  tt->tried = first.tried;
  tt->poses = first.poses;
  tt->touching = first.touching;
  tt->stable = first.stable;
  tt->table_free = first.table_free;
  tt->reachable = int(first.candidates.size());
  char line[200];
  std::snprintf(line, sizeof(line),
                "first grasp: %d poses, %d touching, %d stable, %d clear of the table, %d "
                "reachable (%.2f s)",
                tt->tried, tt->touching, tt->stable, tt->table_free, tt->reachable, first.seconds);
  return line;
}

// The first pick-up from the table, the candidates in turn (their attempts into tt). Found
// elsewhere after a failed attempt: candidates planned where it lies now (the table plane in
// its frame moved with it; T_B_O_now follows it), the attempts left tried on them.
PickUp pickFromTable(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                     const TableTopObject& object, const GraspGeneration& first,
                     const std::vector<Vec3>& seen_O, const ScanOptions& options, Iso3& T_B_O_now,
                     TableTopRecord* tt, const std::function<void(const std::string&)>& log) {
  PickUp pick =
      pickAndVerify(session, robot, sensor, T_B_O_now, seen_O, first.candidates, options, log);
  tt->attempts = pick.attempts;
  TableTopObject there = object;
  while (!pick.achieved && pick.moved_to && !session.progress().stopRequested()) {
    const Vec3 n_B = T_B_O_now.linear() * there.table_O.n;
    const Vec3 on_B = T_B_O_now * (-there.table_O.d * there.table_O.n);
    T_B_O_now = *pick.moved_to;
    there.table_O.n = T_B_O_now.linear().transpose() * n_B;
    there.table_O.d = -there.table_O.n.dot(T_B_O_now.inverse() * on_B);
    const GraspGeneration again = firstGrasps(session, there, T_B_O_now, robot.joints());
    log("grasp candidates where it lies now: " + std::to_string(again.candidates.size()));
    if (again.candidates.empty()) break;
    pick = pickAndVerify(session, robot, sensor, T_B_O_now, seen_O, again.candidates, options, log,
                         tt->attempts);
    tt->attempts.insert(tt->attempts.end(), pick.attempts.begin(), pick.attempts.end());
  }
  return pick;
}
}  // namespace

bool repeatsAFailedPickUp(const Iso3& T_O_palm, const std::vector<PickAttempt>& attempts) {
  for (const PickAttempt& a : attempts)
    if (a.outcome != PickOutcome::kPicked && a.T_O_palm &&
        (a.T_O_palm->translation() - T_O_palm.translation()).norm() < 0.01 &&
        rotationBetween(*a.T_O_palm, T_O_palm) < 15 * M_PI / 180)
      return true;
  return false;
}

MultiGraspResult scanFromTable(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_B_O_rest,
                               const ScanOptions& options, const MultiGraspOptions& multi,
                               const NoiseModelOptions& noise, const ScanProgress& progress) {
  const auto t0 = Clock::now();
  validate(options, multi);
  auto log = [&](const std::string& s) {
    if (progress.log) progress.log(s);
  };
  const RobotModel& m = robot.model();
  const TableTopOptions& to = multi.table_top;
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  MultiGraspResult out;
  out.table_top = TableTopRecord{};
  TableTopRecord& tt = *out.table_top;
  ScanResult& all = out.scan;
  auto finish = [&](Termination termination) {
    all.termination = termination;
    all.total_s = std::chrono::duration<double>(Clock::now() - t0).count();
    tt.seconds = tt.seconds > 0 ? tt.seconds : all.total_s;
    log("table top: " + terminationName(termination));
    return out;
  };

  // Frames of the object where it rests, the robot as it stands (its own pixels only carve).
  const std::optional<Iso3> aim =
      m.camera().aimAt(T_B_O_rest.translation() + Vec3(0, 0, to.aim_height_m));
  if (!aim) return finish(Termination::kObjectOutOfView);
  sensor.setPose(*aim);
  const JointVector q = robot.joints();
  TableFrames table = captureOnTable(sensor, m, *aim, q, options, to.frames, log);
  if (progress.stopRequested()) return finish(Termination::kInterrupted);
  const TableTopObject object = findObjectOnTable(table.depth, table.robotMask, *aim, K, T_B_O_rest,
                                                  m, options, to, &tt, log);
  if (object.problem != Termination::kRunning) return finish(object.problem);  // nothing fused

  // The volume fitted to the object, the frames fused into it: table pixels (on or below the
  // plane) and robot pixels only carve.
  const ScanOptions fitted = fitScanVolume(options, object);
  tt.volume_size_m = fitted.volume_size_m;
  tt.voxel_m = fitted.voxel_m;
  ScanSession session(m, sensor.camera(), noise, fitted, multi, object.centre_O);
  session.setProgress(progress);
  const std::optional<TableAnchor> anchor =
      to.reanchor ? std::optional(tableAnchor(table, *aim, K, T_B_O_rest, m.table().topZ()))
                  : std::nullopt;
  fuseOnTable(session, table, q, *aim, T_B_O_rest, object.table_O, to.above_table_m);
  all.frames = session.summary().frames;
  all.fusion_s = session.summary().fusion_s;

  // The first grasp: candidates on what the camera saw, the robot picks the object up with the
  // first that holds.
  const GraspGeneration first = firstGrasps(session, object, T_B_O_rest, robot.joints());
  log(recordFirstGrasps(first, &tt));
  tt.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  if (first.candidates.empty() || progress.stopRequested()) {
    all.model = session.model();
    return finish(progress.stopRequested() ? Termination::kInterrupted
                  : tt.stable == 0         ? Termination::kNoStableGrasp
                                           : Termination::kNoReachableGrasp);
  }
  std::vector<Vec3> seen_O;
  for (size_t k = 0; k < object.points_O.size(); k += 5) seen_O.push_back(object.points_O[k]);
  Iso3 T_B_O_now = T_B_O_rest;
  const PickUp pick =
      pickFromTable(session, robot, sensor, object, first, seen_O, options, T_B_O_now, &tt, log);
  if (!pick.achieved) {
    all.model = session.model();
    return finish(progress.stopRequested() ? Termination::kInterrupted
                                           : Termination::kPickUpFailed);
  }
  runGrasps(robot, sensor, session, *pick.achieved, T_B_O_now, firstGraspRecord(*pick.picked, tt),
            out, object.box_O, anchor ? &*anchor : nullptr);
  if (anchor) reanchorModel(session, *anchor, to.reanchor_gap_m, &out);
  all.total_s = std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

void reanchorModel(ScanSession& session, const TableAnchor& a, double gap_m,
                   MultiGraspResult* out) {
  ObjectModel& model = out->scan.model;
  if (!out->table_top || model.mesh.empty() || session.progress().stopRequested()) return;
  TableTopRecord::Reanchor& rec = out->table_top->reanchor;
  rec = TableTopRecord::Reanchor{};
  rec.tried = true;
  const auto fit = session.registerObjectAt(a.depth, a.hidden, a.T_B_C, {a.T_B_O}).front();
  if (!fit.first) {
    rec.reason = fit.second.reason;
    session.log("the model not aligned again with the table-top frame: " + rec.reason);
    return;
  }
  rec.found = true;
  const Iso3 fix = a.T_B_O.inverse() * *fit.first;  // frame O as the frame shows it
  rec.shift_m = fix.translation().norm();
  rec.turn_rad = rotationBetween(a.T_B_O, *fit.first);
  rec.gap_m =
      surfaceGap(TriangleDistanceIndex(model.mesh), observedVertices(model), a.T_B_O, *fit.first);
  rec.applied = rec.gap_m > gap_m;
  if (rec.applied)
    for (Vec3f& v : model.mesh.vertices) v = (fix * v.cast<double>()).cast<float>();
  char line[240];
  std::snprintf(line, sizeof line,
                "the model aligned again with the table-top frame: its surface %.2f mm off on "
                "average (%.2f mm, %.2f°); %s",
                1000 * rec.gap_m, 1000 * rec.shift_m, 180 / M_PI * rec.turn_rad,
                rec.applied ? "moved there" : "kept where it was");
  session.log(line);
}

MultiGraspResult resumeScan(RobotInterface& robot, DepthSensor& sensor, LoadedCheckpoint c,
                            const ScanProgress& progress) {
  const auto t0 = Clock::now();
  if (!c.session) throw Error("resumeScan: the checkpoint has no session");
  ScanSession& session = *c.session;
  session.setProgress(progress);
  MultiGraspResult out = std::move(c.sofar);
  const double before = out.scan.total_s;
  runGrasps(robot, sensor, session, session.graspPose(), c.T_B_O_rest, c.current, out,
            c.object_box_O, c.anchor ? &*c.anchor : nullptr, c.grasp, /*resumed=*/true);
  if (c.anchor)
    reanchorModel(session, *c.anchor, session.multiOptions().table_top.reanchor_gap_m, &out);
  out.scan.total_s = before + std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

}  // namespace inhand
