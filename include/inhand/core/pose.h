#pragma once
#include <array>
#include <optional>
#include <string>

#include "inhand/core/types.h"

namespace inhand {

// Camera pose T_W_C (camera frame C: x right, y down, z forward, the OpenCV/ROS optical frame)
// at eye_W looking at target_W. up_W is the approximate world "up" that maps to −y in the image.
// Falls back to another up vector when the viewing direction is parallel to up_W.
Iso3 lookAt(const Vec3& eye_W, const Vec3& target_W, const Vec3& up_W = Vec3::UnitZ());

// Builds a pose from 16 row-major numbers. Returns nullopt with a reason in *why when the matrix
// is not a rigid transform (rotation farther than tol from orthonormal, det != +1, bottom row not
// 0 0 0 1, non-finite entries). A rotation within tol is replaced by the nearest rotation: pose
// files written with 7–8 significant digits deviate by ~1e-4 (max |RᵀR − I|), which
// *deviation (when given) reports.
std::optional<Iso3> poseFromRowMajor(const std::array<double, 16>& m, std::string* why,
                                     double tol = 1e-2, double* deviation = nullptr);
// (Written as JSON by isoJson, core/json_util.h.)

// Re-orthonormalises the rotation part (nearest rotation, via SVD).
Iso3 orthonormalized(const Iso3& T);

// The angle of the rotation between the orientations of a and b, rad (0..π).
double rotationBetween(const Iso3& a, const Iso3& b);

// Unit vectors spread evenly on the sphere (Fibonacci lattice); deterministic.
std::vector<Vec3> fibonacciSphere(int count);

}  // namespace inhand
