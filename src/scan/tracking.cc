#include "inhand/scan/tracking.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "inhand/core/enum_names.h"
#include "inhand/core/internal/parallel.h"

namespace inhand {

namespace {
const EnumNames<TrackRefusal, 5> kTrackRefusals = {{TrackRefusal::kNone, ""},
                                                   {TrackRefusal::kTooFewPoints, "too_few_points"},
                                                   {TrackRefusal::kSeesThrough, "sees_through"},
                                                   {TrackRefusal::kResidual, "residual"},
                                                   {TrackRefusal::kCorrection, "correction"}};
}  // namespace

const char* trackRefusalName(TrackRefusal r) { return enumName(kTrackRefusals, r); }

std::string TrackingOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (!(final_gate_m <= gate_m)) return "final_gate_m must be at most gate_m";
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
  int handPairs = 0, handSeeThrough = 0;  // of the first `handCount` points
  double sq = 0;
  double var = 0;  // the paired points' own variances (SurfacePoint::var, at most (gate/2)²)
};

// Where the body may be seen in the frame (its depths, the pixels something else hides, and with
// NoDepthPixels::kUnknown those without depth) and
// each pixel's distance to the nearest such pixel (pixels; chamfer 1/√2): a point of the body
// that projects outside it lies past the body's true outline and is pulled back across it.
struct Silhouette {
  PixelRect window;  // where dist is known: the body's image widened by the alignment's reach
  std::vector<float> dist;
  double near = 0, far = 0;  // the depths at which the frame may show the body, m
  // How far apart the body's points lie (typicalSpacing; 0: no uncovered pixels); a point covers
  // the pixels within 1.5 times that.
  double spacing_m = 0;
  // The distance at a pixel; one outside the window takes its nearest window pixel's.
  float at(int u, int v) const {
    const int w = window.u1 - window.u0;
    u = std::clamp(u - window.u0, 0, w - 1);
    v = std::clamp(v - window.v0, 0, window.v1 - window.v0 - 1);
    return dist[size_t(v) * w + u];
  }
};

// The frame's pixels at the body's depths (near to far), the hidden ones and, with kUnknown,
// those without depth; their distance within `window` (not empty).
Silhouette silhouette(const DepthImage& depth, const std::vector<uint8_t>& hidden, double near,
                      double far, NoDepthPixels no_depth, const PixelRect& window) {
  Silhouette s;
  s.window = window;
  s.near = near;
  s.far = far;
  std::vector<uint8_t> zero(depth.depth_m.size(), 0);
  for (int v = window.v0; v < window.v1; ++v)
    for (int u = window.u0; u < window.u1; ++u) {
      const size_t i = size_t(v) * depth.width + size_t(u);
      const float z = depth.depth_m[i];
      zero[i] = (!hidden.empty() && hidden[i]) || (z >= near && z <= far) ||
                (no_depth == NoDepthPixels::kUnknown && !(z > 0));
    }
  s.dist = chamferDistance(zero, depth.width, window);
  return s;
}

}  // namespace

std::vector<float> chamferDistance(const std::vector<uint8_t>& zero, int width,
                                   const PixelRect& window) {
  const int w = window.u1 - window.u0, h = window.v1 - window.v0;
  std::vector<float> dist(size_t(std::max(0, w)) * size_t(std::max(0, h)), 1e9f);
  if (w <= 0 || h <= 0) return dist;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      if (zero[size_t(v + window.v0) * width + size_t(u + window.u0)]) dist[size_t(v) * w + u] = 0;
  const float d1 = 1.0f, d2 = 1.41421356f;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      float& d = dist[size_t(v) * w + u];
      if (u > 0) d = std::min(d, dist[size_t(v) * w + u - 1] + d1);
      if (v > 0) {
        d = std::min(d, dist[size_t(v - 1) * w + u] + d1);
        if (u > 0) d = std::min(d, dist[size_t(v - 1) * w + u - 1] + d2);
        if (u + 1 < w) d = std::min(d, dist[size_t(v - 1) * w + u + 1] + d2);
      }
    }
  for (int v = h - 1; v >= 0; --v)
    for (int u = w - 1; u >= 0; --u) {
      float& d = dist[size_t(v) * w + u];
      if (u + 1 < w) d = std::min(d, dist[size_t(v) * w + u + 1] + d1);
      if (v + 1 < h) {
        d = std::min(d, dist[size_t(v + 1) * w + u] + d1);
        if (u + 1 < w) d = std::min(d, dist[size_t(v + 1) * w + u + 1] + d2);
        if (u > 0) d = std::min(d, dist[size_t(v + 1) * w + u - 1] + d2);
      }
    }
  return dist;
}

