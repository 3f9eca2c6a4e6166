#include "inhand/volume/tsdf_volume.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "inhand/core/error.h"

namespace inhand {

std::string VolumeOptions::validate() const {
  if (!(voxel_size_m > 0 && voxel_size_m <= 1.0)) return "voxel_size_m must be in (0, 1] m";
  if (!(truncation_m >= 0 && std::isfinite(truncation_m))) return "truncation_m must be >= 0";
  if (truncation_m > 0 && truncation_m < voxel_size_m)
    return "truncation_m must be at least one voxel (voxel_size_m)";
  if (!(memory_budget_mb > 0)) return "memory_budget_mb must be > 0";
  if (!(band_sigmas >= 0 && band_sigmas <= 100)) return "band_sigmas must be in [0, 100]";
  return {};
}

Vec3i TsdfVolume::dimsFor(const Aabb& box, double voxel) {
  Vec3 n = (box.size() / voxel).array().ceil() + 1.0;
  return Vec3i(int(std::min(n.x(), 1e9)), int(std::min(n.y(), 1e9)), int(std::min(n.z(), 1e9)));
}

TsdfVolume::TsdfVolume(const Aabb& box, const VolumeOptions& options) {
  std::string problem = options.validate();
  if (!problem.empty()) throw Error("volume options: " + problem);
  if (box.empty() || !box.min.allFinite() || !box.max.allFinite())
    throw Error("volume bounds are empty or not finite");
  voxel_ = options.voxel_size_m;
  truncation_ = options.truncation();
  bandSigmas_ = options.band_sigmas;
  smoothDepth_ = options.smooth_depth;
  origin_ = box.min;
  dims_ = dimsFor(box, voxel_);
  double needed = megabytesFor(dims_);
  if (needed > options.memory_budget_mb) {
    std::ostringstream s;
    s.precision(4);
    s << "the volume would need " << needed << " MiB (" << dims_.x() << " x " << dims_.y() << " x "
      << dims_.z() << " voxels of " << voxel_ * 1000 << " mm over " << box.size().x() << " x "
      << box.size().y() << " x " << box.size().z() << " m), over the memory budget of "
      << options.memory_budget_mb << " MiB; use larger voxels, tighter bounds or a larger budget";
    throw Error(s.str());
  }
  size_t n = size_t(dims_.prod());
  sumWD_.assign(n, 0.f);
  sumW_.assign(n, 0.f);
  state_.assign(n, uint8_t(VoxelState::kUnknown));
}

float TsdfVolume::variance(size_t i) const {
  return sumW_[i] > 0 ? 1.f / sumW_[i] : std::numeric_limits<float>::infinity();
}

size_t TsdfVolume::countState(VoxelState s) const {
  size_t n = 0;
  for (uint8_t v : state_) n += v == uint8_t(s);
  return n;
}

}  // namespace inhand
