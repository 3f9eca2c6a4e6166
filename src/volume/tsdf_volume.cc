#include "inhand/volume/tsdf_volume.h"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <istream>
#include <limits>
#include <ostream>
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

namespace {

template <class T>
void put(std::ostream& out, const T* data, size_t count) {
  out.write(reinterpret_cast<const char*>(data), std::streamsize(count * sizeof(T)));
}

template <class T>
bool get(std::istream& in, T* data, size_t count) {
  return bool(in.read(reinterpret_cast<char*>(data), std::streamsize(count * sizeof(T))));
}

// The bytes left to read in `in` (when it can seek; else the most a size_t holds), so that a
// count read from a file is checked against the file before anything is allocated for it.
uint64_t bytesLeft(std::istream& in) {
  const std::istream::pos_type at = in.tellg();
  if (at == std::istream::pos_type(-1)) return UINT64_MAX;
  in.seekg(0, std::ios::end);
  const std::istream::pos_type end = in.tellg();
  in.seekg(at);
  if (end == std::istream::pos_type(-1) || end < at) return UINT64_MAX;
  return uint64_t(end - at);
}

// Whether a float's bits are not all zero (-0 included: the data come back bit for bit).
bool nonZeroBits(float x) {
  uint32_t b;
  std::memcpy(&b, &x, sizeof b);
  return b != 0;
}

}  // namespace

void TsdfVolume::writeData(std::ostream& out) const {
  // The states' runs (lengths, values) and the sums' spans (first, count) where either sum is
  // non-zero: two scans of the volume, one on each core.
  std::vector<uint64_t> lengths;
  std::vector<uint8_t> values;
  std::vector<uint64_t> spans;
  const size_t n = state_.size();
  tbb::parallel_invoke(
      [&] {
        for (size_t i = 0; i < n;) {
          size_t j = i + 1;
          while (j < n && state_[j] == state_[i]) ++j;
          lengths.push_back(j - i);
          values.push_back(state_[i]);
          i = j;
        }
      },
      [&] {
        for (size_t i = 0; i < n;) {
          if (!nonZeroBits(sumWD_[i]) && !nonZeroBits(sumW_[i])) {
            ++i;
            continue;
          }
          size_t j = i + 1;
          while (j < n && (nonZeroBits(sumWD_[j]) || nonZeroBits(sumW_[j]))) ++j;
          spans.push_back(i);
          spans.push_back(j - i);
          i = j;
        }
      });
  // The states: the runs' count, their lengths, their values.
  const uint64_t runs = lengths.size();
  put(out, &runs, 1);
  put(out, lengths.data(), lengths.size());
  put(out, values.data(), values.size());
  // The sums: the spans' count, their (first, count) pairs, then the spans' Σw·d and Σw.
  const uint64_t count = spans.size() / 2;
  put(out, &count, 1);
  put(out, spans.data(), spans.size());
  for (const std::vector<float>* a : {&sumWD_, &sumW_})
    for (size_t k = 0; k < spans.size(); k += 2) put(out, a->data() + spans[k], spans[k + 1]);
}

std::string TsdfVolume::readData(std::istream& in) {
  const uint64_t n = state_.size();
  uint64_t runs = 0;
  if (!get(in, &runs, 1)) return "voxel data cut short";
  if (runs > n) return "more state runs than voxels";
  if (runs > bytesLeft(in) / 9) return "voxel data cut short";  // 8 + 1 bytes a run
  std::vector<uint64_t> lengths(runs);
  std::vector<uint8_t> values(runs);
  if (!get(in, lengths.data(), runs) || !get(in, values.data(), runs))
    return "voxel data cut short";
  uint64_t at = 0;
  for (uint64_t r = 0; r < runs; ++r) {
    if (lengths[r] == 0 || lengths[r] > n - at) return "state runs do not cover the volume";
    if (values[r] > uint8_t(VoxelState::kObserved)) return "invalid voxel state";
    std::fill_n(state_.begin() + std::ptrdiff_t(at), lengths[r], values[r]);
    at += lengths[r];
  }
  if (at != n) return "state runs do not cover the volume";
  uint64_t count = 0;
  if (!get(in, &count, 1)) return "voxel data cut short";
  if (count > n) return "more spans than voxels";
  if (count > bytesLeft(in) / 24) return "voxel data cut short";  // 16 + 2 × 4 bytes at least
  std::vector<uint64_t> spans(2 * count);
  if (!get(in, spans.data(), spans.size())) return "voxel data cut short";
  uint64_t end = 0;
  for (uint64_t k = 0; k < spans.size(); k += 2) {
    if (spans[k] < end || spans[k] >= n || spans[k + 1] == 0 || spans[k + 1] > n - spans[k])
      return "voxel spans out of order or outside the volume";
    end = spans[k] + spans[k + 1];
  }
  std::fill(sumWD_.begin(), sumWD_.end(), 0.f);
  std::fill(sumW_.begin(), sumW_.end(), 0.f);
  for (std::vector<float>* a : {&sumWD_, &sumW_})
    for (uint64_t k = 0; k < spans.size(); k += 2)
      if (!get(in, a->data() + spans[k], spans[k + 1])) return "voxel data cut short";
  return {};
}

}  // namespace inhand