namespace {

// How a point x (camera frame) moves in the image along direction g (pixels), in metres at its
// depth, per step of the body's motion about c (x' = x + ω × (x − c) + t; rotation vector,
// then translation): (x_z / f_x) ∂(g·uv)/∂x · ∂x/∂(ω, t).
Eigen::Matrix<double, 6, 1> imageJacobian(const CameraIntrinsics& K, const Vec3& x, const Vec3& c,
                                          const Vec2& g) {
  Eigen::Matrix<double, 1, 3> dd;  // ∂(g·uv)/∂x, pixels per metre
  dd << g.x() * K.fx / x.z(), g.y() * K.fy / x.z(),
      -(g.x() * K.fx * x.x() + g.y() * K.fy * x.y()) / (x.z() * x.z());
  Eigen::Matrix<double, 3, 6> dx;
  const Vec3 r = x - c;
  dx.leftCols<3>() << 0, r.z(), -r.y(), -r.z(), 0, r.x(), r.y(), -r.x(), 0;
  dx.rightCols<3>().setIdentity();
  return (x.z() / K.fx) * (dd * dx).transpose();
}

// The pairs of the points visible at T (palm to camera) within `gate` in depth, and the normal
// equations of n·(y − x) = (x × n)·ω + n·t (Huber-weighted at half the final gate).
// Which points are in front of the model's other points (and the occluders) at T.
std::vector<int> visiblePoints(const CameraIntrinsics& K, const std::vector<SurfacePoint>& points,
                               const std::vector<Vec3>& occluders, const Iso3& T) {
  PointBuffer buffer(K);
  // Each point moved once (kept for the visibility test).
  thread_local std::vector<Vec3> moved;
  moved.resize(points.size());
  for (size_t k = 0; k < points.size(); ++k) {
    moved[k] = T * points[k].p;
    buffer.add(moved[k]);
  }
  for (const Vec3& p : occluders) buffer.add(T * p);
  std::vector<int> visible;
  for (size_t k = 0; k < points.size(); ++k) {
    const Vec3& x = moved[k];
    if (x.z() > 0.1 && (T.linear() * points[k].n).dot(x) < 0 && buffer.visible(x))
      visible.push_back(int(k));
  }
  return visible;
}

// The pairs of the `visible` points at T within `gate` in depth (both cores).
Pairs pairUp(const DepthImage& depth, const CameraIntrinsics& K,
             const std::vector<SurfacePoint>& points, const std::vector<int>& visible,
             const Iso3& T, double gate, double huber, size_t handCount, double objectWeight,
             const Silhouette* outline = nullptr) {
  const Vec3 c = T.translation();  // rotations about the palm: x' = x + ω × (x − c) + t
  const int chunks = 8;
  std::vector<Pairs> part(chunks);
  parallelFor(0, chunks, [&](int chunk) {
    Pairs& P = part[size_t(chunk)];
    const size_t begin = visible.size() * size_t(chunk) / chunks;
    const size_t end = visible.size() * size_t(chunk + 1) / chunks;
    for (size_t i = begin; i < end; ++i) {
      const size_t k = size_t(visible[i]);
      const SurfacePoint& sp = points[k];
      const bool hand = k < handCount;
      const Vec3 x = T * sp.p;
      const Vec3 n = T.linear() * sp.n;
      if (x.z() <= 0.1 || n.dot(x) >= 0) continue;
      const Vec2 uv = K.project(x);
      const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
      if (u < 0 || v < 0 || u >= depth.width || v >= depth.height) continue;
      const float z = depth.depth_m[size_t(v) * depth.width + u];
      if (outline) {
        // Outside the outline: the distance to it (in metres at the point's depth), pulled
        // along the distance's gradient in the image.
        const float d = outline->at(u, v);
        if (d > 0.5f) {
          const Vec2 g(0.5 * (outline->at(u + 1, v) - outline->at(u - 1, v)),
                       0.5 * (outline->at(u, v + 1) - outline->at(u, v - 1)));
          const double scale = x.z() / K.fx;  // metres per pixel
          const Eigen::Matrix<double, 6, 1> J = imageJacobian(K, x, c, g);
          const double e = -scale * d;
          const double w = std::abs(e) < huber ? 1.0 : huber / std::abs(e);
          P.A += w * J * J.transpose();
          P.b += w * J * e;
          ++P.seeThrough;
          continue;
        }
      }
      if (!(z > 0)) continue;
      if (double(z) > x.z() + 0.015) {
        ++P.seeThrough;
        P.handSeeThrough += hand;
      }
      if (std::abs(double(z) - x.z()) > gate) continue;
      const Vec3 y = double(z) * K.rayZ1(u, v);
      const double e = n.dot(y - x);
      const double w =
          (hand ? 1.0 : objectWeight) * (std::abs(e) < huber ? 1.0 : huber / std::abs(e));
      Eigen::Matrix<double, 6, 1> J;
      J.head<3>() = (x - c).cross(n);
      J.tail<3>() = n;
      P.A += w * J * J.transpose();
      P.b += w * J * e;
      ++P.pairs;
      P.handPairs += hand;
      P.sq += e * e;
      P.var += std::min(sp.var, 0.25 * gate * gate);  // at most a pair's reach
    }
  });
  Pairs P;
  for (const Pairs& q : part) {  // in chunk order: the same sums for any thread count
    P.A += q.A;
    P.b += q.b;
    P.pairs += q.pairs;
    P.seeThrough += q.seeThrough;
    P.handPairs += q.handPairs;
    P.handSeeThrough += q.handSeeThrough;
    P.sq += q.sq;
    P.var += q.var;
  }
  return P;
}

// The outline the other way: frame pixels at the body's depths (`body`: hidden pixels zeroed)
// that no point of the body covers, each pulling the body's nearest point in the image towards
// it. The outline term alone pulls only points that project past the frame's outline; where the
// body's far end projects onto hidden pixels (a finger, the table) and its near end falls short
// of the frame's, nothing pulls it along (a pen held 8 mm off along its axis fits there).
struct Uncovered {
  Vec2 pixel;
  int point;  // index into the body's points, then its occluders
};

const Vec3& bodyPoint(const std::vector<SurfacePoint>& points, const std::vector<Vec3>& occluders,
                      int k) {
  return size_t(k) < points.size() ? points[size_t(k)].p : occluders[size_t(k) - points.size()];
}

// Projected points (those at z > 0.1) in 8-pixel buckets over the rectangle [u0, u1] × [v0, v1].
class PointBuckets {
 public:
  static constexpr int kSize = 8;
  PointBuckets(const std::vector<Vec2>& uv, const std::vector<double>& z, int u0, int v0, int u1,
               int v1)
      : uv_(uv), u0_(u0), v0_(v0), bw_((u1 - u0) / kSize + 1), bh_((v1 - v0) / kSize + 1) {
    first_.assign(size_t(bw_) * size_t(bh_), -1);
    next_.assign(uv.size(), -1);
    for (size_t k = 0; k < uv.size(); ++k) {
      if (z[k] <= 0.1) continue;
      const int bu = int(std::floor((uv[k].x() - u0) / kSize)),
                bv = int(std::floor((uv[k].y() - v0) / kSize));
      if (bu < 0 || bv < 0 || bu >= bw_ || bv >= bh_) continue;
      int& head = first_[size_t(bv) * bw_ + bu];
      next_[k] = head;
      head = int(k);
    }
  }
  // The nearest projected point to q (a pixel of the rectangle) among the buckets within
  // `reach` of its own (-1: none), its squared distance in *d2.
  int nearest(const Vec2& q, int reach, double* d2) const {
    const int bu = (int(q.x()) - u0_) / kSize, bv = (int(q.y()) - v0_) / kSize;
    int best = -1;
    *d2 = std::numeric_limits<double>::infinity();
    for (int j = std::max(0, bv - reach); j <= std::min(bh_ - 1, bv + reach); ++j)
      for (int i = std::max(0, bu - reach); i <= std::min(bw_ - 1, bu + reach); ++i)
        for (int k = first_[size_t(j) * bw_ + i]; k >= 0; k = next_[size_t(k)])
          if (const double e = (uv_[size_t(k)] - q).squaredNorm(); e < *d2) {
            *d2 = e;
            best = k;
          }
    return best;
  }
  // Whether a projected point lies within √r2 (at most 8 pixels) of q: its own bucket first.
  bool covered(const Vec2& q, double r2) const {
    const int bu = (int(q.x()) - u0_) / kSize, bv = (int(q.y()) - v0_) / kSize;
    for (int ring = 0; ring <= 1; ++ring)
      for (int j = std::max(0, bv - ring); j <= std::min(bh_ - 1, bv + ring); ++j)
        for (int i = std::max(0, bu - ring); i <= std::min(bw_ - 1, bu + ring); ++i) {
          if (ring == 1 && i != bu - 1 && i != bu + 1 && j != bv - 1 && j != bv + 1) continue;
          for (int k = first_[size_t(j) * bw_ + i]; k >= 0; k = next_[size_t(k)])
            if ((uv_[size_t(k)] - q).squaredNorm() <= r2) return true;
        }
    return false;
  }

