#include "inhand/geometry/point_cloud.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/random.h"

namespace inhand {

std::optional<PlaneFit> fitPlaneRansac(const std::vector<Vec3>& pts, const PlaneFitOptions& o) {
  if (pts.size() < 3) return std::nullopt;
  const double cosTilt = std::cos(
      (o.expected_plane ? std::min(o.max_tilt_deg, o.max_expected_tilt_deg) : o.max_tilt_deg) *
      M_PI / 180);
  const Vec3 up = o.expected_normal.normalized();
  Rng rng = makeRng(o.seed, 0x9a7e);
  // Hypotheses from the points near the expected plane, where there is one.
  std::vector<size_t> candidates;
  for (size_t i = 0; i < pts.size(); ++i)
    if (!o.expected_plane || std::abs(o.expected_plane->distance(pts[i])) <= o.max_offset_m)
      candidates.push_back(i);
  if (candidates.size() < 3) return std::nullopt;
  std::uniform_int_distribution<size_t> pick(0, candidates.size() - 1);
  // The hypotheses drawn in order, their inliers counted on both cores, the first with the most
  // kept.
  std::vector<std::optional<Plane>> hypotheses(size_t(std::max(0, o.iterations)));
  for (std::optional<Plane>& h : hypotheses) {
    const Vec3 &a = pts[candidates[pick(rng)]], &b = pts[candidates[pick(rng)]],
               &c = pts[candidates[pick(rng)]];
    Vec3 n = (b - a).cross(c - a);
    if (n.norm() < 1e-9) continue;
    n.normalize();
    if (n.dot(up) < 0) n = -n;
    if (n.dot(up) < cosTilt) continue;
    h = Plane{n, -n.dot(a)};
  }
  std::vector<int> counts(hypotheses.size(), 0);
  parallelFor(0, int(hypotheses.size()), [&](int it) {
    const std::optional<Plane>& h = hypotheses[size_t(it)];
    if (!h) return;
    int count = 0;
    for (const Vec3& p : pts) count += std::abs(h->distance(p)) < o.inlier_m;
    counts[size_t(it)] = count;
  });
  std::optional<Plane> best;
  int bestCount = 0;
  for (size_t it = 0; it < hypotheses.size(); ++it)
    if (hypotheses[it] && counts[it] > bestCount) {
      bestCount = counts[it];
      best = hypotheses[it];
    }
  if (!best) return std::nullopt;
  std::vector<Vec3> in;
  for (const Vec3& p : pts)
    if (std::abs(best->distance(p)) < o.inlier_m) in.push_back(p);
  PrincipalAxes pa = principalAxes(in);
  Vec3 n = pa.axes.col(2);
  if (n.dot(up) < 0) n = -n;
  // Inliers along a thin strip (a large object hiding most of the table) leave the plane's tilt
  // about the strip undetermined: the refit keeps the hypothesis' normal then.
  if (n.dot(best->n) < std::cos(5 * M_PI / 180) || pa.variances[1] < 25 * pa.variances[2])
    n = best->n;
  PlaneFit fit;
  fit.plane = Plane{n, -n.dot(pa.centroid)};
  for (const Vec3& p : pts) fit.inliers += std::abs(fit.plane.distance(p)) < o.inlier_m;
  return fit;
}

std::vector<Vec3> largestCluster(const std::vector<Vec3>& pts, double cell) {
  INHAND_CHECK(cell > 0, "cluster cell must be > 0");
  using Key = std::tuple<int, int, int>;
  std::map<Key, int> cellId;  // ordered: deterministic ids
  std::vector<int> cellOf(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    const Key k{int(std::floor(pts[i].x() / cell)), int(std::floor(pts[i].y() / cell)),
                int(std::floor(pts[i].z() / cell))};
    cellOf[i] = cellId.emplace(k, int(cellId.size())).first->second;
  }
  std::vector<int> parent(cellId.size());
  for (size_t c = 0; c < parent.size(); ++c) parent[c] = int(c);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const auto& [k, id] : cellId) {
    const auto [x, y, z] = k;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          auto it = cellId.find(Key{x + dx, y + dy, z + dz});
          if (it == cellId.end()) continue;
          const int a = find(id), b = find(it->second);
          if (a != b) parent[std::max(a, b)] = std::min(a, b);
        }
  }
  std::vector<int> count(parent.size(), 0);
  for (size_t i = 0; i < pts.size(); ++i) ++count[find(cellOf[i])];
  const int best = int(std::max_element(count.begin(), count.end()) - count.begin());
  std::vector<Vec3> out;
  for (size_t i = 0; i < pts.size(); ++i)
    if (find(cellOf[i]) == best) out.push_back(pts[i]);
  return out;
}

