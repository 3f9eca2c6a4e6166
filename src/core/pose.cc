#include "inhand/core/pose.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <sstream>

namespace inhand {

Iso3 lookAt(const Vec3& eye_W, const Vec3& target_W, const Vec3& up_W) {
  Vec3 z = (target_W - eye_W).normalized();
  Vec3 up = up_W.normalized();
  if (std::abs(z.dot(up)) > 0.999) up = std::abs(z.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  Vec3 x = z.cross(up).normalized();  // image right: y = z × x points down, −y points along up
  Vec3 y = z.cross(x);
  Iso3 T = Iso3::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = eye_W;
  return T;
}

std::optional<Iso3> poseFromRowMajor(const std::array<double, 16>& m, std::string* why, double tol,
                                     double* deviation) {
  auto fail = [&](const std::string& reason) -> std::optional<Iso3> {
    if (why) *why = reason;
    return std::nullopt;
  };
  for (double v : m)
    if (!std::isfinite(v)) return fail("has a non-finite entry");
  Mat4 M;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) M(r, c) = m[r * 4 + c];
  const double rowTol = 1e-6;  // pose files write the bottom row exactly
  if (std::abs(M(3, 0)) > rowTol || std::abs(M(3, 1)) > rowTol || std::abs(M(3, 2)) > rowTol ||
      std::abs(M(3, 3) - 1.0) > rowTol)
    return fail("bottom row is not [0, 0, 0, 1]");
  Mat3 R = M.topLeftCorner<3, 3>();
  double det = R.determinant();
  if (std::abs(det) < 1e-9) return fail("rotation part is singular (determinant 0)");
  if (det < 0) return fail("rotation part has determinant < 0 (a reflection)");
  double err = (R.transpose() * R - Mat3::Identity()).cwiseAbs().maxCoeff();
  if (deviation) *deviation = err;
  if (err > tol) {
    std::ostringstream s;
    s << "rotation part is not orthonormal (max |R^T R - I| = " << err << ")";
    return fail(s.str());
  }
  Iso3 T = Iso3::Identity();
  T.linear() = R;
  T.translation() = M.topRightCorner<3, 1>();
  return orthonormalized(T);
}

double rotationBetween(const Iso3& a, const Iso3& b) {
  return Eigen::AngleAxisd(b.linear() * a.linear().transpose()).angle();
}

Iso3 orthonormalized(const Iso3& T) {
  Eigen::JacobiSVD<Mat3> svd(T.linear(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 R = svd.matrixU() * svd.matrixV().transpose();
  if (R.determinant() < 0) {
    Mat3 U = svd.matrixU();
    U.col(2) *= -1;
    R = U * svd.matrixV().transpose();
  }
  Iso3 out = Iso3::Identity();
  out.linear() = R;
  out.translation() = T.translation();
  return out;
}

std::vector<Vec3> fibonacciSphere(int count) {
  std::vector<Vec3> dirs;
  dirs.reserve(count > 0 ? count : 0);
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < count; ++i) {
    double z = 1.0 - (2.0 * i + 1.0) / count;
    double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    double phi = golden * i;
    dirs.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
  }
  return dirs;
}

}  // namespace inhand