 private:
  const std::vector<Vec2>& uv_;
  int u0_, v0_, bw_, bh_;
  std::vector<int> first_, next_;
};

// Every second pixel each way at the body's depths (within the body's image, widened by the
// gate) that no point of the body (its points and occluders at T) covers (none within 1.5 times
// their spacing); each with its nearest point, when that lies within the gate (in the image at its
// depth, and in depth).
std::vector<Uncovered> findUncovered(const DepthImage& body, const CameraIntrinsics& K,
                                     const Silhouette& outline,
                                     const std::vector<SurfacePoint>& points,
                                     const std::vector<Vec3>& occluders, const Iso3& T,
                                     double gate) {
  std::vector<Uncovered> out;
  const size_t n = points.size() + occluders.size();
  std::vector<Vec2> uv(n);
  std::vector<double> z(n);
  double uMin = 1e9, vMin = 1e9, uMax = -1e9, vMax = -1e9, zMin = 1e9;
  for (size_t k = 0; k < n; ++k) {
    const Vec3 x = T * bodyPoint(points, occluders, int(k));
    z[k] = x.z();
    if (x.z() <= 0.1) continue;
    uv[k] = K.project(x);
    uMin = std::min(uMin, uv[k].x());
    uMax = std::max(uMax, uv[k].x());
    vMin = std::min(vMin, uv[k].y());
    vMax = std::max(vMax, uv[k].y());
    zMin = std::min(zMin, x.z());
  }
  if (zMin > 1e8) return out;
  const double cover_m = 1.5 * outline.spacing_m;
  const double margin = std::min(80.0, std::ceil(gate * K.fx / zMin) + 2);
  const int u0 = std::max(0, int(std::floor(uMin - margin)));
  const int v0 = std::max(0, int(std::floor(vMin - margin)));
  const int u1 = std::min(body.width - 1, int(std::ceil(uMax + margin)));
  const int v1 = std::min(body.height - 1, int(std::ceil(vMax + margin)));
  if (u1 < u0 || v1 < v0) return out;
  const PointBuckets buckets(uv, z, u0, v0, u1, v1);
  const int reach = int(std::ceil(margin / PointBuckets::kSize)) + 1;
  for (int v = v0; v <= v1; v += 2)
    for (int u = u0; u <= u1; u += 2) {
      const double d = body.depth_m[size_t(v) * body.width + size_t(u)];
      if (!(d >= outline.near && d <= outline.far)) continue;
      const Vec2 q(u, v);
      const double cover = cover_m * K.fx / d;  // pixels
      if (buckets.covered(q, std::min(cover * cover, 64.0))) continue;
      double d2 = 0;
      const int k = buckets.nearest(q, reach, &d2);
      if (k < 0 || std::sqrt(d2) * z[size_t(k)] / K.fx > gate + cover_m ||
          std::abs(d - z[size_t(k)]) > gate)
        continue;
      out.push_back({q, k});
    }
  return out;
}

// The uncovered pixels' terms at T: each pixel's point moved towards it in the image until it
// covers the pixel, every term counting for the four pixels it stands for.
void addUncovered(const std::vector<Uncovered>& uncovered, const CameraIntrinsics& K,
                  const Silhouette& outline, const std::vector<SurfacePoint>& points,
                  const std::vector<Vec3>& occluders, const Iso3& T, double huber, Pairs* P) {
  const Vec3 c = T.translation();
  for (const Uncovered& un : uncovered) {
    const Vec3 x = T * bodyPoint(points, occluders, un.point);
    if (x.z() <= 0.1) continue;
    const Vec2 uv = K.project(x);
    const double scale = x.z() / K.fx;  // metres per pixel
    const double d = (un.pixel - uv).norm() - 1.5 * outline.spacing_m / scale;
    if (d <= 0) continue;
    // The point's image distance to the pixel, d, shrinks as the point moves along g.
    const Eigen::Matrix<double, 6, 1> J = imageJacobian(K, x, c, (un.pixel - uv).normalized());
    const double e = scale * d;
    const double w = 4 * (e < huber ? 1.0 : huber / e);
    P->A += w * J * J.transpose();
    P->b += w * J * e;
  }
}

// The residual a right alignment leaves: the sensor's noise and the model's own uncertainty at
// the paired points (a surface scanned from few frames or at grazing angles is known to
// millimetres only: a thin object's first model).
double expectedResidual(const Pairs& P, double sigma) {
  return P.pairs > 0 ? std::sqrt(sigma * sigma + P.var / P.pairs) : sigma;
}

TrackResult alignFrom(const DepthImage& depth, const CameraIntrinsics& K,
                      const std::vector<SurfacePoint>& points, size_t handCount,
                      const std::vector<Vec3>& occluders, const Iso3& T_C_palm, const Iso3& initial,
                      int iterations, double sigma, const TrackingOptions& o,
                      const Silhouette* outline = nullptr) {
  TrackResult r;
  Iso3 D = initial;
  const double shrink = std::pow(o.final_gate_m / o.gate_m, 1.0 / std::max(1, o.iterations - 1));
  double gate = o.gate_m;
  // The correction's parameters about the predicted palm: rotation vector and translation.
  auto params = [&](const Iso3& D) {
    const Iso3 T = D * T_C_palm;
    Eigen::Matrix<double, 6, 1> x;
    const Eigen::AngleAxisd aa(T.linear() * T_C_palm.linear().transpose());
    x.head<3>() = aa.angle() * aa.axis();
    x.tail<3>() = T.translation() - T_C_palm.translation();
    return x;
  };
  std::vector<int> visible;
  std::vector<Uncovered> uncovered;
  const bool withUncovered = outline && outline->spacing_m > 0;
  for (int it = 0; it < iterations; ++it, gate = std::max(o.final_gate_m, gate * shrink)) {
    const Iso3 T = D * T_C_palm;
    // Visibility and the uncovered pixels change little between iterations: every 8th.
    if (it % 8 == 0) visible = visiblePoints(K, points, occluders, T);
    if (withUncovered && it % 8 == 0)
      uncovered = findUncovered(depth, K, *outline, points, occluders, T, o.final_gate_m);
    Pairs P = pairUp(depth, K, points, visible, T, gate, 0.5 * o.final_gate_m, handCount,
                     o.object_weight, outline);
    if (withUncovered)
      addUncovered(uncovered, K, *outline, points, occluders, T, 0.5 * o.final_gate_m, &P);
    if (P.pairs < 6) break;
    // A weak prior towards the reported pose: directions the points do not constrain (a flat
    // face seen head-on slides freely) stay where the robot says, the others follow the data
    // (the prior is 0.2 % of their curvature).
    Eigen::Matrix<double, 6, 1> lambda;
    lambda.head<3>().setConstant(o.prior * P.pairs * 0.0025);  // ~(5 cm)² lever arms
    lambda.tail<3>().setConstant(o.prior * P.pairs);
    P.A.diagonal() += lambda;
    P.b -= lambda.cwiseProduct(params(D));
    const Eigen::Matrix<double, 6, 1> d = P.A.ldlt().solve(P.b);
    Iso3 step = Iso3::Identity();
    const Vec3 w = d.head<3>();
    if (w.norm() > 1e-12)
      step.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    // x' = R (x − c) + c + t, c the palm's current position.
    const Vec3 c = T.translation();
    step.translation() = c - step.linear() * c + d.tail<3>();
    D = step * D;
  }
  const Pairs last =
      pairUp(depth, K, points, visiblePoints(K, points, occluders, D * T_C_palm), D * T_C_palm,
             o.final_gate_m, 0.5 * o.final_gate_m, handCount, o.object_weight);
  r.hand_inliers = last.handPairs;
  r.hand_see_through = last.handSeeThrough;
  r.correction = D;
  r.inliers = last.pairs;
  r.see_through = last.seeThrough;
  r.rms_m = last.pairs > 0 ? std::sqrt(last.sq / last.pairs) : 0;
  const double spread = std::max(r.rms_m, 0.5 * sigma);
  r.information = last.A / (spread * spread);
  const double moved = ((D * T_C_palm).translation() - T_C_palm.translation()).norm();
  if (r.inliers < o.min_inliers) {
    r.refusal = TrackRefusal::kTooFewPoints;
    r.reason = "too few points to align (" + std::to_string(r.inliers) + ")";
  } else if (r.see_through * 10 > r.inliers) {
    r.refusal = TrackRefusal::kSeesThrough;
    r.reason = "the camera sees through " + std::to_string(r.see_through) + " aligned points";
  } else if (r.rms_m > o.max_rms_ratio * expectedResidual(last, sigma)) {
    r.refusal = TrackRefusal::kResidual;
    r.reason = "alignment residual " + std::to_string(r.rms_m * 1000) + " mm";
  } else if (moved > o.max_correction_m) {
    r.refusal = TrackRefusal::kCorrection;
    r.reason = "correction of " + std::to_string(moved * 100) + " cm";
  } else {
    r.ok = true;
  }
  return r;
}

}  // namespace

