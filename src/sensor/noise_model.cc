#include "inhand/sensor/noise_model.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace inhand {

std::string NoiseModelOptions::validate() const {
  if (!(axial_c0_m >= 0)) return "axial_c0_m must be >= 0";
  if (!(axial_c1 >= 0)) return "axial_c1 must be >= 0";
  if (!(grazing_c_m >= 0)) return "grazing_c_m must be >= 0";
  if (!(grazing_start_deg >= 0 && grazing_start_deg < 90))
    return "grazing_start_deg must be in [0, 90)";
  if (!(lateral_c0_px >= 0)) return "lateral_c0_px must be >= 0";
  if (!(lateral_c1_px >= 0)) return "lateral_c1_px must be >= 0";
  if (!(disparity_step_px > 0)) return "disparity_step_px must be > 0";
  if (!(discontinuity_jump_m > 0)) return "discontinuity_jump_m must be > 0";
  if (!(discontinuity_factor >= 1)) return "discontinuity_factor must be >= 1";
  if (!(max_incidence_deg > 0 && max_incidence_deg < 90))
    return "max_incidence_deg must be in (0, 90)";
  if (axial_c0_m + axial_c1 == 0) return "axial_c0_m and axial_c1 cannot both be 0";
  return {};
}

double axialSigma(const NoiseModelOptions& o, double z_m, double theta_rad) {
  double theta = std::min(std::abs(theta_rad), o.max_incidence_deg * M_PI / 180.0);
  double dz = z_m - o.axial_z0_m;
  double sigma = o.axial_c0_m + o.axial_c1 * dz * dz;
  if (theta > o.grazing_start_deg * M_PI / 180.0) {
    double r = theta / (M_PI / 2 - theta);
    sigma += o.grazing_c_m / std::sqrt(std::max(z_m, 1e-3)) * r * r;
  }
  return sigma;
}

double lateralSigmaPx(const NoiseModelOptions& o, double theta_rad) {
  double theta = std::min(std::abs(theta_rad), o.max_incidence_deg * M_PI / 180.0);
  return o.lateral_c0_px + o.lateral_c1_px * theta / (M_PI / 2 - theta);
}

double quantizeDepth(double z_m, double f_px, double baseline_m, double step_px) {
  if (!(z_m > 0)) return z_m;
  const double steps = f_px * baseline_m / (z_m * step_px);  // the disparity in steps
  // Rounded half away from zero; positive steps by truncation (no libm call per pixel).
  const double q =
      (steps >= 0 && steps < 0x1.0p52 ? double(int64_t(steps + 0.5)) : std::round(steps)) * step_px;
  if (q <= 0) return z_m;
  return f_px * baseline_m / q;
}

}  // namespace inhand
