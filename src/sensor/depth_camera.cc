#include "inhand/sensor/depth_camera.h"

#include <cmath>

namespace inhand {

std::string CameraIntrinsics::validate() const {
  if (width <= 0 || width > 16384) return "width must be in 1..16384";
  if (height <= 0 || height > 16384) return "height must be in 1..16384";
  if (!(fx > 0) || !std::isfinite(fx)) return "fx must be a positive number";
  if (!(fy > 0) || !std::isfinite(fy)) return "fy must be a positive number";
  if (!std::isfinite(cx)) return "cx must be a finite number";
  if (!std::isfinite(cy)) return "cy must be a finite number";
  return {};
}

std::string DepthCameraOptions::validate() const {
  std::string e = intrinsics.validate();
  if (!e.empty()) return "intrinsics." + e;
  if (!projector_C.allFinite()) return "projector_C must be finite";
  if (!(min_range_m > 0)) return "min_range_m must be > 0";
  if (!(max_range_m > min_range_m)) return "max_range_m must be > min_range_m";
  if (!(max_incidence_deg > 0 && max_incidence_deg < 90))
    return "max_incidence_deg must be in (0, 90)";
  if (!(max_projector_incidence_deg > 0 && max_projector_incidence_deg < 90))
    return "max_projector_incidence_deg must be in (0, 90)";
  return {};
}

}  // namespace inhand