double correctionSignificance(const TrackResult& r, const Iso3& T_C_X, double pair_information) {
  Eigen::Matrix<double, 6, 1> x;
  const Eigen::AngleAxisd aa(r.correction.linear());
  x.head<3>() = aa.angle() * aa.axis();
  x.tail<3>() = (r.correction * T_C_X).translation() - T_C_X.translation();
  return x.dot(pair_information * (r.information * x));
}

TrackResult alignToDepth(const DepthImage& depth, const CameraIntrinsics& K,
                         const std::vector<SurfacePoint>& hand,
                         const std::vector<SurfacePoint>& object,
                         const std::vector<Vec3>& occluders, const Iso3& T_C_palm,
                         const std::vector<Iso3>& starts, double sigma, const TrackingOptions& o) {
  std::vector<SurfacePoint> points = hand;
  points.insert(points.end(), object.begin(), object.end());
  TrackResult best;
  bool first = true;
  // Each start as it is and after ICP from it; ok beats not ok, then the hand's fit decides:
  // its aligned points less ten times those the camera sees through (the hand's geometry is
  // known exactly; the model's is not).
  auto score = [](const TrackResult& t) { return t.hand_inliers - 10.0 * t.hand_see_through; };
  // The alignments are independent: on both cores at once (each pairs its points on both cores
  // too, when the other has finished), then compared in order.
  const int runs = 2 * int(starts.size());
  std::vector<TrackResult> results(static_cast<size_t>(runs));
  parallelFor(0, runs, [&](int k) {
    results[size_t(k)] = alignFrom(depth, K, points, hand.size(), occluders, T_C_palm,
                                   starts[size_t(k / 2)], k % 2 ? o.iterations : 0, sigma, o);
  });
  for (const TrackResult& r : results) {
    if (first || (r.ok && !best.ok) || (r.ok == best.ok && score(r) > score(best))) best = r;
    first = false;
  }
  return best;
}

