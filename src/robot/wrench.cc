#include "inhand/robot/wrench.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <tuple>

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

HandContacts handContacts(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                          const std::vector<SurfacePoint>& samples, double contact_m,
                          double cell_m) {
  HandContacts out;
  const double palmTop = robot.palmFaceZ();
  const HandGeometry hand(robot, q, T_O_palm);
  const Iso3 T_palm_O = T_O_palm.inverse();
  const Aabb hb = hand.bounds();  // a cull only: distanceWithin decides
  std::map<std::tuple<int, int, int>, std::pair<Contact, int>> cells;
  std::vector<uint8_t> touch(robot.fingers().size(), 0);
  for (const SurfacePoint& sm : samples) {
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

}  // namespace inhand
