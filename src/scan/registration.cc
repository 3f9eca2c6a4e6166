#include "inhand/scan/registration.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/robot/collision.h"

namespace inhand {

// The model's observed triangles (all three vertices observed): centroids and outward normals,
// every k-th so that about `budget` remain (none for budget <= 0), moved by T; with
// `with_variance`, each point's variance the mean of its corners' (registration.h).
std::vector<SurfacePoint> observedSurface(const ObjectModel& m, int budget, const Iso3& T,
                                          bool with_variance) {
  std::vector<size_t> observed;
  for (size_t t = 0; t < m.mesh.triangles.size(); ++t) {
    const Tri& f = m.mesh.triangles[t];
    if (m.observed[size_t(f[0])] && m.observed[size_t(f[1])] && m.observed[size_t(f[2])])
      observed.push_back(t);
  }
  std::vector<SurfacePoint> points;
  const size_t step = std::max<size_t>(1, observed.size() / size_t(std::max(1, budget)) + 1);
  for (size_t k = 0; budget > 0 && k < observed.size(); k += step) {
    const Tri& f = m.mesh.triangles[observed[k]];
    const Vec3 a = m.mesh.vertices[size_t(f[0])].cast<double>();
    const Vec3 b = m.mesh.vertices[size_t(f[1])].cast<double>();
    const Vec3 c = m.mesh.vertices[size_t(f[2])].cast<double>();
    const Vec3 n = (b - a).cross(c - a);
    if (n.norm() < 1e-12) continue;
    double var = 0;
    if (with_variance && m.variance.size() == m.mesh.vertices.size())
      var =
          (double(m.variance[size_t(f[0])]) + m.variance[size_t(f[1])] + m.variance[size_t(f[2])]) /
          3;
    points.push_back({T * ((a + b + c) / 3), T.linear() * n.normalized(), var});
  }
  return points;
}

// Every k-th vertex of the model (about 6000), moved by T: what hides the surface behind it.
std::vector<Vec3> modelOccluders(const ObjectModel& m, const Iso3& T) {
  std::vector<Vec3> out;
  const size_t every = std::max<size_t>(1, m.mesh.vertices.size() / 6000 + 1);
  for (size_t k = 0; k < m.mesh.vertices.size(); k += every)
    out.push_back(T * m.mesh.vertices[k].cast<double>());
  return out;
}

RegistrationModel registrationModel(const ObjectModel& m, const TrackingOptions& o) {
  return {observedSurface(m, std::max(2000, o.max_object_points), Iso3::Identity(), true),
          modelOccluders(m, Iso3::Identity())};
}

namespace {
// The nearest model point (frame O) of every 5 mm cell within 4.5 cm of the model: a
// breadth-first sweep out from the cells the points lie in (near enough to the nearest for
// pairing). Built once per model, shared by every start.
struct NearestGrid {
  const std::vector<Vec3>& model_O;
  double cell = 0.005;
  Aabb bounds;
  Eigen::Vector3i n;
  std::vector<int> nearest;

