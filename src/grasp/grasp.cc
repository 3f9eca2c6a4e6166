#include "inhand/grasp/grasp.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <random>

#include "inhand/core/error.h"
#include "inhand/core/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/ik.h"

namespace inhand {

std::string GraspOptions::validate() const {
  if (approaches < 1) return "approaches must be >= 1";
  if (rolls < 1) return "rolls must be >= 1";
  if (spreads.empty()) return "spreads must not be empty";
  if (!(friction > 0 && friction <= 2)) return "friction must be in (0, 2]";
  if (cone_edges < 3 || cone_edges > 64) return "cone_edges must be in 3..64";
  if (wrench_directions < 12) return "wrench_directions must be >= 12";
  if (!(contact_m > 0 && contact_m < 0.05)) return "contact_m must be in (0, 0.05) m";
  if (!(contact_cell_m > 0)) return "contact_cell_m must be > 0";
  if (!(min_epsilon >= 0)) return "min_epsilon must be >= 0";
  if (!(lift_m >= 0 && lift_m < 1)) return "lift_m must be in [0, 1) m";
  if (!(stability_weight >= 0)) return "stability_weight must be >= 0";
  if (max_candidates < 1) return "max_candidates must be >= 1";
  return {};
}

namespace {
using Vec6 = Eigen::Matrix<double, 6, 1>;

// Fixed unit directions in R⁶: the 12 signed axes, then seeded Gaussian samples.
const std::vector<Vec6>& wrenchDirections(int n) {
  thread_local std::vector<Vec6> dirs;
  thread_local int made = -1;
  if (made == n) return dirs;
  dirs.clear();
  for (int a = 0; a < 6; ++a)
    for (double s : {1.0, -1.0}) {
      Vec6 d = Vec6::Zero();
      d[a] = s;
      dirs.push_back(d);
    }
  std::mt19937_64 rng(0x9e3779b97f4a7c15ULL);
  std::normal_distribution<double> g;
  while (int(dirs.size()) < n) {
    Vec6 d;
    for (int k = 0; k < 6; ++k) d[k] = g(rng);
    if (d.norm() > 1e-9) dirs.push_back(d.normalized());
  }
  made = n;
  return dirs;
}
}  // namespace

double forceClosureEpsilon(const std::vector<Contact>& contacts, const Vec3& centre, double rho,
                           double mu, int edges, int directions) {
  if (contacts.empty()) return -1.0;
  std::vector<Vec6> w;
  for (const Contact& c : contacts) {
    const Vec3 n = -c.normal_O.normalized();  // pushing into the object
    Vec3 t1 = n.unitOrthogonal(), t2 = n.cross(t1);
    for (int e = 0; e < edges; ++e) {
      const double a = 2 * M_PI * e / edges;
      Vec3 f = n + mu * (std::cos(a) * t1 + std::sin(a) * t2);
      f.normalize();
      Vec6 x;
      x.head<3>() = f;
      x.tail<3>() = (c.p_O - centre).cross(f) / rho;
      w.push_back(x);
    }
  }
  double eps = std::numeric_limits<double>::infinity();
  for (const Vec6& d : wrenchDirections(directions)) {
    double h = -std::numeric_limits<double>::infinity();
    for (const Vec6& x : w) h = std::max(h, d.dot(x));
    eps = std::min(eps, h);
  }
  return eps;
}

GraspGeneration generateGrasps(const RobotModel& robot, const TriangleMesh& mesh, const Iso3& T_B_O,
                               const JointVector& q_now, const GraspOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string problem = o.validate();
  if (!problem.empty()) throw Error("grasp options: " + problem);
  INHAND_CHECK(!robot.fingers().empty(), "the hand has no fingers to grasp with");
  GraspGeneration out;
  if (mesh.empty()) return out;

  // Palm face (top of the palm geometry along palm z) and footprint.
  Aabb palm;
  for (const Primitive& p : robot.links()[robot.tipLink()].collision) {
    Aabb b = p.toMesh().bounds();
    palm.extend(b.min);
    palm.extend(b.max);
  }
  // Surface samples with outward normals (vertices, plus a lattice on large triangles).
  const std::vector<SurfacePoint> samples = surfaceSamples(mesh, 0.5 * o.contact_cell_m);
  const Vec3 centre = mesh.bounds().center();
  double rho = 0;
  for (const SurfacePoint& sm : samples) rho = std::max(rho, (sm.p - centre).norm());
  const double tableTop = robot.table().topZ();

  // Every (approach, roll, spread) pose, closed to contact on both cores.
  struct Pose {
    Vec3 approach;
    double roll, spread;
  };
  std::vector<Pose> poses;
  for (const Vec3& d : fibonacciSphere(o.approaches))
    for (int r = 0; r < o.rolls; ++r)
      for (double s : o.spreads) poses.push_back({d, M_PI * r / o.rolls, s});
  out.tried = int(poses.size());
  std::vector<std::optional<GraspCandidate>> found(poses.size());
  const FingerCloser closer(robot, mesh);
  parallelFor(0, int(poses.size()), [&](int i) {
    const Pose& ps = poses[i];
    // Palm z points into the object (against the outward approach direction d).
    Iso3 T = cameraPoseInObject(centre, -ps.approach, 1.0, ps.roll);  // z = −d, rolled
    T.translation().setZero();
    const Mat3 R = T.linear();
    // Slide the palm along −d until its face touches the nearest sample in its footprint.
    double nearest = std::numeric_limits<double>::infinity();
    for (const SurfacePoint& sm : samples) {
      const Vec3 p = R.transpose() * (sm.p - centre);
      if (p.x() < palm.min.x() || p.x() > palm.max.x() || p.y() < palm.min.y() ||
          p.y() > palm.max.y())
        continue;
      nearest = std::min(nearest, p.z());
    }
    if (!std::isfinite(nearest)) return;
    T.translation() = centre + R * Vec3(0, 0, nearest - palm.max.z() - 0.002);
    JointVector q = robot.home();
    for (const FingerInfo& f : robot.fingers()) q[f.variable] = f.open;
    if (robot.spreadVariable() >= 0) q[robot.spreadVariable()] = ps.spread;
    robot.applyCouplings(&q);
    ClosingResult closed = closer.close(q, T);
    GraspCandidate c;
    c.T_O_palm = T;
    c.q = closed.q;
    for (const FingerClosing& f : closed.fingers) c.links_in_contact += f.contact;
    // Contacts: model surface samples near the closed hand, pooled per cell.
    HandGeometry hand(robot, c.q, T);
    const Iso3 T_palm_O = T.inverse();
    Aabb hb = hand.mesh().bounds();
    std::map<std::tuple<int, int, int>, std::pair<Contact, int>> cells;
    bool palmTouch = false;
    for (const SurfacePoint& sm : samples) {
      const Vec3& p = sm.p;
      if (((p - hb.min).array() < -o.contact_m).any() || ((p - hb.max).array() > o.contact_m).any())
        continue;
      if (hand.distance(p) > o.contact_m) continue;
      if ((T_palm_O * p).z() < palm.max.z() + 0.002 + o.contact_m) palmTouch = true;
      auto key = std::make_tuple(int(std::floor(p.x() / o.contact_cell_m)),
                                 int(std::floor(p.y() / o.contact_cell_m)),
                                 int(std::floor(p.z() / o.contact_cell_m)));
      auto& cell = cells[key];
      cell.first.p_O += p;
      cell.first.normal_O += sm.n;
      ++cell.second;
    }
    c.links_in_contact += palmTouch;
    for (const auto& entry : cells) {
      const auto& [sum, count] = entry.second;
      c.contacts.push_back({sum.p_O / count, sum.normal_O.normalized()});
    }
    if (c.links_in_contact < 2) return;
    c.epsilon =
        forceClosureEpsilon(c.contacts, centre, rho, o.friction, o.cone_edges, o.wrench_directions);
    found[i] = c;
  });
  std::vector<GraspCandidate> kept;
  for (auto& f : found) {
    if (!f) continue;
    ++out.touching;
    if (f->epsilon < o.min_epsilon) continue;
    ++out.stable;
    // The hand on the object resting on the table must stay above the table top.
    HandGeometry hand(robot, f->q, T_B_O * f->T_O_palm);
    bool clear = true;
    for (const Vec3f& v : hand.mesh().vertices)
      if (v.z() < tableTop + 0.002) {
        clear = false;
        break;
      }
    if (!clear) continue;
    ++out.table_free;
    kept.push_back(std::move(*f));
  }
  // Reachable at the table (IK to the palm pose, arm and hand free of table and base).
  std::vector<Iso3> targets;
  for (const GraspCandidate& c : kept) targets.push_back(T_B_O * c.T_O_palm);
  IkOptions ik;
  ik.random_restarts = 2;
  auto sols = solveIkBatch(robot, targets, robot.arm(q_now), 7, ik);
  CollisionChecker checker(robot);
  IkSolver lift(robot, ik);
  Rng rng = makeRng(11);
  const Iso3 up(Eigen::Translation3d(0, 0, o.lift_m));
  for (size_t k = 0; k < kept.size(); ++k) {
    if (!sols[k]) continue;
    JointVector q = robot.withArm(kept[k].q, *sols[k]);
    if (checker.inCollision(q)) continue;
    auto lifted = lift.solve(up * T_B_O * kept[k].T_O_palm, *sols[k], &rng);
    if (!lifted) continue;
    JointVector ql = robot.withArm(kept[k].q, *lifted);
    if (checker.inCollision(ql)) continue;
    kept[k].q = q;
    kept[k].q_lift = ql;
    out.candidates.push_back(std::move(kept[k]));
  }
  std::stable_sort(
      out.candidates.begin(), out.candidates.end(),
      [](const GraspCandidate& a, const GraspCandidate& b) { return a.epsilon > b.epsilon; });
  if (int(out.candidates.size()) > o.max_candidates) out.candidates.resize(o.max_candidates);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

double rankGrasps(const ViewPlanner& planner, const ObjectModel& S_obj, const GraspOptions& o,
                  std::vector<GraspCandidate>* candidates) {
  const auto t0 = std::chrono::steady_clock::now();
  const ViewQualityOptions& qo = planner.options().quality;
  ViewQualityScene scene = planner.qualityScene(S_obj);  // S_obj's BVH once for all candidates
  const Aabb region = S_obj.mesh.bounds();  // near-hand cells only where S_obj can be hit
  for (GraspCandidate& c : *candidates) {
    HandGeometry hand(planner.model(), c.q, c.T_O_palm);
    auto nearHand = std::make_shared<NearHandGrid>(hand, qo.t_hand_m, qo.near_hand_cell_m, &region);
    ViewSelection sel = planner.select(scene, GraspState{c.T_O_palm, c.q_lift}, {}, nearHand);
    c.reachable_views = sel.reachable;
    c.quality = 0;
    for (const ViewCandidate& v : sel.candidates) c.quality = std::max(c.quality, v.quality);
    c.score = c.quality + o.stability_weight * c.epsilon;
  }
  std::stable_sort(
      candidates->begin(), candidates->end(),
      [](const GraspCandidate& a, const GraspCandidate& b) { return a.score > b.score; });
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace inhand
