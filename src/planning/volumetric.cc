#include "inhand/planning/volumetric.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/error.h"

namespace inhand {

std::string VolumetricOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (!(p_free < p_unknown)) return "p_free must be below p_unknown";
  if (!(p_occupied > p_unknown)) return "p_occupied must be above p_unknown";
  return {};
}

VolumetricScorer::VolumetricScorer(const TsdfVolume& volume, const DepthCameraOptions& camera,
                                   const VolumetricOptions& options)
    : volume_(&volume), camera_(camera), options_(options) {
  const std::string p = options.validate();
  if (!p.empty()) throw Error("volumetric options: " + p);
}

double VolumetricScorer::occupancy(size_t i) const {
  switch (volume_->state(i)) {
    case VoxelState::kUnknown:
      return options_.p_unknown;
    case VoxelState::kEmpty:
      return options_.p_free;
    case VoxelState::kObserved:
      return volume_->distance(i) > 0 ? options_.p_free : options_.p_occupied;
  }
  return options_.p_unknown;
}

namespace {
double entropyBits(double p) { return -(p * std::log2(p) + (1 - p) * std::log2(1 - p)); }
}  // namespace

double VolumetricScorer::traverse(const Vec3& o, const Vec3& dir, double t_max,
                                  VolumetricMetric metric) const {
  const TsdfVolume& V = *volume_;
  const double s = V.voxelSize();
  const Vec3 lo = V.origin() - Vec3::Constant(0.5 * s);
  const Vec3 hi = lo + s * V.dims().cast<double>();
  // Slab test against the grid's box.
  double t0 = 0, t1 = t_max;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(dir[k]) < 1e-12) {
      if (o[k] < lo[k] || o[k] > hi[k]) return 0;
      continue;
    }
    double a = (lo[k] - o[k]) / dir[k], b = (hi[k] - o[k]) / dir[k];
    if (a > b) std::swap(a, b);
    t0 = std::max(t0, a);
    t1 = std::min(t1, b);
  }
  if (!(t0 < t1)) return 0;
  // 3-D DDA from the entry point: each voxel cell on the ray visited once, in order.
  const Vec3 p = o + t0 * dir;
  Vec3i cell;
  int step[3];
  double tNext[3], tDelta[3];
  for (int k = 0; k < 3; ++k) {
    cell[k] = std::clamp(int(std::floor((p[k] - lo[k]) / s)), 0, V.dims()[k] - 1);
    if (dir[k] > 0) {
      step[k] = 1;
      tNext[k] = t0 + (lo[k] + (cell[k] + 1) * s - p[k]) / dir[k];
      tDelta[k] = s / dir[k];
    } else if (dir[k] < 0) {
      step[k] = -1;
      tNext[k] = t0 + (lo[k] + cell[k] * s - p[k]) / dir[k];
      tDelta[k] = -s / dir[k];
    } else {
      step[k] = 0;
      tNext[k] = std::numeric_limits<double>::infinity();
      tDelta[k] = std::numeric_limits<double>::infinity();
    }
  }
  // Rear-side entropy walks in three phases: up to the first occupied voxel (the observed
  // surface, visibility v_hit), through the surface's band of observed voxels (the TSDF's band
  // behind the zero crossing is one surface, not a wall of them: no attenuation), then the
  // unknown voxels right behind it, attenuated from v_hit, until the first voxel not unknown.
  double vis = 1, gain = 0;
  int phase = 0;
  double t = t0;
  while (t < t1 && vis >= options_.min_visibility) {
    const size_t i = V.index(cell.x(), cell.y(), cell.z());
    const double occ = occupancy(i);
    const bool unknown = V.state(i) == VoxelState::kUnknown;
    const bool occupied = V.state(i) == VoxelState::kObserved && V.distance(i) <= 0;
    if (metric == VolumetricMetric::kUnobservedVoxels) {
      if (unknown) gain += vis;
      vis *= 1 - occ;
    } else if (phase == 0) {
      if (occupied)
        phase = 1;
      else
        vis *= 1 - occ;
    } else if (phase == 1) {
      if (unknown) phase = 2;
    }
    if (metric == VolumetricMetric::kRearSideEntropy && phase == 2) {
      if (!unknown) break;
      gain += vis * entropyBits(occ);
      vis *= 1 - occ;
    }
    const int k =
        tNext[0] < tNext[1] ? (tNext[0] < tNext[2] ? 0 : 2) : (tNext[1] < tNext[2] ? 1 : 2);
    t = tNext[k];
    tNext[k] += tDelta[k];
    cell[k] += step[k];
    if (cell[k] < 0 || cell[k] >= V.dims()[k]) break;
  }
  return gain;
}

double VolumetricScorer::score(const Iso3& T_O_C, VolumetricMetric metric,
                               const std::vector<Occluder>& occluders) const {
  const CameraIntrinsics& K = camera_.intrinsics;
  const int s = options_.ray_stride;
  std::vector<Ray> rays;
  const Mat3 R = T_O_C.linear();
  const Vec3 o = T_O_C.translation();
  for (int v = 0; v < K.height; v += s)
    for (int u = 0; u < K.width; u += s) {
      Ray r;
      r.origin = o.cast<float>();
      r.dir = (R * K.rayZ1(u, v)).cast<float>();  // t = depth
      rays.push_back(r);
    }
  std::vector<double> tMax(rays.size(), std::numeric_limits<double>::infinity());
  if (!occluders.empty()) {
    RayScene robot;
    for (const Occluder& oc : occluders) robot.addInstance(*oc.scene, oc.T_O_scene);
    robot.commit();
    std::vector<Hit> hits(rays.size());
    robot.intersect(rays.data(), hits.data(), rays.size(), /*parallel=*/false);
    for (size_t i = 0; i < rays.size(); ++i)
      if (hits[i].valid()) tMax[i] = hits[i].t;
  }
  double total = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Vec3 d = rays[i].dir.cast<double>();
    const double n = d.norm();
    total += traverse(o, d / n, tMax[i] * n, metric);
  }
  return total * double(s) * double(s);
}

}  // namespace inhand
