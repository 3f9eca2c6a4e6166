#pragma once
// Volumetric view metrics of Isler et al. (ICRA 2016), the baselines of `inhand eval`: rays of the
// candidate's depth camera are traversed voxel by voxel (3-D DDA, each voxel once) through the
// TsdfVolume up to the first robot surface (hand, arm, table) or the volume's edge, and each voxel
// contributes its information weighted by its visibility, the product of (1 − p) over the voxels
// before it on the ray.
//
// Occupancy p of a voxel from the volume's states:
//   unknown (never seen)                          → p_unknown  (0.5)
//   empty (seen through), or observed with fused
//   distance > 0 (in front of the surface)        → p_free     (0: a clear line of sight; an
//                                                   OctoMap-like 0.12 would leave 10⁻⁵ of the
//                                                   visibility after the ~90 free voxels
//                                                   between the volume's edge and the object)
//   observed with fused distance ≤ 0 (the surface
//   and just behind it)                           → p_occupied (0.9)
// Metrics per ray (each sampled ray stands for stride² pixels):
//   unobserved voxels  Σ vis·[unknown] over the whole ray                      (voxels)
//   rear-side entropy  Σ vis·H(p) over the unknown voxels right behind the first observed
//                      surface on the ray (the surface's band passed unattenuated, the
//                      visibility continuing from the surface's own)       (bits; H(0.5) = 1)
// The object's never-seen interior is unknown too, so rear-side entropy stays high on every view
// of a closed object; it tells apart views only by how much surface they see.
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/planning/view_quality.h"
#include "inhand/volume/tsdf_volume.h"

namespace inhand {

enum class VolumetricMetric { kUnobservedVoxels, kRearSideEntropy };

struct VolumetricOptions {
  int ray_stride = 8;  // every n-th pixel in u and v (80×60 rays at 640×480)
  double p_unknown = 0.5, p_free = 0.0, p_occupied = 0.9;
  double min_visibility = 1e-3;  // a ray stops when its visibility falls below this

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.integer("ray_stride", o.ray_stride, "volumetric baselines: every n-th pixel in u and v",
              Range::closed(1, 64));
    v.num("p_unknown", o.p_unknown, "occupancy of an unknown voxel", Range::open(0, 1));
    v.num("p_free", o.p_free, "occupancy of a voxel in front of the surface (< p_unknown)",
          Range::closedOpen(0, 1));
    v.num("p_occupied", o.p_occupied,
          "occupancy of a voxel on or just behind the surface (> p_unknown)", Range::open(0, 1));
    v.num("min_visibility", o.min_visibility, "a ray stops when its visibility falls below this",
          Range::open(0, 1));
  }
  std::string validate() const;
};

class VolumetricScorer {
 public:
  VolumetricScorer(const TsdfVolume& volume, const DepthCameraOptions& camera,
                   const VolumetricOptions& options = {});
  // The metric for a camera at T_O_C with `occluders` (robot surfaces, frame O) cutting rays.
  double score(const Iso3& T_O_C, VolumetricMetric metric,
               const std::vector<Occluder>& occluders = {}) const;
  // Occupancy of voxel i by the mapping above.
  double occupancy(size_t i) const;

 private:
  // One ray: origin and unit direction in O, cut at t_max (m).
  double traverse(const Vec3& o, const Vec3& dir, double t_max, VolumetricMetric metric) const;
  const TsdfVolume* volume_;
  DepthCameraOptions camera_;
  VolumetricOptions options_;
};

}  // namespace inhand