PrincipalAxes principalAxes(const std::vector<Vec3>& pts) {
  if (pts.empty()) throw Error("principal axes of no points");
  PrincipalAxes out;
  for (const Vec3& p : pts) out.centroid += p;
  out.centroid /= double(pts.size());
  Mat3 C = Mat3::Zero();
  for (const Vec3& p : pts) {
    const Vec3 d = p - out.centroid;
    C += d * d.transpose();
  }
  C /= double(pts.size());
  Eigen::SelfAdjointEigenSolver<Mat3> es(C);  // ascending eigenvalues
  for (int k = 0; k < 3; ++k) {
    out.axes.col(k) = es.eigenvectors().col(2 - k).normalized();
    out.variances[k] = std::max(0.0, es.eigenvalues()[2 - k]);
  }
  out.axes.col(2) = out.axes.col(0).cross(out.axes.col(1));  // right-handed
  out.min = Vec3::Constant(std::numeric_limits<double>::infinity());
  out.max = -out.min;
  for (const Vec3& p : pts) {
    const Vec3 q = out.axes.transpose() * (p - out.centroid);
    out.min = out.min.cwiseMin(q);
    out.max = out.max.cwiseMax(q);
  }
  return out;
}

PrincipalAxes principalAxesUpright(const std::vector<Vec3>& pts, const Vec3& upIn, double trim) {
  if (pts.empty()) throw Error("principal axes of no points");
  INHAND_CHECK(trim >= 0 && trim < 0.5, "trim must be in [0, 0.5)");
  const Vec3 up = upIn.normalized();
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& p : pts) centroid += p;
  centroid /= double(pts.size());
  const Vec3 u = up.unitOrthogonal(), v = up.cross(u);
  Eigen::Matrix2d C = Eigen::Matrix2d::Zero();
  for (const Vec3& p : pts) {
    const Eigen::Vector2d q((p - centroid).dot(u), (p - centroid).dot(v));
    C += q * q.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(C);  // ascending
  const double pca = std::atan2(es.eigenvectors()(1, 1), es.eigenvectors()(0, 1));
  // Refined to the least-area bounding rectangle within ±45° of the principal direction, in
  // 0.5° steps: one side of the object's points tilts the covariance, not the rectangle.
  std::vector<Eigen::Vector2d> q2;
  q2.reserve(pts.size());
  for (const Vec3& p : pts) q2.emplace_back((p - centroid).dot(u), (p - centroid).dot(v));
  const size_t cut2 = size_t(trim * double(q2.size()));
  // (The rectangle ignores the trimmed tails too: a few stray points would otherwise set it.)
  // Each angle's area on both cores, then the least in angle order.
  constexpr int kSteps = 90;
  std::vector<double> areas(2 * kSteps + 1);
  parallelFor(-kSteps, kSteps + 1, [&](int k) {
    thread_local std::vector<double> proj;
    proj.resize(q2.size());
    const double a = pca + k * M_PI / 360;
    const Eigen::Vector2d d1(std::cos(a), std::sin(a)), d2(-d1.y(), d1.x());
    auto extent = [&](const Eigen::Vector2d& d) {
      for (size_t i = 0; i < q2.size(); ++i) proj[i] = q2[i].dot(d);
      std::nth_element(proj.begin(), proj.begin() + cut2, proj.end());
      const double lo = proj[cut2];
      std::nth_element(proj.begin(), proj.end() - 1 - cut2, proj.end());
      return proj[proj.size() - 1 - cut2] - lo;
    };
    areas[size_t(k + kSteps)] = extent(d1) * extent(d2);
  });
  double bestArea = std::numeric_limits<double>::infinity(), bestAngle = pca;
  for (int k = -kSteps; k <= kSteps; ++k)
    if (areas[size_t(k + kSteps)] < bestArea - 1e-12) {
      bestArea = areas[size_t(k + kSteps)];
      bestAngle = pca + k * M_PI / 360;
    }
  const Vec3 h1 = (std::cos(bestAngle) * u + std::sin(bestAngle) * v).normalized();
  const Vec3 h2 = up.cross(h1);
  Vec3 cand[3] = {up, h1, h2};
  double lo[3], hi[3];
  std::vector<double> s(pts.size());
  const size_t cut = size_t(trim * double(pts.size()));
  for (int k = 0; k < 3; ++k) {
    for (size_t i = 0; i < pts.size(); ++i) s[i] = (pts[i] - centroid).dot(cand[k]);
    std::nth_element(s.begin(), s.begin() + cut, s.end());
    lo[k] = s[cut];
    std::nth_element(s.begin(), s.end() - 1 - cut, s.end());
    hi[k] = s[s.size() - 1 - cut];
  }
  int order[3] = {0, 1, 2};
  std::stable_sort(order, order + 3, [&](int a, int b) { return hi[a] - lo[a] > hi[b] - lo[b]; });
  PrincipalAxes out;
  out.centroid = centroid;
  for (int k = 0; k < 3; ++k) {
    const int j = order[k];
    out.axes.col(k) = cand[j];
    out.min[k] = lo[j];
    out.max[k] = hi[j];
    double var = 0;
    for (const Vec3& p : pts) var += std::pow((p - centroid).dot(cand[j]), 2);
    out.variances[k] = var / double(pts.size());
  }
  if (out.axes.determinant() < 0) {  // keep it right-handed
    out.axes.col(2) = -out.axes.col(2);
    std::swap(out.min[2], out.max[2]);
    out.min[2] = -out.min[2];
    out.max[2] = -out.max[2];
  }
  return out;
}

}  // namespace inhand