  explicit NearestGrid(const std::vector<Vec3>& model) : model_O(model) {
    for (const Vec3& p : model_O) bounds.extend(p);
    bounds.min.array() -= 0.045;
    bounds.max.array() += 0.045;
    n = ((bounds.max - bounds.min) / cell).array().ceil().cast<int>().max(1);
    nearest.assign(size_t(n.prod()), -1);
    std::vector<Eigen::Vector3i> front, next;
    for (size_t i = 0; i < model_O.size(); ++i)
      if (const auto c = cellOf(model_O[i]); c && nearest[index(*c)] < 0) {
        nearest[index(*c)] = int(i);
        front.push_back(*c);
      }
    for (int ring = 0; ring < 9 && !front.empty(); ++ring, front.swap(next)) {
      next.clear();
      for (const Eigen::Vector3i& c : front)
        for (int a = 0; a < 3; ++a)
          for (int step : {-1, 1}) {
            Eigen::Vector3i d = c;
            d[a] += step;
            if (d[a] < 0 || d[a] >= n[a] || nearest[index(d)] >= 0) continue;
            nearest[index(d)] = nearest[index(c)];
            next.push_back(d);
          }
    }
  }
  size_t index(const Eigen::Vector3i& c) const {
    return (size_t(c.z()) * size_t(n.y()) + size_t(c.y())) * size_t(n.x()) + size_t(c.x());
  }
  std::optional<Eigen::Vector3i> cellOf(const Vec3& p) const {
    const Eigen::Vector3i c = ((p - bounds.min) / cell).array().floor().cast<int>();
    if ((c.array() < 0).any() || (c.array() >= n.array()).any()) return std::nullopt;
    return c;
  }
};

// A coarse alignment of the model points (frame O) with a frame's points (frame B) from T_B_O:
// point-to-point ICP, each frame point paired with the nearest model point (of the grid's
// neighbouring cells) within a gate that shrinks from 4 cm to 1 cm, the rigid motion of the pairs
// by Umeyama's method (Eigen), 20 rounds. It brings a start within the reach of the fine
// alignment (alignBodyToDepth pairs along rays within centimetres).
Iso3 coarseAlign(const std::vector<Vec3>& frame_B, const NearestGrid& grid, Iso3 T) {
  const std::vector<Vec3>& model_O = grid.model_O;
  const Eigen::Vector3i& n = grid.n;
  for (int round = 0; round < 20; ++round) {
    const double gate = std::max(0.01, 0.04 - 0.003 * round);
    const Iso3 T_O_B = T.inverse();
    Eigen::Matrix3Xd src(3, 0), dst(3, 0);
    std::vector<Vec3> a, b;
    for (const Vec3& p_B : frame_B) {
      const Vec3 p = T_O_B * p_B;
      const auto c = grid.cellOf(p);
      if (!c) continue;
      // The nearest of the neighbouring cells' nearest points.
      int found = -1;
      double best = gate * gate;
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const Eigen::Vector3i d = *c + Eigen::Vector3i(dx, dy, dz);
            if ((d.array() < 0).any() || (d.array() >= n.array()).any()) continue;
            const int k = grid.nearest[grid.index(d)];
            if (k < 0) continue;
            if (const double e = (model_O[size_t(k)] - p).squaredNorm(); e < best) {
              best = e;
              found = k;
            }
          }
      if (found < 0) continue;
      a.push_back(T * model_O[size_t(found)]);
      b.push_back(p_B);
    }
    if (a.size() < 20) break;
    src.resize(3, long(a.size()));
    dst.resize(3, long(b.size()));
    for (size_t i = 0; i < a.size(); ++i) {
      src.col(long(i)) = a[i];
      dst.col(long(i)) = b[i];
    }
    const Eigen::Matrix4d U = Eigen::umeyama(src, dst, false);
    Iso3 D = Iso3::Identity();
    D.linear() = U.block<3, 3>(0, 0);
    D.translation() = U.block<3, 1>(0, 3);
    T = D * T;
    if (D.translation().norm() < 1e-5 && Eigen::AngleAxisd(D.linear()).angle() < 1e-4) break;
  }
  return T;
}
}  // namespace

std::vector<std::pair<std::optional<Iso3>, TrackResult>> registerModelAt(
    const RegistrationModel& model, const DepthImage& depth, const std::vector<uint8_t>& hidden,
    const Iso3& T_B_C, const CameraIntrinsics& K, const NoiseModelOptions& noise,
    const TrackingOptions& options, const std::vector<Iso3>& starts, bool in_hand) {
  if (hidden.size() != depth.depth_m.size())
    throw Error("registerModelAt: the hidden mask does not match the image");
  // The frame's points near the starts (every other pixel each way, not hidden), for the coarse
  // alignment; the model's observed points.
  Vec3 near = Vec3::Zero();
  for (const Iso3& T : starts) near += T.translation();
  near /= double(std::max<size_t>(1, starts.size()));
  std::vector<Vec3> frame_B, model_O;
  for (int v = 0; v < depth.height; v += 2)
    for (int u = 0; u < depth.width; u += 2) {
      const size_t i = size_t(v) * size_t(depth.width) + size_t(u);
      if (hidden[i] || !(depth.depth_m[i] > 0)) continue;
      const Vec3 p = T_B_C * (double(depth.depth_m[i]) * K.rayZ1(u, v));
      if ((p - near).norm() < 0.3) frame_B.push_back(p);
    }
  for (const SurfacePoint& sp : model.points) model_O.push_back(sp.p);
  std::vector<std::pair<std::optional<Iso3>, TrackResult>> out(starts.size());
  const NearestGrid grid(model_O);
  parallelFor(0, int(starts.size()), [&](int k) {
    const Iso3 T_C_O = T_B_C.inverse() * coarseAlign(frame_B, grid, starts[size_t(k)]);
    TrackResult r =
        alignBodyToDepth(depth, hidden, K, model.points, model.occluders, T_C_O,
                         axialSigma(noise, T_C_O.translation().z(), 0), options,
                         in_hand ? UncoveredPull::kAfterConverging : UncoveredPull::kOff,
                         in_hand ? NoDepthPixels::kUnknown : NoDepthPixels::kOutside);
    if (r.ok) out[size_t(k)].first = T_B_C * r.correction * T_C_O;
    out[size_t(k)].second = std::move(r);
  });
  return out;
}

