#include "inhand/scan/tracking.h"

#include <cmath>
#include <limits>

namespace inhand {

std::string TrackingOptions::validate() const {
  if (iterations < 1 || iterations > 200) return "iterations must be in 1..200";
  if (!(final_gate_m > 0 && final_gate_m <= gate_m && gate_m < 1))
    return "gates must satisfy 0 < final_gate_m <= gate_m < 1 m";
  if (min_inliers < 6) return "min_inliers must be >= 6";
  if (!(max_rms_m > 0)) return "max_rms_m must be > 0";
  if (!(max_correction_m > 0)) return "max_correction_m must be > 0";
  if (!(hand_spacing_m >= 0.001 && hand_spacing_m < 0.05))
    return "hand_spacing_m must be in [0.001, 0.05) m";
  if (max_object_points < 0) return "max_object_points must be >= 0";
  return {};
}

namespace {

// A coarse depth buffer of the model's points (every 4th pixel): a point is visible when it lies
// within 1 cm of the nearest model point over its cell.
class PointBuffer {
 public:
  PointBuffer(const CameraIntrinsics& K) : K_(K), w_((K.width + 3) / 4), h_((K.height + 3) / 4) {
    z_.assign(size_t(w_) * h_, std::numeric_limits<float>::infinity());
  }
  void add(const Vec3& x) {
    if (const int c = cell(x); c >= 0) z_[size_t(c)] = std::min(z_[size_t(c)], float(x.z()));
  }
  bool visible(const Vec3& x) const {
    const int c = cell(x);
    return c >= 0 && x.z() <= z_[size_t(c)] + 0.01;
  }

 private:
  int cell(const Vec3& x) const {
    if (x.z() <= 0.1) return -1;
    const Vec2 uv = K_.project(x);
    const int u = int(uv.x()) / 4, v = int(uv.y()) / 4;
    if (uv.x() < 0 || uv.y() < 0 || u >= w_ || v >= h_) return -1;
    return v * w_ + u;
  }
  const CameraIntrinsics& K_;
  int w_, h_;
  std::vector<float> z_;
};

struct Pairs {
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  int pairs = 0, seeThrough = 0;
  double sq = 0;
};

// The pairs of the points visible at T (palm to camera) within `gate` in depth, and the normal
// equations of n·(y − x) = (x × n)·ω + n·t (Huber-weighted at half the final gate).
Pairs pairUp(const DepthImage& depth, const CameraIntrinsics& K,
             const std::vector<SurfacePoint>& points, const std::vector<Vec3>& occluders,
             const Iso3& T, double gate, double huber) {
  PointBuffer buffer(K);
  for (const SurfacePoint& sp : points) buffer.add(T * sp.p);
  for (const Vec3& p : occluders) buffer.add(T * p);
  Pairs P;
  for (const SurfacePoint& sp : points) {
    const Vec3 x = T * sp.p;
    const Vec3 n = T.linear() * sp.n;
    if (x.z() <= 0.1 || n.dot(x) >= 0 || !buffer.visible(x)) continue;
    const Vec2 uv = K.project(x);
    const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
    if (u < 0 || v < 0 || u >= depth.width || v >= depth.height) continue;
    const float z = depth.depth_m[size_t(v) * depth.width + u];
    if (!(z > 0)) continue;
    if (double(z) > x.z() + 0.015) ++P.seeThrough;
    if (std::abs(double(z) - x.z()) > gate) continue;
    const Vec3 y = double(z) * K.rayZ1(u, v);
    const double e = n.dot(y - x);
    const double w = std::abs(e) < huber ? 1.0 : huber / std::abs(e);
    Eigen::Matrix<double, 6, 1> J;
    J.head<3>() = x.cross(n);
    J.tail<3>() = n;
    P.A += w * J * J.transpose();
    P.b += w * J * e;
    ++P.pairs;
    P.sq += e * e;
  }
  return P;
}

TrackResult alignFrom(const DepthImage& depth, const CameraIntrinsics& K,
                      const std::vector<SurfacePoint>& points, const std::vector<Vec3>& occluders,
                      const Iso3& T_C_palm, const Iso3& initial, const TrackingOptions& o) {
  TrackResult r;
  Iso3 D = initial;
  const double shrink = std::pow(o.final_gate_m / o.gate_m, 1.0 / std::max(1, o.iterations - 1));
  double gate = o.gate_m;
  for (int it = 0; it < o.iterations; ++it, gate = std::max(o.final_gate_m, gate * shrink)) {
    Pairs P = pairUp(depth, K, points, occluders, D * T_C_palm, gate, 0.5 * o.final_gate_m);
    if (P.pairs < 6) break;
    P.A.diagonal().array() += 1e-9;
    const Eigen::Matrix<double, 6, 1> d = P.A.ldlt().solve(P.b);
    Iso3 step = Iso3::Identity();
    const Vec3 w = d.head<3>();
    if (w.norm() > 1e-12)
      step.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    step.translation() = d.tail<3>();
    D = step * D;  // the step applies to camera-frame points: x' = R x + t
  }
  const Pairs last =
      pairUp(depth, K, points, occluders, D * T_C_palm, o.final_gate_m, 0.5 * o.final_gate_m);
  r.correction = D;
  r.inliers = last.pairs;
  r.see_through = last.seeThrough;
  r.rms_m = last.pairs > 0 ? std::sqrt(last.sq / last.pairs) : 0;
  const double moved = ((D * T_C_palm).translation() - T_C_palm.translation()).norm();
  if (r.inliers < o.min_inliers)
    r.reason = "too few points to align (" + std::to_string(r.inliers) + ")";
  else if (r.see_through * 10 > r.inliers)
    r.reason = "the camera sees through " + std::to_string(r.see_through) + " aligned points";
  else if (r.rms_m > o.max_rms_m)
    r.reason = "alignment residual " + std::to_string(r.rms_m * 1000) + " mm";
  else if (moved > o.max_correction_m)
    r.reason = "correction of " + std::to_string(moved * 100) + " cm";
  else
    r.ok = true;
  return r;
}

}  // namespace

TrackResult alignToDepth(const DepthImage& depth, const CameraIntrinsics& K,
                         const std::vector<SurfacePoint>& points,
                         const std::vector<Vec3>& occluders, const Iso3& T_C_palm,
                         const std::vector<Iso3>& starts, const TrackingOptions& o) {
  TrackResult best;
  bool first = true;
  for (const Iso3& start : starts) {
    TrackResult r = alignFrom(depth, K, points, occluders, T_C_palm, start, o);
    // Ok beats not ok; then fewer see-through points per pair, then more pairs.
    auto score = [](const TrackResult& t) { return t.inliers - 10.0 * t.see_through; };
    if (first || (r.ok && !best.ok) || (r.ok == best.ok && score(r) > score(best))) best = r;
    first = false;
  }
  return best;
}

}  // namespace inhand
