#pragma once
// Depth noise of a Kinect-v1-class sensor (Nguyen, Izadi, Lovell 2012; DESIGN.md).
// θ is the angle between the surface normal and the camera ray through the point.
#include <string>

#include "inhand/core/types.h"

namespace inhand {

struct NoiseModelOptions {
  double axial_c0_m = 0.0012;   // σ_z constant term, m
  double axial_c1 = 0.0019;     // σ_z quadratic coefficient, 1/m
  double axial_z0_m = 0.4;      // σ_z quadratic centre, m
  double grazing_c_m = 0.0001;  // σ_z grazing term coefficient (· 1/√z · θ²/(π/2−θ)²)
  double grazing_start_deg = 60.0;     // grazing term applies beyond this incidence angle
  double lateral_c0_px = 0.8;          // σ_L constant term, pixels
  double lateral_c1_px = 0.035;        // σ_L coefficient of θ/(π/2−θ), pixels
  bool quantize = true;                // disparity quantisation in rendering
  double disparity_step_px = 0.125;    // disparity resolution, pixels (1/8 sub-pixel)
  double discontinuity_jump_m = 0.01;  // a 4-neighbour this much farther/nearer marks an edge
  double discontinuity_factor = 3.0;   // σ multiplier at depth discontinuities (paper footnote 1)
  double max_incidence_deg = 85.0;     // θ is clamped here so σ stays finite

  std::string validate() const;
};

// Axial (along-ray depth) standard deviation, m, at depth z (m) and incidence θ (rad).
double axialSigma(const NoiseModelOptions& o, double z_m, double theta_rad);
// Lateral standard deviation in pixels at incidence θ (rad); times z/f for metres.
double lateralSigmaPx(const NoiseModelOptions& o, double theta_rad);
// Depth after disparity quantisation: d = f b / z rounded to the disparity step.
double quantizeDepth(double z_m, double f_px, double baseline_m, double step_px);

}  // namespace inhand