double surfaceGap(const TriangleDistanceIndex& surface_O, const std::vector<Vec3>& points_O,
                  const Iso3& T_a, const Iso3& T_b) {
  if (points_O.empty() || surface_O.empty()) return 0;
  const Iso3 T_ab = T_a.inverse() * T_b;
  const size_t stride = std::max<size_t>(1, points_O.size() / 1000);
  double sum = 0;
  int n = 0;
  for (size_t i = 0; i < points_O.size(); i += stride, ++n)
    sum += surface_O.distance(T_ab * points_O[i]);
  return sum / n;
}

// How far a depth frame bears out object points `points_B`: of those in view whose pixel
// measured something, the fraction measured within 1 cm of the point's depth, against those
// measured more than 1 cm behind it (the camera sees through where the point should be). Points
// in front of their measurement (occluded) and robot pixels do not count. -1: none counted.
SupportCounts depthSupportCounts(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K,
                                 const std::vector<uint8_t>& hidden,
                                 const std::vector<Vec3>& points_B) {
  const Iso3 T_C_B = T_B_C.inverse();
  int support = 0, against = 0;
  for (const Vec3& p_B : points_B) {
    const Vec3 p = T_C_B * p_B;
    if (p.z() <= 0.1) continue;
    const Vec2 uv = K.project(p);
    const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
    if (u < 0 || v < 0 || u >= d.width || v >= d.height) continue;
    const size_t i = size_t(v) * d.width + u;
    const float z = d.depth_m[i];
    if (!(z > 0) || (!hidden.empty() && hidden[i])) continue;
    if (std::abs(z - p.z()) < 0.01)
      ++support;
    else if (z > p.z() + 0.01)
      ++against;
  }
  return {support, against};
}

double depthSupport(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K,
                    const std::vector<uint8_t>& hidden, const std::vector<Vec3>& points_B) {
  const SupportCounts c = depthSupportCounts(d, T_B_C, K, hidden, points_B);
  return c.support + c.against == 0 ? -1.0 : double(c.support) / (c.support + c.against);
}

// A frame from the sensor that can be used: one that arrived (the camera's size) with depth in
// it, non-finite depths as no return; up to `tries` captures. nullopt when none came.
std::optional<DepthImage> captureUsable(DepthSensor& sensor, const FrameChecks& checks, int tries) {
  const CameraIntrinsics& K = sensor.camera().intrinsics;
  for (int t = 0; t < tries; ++t) {
    DepthImage d = sensor.capture();
    if (d.width != K.width || d.height != K.height) continue;
    for (float& z : d.depth_m)
      if (!(std::isfinite(z) && z >= 0)) z = 0;
    if (d.validCount() < checks.min_valid_fraction * double(d.depth_m.size())) continue;
    return d;
  }
  return std::nullopt;
}

std::vector<Vec3> observedVertices(const ObjectModel& model) {
  std::vector<Vec3> out;
  for (size_t k = 0; k < model.mesh.vertices.size(); k += 7)
    if (model.observed.empty() || model.observed[k])
      out.push_back(model.mesh.vertices[k].cast<double>());
  return out;
}