namespace {
// How far apart the body's points lie (its points and occluders together): the median, over
// about 32 of them, of the distance to the nearest other point (a point given twice counts
// once). 0 with fewer than two.
double typicalSpacing(const std::vector<SurfacePoint>& points, const std::vector<Vec3>& occluders) {
  const size_t n = points.size() + occluders.size();
  std::vector<double> nearest;
  for (size_t k = 0; k < n; k += std::max<size_t>(1, n / 32)) {
    const Vec3& p = bodyPoint(points, occluders, int(k));
    double best = std::numeric_limits<double>::infinity();
    for (size_t j = 0; j < n; ++j)
      if (const double e = (bodyPoint(points, occluders, int(j)) - p).squaredNorm(); e > 1e-12)
        best = std::min(best, e);
    if (std::isfinite(best)) nearest.push_back(std::sqrt(best));
  }
  if (nearest.empty()) return 0;
  std::nth_element(nearest.begin(), nearest.begin() + long(nearest.size() / 2), nearest.end());
  return nearest[nearest.size() / 2];
}
}  // namespace

TrackResult alignBodyToDepth(const DepthImage& depth, const std::vector<uint8_t>& hidden,
                             const CameraIntrinsics& K, const std::vector<SurfacePoint>& points_X,
                             const std::vector<Vec3>& occluders_X, const Iso3& T_C_X,
                             double sigma_m, const TrackingOptions& options, UncoveredPull pull,
                             NoDepthPixels no_depth) {
  TrackingOptions o = options;
  o.object_weight = 1;      // no hand: the body's points alone
  DepthImage body = depth;  // hidden pixels pair with nothing
  if (!hidden.empty())
    for (size_t i = 0; i < hidden.size() && i < body.depth_m.size(); ++i)
      if (hidden[i]) body.depth_m[i] = 0;
  // The outline: pixels within 5 cm of the body's depths as given, the hidden ones (and with
  // kUnknown those without depth).
  double near = std::numeric_limits<double>::infinity(), far = 0;
  double uMin = depth.width, vMin = depth.height, uMax = 0, vMax = 0;
  for (const SurfacePoint& sp : points_X) {
    const Vec3 x = T_C_X * sp.p;
    near = std::min(near, x.z());
    far = std::max(far, x.z());
    if (x.z() <= 0.1) continue;
    const Vec2 uv = K.project(x);
    uMin = std::min(uMin, uv.x());
    uMax = std::max(uMax, uv.x());
    vMin = std::min(vMin, uv.y());
    vMax = std::max(vMax, uv.y());
  }
  // Its distances where the body's points project, as it moves within the gate, and 80 pixels
  // (about 10 cm at 0.7 m) around: a point farther outside the outline is pulled as hard (its
  // error is past the Huber bound) along the distance's gradient there.
  const double reach = 80 + std::ceil(o.gate_m * K.fx / std::max(0.1, near));
  PixelRect window{std::max(0, int(std::floor(uMin - reach))),
                   std::max(0, int(std::floor(vMin - reach))),
                   std::min(depth.width, int(std::ceil(uMax + reach)) + 1),
                   std::min(depth.height, int(std::ceil(vMax + reach)) + 1)};
  if (window.empty()) window = {0, 0, depth.width, depth.height};
  Silhouette outline = silhouette(depth, hidden, near - 0.05, far + 0.05, no_depth, window);
  if (pull == UncoveredPull::kFromStart) outline.spacing_m = typicalSpacing(points_X, occluders_X);
  // Without the pull (with it from the start for kFromStart), then the refinement.
  const TrackResult first = alignFrom(body, K, points_X, 0, occluders_X, T_C_X, Iso3::Identity(),
                                      o.iterations, sigma_m, o, &outline);
  if (pull != UncoveredPull::kAfterConverging || !first.ok) return first;
  outline.spacing_m = typicalSpacing(points_X, occluders_X);
  const TrackResult fine = alignFrom(body, K, points_X, 0, occluders_X, T_C_X, first.correction,
                                     o.iterations, sigma_m, o, &outline);
  if (!fine.ok) return first;
  // The pull pairs the frame's pixels that no point covers with the nearest points: where the
  // model lacks a part of the body (its far side unseen), the pixels of that part drag the
  // points over them, and the camera then sees through what was paired before.
  const int margin = std::max(3, first.inliers / 100);
  if (fine.see_through > first.see_through + margin || fine.inliers < first.inliers - 5 * margin)
    return first;
  return fine;
}

}  // namespace inhand
