#include "inhand/scan/regrasp.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/grasp/hold_test.h"
#include "inhand/robot/robot_scenes.h"
#include "inhand/scan/registration.h"
#include "inhand/scan/table_top.h"

namespace inhand {

namespace {
using Clock = std::chrono::steady_clock;
double secondsFrom(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// How far a frame bears out the model at T_B_O where it faces the camera: of the points facing it
// (`surface_O`, outward normals) in view on pixels that measured something and are not hidden,
// and not behind the model's own nearer surface, the fraction measured within 1 cm of the
// point's depth. Unlike depthSupport, a facing point
// that the frame shows something in front of counts against: a model pushed behind what the
// camera sees (into the object, where every point is "occluded") is not borne out. -1: none.
double facingSupport(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K,
                     const std::vector<uint8_t>& hidden, const std::vector<SurfacePoint>& surface_O,
                     const Iso3& T_B_O) {
  const Iso3 T_C_O = T_B_C.inverse() * T_B_O;
  // The facing points in view, and the model's own nearest depth per 4 × 4 pixel cell: a facing
  // point more than 1 cm behind it is hidden by the model itself (a mug's handle).
  struct Seen {
    size_t pixel, cell;
    double z;
  };
  std::vector<Seen> seen;
  const int cw = (d.width + 3) / 4, ch = (d.height + 3) / 4;
  std::vector<double> nearest(size_t(cw) * size_t(ch), std::numeric_limits<double>::infinity());
  for (const SurfacePoint& s : surface_O) {
    const Vec3 p = T_C_O * s.p;
    if (p.z() <= 0.1 || (T_C_O.linear() * s.n).dot(p) >= 0) continue;  // facing away
    const Vec2 uv = K.project(p);
    const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
    if (u < 0 || v < 0 || u >= d.width || v >= d.height) continue;
    const size_t cell = size_t(v / 4) * size_t(cw) + size_t(u / 4);
    nearest[cell] = std::min(nearest[cell], p.z());
    seen.push_back({size_t(v) * size_t(d.width) + size_t(u), cell, p.z()});
  }
  int support = 0, against = 0;
  for (const Seen& s : seen) {
    const float z = d.depth_m[s.pixel];
    if (!(z > 0) || hidden[s.pixel] || s.z > nearest[s.cell] + 0.01) continue;
    if (std::abs(z - s.z) < 0.01)
      ++support;
    else
      ++against;
  }
  return support + against == 0 ? -1.0 : double(support) / (support + against);
}

// T_B_O, then the poses that put a symmetric object's surface where T_B_O puts it (a can on its
// side rolled, a box turned over): the model in each of its 4 most probable resting orientations
// (stablePoses) at headings every 5° about the vertical, its surface's centroid where T_B_O puts
// it, whose surface lies within 1.5 mm of the model at T_B_O on average (500 points), each brought
// onto it by 10 rounds of point-to-point ICP (nearest points, Umeyama's motion); each more than
// 10° from those before, at most 8, the nearest first.
std::vector<Iso3> turnsAsGood(const TriangleMesh& mesh, const Iso3& T_B_O) {
  std::vector<Iso3> out{T_B_O};
  std::vector<StablePose> rests;
  try {
    rests = stablePoses(mesh);
  } catch (const Error&) {
    return out;
  }
  const std::vector<Vec3> points = sampleSurfaceUniform(mesh, 500, 11);
  if (points.empty()) return out;
  const TriangleDistanceIndex index(mesh);
  Vec3 c = Vec3::Zero();
  for (const Vec3& p : points) c += p;
  c /= double(points.size());
  const Vec3 at = T_B_O * c;
  // The mean distance of the points moved by `moved` (frame O to frame O) from the surface.
  auto meanDistance = [&](const Iso3& moved) {
    double sum = 0;
    for (size_t k = 0; k < points.size(); ++k) {
      sum += index.distance(moved * points[k], 0.01);
      if (k == 99 && sum > 100 * 0.003) return 1.0;  // most turns are told apart here
    }
    return sum / double(points.size());
  };
  const size_t turns = std::min<size_t>(rests.size(), 4) * 72;
  std::vector<std::pair<double, Iso3>> all(turns, {1.0, Iso3::Identity()});
  parallelFor(0, int(turns), [&](int i) {
    Iso3 T = Iso3::Identity();
    T.linear() =
        Eigen::AngleAxisd((i % 72) * M_PI / 36, Vec3::UnitZ()) * rests[size_t(i / 72)].R_B_O;
    T.translation() = at - T.linear() * c;
    all[size_t(i)] = {meanDistance(T_B_O.inverse() * T), T};
  });
  std::vector<std::pair<double, Iso3>> near;
  for (const auto& a : all)
    if (a.first <= 0.0015) near.push_back(a);
  std::stable_sort(near.begin(), near.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& candidate : near) {
    if (out.size() >= 9) break;
    Iso3 T = candidate.second;
    // Brought onto the surface at T_B_O: the points at T paired with their nearest on it.
    for (int round = 0; round < 10; ++round) {
      const Iso3 moved = T_B_O.inverse() * T;
      Eigen::Matrix3Xd src(3, long(points.size())), dst(3, long(points.size()));
      for (size_t k = 0; k < points.size(); ++k) {
        int tri = -1;
        Vec3 q;
        index.nearest(moved * points[k], &tri, &q);
        src.col(long(k)) = T * points[k];
        dst.col(long(k)) = T_B_O * q;
      }
      const Eigen::Matrix4d U = Eigen::umeyama(src, dst, false);
      Iso3 D = Iso3::Identity();
      D.linear() = U.block<3, 3>(0, 0);
      D.translation() = U.block<3, 1>(0, 3);
      T = D * T;
    }
    const bool other = std::all_of(out.begin(), out.end(), [&](const Iso3& U) {
      return rotationBetween(U, T) > 10 * M_PI / 180;
    });
    if (other) out.push_back(T);
  }
  return out;
}

// One frame of the table aimed over look_at_B (the arm at home): the robot's pixels, the object's
// points (the largest cluster above the table near there, findObjectOnTable) and the frame with
// the table (its pixels at most 5 mm above its top) made no return for the registration: the
// model is drawn to the object's pixels and away from the table's, and pairs with neither.
struct TableFrame {
  DepthImage depth, objectOnly;
  Iso3 aim = Iso3::Identity();
  std::vector<uint8_t> robotMask;
  std::vector<Vec3> object_B;  // the object's points
};
std::optional<TableFrame> frameOfTable(RobotInterface& robot, DepthSensor& sensor,
                                       const Vec3& look_at_B, const RegraspOptions& o,
                                       const std::function<void(const std::string&)>& log) {
  const RobotModel& m = robot.model();
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  const double top = m.table().topZ();
  const Iso3 guess(Eigen::Translation3d(look_at_B.x(), look_at_B.y(), top));
  const std::optional<Iso3> aim =
      m.camera().aimAt(guess.translation() + Vec3(0, 0, o.table_top.aim_height_m));
  std::optional<DepthImage> frame;
  if (aim) {
    sensor.setPose(*aim);
    frame = captureUsable(sensor, o.scan.checks);
  }
  if (!frame) {
    log("no usable frame of the table");
    return std::nullopt;
  }
  TableFrame f{*frame, *frame, *aim, {}, {}};
  f.robotMask = robotPixelMask(f.depth, f.aim, robot.joints(), RobotOccluders(m), sensor.camera(),
                               o.scan.t_hand_m, o.scan.carve_radius_px, /*with_table=*/false);
  const TableTopObject object = findObjectOnTable({f.depth}, {f.robotMask}, f.aim, K, guess, m,
                                                  o.scan, o.table_top, nullptr, {});
  if (object.problem == Termination::kObjectNotFound) {
    log("no object on the table there");
    return std::nullopt;
  }
  for (const Vec3& p : object.points_O) f.object_B.push_back(guess * p);
  for (int v = 0; v < f.depth.height; ++v)
    for (int u = 0; u < f.depth.width; ++u) {
      const size_t i = size_t(v) * size_t(f.depth.width) + size_t(u);
      const float z = f.depth.depth_m[i];
      if (z > 0 && (f.aim * (double(z) * K.rayZ1(u, v))).z() < top + 0.005)
        f.objectOnly.depth_m[i] = 0;
    }
  return f;
}

// The model registered to the table's frame from its resting orientations at headings over the
// object's points (restingStarts). Each registration: how far the frame bears the model out where
// it faces the camera (facingSupport), and how much of the object's points (up to 2000) lie within
// 4 mm of the model's surface (a model that fits the faces it shows may still leave part of the
// object uncovered: a box slid along its top face). The best bears out and covers most (their
// sum; the smaller residual within 1 %), at least min_support borne out; sets out.T_B_O.
void findOnTable(RobotInterface& robot, DepthSensor& sensor, const ObjectModel& model,
                 const Vec3& look_at_B, const RegraspOptions& o, RegraspResult& out,
                 const std::function<void(const std::string&)>& log) {
  const std::optional<TableFrame> f = frameOfTable(robot, sensor, look_at_B, o, log);
  if (!f) {
    out.failure = "object_not_found";
    return;
  }
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  Vec3 centre_B = Vec3::Zero();
  for (const Vec3& p : f->object_B) centre_B += p;
  centre_B /= double(std::max<size_t>(1, f->object_B.size()));
  const std::vector<Iso3> starts =
      restingStarts(model.mesh, centre_B, f->aim.translation(), robot.model().table().topZ(),
                    o.orientations, o.headings);
  out.starts = int(starts.size());
  const RegistrationModel reg = registrationModel(model, o.scan.tracking);
  struct Fit {
    Iso3 T;
    double support, rms, covered = 0;
  };
  std::vector<Fit> fits;
  for (const auto& [T, r] : registerModelAt(reg, f->objectOnly, f->robotMask, f->aim, K, o.noise,
                                            o.scan.tracking, starts))
    if (T)
      fits.push_back(
          {*T, facingSupport(f->depth, f->aim, K, f->robotMask, reg.points, *T), r.rms_m});
  std::vector<Vec3> seen_B;
  for (size_t k = 0; k < f->object_B.size(); k += f->object_B.size() / 2000 + 1)
    seen_B.push_back(f->object_B[k]);
  const TriangleDistanceIndex surface(model.mesh);
  parallelFor(0, int(fits.size()), [&](int k) {
    Fit& fit = fits[size_t(k)];
    if (fit.support < o.min_support || seen_B.empty()) return;
    const Iso3 T_O_B = fit.T.inverse();
    int near = 0;
    for (const Vec3& p : seen_B) near += surface.within(T_O_B * p, 0.004);
    fit.covered = double(near) / double(seen_B.size());
  });
  const Fit* best = nullptr;
  double most = -1;
  auto score = [](const Fit& fit) { return fit.support + fit.covered; };
  for (const Fit& fit : fits) {
    most = std::max(most, fit.support);
    if (fit.support >= o.min_support && (!best || score(fit) > score(*best) + 0.01 ||
                                         (score(fit) > score(*best) - 0.01 && fit.rms < best->rms)))
      best = &fit;
  }
  if (!best) {
    out.failure = "not_registered";
    log("the model does not fit what the camera sees (best " +
        std::to_string(int(std::lround(100 * std::max(0.0, most)))) + " % borne out)");
    return;
  }
  out.T_B_O = best->T;
  out.support = best->support;
  out.rms_m = best->rms;
  char line[200];
  std::snprintf(line, sizeof line,
                "found: the model registered from %d starts, %d %% borne out, %d %% of the "
                "object's points covered, residual %.2f mm",
                out.starts, int(std::lround(100 * out.support)),
                int(std::lround(100 * best->covered)), 1000 * out.rms_m);
  log(line);
}

// The set's grasps made where the object was found (out.T_B_O); when none can be made there, on
// the poses a symmetric object fits the frame as well in (turnsAsGood, in order: the object is the
// same there, its frame O is not), the first where some can. Those made are tried on the model in
// physics at the object's mass and reordered (hold test). False when none can be made.
bool chooseGrasp(const RobotModel& m, const JointVector& q_now, const KnownObject& object,
                 const TriangleMesh& dense_O, const RegraspOptions& options, RegraspResult& out,
                 const std::function<void(const std::string&)>& log) {
  const TriangleMesh& mesh = object.model_O.mesh;
  const std::vector<KnownGrasp>& set = object.grasps;
  out.generation = graspsFromSet(m, mesh, *out.T_B_O, q_now, set, options.grasp);
  if (out.generation.candidates.empty()) {
    const std::vector<Iso3> turns = turnsAsGood(dense_O, *out.T_B_O);
    for (size_t k = 1; k < turns.size(); ++k) {
      out.generation = graspsFromSet(m, mesh, turns[k], q_now, set, options.grasp);
      if (out.generation.candidates.empty()) continue;
      log("the set's grasps are made on a pose as well borne out, turned " +
          std::to_string(int(std::lround(180 / M_PI * rotationBetween(turns[0], turns[k])))) +
          "° from the best (the object's symmetry)");
      out.T_B_O = turns[k];
      break;
    }
  }
  std::vector<GraspCandidate>& made = out.generation.candidates;
  out.made = int(made.size());
  if (made.empty()) {
    out.failure = "no_grasp_here";
    log("none of the " + std::to_string(out.set) +
        " grasps of the set can be made where the object lies");
    return false;
  }
  HoldTestOptions hold = options.grasp.hold;
  const double volume = massProperties(mesh).volume_m3;
  if (volume > 0) hold.density_kg_m3 = object.mass_kg / volume;
  hold.pose_tolerance_m = options.pose_tolerance_m;
  const double seconds =
      rankByHold(m, mesh, *out.T_B_O, nullptr, options.grasp.friction, hold, &made);
  for (const GraspCandidate& c : made) out.held_in_test += c.hold == 1;
  int robust = 0, tried = 0;
  for (const GraspCandidate& c : made) {
    robust += c.hold_robust == 1;
    tried += c.hold_robust >= 0;
  }
  log(std::to_string(out.made) + " of the set's " + std::to_string(out.set) +
      " grasps can be made here; " + holdLine(made, seconds) + "; " + std::to_string(robust) +
      " of " + std::to_string(tried) + " tried held with the model moved " +
      std::to_string(int(std::lround(1000 * hold.pose_tolerance_m))) + " mm each way");
  out.grasp = made.front();
  out.chosen = made.front().pose;
  return true;
}

// After the lift: how far a frame aimed at the hand bears out the model where the hand holds it
// and where it lay.
void checkLift(RobotInterface& robot, DepthSensor& sensor, const ObjectModel& model,
               const Iso3& T_O_palm, const Iso3& T_B_O_rest, const RegraspOptions& o,
               RegraspResult& out) {
  const RobotModel& m = robot.model();
  const Iso3 T_B_O_held = m.tipPose(robot.joints()) * T_O_palm.inverse();
  std::vector<Vec3> held_B, rest_B;
  Aabb box;
  for (const Vec3& p : observedVertices(model)) {
    held_B.push_back(T_B_O_held * p);
    box.extend(held_B.back());
    const Vec3 r = T_B_O_rest * p;
    if (r.z() > m.table().topZ() + 0.015) rest_B.push_back(r);  // the table is near the others
  }
  const std::optional<Iso3> aim = m.camera().aimAt(box.center());
  if (!aim) return;
  sensor.setPose(*aim);
  const std::optional<DepthImage> d = captureUsable(sensor, o.scan.checks);
  if (!d) return;
  const std::vector<uint8_t> mask =
      robotPixelMask(*d, *aim, robot.joints(), RobotOccluders(m), sensor.camera(), o.scan.t_hand_m,
                     o.scan.carve_radius_px, /*with_table=*/false);
  out.in_hand = depthSupport(*d, *aim, sensor.camera().intrinsics, mask, held_B);
  out.on_table = depthSupport(*d, *aim, sensor.camera().intrinsics, mask, rest_B);
}

// The object's weight the arm's torques at rest show, held at T_O_palm with its centre of mass
// at com_O (weighAt, not below 0); −1 without torques.
double weighed(const RobotModel& m, const JointVector& q, const std::optional<TorqueSamples>& rest,
               const Iso3& T_O_palm, const Vec3& com_O) {
  if (!rest) return -1;
  const std::optional<Weighing> w =
      weighAt(m, q, *rest, m.tipPose(q) * (T_O_palm.inverse() * com_O));
  return w ? std::max(0.0, w->kg) : -1;
}
}  // namespace

std::string RegraspOptions::validate() const {
  if (std::string p = scan.validate(); !p.empty()) return p;
  if (std::string p = table_top.validate(); !p.empty()) return "table_top." + p;
  if (std::string p = grasp.validate(); !p.empty()) return "grasp." + p;
  if (std::string p = noise.validate(); !p.empty()) return "noise." + p;
  if (orientations < 1 || headings < 1) return "orientations and headings must be at least 1";
  if (!(min_support > 0 && min_support <= 1)) return "min_support must be in (0, 1]";
  if (!(pose_tolerance_m >= 0 && pose_tolerance_m < 0.05))
    return "pose_tolerance_m must be in [0, 0.05) m";
  return "";
}

RegraspResult pickUpKnownObject(RobotInterface& robot, DepthSensor& sensor,
                                const KnownObject& object, const Vec3& look_at_B,
                                const RegraspOptions& options,
                                const std::function<void(const std::string&)>& logTo) {
  if (std::string p = options.validate(); !p.empty()) throw Error("regrasp options: " + p);
  if (!(object.mass_kg > 0)) throw Error("pickUpKnownObject: the object's mass must be positive");
  auto log = [&](const std::string& s) {
    if (logTo) logTo(s);
  };
  const RobotModel& m = robot.model();
  RegraspResult out;
  out.set = int(object.grasps.size());
  // The arm out of the camera's way: home, the hand open.
  const JointVector home = m.withFingersOpen(m.home());
  if (!robot.joints().isApprox(home, 1e-9))
    robot.execute({robot.joints(), home}, [](const JointVector&) {});
  auto t0 = Clock::now();
  // Registration works on the model's surface points: a coarse model (a box of 12 triangles) is
  // subdivided to edges of at most 4 mm first.
  ObjectModel dense;
  dense.observed = object.model_O.observed;
  if (dense.observed.size() != object.model_O.mesh.vertices.size())
    dense.observed.assign(object.model_O.mesh.vertices.size(), 1);
  dense.mesh = subdivided(object.model_O.mesh, 0.004, &dense.observed);
  findOnTable(robot, sensor, dense, look_at_B, options, out, log);
  out.find_s = secondsFrom(t0);
  if (!out.T_B_O) return out;
  t0 = Clock::now();
  const bool chosen = chooseGrasp(m, robot.joints(), object, dense.mesh, options, out, log);
  out.plan_s = secondsFrom(t0);
  if (!chosen) return out;

  // The pick-up and the lift.
  t0 = Clock::now();
  const GraspCandidate& c = *out.grasp;
  const std::optional<Iso3> achieved = robot.pickUp(c.T_O_palm, c.q_open);
  out.picked = bool(achieved);
  if (!achieved) {
    out.failure = "no_contact";
  } else if (fingersClosedOnNothing(m, robot.joints())) {
    out.failure = "empty_hand";
  } else {
    robot.execute({robot.joints(), m.withArm(robot.joints(), m.arm(c.q_lift))},
                  [](const JointVector&) {});
    checkLift(robot, sensor, dense, *achieved, *out.T_B_O, options, out);
    out.weighed_kg = weighed(m, robot.joints(), torquesAtRest(robot, options.scan.torque_readings),
                             *achieved, object.com_O);
    // The weight decides when it can be the object's (less than half its mass: not in the hand;
    // more than twice: the torques' noise on a light object, or something else, and the frame
    // decides, as it does without torques).
    const bool seen = out.in_hand > 0.5 && !(out.on_table > 0.5);
    out.lifted = out.weighed_kg < 0 || out.weighed_kg >= 2 * object.mass_kg
                     ? seen
                     : out.weighed_kg > 0.5 * object.mass_kg;
    if (!out.lifted) out.failure = "not_in_hand";
  }
  out.pick_s = secondsFrom(t0);
  char line[200];
  std::snprintf(line, sizeof line,
                "known grasp %d: %s (the arm weighs %.3f kg of %.3f; the model borne out in "
                "the hand %d %%, where it lay %d %%)",
                out.chosen, out.lifted ? "lifted" : out.failure.c_str(), out.weighed_kg,
                object.mass_kg, int(std::lround(100 * out.in_hand)),
                int(std::lround(100 * out.on_table)));
  log(line);
  return out;
}

}  // namespace inhand