bool fingersClosedOnNothing(const RobotModel& robot, const JointVector& q) {
  for (const FingerInfo& f : robot.fingers())
    if (std::abs(q[f.variable] - f.closed) > 1e-3) return false;
  return true;
}

int pointsInsideHand(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                     const std::vector<Vec3>& points_O) {
  const HandGeometry hand(robot, q, Iso3::Identity());  // the palm frame
  const Iso3 T_palm_O = T_O_palm.inverse();
  int n = 0;
  for (const Vec3& p : points_O) n += hand.distanceWithin(T_palm_O * p, 0.001) < -0.003;
  return n;
}

void markBelow(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K, double below_z,
               std::vector<uint8_t>* marked) {
  for (int v = 0; v < d.height; ++v)
    for (int u = 0; u < d.width; ++u) {
      const size_t i = size_t(v) * size_t(d.width) + size_t(u);
      const float z = d.depth_m[i];
      if (z > 0 && (T_B_C * (double(z) * K.rayZ1(u, v))).z() < below_z) (*marked)[i] = 1;
    }
}

std::vector<Iso3> heldObjectStarts(const DepthImage& d, const std::vector<uint8_t>& hidden,
                                   const Iso3& T_B_C, const CameraIntrinsics& K, double table_top_z,
                                   const Iso3& T_B_O, const std::vector<Vec3>& points_O) {
  // Front-most per cell of 8 x 8 pixels (the points are sparser than the pixels).
  const int cell = 8, cw = (d.width + cell - 1) / cell, ch = (d.height + cell - 1) / cell;
  std::vector<float> front(size_t(cw) * size_t(ch), std::numeric_limits<float>::infinity());
  std::vector<std::pair<Vec3, int>> inView;  // camera frame, cell
  Vec3 centre_B = Vec3::Zero();
  double radius = 0;
  for (const Vec3& p : points_O) centre_B += T_B_O * p;
  centre_B /= double(std::max<size_t>(1, points_O.size()));
  for (const Vec3& p : points_O) {
    radius = std::max(radius, (T_B_O * p - centre_B).norm());
    const Vec3 c = T_B_C.inverse() * (T_B_O * p);
    if (c.z() <= 0) continue;
    const Vec2 uv = K.project(c);
    const int u = int(std::floor(uv.x())), v = int(std::floor(uv.y()));
    if (u < 0 || v < 0 || u >= d.width || v >= d.height) continue;
    const int k = (v / cell) * cw + u / cell;
    inView.emplace_back(c, k);
    front[size_t(k)] = std::min(front[size_t(k)], float(c.z()));
  }
  Vec3 shown = Vec3::Zero();
  int nShown = 0;
  for (const auto& [c, k] : inView)
    if (c.z() <= front[size_t(k)] + 0.01) {
      shown += T_B_C * c;
      ++nShown;
    }
  Vec3 seen = Vec3::Zero();
  int nSeen = 0;
  const double reach = radius + 0.06;  // how far the object may have moved, and its size
  for (int v = 0; v < d.height; ++v)
    for (int u = 0; u < d.width; ++u) {
      const size_t i = size_t(v) * size_t(d.width) + size_t(u);
      const float z = d.depth_m[i];
      if (!(z > 0) || (!hidden.empty() && hidden[i])) continue;
      const Vec3 p = T_B_C * (double(z) * K.rayZ1(u, v));
      if (p.z() < table_top_z + 0.01 || (p - centre_B).norm() > reach) continue;
      seen += p;
      ++nSeen;
    }
  if (nSeen < 50 || nShown == 0) return {};
  seen /= nSeen;
  shown /= nShown;
  std::vector<Iso3> starts;
  for (double turn : {0.0, M_PI / 4, -M_PI / 4}) {
    Iso3 R = Iso3::Identity();
    R.linear() = Eigen::AngleAxisd(turn, Vec3::UnitZ()).toRotationMatrix();
    // Turned about the vertical through the seen points' centre, the shown points' centre there.
    Iso3 T = T_B_O;
    T.translation() += seen - shown;
    Iso3 about = Iso3::Identity();
    about.translation() = seen;
    starts.push_back(about * R * about.inverse() * T);
  }
  return starts;
}

}  // namespace inhand
