#pragma once
// Depth images in metres (z along the optical axis); 0 means "no return".
// On disk: 16-bit grey PNG, one unit = depth_scale metres (default 1 mm), 0 = no return — the
// convention of ROS and the TUM RGB-D benchmark.
#include <filesystem>
#include <vector>

#include "inhand/core/types.h"

namespace inhand {

// Pixels [u0, u1) × [v0, v1) of an image.
struct PixelRect {
  int u0 = 0, v0 = 0, u1 = 0, v1 = 0;
  bool empty() const { return u0 >= u1 || v0 >= v1; }
};

struct DepthImage {
  int width = 0;
  int height = 0;
  std::vector<float> depth_m;  // row-major, width · height

  DepthImage() = default;
  DepthImage(int w, int h) : width(w), height(h), depth_m(size_t(w) * h, 0.f) {}
  float at(int u, int v) const { return depth_m[size_t(v) * width + u]; }
  float& at(int u, int v) { return depth_m[size_t(v) * width + u]; }
  int validCount() const;
};

// Writes a 16-bit PNG atomically; depths beyond 65535 units are written as 0 (no return).
// Throws Error naming the path on failure.
void writeDepthPng(const std::filesystem::path& path, const DepthImage& image,
                   double depth_scale_m = 0.001);

// Reads a 16-bit single-channel PNG. Throws Error naming the file when it is missing, not a PNG,
// not 16-bit grey, or (when expected_width > 0) not expected_width × expected_height.
DepthImage readDepthPng(const std::filesystem::path& path, double depth_scale_m = 0.001,
                        int expected_width = 0, int expected_height = 0);

}  // namespace inhand
