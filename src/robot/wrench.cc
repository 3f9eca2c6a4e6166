#include "inhand/robot/wrench.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <tuple>

#include "inhand/core/error.h"

namespace inhand {

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

namespace {
// The unit forces along each contact's friction-cone edges (pushing into the object) and their
// torques about the centre over rho.
std::vector<Vec6> contactWrenches(const std::vector<Contact>& contacts, const Vec3& centre,
                                  double rho, double mu, int edges) {
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
  return w;
}
}  // namespace

double forceClosureEpsilonReference(const std::vector<Contact>& contacts, const Vec3& centre,
                                    double rho, double mu, int edges, int directions) {
  if (contacts.empty()) return -1.0;
  const std::vector<Vec6> w = contactWrenches(contacts, centre, rho, mu, edges);
  double eps = std::numeric_limits<double>::infinity();
  for (const Vec6& d : wrenchDirections(directions)) {
    double h = -std::numeric_limits<double>::infinity();
    for (const Vec6& x : w) h = std::max(h, d.dot(x));
    eps = std::min(eps, h);
  }
  return eps;
}

double forceClosureEpsilon(const std::vector<Contact>& contacts, const Vec3& centre, double rho,
                           double mu, int edges, int directions) {
  if (contacts.empty()) return -1.0;
  const std::vector<Vec6> w = contactWrenches(contacts, centre, rho, mu, edges);
  // ε = min over directions of the support max over wrenches. A direction's support can only
  // grow as more wrenches are seen: once it reaches the least support so far it cannot lower ε,
  // and the rest of its wrenches are skipped (the same ε, to the bit).
  double eps = std::numeric_limits<double>::infinity();
  for (const Vec6& d : wrenchDirections(directions)) {
    double h = -std::numeric_limits<double>::infinity();
    for (const Vec6& x : w) {
      h = std::max(h, d.dot(x));
      if (h >= eps) break;
    }
    eps = std::min(eps, h);
  }
  return eps;
}

namespace {
// handContacts over the samples `visit` names (all of them when null), in that order.
HandContacts contactsOf(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                        const std::vector<SurfacePoint>& samples, const std::vector<int>* visit,
                        double contact_m, double cell_m) {
  HandContacts out;
  const double palmTop = robot.palmFaceZ();
  const HandGeometry hand(robot, q, T_O_palm);
  const Iso3 T_palm_O = T_O_palm.inverse();
  const Aabb hb = hand.bounds();  // a cull only: distanceWithin decides
  std::map<std::tuple<int, int, int>, std::pair<Contact, int>> cells;
  std::vector<uint8_t> touch(robot.fingers().size(), 0);
  const size_t n = visit ? visit->size() : samples.size();
  for (size_t k = 0; k < n; ++k) {
    const SurfacePoint& sm = samples[visit ? size_t((*visit)[k]) : k];
    const Vec3& p = sm.p;
    if (((p - hb.min).array() < -contact_m).any() || ((p - hb.max).array() > contact_m).any())
      continue;
    int link = -1;
    if (hand.distanceWithin(p, contact_m, &link) > contact_m) continue;
    if (const int finger = robot.fingerOfLink(link); finger >= 0) touch[finger] = 1;
    if ((T_palm_O * p).z() < palmTop + 0.002 + contact_m) out.palm_touching = true;
    auto key = std::make_tuple(int(std::floor(p.x() / cell_m)), int(std::floor(p.y() / cell_m)),
                               int(std::floor(p.z() / cell_m)));
    auto& cell = cells[key];
    cell.first.p_O += p;
    cell.first.normal_O += sm.n;
    ++cell.second;
  }
  for (uint8_t t : touch) out.fingers_touching += t;
  for (const auto& entry : cells) {
    const auto& [sum, count] = entry.second;
    out.contacts.push_back({sum.p_O / count, sum.normal_O.normalized()});
  }
  return out;
}
}  // namespace

HandContacts handContacts(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                          const std::vector<SurfacePoint>& samples, double contact_m,
                          double cell_m) {
  return contactsOf(robot, q, T_O_palm, samples, nullptr, contact_m, cell_m);
}

SampleGrid::SampleGrid(std::vector<SurfacePoint> samples, double cell_m)
    : samples_(std::move(samples)) {
  if (!(cell_m > 0)) throw Error("SampleGrid: the cell size must be positive");
  Aabb b;
  for (const SurfacePoint& s : samples_) b.extend(s.p);
  if (samples_.empty()) b.extend(Vec3::Zero());
  origin_ = b.min;
  cell_ = std::max(cell_m, b.size().maxCoeff() / 64);
  for (int a = 0; a < 3; ++a) dims_[a] = std::max(1, int(std::floor(b.size()[a] / cell_)) + 1);
  auto cellOf = [&](const Vec3& p) {
    Eigen::Vector3i c;
    for (int a = 0; a < 3; ++a)
      c[a] = std::clamp(int(std::floor((p[a] - origin_[a]) / cell_)), 0, dims_[a] - 1);
    return (c.z() * dims_.y() + c.y()) * dims_.x() + c.x();
  };
  start_.assign(size_t(dims_.prod()) + 1, 0);
  std::vector<int> cellOfSample(samples_.size());
  for (size_t i = 0; i < samples_.size(); ++i) {
    cellOfSample[i] = cellOf(samples_[i].p);
    ++start_[size_t(cellOfSample[i]) + 1];
  }
  for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
  index_.resize(samples_.size());
  std::vector<int> fill(start_.begin(), start_.end() - 1);
  for (size_t i = 0; i < samples_.size(); ++i)
    index_[size_t(fill[size_t(cellOfSample[i])]++)] = int(i);
}

void SampleGrid::near(const Aabb& box, std::vector<int>* out) const {
  Eigen::Vector3i lo, hi;
  for (int a = 0; a < 3; ++a) {
    const double l = std::floor((box.min[a] - origin_[a]) / cell_),
                 h = std::floor((box.max[a] - origin_[a]) / cell_);
    if (h < 0 || l > dims_[a] - 1 || !(l <= h)) return;
    lo[a] = int(std::max(0.0, l));
    hi[a] = int(std::min(double(dims_[a] - 1), h));
  }
  for (int z = lo.z(); z <= hi.z(); ++z)
    for (int y = lo.y(); y <= hi.y(); ++y)
      for (int x = lo.x(); x <= hi.x(); ++x) {
        const size_t c = size_t((z * dims_.y() + y) * dims_.x() + x);
        out->insert(out->end(), index_.begin() + start_[c], index_.begin() + start_[c + 1]);
      }
}

HandContacts handContacts(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                          const SampleGrid& grid, double contact_m, double cell_m) {
  const HandGeometry hand(robot, q, T_O_palm);
  thread_local std::vector<int> visit;
  visit.clear();
  // Grown a little more than contact_m: distanceWithin's own test rounds differently.
  const Vec3 grow = Vec3::Constant(contact_m + 1e-9);
  for (const std::vector<Aabb>& link : hand.primitiveBoxes())
    for (const Aabb& b : link) grid.near(Aabb{b.min - grow, b.max + grow}, &visit);
  std::sort(visit.begin(), visit.end());
  visit.erase(std::unique(visit.begin(), visit.end()), visit.end());
  return contactsOf(robot, q, T_O_palm, grid.samples(), &visit, contact_m, cell_m);
}

}  // namespace inhand
