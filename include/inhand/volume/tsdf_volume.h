#pragma once
// The probabilistic signed-distance volume of the paper (§III-B, after Curless & Levoy): a dense
// grid in the object frame O. Each voxel stores Σ w·d and Σ w, with w = 1/σ² of each
// measurement (so 1/Σw is the fused variance, eq. 6), and a state: unknown (never seen), empty
// (seen through), observed (inside the truncation band of a measurement).
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

enum class VoxelState : uint8_t { kUnknown = 0, kEmpty = 1, kObserved = 2 };

struct VolumeOptions {
  double voxel_size_m = 0.002;  // edge of a voxel, m
  double truncation_m = 0.0;    // half-width μ of the signed-distance band, m; 0: 4 voxels
  // > 0: each measurement reaches this many of its σ behind its smoothed surface (at least a
  // voxel across the surface, at most μ: farLimit in integrate.h), so that the two sides of a wall
  // thinner than μ do not cancel; 0: μ behind every measurement's depth.
  double band_sigmas = 0.0;
  // Update the voxels from each pixel's smoothed surface (smoothedSurface in integrate.h: the plane
  // fitted to its 5×5 neighbourhood on the same surface) rather than its raw depth.
  bool smooth_depth = false;
  double memory_budget_mb = 2048;  // a volume needing more memory than this is refused, MiB

  double truncation() const { return truncation_m > 0 ? truncation_m : 4.0 * voxel_size_m; }
  std::string validate() const;  // empty when valid, else names the field
};

class TsdfVolume {
 public:
  static constexpr size_t kBytesPerVoxel = 2 * sizeof(float) + 1;

  // Covers `box_O` (object frame) with voxels of options.voxel_size_m; samples sit at
  // origin + i·voxel_size. Throws Error when the options are invalid or the volume would exceed
  // the memory budget (the message gives the size it would need).
  TsdfVolume(const Aabb& box_O, const VolumeOptions& options);

  static Vec3i dimsFor(const Aabb& box_O, double voxel_size_m);
  static double megabytesFor(const Vec3i& dims) {
    return double(dims.prod()) * kBytesPerVoxel / (1 << 20);
  }

  const Vec3i& dims() const { return dims_; }
  const Vec3& origin() const { return origin_; }
  double voxelSize() const { return voxel_; }
  double truncation() const { return truncation_; }
  double bandSigmas() const { return bandSigmas_; }  // VolumeOptions::band_sigmas
  bool smoothDepth() const { return smoothDepth_; }  // VolumeOptions::smooth_depth
  size_t voxelCount() const { return state_.size(); }
  size_t index(int x, int y, int z) const {
    return (size_t(z) * size_t(dims_.y()) + size_t(y)) * size_t(dims_.x()) + size_t(x);
  }
  Vec3 point(int x, int y, int z) const { return origin_ + voxel_ * Vec3(x, y, z); }

  VoxelState state(size_t i) const { return VoxelState(state_[i]); }
  // Fused signed distance (m, positive in front of the surface); valid for observed voxels.
  float distance(size_t i) const { return sumW_[i] > 0 ? sumWD_[i] / sumW_[i] : 0.f; }
  // Fused variance 1/Σw (m²); infinite for voxels without measurements.
  float variance(size_t i) const;
  size_t countState(VoxelState s) const;

  // The voxels' data in a compact binary form (native byte order): the states as runs, then Σw·d
  // and Σw of the voxels where either is non-zero (bit for bit), as spans. A scan's volume is
  // mostly unknown or empty: tens of times smaller than the three arrays. readData reads what
  // writeData wrote into a volume of the same dims, bit for bit; it returns "" or what is wrong
  // (the volume's contents are then unspecified).
  void writeData(std::ostream& out) const;
  std::string readData(std::istream& in);

  // Raw storage for the integration kernels.
  float* sumWD() { return sumWD_.data(); }
  float* sumW() { return sumW_.data(); }
  uint8_t* states() { return state_.data(); }
  const float* sumWD() const { return sumWD_.data(); }
  const float* sumW() const { return sumW_.data(); }
  const uint8_t* states() const { return state_.data(); }

 private:
  Vec3i dims_;
  Vec3 origin_;
  double voxel_;
  double truncation_;
  double bandSigmas_ = 0;
  bool smoothDepth_ = false;
  std::vector<float> sumWD_, sumW_;
  std::vector<uint8_t> state_;
};

}  // namespace inhand
