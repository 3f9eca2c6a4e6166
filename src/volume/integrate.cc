#include "inhand/volume/integrate.h"

#include <emmintrin.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>

#include "inhand/core/error.h"
#include "inhand/core/internal/fast_math.h"
#include "inhand/core/internal/parallel.h"

namespace inhand {

namespace {
// The volume's eight corner samples in the camera frame.
std::array<Vec3, 8> cornersInCamera(const TsdfVolume& volume, const Iso3& T_C_O) {
  const Vec3 lo = volume.origin();
  const Vec3 hi = volume.point(volume.dims().x() - 1, volume.dims().y() - 1, volume.dims().z() - 1);
  std::array<Vec3, 8> out;
  for (int c = 0; c < 8; ++c)
    out[size_t(c)] = T_C_O * Vec3((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(),
                                  (c & 4) ? hi.z() : lo.z());
  return out;
}
}  // namespace

PixelRect volumeImageRect(const TsdfVolume& volume, const Iso3& T_O_C, const CameraIntrinsics& K) {
  const PixelRect all{0, 0, K.width, K.height};
  double u0 = 1e300, v0 = 1e300, u1 = -1e300, v1 = -1e300;
  for (const Vec3& p : cornersInCamera(volume, T_O_C.inverse())) {
    if (!(p.z() > 1e-6)) return all;
    const Vec2 uv = K.project(p);
    u0 = std::min(u0, uv.x());
    v0 = std::min(v0, uv.y());
    u1 = std::max(u1, uv.x());
    v1 = std::max(v1, uv.y());
  }
  // Voxels round to the nearest pixel: floor(x + 0.5); one more pixel each side for safety.
  auto clampTo = [](double x, int n) { return int(std::clamp(x, 0.0, double(n))); };
  PixelRect r;
  r.u0 = clampTo(std::floor(u0 + 0.5) - 1, K.width);
  r.v0 = clampTo(std::floor(v0 + 0.5) - 1, K.height);
  r.u1 = clampTo(std::floor(u1 + 0.5) + 2, K.width);
  r.v1 = clampTo(std::floor(v1 + 0.5) + 2, K.height);
  return r;
}

std::vector<float> measurementSigma(const DepthImage& depth, const CameraIntrinsics& K,
                                    const NoiseModelOptions& noise, const PixelRect* region,
                                    const std::vector<uint8_t>* carve_only) {
  const int w = depth.width, h = depth.height;
  std::vector<float> sigma(size_t(w) * h, 0.f);
  INHAND_CHECK(!carve_only || carve_only->size() == sigma.size(), "carve mask size != depth size");
  const PixelRect r = region ? *region : PixelRect{0, 0, w, h};
  // K.rayZ1's two quotients per column and row, computed once (the same values: a point is
  // rayZ1(u, v) · D to the last bit).
  std::vector<double> xs(static_cast<size_t>(w)), ys(static_cast<size_t>(h));
  for (int u = 0; u < w; ++u) xs[size_t(u)] = (double(u) - K.cx) / K.fx;
  for (int v = 0; v < h; ++v) ys[size_t(v)] = (double(v) - K.cy) / K.fy;
  // Below the grazing angle the incidence does not enter the noise model: no acos needed there.
  const double cosGrazing = std::cos(noise.grazing_start_deg * M_PI / 180.0);
  const double jump = noise.discontinuity_jump_m;
  parallelFor(std::max(0, r.v0), std::min(h, r.v1), [&](int v) {
    const float* row = depth.depth_m.data() + size_t(v) * w;
    const float* up = v > 0 ? row - w : nullptr;
    const float* down = v + 1 < h ? row + w : nullptr;
    const double y = ys[size_t(v)];
    const int uEnd = std::min(w, r.u1);
    for (int u = std::max(0, r.u0); u < uEnd; ++u) {
      // Runs without a depth skipped four pixels at a time.
      while (u + 4 <= uEnd &&
             !_mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(row + u), _mm_setzero_ps())))
        u += 4;
      if (u >= uEnd) break;
      const double D = row[u];
      if (!(D > 0)) continue;
      if (carve_only) {
        const uint8_t c = (*carve_only)[size_t(v) * w + u];
        if (c && c != kCarveToSurface) continue;
      }
      const double x = xs[size_t(u)];
      const Vec3 P(x * D, y * D, 1.0 * D);
      bool edge = false;
      // Tangent along each image axis from the neighbours that lie on the same surface (the
      // point of depth Dn at column uu, row yy: (x_uu·Dn, y_vv·Dn, Dn)).
      Vec3 tu = Vec3::Zero(), tv = Vec3::Zero();
      auto side = [&](double Dn, double xn, double yn, double s, Vec3* t) {
        if (!(Dn > 0) || std::abs(Dn - D) > jump) {
          edge = true;
          return;
        }
        *t += s * (Vec3(xn * Dn, yn * Dn, 1.0 * Dn) - P);
      };
      if (u > 0) side(row[u - 1], xs[size_t(u - 1)], y, -1, &tu);
      if (u + 1 < w) side(row[u + 1], xs[size_t(u + 1)], y, 1, &tu);
      if (up) side(up[u], x, ys[size_t(v - 1)], -1, &tv);
      if (down) side(down[u], x, ys[size_t(v + 1)], 1, &tv);
      const Vec3 n = tu.cross(tv);
      double theta = 0.0;
      // |cos| of the incidence: |n · P| / (|n| |P|), one square root.
      const double nn = n.squaredNorm();
      if (nn > 0) {
        const double c = std::min(1.0, std::abs(n.dot(P)) / std::sqrt(nn * P.squaredNorm()));
        theta = c > cosGrazing ? 0.0 : std::acos(c);
      }
      double s;
      if (theta == 0.0) {  // axialSigma head-on, inline
        const double dz = D - noise.axial_z0_m;
        s = noise.axial_c0_m + noise.axial_c1 * dz * dz;
      } else {
        s = axialSigma(noise, D, theta);
      }
      if (edge) s *= noise.discontinuity_factor;
      sigma[size_t(v) * w + u] = float(s);
    }
  });
  return sigma;
}

// The far side of the silhouette against the robot: its voxels of the object's rim read these
// pixels (a voxel reads its nearest pixel, and the sensor's lateral noise moves returns across
// silhouettes), and they must not pull those voxels out of the surface (a 12 mm pen held in front
// of the palm was thinned by 0.3 mm on average, dented 1-2 mm along its sides).
void farSideOfSilhouettesReference(const DepthImage& depth, float jump_m, const PixelRect& rect,
                                   std::vector<uint8_t>* carve) {
  std::vector<uint8_t>& c = *carve;
  const int W = depth.width, H = depth.height, R = 2;
  std::vector<uint8_t> rim(c.size(), 0);
  for (int v = std::max(0, rect.v0); v < std::min(H, rect.v1); ++v)
    for (int u = std::max(0, rect.u0); u < std::min(W, rect.u1); ++u) {
      const size_t i = size_t(v) * W + u;
      if (c[i] != kCarveToSurface) continue;
      const float z = depth.depth_m[i];
      bool nearer = false;
      for (int vv = std::max(0, v - R); vv <= std::min(H - 1, v + R) && !nearer; ++vv)
        for (int uu = std::max(0, u - R); uu <= std::min(W - 1, u + R) && !nearer; ++uu) {
          const size_t j = size_t(vv) * W + uu;
          const float zn = depth.depth_m[j];
          nearer = zn > 0 && z - zn > jump_m && c[j] == 0;
        }
      rim[i] = nearer;
    }
  for (size_t i = 0; i < c.size(); ++i)
    if (rim[i]) c[i] = kCarveUnknownToSurface;
}

void farSideOfSilhouettesOnlyCarveUnknown(const DepthImage& depth, float jump_m,
                                          const PixelRect& rect, std::vector<uint8_t>* carve) {
  std::vector<uint8_t>& c = *carve;
  const int W = depth.width, H = depth.height, R = 2;
  INHAND_CHECK(c.size() == depth.depth_m.size(), "carve mask size != depth size");
  const int u0 = std::max(0, rect.u0), u1 = std::min(W, rect.u1);
  const int v0 = std::max(0, rect.v0), v1 = std::min(H, rect.v1);
  if (u0 >= u1 || v0 >= v1) return;
  // The unmarked depths' minimum over each row's 5 pixels, for the rows the rect's 5 × 5 windows
  // reach (+∞ where none). z − zn is monotone in zn under rounding, so z − min zn > jump_m exactly
  // when some zn passes the direct test.
  const float inf = std::numeric_limits<float>::infinity();
  const int rv0 = std::max(0, v0 - R), rv1 = std::min(H, v1 + R);
  const int cw = u1 - u0;
  std::vector<float> rowMin(size_t(rv1 - rv0) * size_t(cw), inf);
  parallelFor(rv0, rv1, [&](int v) {
    const float* z = depth.depth_m.data() + size_t(v) * W;
    const uint8_t* m = c.data() + size_t(v) * W;
    float* out = rowMin.data() + size_t(v - rv0) * cw;
    for (int u = u0; u < u1; ++u) {
      float best = inf;
      for (int uu = std::max(0, u - R); uu <= std::min(W - 1, u + R); ++uu)
        if (m[uu] == 0 && z[uu] > 0) best = std::min(best, z[uu]);
      out[u - u0] = best;
    }
  });
  std::vector<uint8_t> rim(size_t(v1 - v0) * size_t(cw), 0);
  parallelFor(v0, v1, [&](int v) {
    const int a = std::max(rv0, v - R), b = std::min(rv1 - 1, v + R);
    for (int u = u0; u < u1; ++u) {
      const size_t i = size_t(v) * W + u;
      if (c[i] != kCarveToSurface) continue;
      float best = inf;
      for (int vv = a; vv <= b; ++vv)
        best = std::min(best, rowMin[size_t(vv - rv0) * cw + (u - u0)]);
      rim[size_t(v - v0) * cw + (u - u0)] = best < inf && depth.depth_m[i] - best > jump_m;
    }
  });
  for (int v = v0; v < v1; ++v)
    for (int u = u0; u < u1; ++u)
      if (rim[size_t(v - v0) * cw + (u - u0)]) c[size_t(v) * W + u] = kCarveUnknownToSurface;
}

DepthImage nearestAround(const DepthImage& depth, const std::vector<uint8_t>& mask, int radius) {
  if (mask.size() != depth.depth_m.size())
    throw Error("nearestAround: " + std::to_string(mask.size()) + " mask values for " +
                std::to_string(depth.depth_m.size()) + " pixels");
  DepthImage out = depth;
  const int W = depth.width, H = depth.height;
  parallelFor(0, H, [&](int v) {
    for (int u = 0; u < W; ++u) {
      const size_t i = size_t(v) * size_t(W) + size_t(u);
      if (!mask[i]) continue;
      float nearest = depth.depth_m[i] > 0 ? depth.depth_m[i] : std::numeric_limits<float>::max();
      for (int vv = std::max(0, v - radius); vv <= std::min(H - 1, v + radius); ++vv)
        for (int uu = std::max(0, u - radius); uu <= std::min(W - 1, u + radius); ++uu) {
          const float z = depth.depth_m[size_t(vv) * size_t(W) + size_t(uu)];
          if (z > 0 && z < nearest) nearest = z;
        }
      if (nearest < std::numeric_limits<float>::max()) out.depth_m[i] = nearest;
    }
  });
  return out;
}

std::vector<uint8_t> depthDiscontinuities(const DepthImage& depth, double jump_m,
                                          const PixelRect* region) {
  constexpr int kGapPx = 8;
  const int w = depth.width, h = depth.height;
  std::vector<uint8_t> edge(size_t(w) * h, 0);
  const PixelRect r = region ? *region : PixelRect{0, 0, w, h};
  const float* Dp = depth.depth_m.data();
  parallelFor(std::max(0, r.v0), std::min(h, r.v1), [&](int v) {
    for (int u = std::max(0, r.u0); u < std::min(w, r.u1); ++u) {
      const double D = Dp[size_t(v) * w + u];
      if (!(D > 0)) continue;
      // Along (du, dv): the neighbour farther by more than the jump, or a gap of no return whose
      // first return within kGapPx lies farther (or none does, or the image ends): the pixel is
      // at a silhouette, not beside a shadow on its own face or behind a nearer edge.
      auto off = [&](int du, int dv) {
        int uu = u + du, vv = v + dv;
        if (uu < 0 || vv < 0 || uu >= w || vv >= h) return false;
        double Dn = Dp[size_t(vv) * w + uu];
        if (Dn > 0) return Dn - D > jump_m;
        for (int k = 1; k < kGapPx; ++k) {
          uu += du;
          vv += dv;
          if (uu < 0 || vv < 0 || uu >= w || vv >= h) return true;
          Dn = Dp[size_t(vv) * w + uu];
          if (Dn > 0) return Dn - D > jump_m;
        }
        return true;
      };
      edge[size_t(v) * w + u] = off(-1, 0) || off(1, 0) || off(0, -1) || off(0, 1);
    }
  });
  return edge;
}

namespace {

void checkInputs(const DepthImage& depth, const CameraIntrinsics& K,
                 const std::vector<float>& sigma, const std::vector<uint8_t>* carve) {
  INHAND_CHECK(depth.width == K.width && depth.height == K.height, "depth size != intrinsics");
  INHAND_CHECK(sigma.size() == depth.depth_m.size(), "sigma size != depth size");
  INHAND_CHECK(!carve || carve->size() == depth.depth_m.size(), "carve mask size != depth size");
}

}  // namespace

namespace {

// The smoothed surface of pixel (u, v) (depth D) from its plane z = D + a + b·du + c·dv.
SmoothedSurface planeAt(const CameraIntrinsics& K, int u, int v, float D, double a, double b,
                        double c) {
  SmoothedSurface out;
  const double Z = double(D) + a;
  out.depth = float(Z);
  // The plane's normal from its tangents along u and v, P(u, v) = Z(u, v)·ray(u, v) with
  // ray = (x, y, 1): tu = b·ray + (Z / fx, 0, 0), tv = c·ray + (0, Z / fy, 0), and
  // tu × tv = Z / (fx·fy) · m, m = (−b·fx, −c·fy, b·x·fx + c·y·fy + Z), where m · ray = Z.
  if (!(Z != 0.0)) return out;  // no normal (and none from a NaN)
  const double x = (double(u) - K.cx) / K.fx, y = (double(v) - K.cy) / K.fy;
  const double mx = -b * K.fx, my = -c * K.fy, mz = b * x * K.fx + c * y * K.fy + Z;
  const double q = (mx * mx + my * my + mz * mz) * (x * x + y * y + 1.0);
  if (q > 0) out.cos_incidence = float(std::min(1.0, std::abs(Z) / std::sqrt(q)));
  return out;
}

// The whole (2r + 1)² neighbourhood: symmetric offsets make the normal equations diagonal. `sz`,
// `suz`, `svz`: the sums of z = Dn − D, du·z and dv·z.
SmoothedSurface planeSurface(const CameraIntrinsics& K, int u, int v, float D, double sz,
                             double suz, double svz) {
  constexpr int r = kSmoothingRadius, full = (2 * r + 1) * (2 * r + 1);
  const double s2 = double(full) * r * (r + 1) / 3.0;  // Σ du² over the square
  return planeAt(K, u, v, D, sz / double(full), suz / s2, svz / s2);
}

// The first index in [a, b) where bytes[i] != 0, or b; eight bytes at a time.
int firstNonZero(const uint8_t* bytes, int a, int b) {
  int i = a;
  for (; i + 8 <= b; i += 8) {
    uint64_t word;
    std::memcpy(&word, bytes + i, 8);
    if (word) break;
  }
  for (; i < b; ++i)
    if (bytes[i]) return i;
  return b;
}

// The least-squares plane's sums over the neighbours on the pixel's surface (z = Dn − D).
struct PlaneSums {
  double n = 0, su = 0, sv = 0, suu = 0, suv = 0, svv = 0, sz = 0, suz = 0, svz = 0;
};

SmoothedSurface surfaceFromSums(const CameraIntrinsics& K, int u, int v, float D,
                                const PlaneSums& s) {
  SmoothedSurface out;
  out.depth = float(double(D) + s.sz / s.n);  // too few neighbours for a plane: their mean, head-on
  out.cos_incidence = 1.f;
  if (s.n < 6) return out;
  constexpr int r = kSmoothingRadius, full = (2 * r + 1) * (2 * r + 1);
  if (int(s.n) == full) return planeSurface(K, u, v, D, s.sz, s.suz, s.svz);
  // The normal equations [n su sv; su suu suv; sv suv svv]·(a, b, c) = (sz, suz, svz): their
  // entries are small integers, so the determinant and the adjugate are exact.
  const double c00 = s.suu * s.svv - s.suv * s.suv, c01 = s.sv * s.suv - s.su * s.svv,
               c02 = s.su * s.suv - s.sv * s.suu, c11 = s.n * s.svv - s.sv * s.sv,
               c12 = s.su * s.sv - s.n * s.suv, c22 = s.n * s.suu - s.su * s.su;
  const double det = s.n * c00 + s.su * c01 + s.sv * c02;
  if (!(std::abs(det) > 1e-6)) return out;
  const double a = (c00 * s.sz + c01 * s.suz + c02 * s.svz) / det,
               b = (c01 * s.sz + c11 * s.suz + c12 * s.svz) / det,
               c = (c02 * s.sz + c12 * s.suz + c22 * s.svz) / det;
  if (!(std::isfinite(a) && std::isfinite(b) && std::isfinite(c))) return out;
  return planeAt(K, u, v, D, a, b, c);
}

// Per 5-bit code of which neighbours du = −2..2 of a row lie on the surface (bit du + 2): their
// count, Σ du and Σ du².
struct RowCode {
  int n, su, suu;
};
constexpr std::array<RowCode, 32> kRowCodes = [] {
  std::array<RowCode, 32> t{};
  for (int code = 0; code < 32; ++code)
    for (int k = 0; k < 5; ++k)
      if (code >> k & 1) {
        t[size_t(code)].n += 1;
        t[size_t(code)].su += k - 2;
        t[size_t(code)].suu += (k - 2) * (k - 2);
      }
  return t;
}();

// The sums of a pixel at least kSmoothingRadius from every image border, a row of five
// neighbours at a time in SSE2 (the same comparisons as the reference's, in single precision).
// Only for a finite D ≥ 2·max_jump: every neighbour on the surface then lies within
// [D / 2, 3D / 2], so the sums of their depths (weighted by du, dv ∈ −2..2) are exact in double,
// as are the reference's sums of z = Dn − D; the two give the same sums, bit for bit.
PlaneSums interiorPlaneSums(const float* depth, int w, int u, int v, float D, float max_jump) {
  static_assert(kSmoothingRadius == 2, "written for rows of five");
  const __m128 vD = _mm_set1_ps(D), vJ = _mm_set1_ps(max_jump), zero = _mm_setzero_ps();
  const __m128 absMask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128d wLo = _mm_set_pd(-1.0, -2.0), wHi = _mm_set_pd(1.0, 0.0);  // du of lanes 0-3
  __m128d sumD = _mm_setzero_pd(), sumUD = _mm_setzero_pd(), sumVD = _mm_setzero_pd();
  double lastD = 0, lastUD = 0, lastVD = 0;  // the fifth neighbour (du = 2) of each row
  int n = 0, su = 0, sv = 0, suu = 0, suv = 0, svv = 0;
  for (int dv = -2; dv <= 2; ++dv) {
    const float* row = depth + size_t(v + dv) * w + u - 2;
    const __m128 x = _mm_loadu_ps(row);
    const __m128 on = _mm_and_ps(_mm_cmpgt_ps(x, zero),
                                 _mm_cmpngt_ps(_mm_and_ps(_mm_sub_ps(x, vD), absMask), vJ));
    const __m128 xOn = _mm_and_ps(x, on);
    const float x4 = row[4];
    const bool on4 = x4 > 0.f && !(std::abs(x4 - D) > max_jump);
    const RowCode& c = kRowCodes[size_t(_mm_movemask_ps(on) | (int(on4) << 4))];
    n += c.n;
    su += c.su;
    suu += c.suu;
    sv += dv * c.n;
    suv += dv * c.su;
    svv += dv * dv * c.n;
    const __m128d lo = _mm_cvtps_pd(xOn), hi = _mm_cvtps_pd(_mm_movehl_ps(xOn, xOn));
    const __m128d rowSum = _mm_add_pd(lo, hi);
    const __m128d dvs = _mm_set1_pd(double(dv));
    sumD = _mm_add_pd(sumD, rowSum);
    sumUD = _mm_add_pd(sumUD, _mm_add_pd(_mm_mul_pd(lo, wLo), _mm_mul_pd(hi, wHi)));
    sumVD = _mm_add_pd(sumVD, _mm_mul_pd(rowSum, dvs));
    const double d4 = on4 ? double(x4) : 0.0;
    lastD += d4;
    lastUD += 2.0 * d4;
    lastVD += double(dv) * d4;
  }
  auto total = [](__m128d a, double b) {
    return _mm_cvtsd_f64(a) + _mm_cvtsd_f64(_mm_unpackhi_pd(a, a)) + b;
  };
  PlaneSums s{double(n), double(su), double(sv), double(suu), double(suv), double(svv), 0, 0, 0};
  // Σ z = Σ Dn − n·D and likewise weighted: every term and the results exact.
  const double Dd = double(D);
  s.sz = total(sumD, lastD) - s.n * Dd;
  s.suz = total(sumUD, lastUD) - s.su * Dd;
  s.svz = total(sumVD, lastVD) - s.sv * Dd;
  return s;
}

}  // namespace

SmoothedSurface smoothedSurface(const DepthImage& depth, const CameraIntrinsics& K, int u, int v,
                                float max_jump) {
  const float D = depth.at(u, v);
  if (!(D > 0.f)) return {};
  // Least-squares plane z = a + b·du + c·dv through the neighbours on the same surface.
  PlaneSums s;
  const int r = kSmoothingRadius;
  for (int dv = -r; dv <= r; ++dv) {
    const int vv = v + dv;
    if (vv < 0 || vv >= depth.height) continue;
    for (int du = -r; du <= r; ++du) {
      const int uu = u + du;
      if (uu < 0 || uu >= depth.width) continue;
      const float Dn = depth.at(uu, vv);
      if (!(Dn > 0.f) || std::abs(Dn - D) > max_jump) continue;
      const double z = double(Dn) - double(D);  // relative to the centre: well conditioned
      s.n += 1;
      s.su += du;
      s.sv += dv;
      s.suu += du * du;
      s.suv += du * dv;
      s.svv += dv * dv;
      s.sz += z;
      s.suz += du * z;
      s.svz += dv * z;
    }
  }
  return surfaceFromSums(K, u, v, D, s);
}

namespace {
// smoothedSurfaces' sums along one image row (`row`, `w` wide) for columns uMin .. uMax (index 0
// at uMin): the five depths around each column (invalid as 0) summed, summed weighted by du, their
// minimum and maximum; minimum 0 where the five do not all lie in the row.
inline void rowFiveSums(const float* row, int w, int uMin, int uMax, double* s0, double* s1,
                        float* mn, float* mx) {
  for (int u = uMin; u <= uMax; ++u) {
    const size_t j = size_t(u - uMin);
    if (u < 2 || u + 2 >= w) {
      mn[j] = 0.f;
      continue;
    }
    float c[5];
    for (int t = 0; t < 5; ++t) {
      const float x = row[u - 2 + t];
      c[t] = x > 0.f ? x : 0.f;
    }
    s0[j] = double(c[0]) + double(c[1]) + double(c[2]) + double(c[3]) + double(c[4]);
    s1[j] = 2.0 * (double(c[4]) - double(c[0])) + (double(c[3]) - double(c[1]));
    mn[j] = std::min(std::min(std::min(c[0], c[1]), std::min(c[2], c[3])), c[4]);
    mx[j] = std::max(std::max(std::max(c[0], c[1]), std::max(c[2], c[3])), c[4]);
  }
}
}  // namespace

void smoothedSurfaces(const DepthImage& depth, const CameraIntrinsics& K, const PixelRect& rect,
                      const uint8_t* fit, float max_jump,
                      const std::function<void(size_t, const SmoothedSurface&)>& out) {
  static_assert(kSmoothingRadius == 2, "the sliding sums below are written for 5 x 5");
  const int w = depth.width, h = depth.height;
  const PixelRect r{std::max(0, rect.u0), std::max(0, rect.v0), std::min(w, rect.u1),
                    std::min(h, rect.v1)};
  if (r.empty()) return;
  constexpr int kRows = 8;  // output rows per task
  const int blocks = (r.v1 - r.v0 + kRows - 1) / kRows;
  parallelFor(0, blocks, [&](int b) {
    const int v0 = r.v0 + b * kRows, v1 = std::min(r.v1, v0 + kRows);
    int uMin = r.u1, uMax = r.u0 - 1;  // the flagged pixels' columns
    for (int v = v0; v < v1; ++v) {
      const uint8_t* row = fit + size_t(v) * w;
      const int first = firstNonZero(row, r.u0, r.u1);
      if (first == r.u1) continue;
      uMin = std::min(uMin, first);
      int last = r.u1 - 1;
      while (!row[last]) --last;
      uMax = std::max(uMax, last);
    }
    if (uMin > uMax) return;
    // Per input row v0 - 2 .. v1 + 1 (minimum 0 off the image), rowFiveSums over uMin .. uMax.
    const int span = uMax - uMin + 1, rows = v1 - v0 + 4;
    thread_local std::vector<double> S0, S1;
    thread_local std::vector<float> lo, hi;
    const size_t n = size_t(span) * rows;
    if (S0.size() < n) {
      S0.resize(n);
      S1.resize(n);
      lo.resize(n);
      hi.resize(n);
    }
    double* s0 = S0.data();
    double* s1 = S1.data();
    float* mn = lo.data();
    float* mx = hi.data();
    for (int k = 0; k < rows; ++k) {
      const int vv = v0 - 2 + k;
      const size_t o = size_t(k) * span;
      if (vv < 0 || vv >= h) {
        std::fill(mn + o, mn + o + span, 0.f);
        continue;
      }
      rowFiveSums(depth.depth_m.data() + size_t(vv) * w, w, uMin, uMax, s0 + o, s1 + o, mn + o,
                  mx + o);
    }
    for (int v = v0; v < v1; ++v)
      for (int u = uMin; u <= uMax; ++u) {
        const size_t i = size_t(v) * w + u;
        if (!fit[i]) continue;
        const float D = depth.depth_m[i];
        const size_t j = size_t(v - v0) * span + size_t(u - uMin);  // input row v - 2
        const size_t st = size_t(span);
        const float m = std::min(
            std::min(std::min(mn[j], mn[j + st]), std::min(mn[j + 2 * st], mn[j + 3 * st])),
            mn[j + 4 * st]);
        const float M = std::max(
            std::max(std::max(mx[j], mx[j + st]), std::max(mx[j + 2 * st], mx[j + 3 * st])),
            mx[j + 4 * st]);
        // The whole neighbourhood on the pixel's surface: every depth valid and within max_jump
        // of D (D - Dn and Dn - D round monotonically, so the extremes decide), and their
        // exponents close enough that the sums of (Dn - D), du (Dn - D) and dv (Dn - D) in
        // double are exact in any order: the reference's sums, bit for bit.
        if (D > 0.f && m > 0.f && M - D <= max_jump && D - m <= max_jump && M <= m * 0x1p20f) {
          const double sum = s0[j] + s0[j + st] + s0[j + 2 * st] + s0[j + 3 * st] + s0[j + 4 * st];
          const double suz = s1[j] + s1[j + st] + s1[j + 2 * st] + s1[j + 3 * st] + s1[j + 4 * st];
          const double svz = 2.0 * (s0[j + 4 * st] - s0[j]) + (s0[j + 3 * st] - s0[j + st]);
          out(i, planeSurface(K, u, v, D, sum - 25.0 * double(D), suz, svz));
        } else if (D > 0.f && D >= 2.f * max_jump && D < std::numeric_limits<float>::infinity() &&
                   u >= 2 && v >= 2 && u + 2 < w && v + 2 < h) {
          out(i, surfaceFromSums(K, u, v, D,
                                 interiorPlaneSums(depth.depth_m.data(), w, u, v, D, max_jump)));
        } else {
          out(i, smoothedSurface(depth, K, u, v, max_jump));
        }
      }
  });
}

float farLimit(float D, const SmoothedSurface& surface, float sigma, float k, float voxel,
               float mu) {
  if (!(k > 0.f) || !(sigma > 0.f)) return D + mu;
  const float c = std::max(surface.cos_incidence, kMinBandCosine);
  const float band = std::min(mu, std::max(k * sigma, voxel / c));
  return std::min(D + mu, surface.depth + band);
}

namespace {

// The per-voxel update rule shared by both kernels, for a voxel that lies within the
// measurement's reach behind its surface (farLimit). `mu`: the volume's μ, the band in front of
// the surface. Returns whether the voxel changed.
inline bool updateVoxel(float d, float mu, float weight, uint8_t carve, float* sumWD, float* sumW,
                        uint8_t* state) {
  // A carve-only pixel empties unknown voxels: in front of a known surface (the robot's own, the
  // table) right up to it, in front of a depth edge's return only beyond the band
  // (kCarveBeyondBand). A known surface's pixel away from depth edges also pulls an observed
  // voxel more than μ in front of it out of the surface, as any measurement does.
  if (carve) {
    if (*state == uint8_t(VoxelState::kUnknown)) {
      if (d > (carve == kCarveBeyondBand ? mu : 0.25f * mu)) {
        *state = uint8_t(VoxelState::kEmpty);
        return true;
      }
    } else if (carve == kCarveToSurface && d > mu && weight > 0 &&
               *state == uint8_t(VoxelState::kObserved)) {
      *sumWD += weight * mu;
      *sumW += weight;
      return true;
    }
    return false;
  }
  if (d > mu) {
    if (*state == uint8_t(VoxelState::kUnknown)) {
      *state = uint8_t(VoxelState::kEmpty);
      return true;
    }
    if (*state == uint8_t(VoxelState::kObserved)) {
      // Seen through after having been in a band (a flying pixel, a mis-registered edge): add the
      // truncated value +μ so free-space evidence pulls the distance back out of the surface.
      *sumWD += weight * mu;
      *sumW += weight;
      return true;
    }
    return false;
  }
  *sumWD += weight * d;
  *sumW += weight;
  *state = uint8_t(VoxelState::kObserved);
  return true;
}

// One row of voxels (fixed y, z) for the eight-voxel kernel: its camera-frame start and step,
// the pixels' arrays and the volume's.
struct RowOfVoxels {
  float ax, ay, az, sx, sy, sz;  // camera coordinates of voxel x = 0 and the step along x
  float fx, fy, cx, cy;
  int w, h;
  float mu;
  bool useBand;
  const float *D, *F, *W;
  const uint8_t* carve;
  size_t base;  // index of voxel x = 0
  float *sumWD, *sumW;
  uint8_t* state;
};

#if INHAND_FAST_MATH_AVX2
// Voxels x, x + 1, ... eight at a time while all eight lie in [x, x1]: the four-voxel kernel's
// steps on eight lanes (the same IEEE single-precision operations in the same order, no FMA:
// the same pixels, depths and tests bit for bit), the depth and reach of the eight pixels
// gathered at once. Returns the first voxel not processed.
__attribute__((target("avx2"))) int integrateEight(const RowOfVoxels& r, int x, int x1,
                                                   int64_t* visited, int64_t* updated) {
  const __m256 vax = _mm256_set1_ps(r.ax), vay = _mm256_set1_ps(r.ay), vaz = _mm256_set1_ps(r.az);
  const __m256 vsx = _mm256_set1_ps(r.sx), vsy = _mm256_set1_ps(r.sy), vsz = _mm256_set1_ps(r.sz);
  const __m256 vfx = _mm256_set1_ps(r.fx), vfy = _mm256_set1_ps(r.fy), vcx = _mm256_set1_ps(r.cx),
               vcy = _mm256_set1_ps(r.cy), half = _mm256_set1_ps(0.5f), one = _mm256_set1_ps(1.f);
  const __m256 zero = _mm256_setzero_ps(), w8 = _mm256_set1_ps(float(r.w)),
               h8 = _mm256_set1_ps(float(r.h)), negMu = _mm256_set1_ps(-r.mu);
  const __m256 lane = _mm256_set_ps(7.f, 6.f, 5.f, 4.f, 3.f, 2.f, 1.f, 0.f);
  for (; x + 7 <= x1; x += 8) {
    // x + lane is exact in single precision (x < 2^24), as the four-voxel kernel's float(x + l).
    const __m256 xf = _mm256_add_ps(_mm256_set1_ps(float(x)), lane);
    const __m256 Z = _mm256_add_ps(vaz, _mm256_mul_ps(xf, vsz));
    const __m256 inv = _mm256_div_ps(one, Z);
    const __m256 fu = _mm256_add_ps(
        _mm256_add_ps(
            _mm256_mul_ps(_mm256_mul_ps(vfx, _mm256_add_ps(vax, _mm256_mul_ps(xf, vsx))), inv),
            vcx),
        half);
    const __m256 fv = _mm256_add_ps(
        _mm256_add_ps(
            _mm256_mul_ps(_mm256_mul_ps(vfy, _mm256_add_ps(vay, _mm256_mul_ps(xf, vsy))), inv),
            vcy),
        half);
    const __m256 inImage = _mm256_and_ps(
        _mm256_and_ps(_mm256_cmp_ps(Z, zero, _CMP_GT_OQ),
                      _mm256_and_ps(_mm256_cmp_ps(fu, zero, _CMP_GE_OQ),
                                    _mm256_cmp_ps(fv, zero, _CMP_GE_OQ))),
        _mm256_and_ps(_mm256_cmp_ps(fu, w8, _CMP_LT_OQ), _mm256_cmp_ps(fv, h8, _CMP_LT_OQ)));
    if (!_mm256_movemask_ps(inImage)) continue;
    const __m256 pf = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(_mm256_cvttps_epi32(fv)), w8),
                                    _mm256_cvtepi32_ps(_mm256_cvttps_epi32(fu)));
    // Lanes off the image read pixel 0 (and are dropped by inImage).
    const __m256i p = _mm256_and_si256(_mm256_cvttps_epi32(pf), _mm256_castps_si256(inImage));
    const __m256 Dm = _mm256_i32gather_ps(r.D, p, 4);
    const __m256 d = _mm256_sub_ps(Dm, Z);
    __m256 keep = _mm256_and_ps(inImage, _mm256_cmp_ps(Dm, zero, _CMP_GT_OQ));
    keep = r.useBand
               ? _mm256_and_ps(keep, _mm256_cmp_ps(Z, _mm256_i32gather_ps(r.F, p, 4), _CMP_NGT_UQ))
               : _mm256_and_ps(keep, _mm256_cmp_ps(d, negMu, _CMP_NLT_UQ));
    int lanes = _mm256_movemask_ps(keep);
    if (!lanes) continue;
    alignas(32) int ps[8];
    alignas(32) float ds[8];
    _mm256_store_si256(reinterpret_cast<__m256i*>(ps), p);
    _mm256_store_ps(ds, d);
    for (; lanes; lanes &= lanes - 1) {
      const int l = __builtin_ctz(unsigned(lanes));
      const int pix = ps[l];
      ++*visited;
      const size_t i = r.base + size_t(x + l);
      *updated += updateVoxel(ds[l], r.mu, r.W[pix], r.carve ? r.carve[pix] : uint8_t(0),
                              &r.sumWD[i], &r.sumW[i], &r.state[i]);
    }
  }
  return x;
}
#endif

// Interval of x (real) where a + b·x >= 0, intersected into [lo, hi].
inline void clipLinear(double a, double b, double* lo, double* hi) {
  if (b > 0)
    *lo = std::max(*lo, -a / b);
  else if (b < 0)
    *hi = std::min(*hi, -a / b);
  else if (a < 0)
    *hi = -1;  // never satisfied
}

// The voxels x of a row (camera coordinates a + x·step) that lie in front of the camera and
// project inside the image, widened by one each side and clipped to [0, nx − 1]: z > 0 and
// −0.5 ≤ fx·X/Z + cx < w − 0.5 (the same for v) are linear in x once multiplied by Z. False when
// none does.
inline bool rowOnImage(const Vec3& a, const Vec3& step, const CameraIntrinsics& K, int nx, int* x0,
                       int* x1) {
  const int w = K.width, h = K.height;
  double lo = 0, hi = nx - 1;
  clipLinear(a.z() - 1e-6, step.z(), &lo, &hi);
  clipLinear(K.fx * a.x() + (K.cx + 0.5) * a.z(), K.fx * step.x() + (K.cx + 0.5) * step.z(), &lo,
             &hi);
  clipLinear(-K.fx * a.x() + (w - 0.5 - K.cx) * a.z(),
             -K.fx * step.x() + (w - 0.5 - K.cx) * step.z(), &lo, &hi);
  clipLinear(K.fy * a.y() + (K.cy + 0.5) * a.z(), K.fy * step.y() + (K.cy + 0.5) * step.z(), &lo,
             &hi);
  clipLinear(-K.fy * a.y() + (h - 0.5 - K.cy) * a.z(),
             -K.fy * step.y() + (h - 0.5 - K.cy) * step.z(), &lo, &hi);
  if (lo > hi) return false;
  *x0 = std::max(0, int(std::floor(lo)) - 1);
  *x1 = std::min(nx - 1, int(std::ceil(hi)) + 1);
  return true;
}

// One voxel of the row from its depth Z and its projection (fu, fv) + 0.5 (the plain path: each
// test in turn). The row is taken by value: the compiler keeps its fields in registers (through
// a reference it reloads them after every store to the volume).
inline void integrateVoxel(const RowOfVoxels r, int x, float Z, float fu, float fv,
                           int64_t* visited, int64_t* updated) {
  if (Z <= 0.f) return;
  // Nearest pixel. Truncation equals floor for non-negative values, and is much cheaper than
  // std::floor without SSE4.1; negatives are rejected first.
  if (!(fu >= 0.f && fv >= 0.f)) return;
  const int u = int(fu), v = int(fv);
  if (u >= r.w || v >= r.h) return;
  const int p = v * r.w + u;
  const float Dm = r.D[p];
  if (!(Dm > 0.f)) return;
  const float d = Dm - Z;
  if (r.useBand ? Z > r.F[p] : d < -r.mu) return;  // predictable: the same every voxel
  ++*visited;
  const size_t i = r.base + size_t(x);
  *updated += updateVoxel(d, r.mu, r.W[p], r.carve ? r.carve[p] : uint8_t(0), &r.sumWD[i],
                          &r.sumW[i], &r.state[i]);
}

// Voxels x … x1 one at a time, in single precision as the four-voxel kernel computes them.
inline void integrateOneByOne(const RowOfVoxels r, int x, int x1, int64_t* visited,
                              int64_t* updated) {
  for (; x <= x1; ++x) {
    const float Z = r.az + float(x) * r.sz;
    if (Z <= 0.f) continue;
    const float inv = 1.f / Z;
    integrateVoxel(r, x, Z, r.fx * (r.ax + float(x) * r.sx) * inv + r.cx + 0.5f,
                   r.fy * (r.ay + float(x) * r.sy) * inv + r.cy + 0.5f, visited, updated);
  }
}

// Voxels x, x + 1, … four at a time while all four lie in [x, x1]: depth, its reciprocal and the
// projection in SSE2, each operation the scalar one in the same order (IEEE single precision,
// no fused multiply-add), so the pixels are those of integrateOneByOne to the last bit. With
// `simdPixels` the tests too, four at once; else each voxel through integrateVoxel. Returns the
// first voxel not processed.
inline int integrateFour(const RowOfVoxels r, int x, int x1, bool simdPixels, int64_t* visited,
                         int64_t* updated) {
  const __m128 vax = _mm_set1_ps(r.ax), vay = _mm_set1_ps(r.ay), vaz = _mm_set1_ps(r.az);
  const __m128 vsx = _mm_set1_ps(r.sx), vsy = _mm_set1_ps(r.sy), vsz = _mm_set1_ps(r.sz);
  const __m128 vfx = _mm_set1_ps(r.fx), vfy = _mm_set1_ps(r.fy), vcx = _mm_set1_ps(r.cx),
               vcy = _mm_set1_ps(r.cy), half = _mm_set1_ps(0.5f), one = _mm_set1_ps(1.f);
  const __m128 zero4 = _mm_setzero_ps(), w4 = _mm_set1_ps(float(r.w)), h4 = _mm_set1_ps(float(r.h)),
               negMu4 = _mm_set1_ps(-r.mu);
  alignas(16) float Zs[4], us[4], vs[4];
  for (; x + 3 <= x1; x += 4) {
    const __m128 xf = _mm_set_ps(float(x + 3), float(x + 2), float(x + 1), float(x));
    const __m128 Z = _mm_add_ps(vaz, _mm_mul_ps(xf, vsz));
    const __m128 inv = _mm_div_ps(one, Z);
    const __m128 fu = _mm_add_ps(
        _mm_add_ps(_mm_mul_ps(_mm_mul_ps(vfx, _mm_add_ps(vax, _mm_mul_ps(xf, vsx))), inv), vcx),
        half);
    const __m128 fv = _mm_add_ps(
        _mm_add_ps(_mm_mul_ps(_mm_mul_ps(vfy, _mm_add_ps(vay, _mm_mul_ps(xf, vsy))), inv), vcy),
        half);
    if (!simdPixels) {
      _mm_store_ps(Zs, Z);
      _mm_store_ps(us, fu);
      _mm_store_ps(vs, fv);
      for (int l = 0; l < 4; ++l) integrateVoxel(r, x + l, Zs[l], us[l], vs[l], visited, updated);
      continue;
    }
    // integrateVoxel's tests for the four at once, the same comparisons: in front of the camera,
    // on the image (trunc(f) < w ⇔ f < w for f ≥ 0), a depth there, within reach; the pixel
    // index v·w + u exact in single precision (< 2^24).
    const __m128 inImage =
        _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(Z, zero4),
                              _mm_and_ps(_mm_cmpge_ps(fu, zero4), _mm_cmpge_ps(fv, zero4))),
                   _mm_and_ps(_mm_cmplt_ps(fu, w4), _mm_cmplt_ps(fv, h4)));
    if (!_mm_movemask_ps(inImage)) continue;
    const __m128 pf = _mm_add_ps(_mm_mul_ps(_mm_cvtepi32_ps(_mm_cvttps_epi32(fv)), w4),
                                 _mm_cvtepi32_ps(_mm_cvttps_epi32(fu)));
    alignas(16) int ps[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(ps),
                    _mm_and_si128(_mm_cvttps_epi32(pf), _mm_castps_si128(inImage)));
    const __m128 Dm = _mm_set_ps(r.D[ps[3]], r.D[ps[2]], r.D[ps[1]], r.D[ps[0]]);
    const __m128 d = _mm_sub_ps(Dm, Z);
    __m128 keep = _mm_and_ps(inImage, _mm_cmpgt_ps(Dm, zero4));
    keep = r.useBand ? _mm_and_ps(keep, _mm_cmpngt_ps(Z, _mm_set_ps(r.F[ps[3]], r.F[ps[2]],
                                                                    r.F[ps[1]], r.F[ps[0]])))
                     : _mm_and_ps(keep, _mm_cmpnlt_ps(d, negMu4));
    int lanes = _mm_movemask_ps(keep);
    if (!lanes) continue;
    alignas(16) float ds[4];
    _mm_store_ps(ds, d);
    for (; lanes; lanes &= lanes - 1) {
      const int l = __builtin_ctz(unsigned(lanes));
      const int p = ps[l];
      ++*visited;
      const size_t i = r.base + size_t(x + l);
      *updated += updateVoxel(ds[l], r.mu, r.W[p], r.carve ? r.carve[p] : uint8_t(0), &r.sumWD[i],
                              &r.sumW[i], &r.state[i]);
    }
  }
  return x;
}

constexpr int kBrick = 8;      // voxels per brick edge
constexpr int kDepthTile = 8;  // pixels per depth tile edge

// The nearest and farthest depth returned in each kDepthTile² tile of the image's `rect`
// (+inf / −inf where the tile has none), and whether any of its depths can change an observed
// voxel (a measurement, or a known surface's carve-only pixel: kCarveToSurface).
class DepthTiles {
 public:
  DepthTiles(const DepthImage& depth, const PixelRect& rect, const uint8_t* carve) : rect_(rect) {
    tw_ = (rect.u1 - rect.u0 + kDepthTile - 1) / kDepthTile;
    th_ = (rect.v1 - rect.v0 + kDepthTile - 1) / kDepthTile;
    if (rect.empty()) tw_ = th_ = 0;
    lo_.assign(size_t(tw_) * th_, std::numeric_limits<float>::infinity());
    hi_.assign(size_t(tw_) * th_, -std::numeric_limits<float>::infinity());
    measured_.assign(size_t(tw_) * th_, 0);
    // A row of tiles per task (on both cores).
    parallelFor(0, th_, [&](int ty) {
      float* lo = lo_.data() + size_t(ty) * tw_;
      float* hi = hi_.data() + size_t(ty) * tw_;
      uint8_t* measured = measured_.data() + size_t(ty) * tw_;
      const int v0 = rect.v0 + ty * kDepthTile, v1 = std::min(rect.v1, v0 + kDepthTile);
      for (int v = v0; v < v1; ++v) {
        const size_t row0 = size_t(v) * depth.width;
        const float* row = depth.depth_m.data() + row0;
        for (int u = rect.u0; u < rect.u1; ++u) {
          const float D = row[u];
          if (!(D > 0.f)) continue;
          const int t = (u - rect.u0) / kDepthTile;
          lo[t] = std::min(lo[t], D);
          hi[t] = std::max(hi[t], D);
          // A known surface's pixel (kCarveToSurface) changes observed voxels too.
          measured[t] |= !carve || carve[row0 + size_t(u)] <= kCarveToSurface;
        }
      }
    });
  }
  // The depth range over pixels [u0, u1] × [v0, v1] (inclusive, clipped to the rect); false when
  // none of them has a depth.
  // *measured: whether any of those depths can change an observed voxel.
  bool range(int u0, int v0, int u1, int v1, float* lo, float* hi, bool* measured) const {
    u0 = std::max(u0, rect_.u0);
    v0 = std::max(v0, rect_.v0);
    u1 = std::min(u1, rect_.u1 - 1);
    v1 = std::min(v1, rect_.v1 - 1);
    if (u0 > u1 || v0 > v1) return false;
    *lo = std::numeric_limits<float>::infinity();
    *hi = -std::numeric_limits<float>::infinity();
    *measured = false;
    for (int ty = (v0 - rect_.v0) / kDepthTile; ty <= (v1 - rect_.v0) / kDepthTile; ++ty)
      for (int tx = (u0 - rect_.u0) / kDepthTile; tx <= (u1 - rect_.u0) / kDepthTile; ++tx) {
        const size_t t = size_t(ty) * tw_ + size_t(tx);
        *lo = std::min(*lo, lo_[t]);
        *hi = std::max(*hi, hi_[t]);
        *measured = *measured || measured_[t];
      }
    return *lo <= *hi;
  }

 private:
  PixelRect rect_;
  int tw_ = 0, th_ = 0;
  std::vector<float> lo_, hi_;
  std::vector<uint8_t> measured_;
};

// Whether a brick of voxels is certain to be left unchanged by the frame, from its corners alone:
// none of its voxels projects onto a pixel with a depth; or all lie more than μ behind every depth
// their pixels can hold (d < −μ ≤ −band: no update); or all lie more than μ in front of them and
// every voxel is already empty (d > μ changes only unknown and observed voxels); or every depth
// their pixels can hold is a carve-only one that changes unknown voxels only (depth edges) and no
// voxel is unknown. The margin covers the kernel's single-precision depth and pixel.
struct BrickCull {
  const TsdfVolume& volume;
  const Iso3& T_C_O;
  const CameraIntrinsics& K;
  const DepthTiles& tiles;
  float mu;
  bool skip(const Vec3i& b) const {
    const Vec3i dims = volume.dims();
    const Vec3i lo = b * kBrick;
    const Vec3i hi = (lo + Vec3i::Constant(kBrick - 1)).cwiseMin(dims - Vec3i::Ones());
    double zMin = 1e300, zMax = -1e300, uMin = 1e300, uMax = -1e300, vMin = 1e300, vMax = -1e300;
    for (int c = 0; c < 8; ++c) {
      const Vec3 p = T_C_O * volume.point((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(),
                                          (c & 4) ? hi.z() : lo.z());
      if (!(p.z() > 1e-3)) return false;  // near or behind the camera: no shortcut
      zMin = std::min(zMin, p.z());
      zMax = std::max(zMax, p.z());
      const Vec2 uv = K.project(p);
      uMin = std::min(uMin, uv.x());
      uMax = std::max(uMax, uv.x());
      vMin = std::min(vMin, uv.y());
      vMax = std::max(vMax, uv.y());
    }
    // Far off the image (and outside int's range): no voxel projects onto a pixel.
    const double big = 1e6;
    if (uMax < -big || vMax < -big || uMin > big || vMin > big) return true;
    // A voxel reads pixel floor(u + 0.5): one more pixel each side for rounding.
    float dLo, dHi;
    bool measured;
    if (!tiles.range(int(std::floor(uMin + 0.5)) - 1, int(std::floor(vMin + 0.5)) - 1,
                     int(std::floor(uMax + 0.5)) + 1, int(std::floor(vMax + 0.5)) + 1, &dLo, &dHi,
                     &measured))
      return true;
    const double margin = 1e-4 + 1e-5 * zMax;
    if (zMin - double(dHi) > double(mu) + margin) return true;  // all behind the band
    if (double(dLo) - zMax > double(mu) + margin)
      return none(lo, hi, VoxelState::kUnknown, VoxelState::kObserved);              // all in front
    if (!measured) return none(lo, hi, VoxelState::kUnknown, VoxelState::kUnknown);  // edges only
    return false;
  }
  // Whether no voxel of the brick is in state a or b.
  bool none(const Vec3i& lo, const Vec3i& hi, VoxelState a, VoxelState b) const {
    const uint8_t* st = volume.states();
    const uint8_t sa = uint8_t(a), sb = uint8_t(b);
    for (int z = lo.z(); z <= hi.z(); ++z)
      for (int y = lo.y(); y <= hi.y(); ++y) {
        const uint8_t* row = st + volume.index(lo.x(), y, z);
        for (int x = 0; x <= hi.x() - lo.x(); ++x)
          if (row[x] == sa || row[x] == sb) return false;
      }
    return true;
  }
};

}  // namespace

// The pixels as the kernel reads them: per pixel the weight w = 1/σ², the farthest depth the
// measurement reaches (band_sigmas) and the depth it updates from (smooth_depth), so the kernel
// reads two or three floats per voxel; only where the volume's voxels can project (`rect`: the
// kernel reads no other pixel). The arrays are this thread's buffers, valid until its next call.
struct PreparedPixels {
  PixelRect rect;
  const DepthImage* depth;  // the depths the voxels are updated from
  const float *weight, *farZ;
};
PreparedPixels preparePixels(const DepthImage& depth, const Iso3& T_O_C, const CameraIntrinsics& K,
                             const std::vector<float>& sigma_m, const TsdfVolume& volume,
                             const std::vector<uint8_t>* carve_only) {
  const int w = K.width;
  const PixelRect rect = volumeImageRect(volume, T_O_C, K);
  const float muFull = float(volume.truncation());
  const float k = float(volume.bandSigmas());
  const float voxelF = float(volume.voxelSize());
  const bool useBand = k > 0;  // else every measurement reaches μ behind its depth: no far image
  const bool smooth = volume.smoothDepth();
  // Per-thread buffers of the image's size: only the rect's entries are written and read, so they
  // are neither cleared nor allocated again frame after frame.
  thread_local std::vector<float> weight, farZ;
  thread_local DepthImage smoothed;
  if (weight.size() < sigma_m.size()) weight.resize(sigma_m.size());
  if (useBand && farZ.size() < sigma_m.size()) farZ.resize(sigma_m.size());
  if (smooth && (smoothed.width != depth.width || smoothed.height != depth.height ||
                 smoothed.depth_m.size() != depth.depth_m.size()))
    smoothed = depth;
  // The volume's depth range in this camera (its corners).
  const Iso3 T_C_O = T_O_C.inverse();
  float zNear = std::numeric_limits<float>::infinity(), zFar = -zNear;
  for (const Vec3& p : cornersInCamera(volume, T_C_O)) {
    zNear = std::min(zNear, float(p.z()));
    zFar = std::max(zFar, float(p.z()));
  }
  // Pointers taken here, on this thread: inside the parallel loops the thread_local names would
  // be the worker threads' own buffers.
  float* F = farZ.data();
  float* Wt = weight.data();
  float* S = smooth ? smoothed.depth_m.data() : nullptr;
  thread_local std::vector<uint8_t> fitFlags;
  if (fitFlags.size() < sigma_m.size()) fitFlags.resize(sigma_m.size());
  uint8_t* fits = fitFlags.data();
  std::atomic<bool> anyFit{false};
  parallelFor(rect.v0, rect.v1, [&](int v) {
    bool rowFits = false;
    for (int u = rect.u0; u < rect.u1; ++u) {
      const size_t i = size_t(v) * w + u;
      const float s = sigma_m[i];
      const float Dm = depth.depth_m[i];
      Wt[i] = s > 0 ? 1.f / (s * s) : 0.f;
      // Carve-only pixels (the robot's own surface) and pixels without a σ keep their depth, as
      // do those more than 2μ beyond the volume (its voxels are more than μ in front of both
      // depths: empty either way) or before it (none within reach).
      const bool fit = s > 0 && !(carve_only && (*carve_only)[i]) && (useBand || smooth) &&
                       Dm < zFar + 2 * muFull && Dm + 2 * muFull > zNear;
      fits[i] = fit;
      rowFits |= fit;
      if (smooth) S[i] = Dm;
      if (useBand) F[i] = Dm + muFull;
    }
    if (rowFits) anyFit.store(true, std::memory_order_relaxed);
  });
  // The fitted pixels' smoothed depth and reach.
  if (anyFit.load())
    smoothedSurfaces(depth, K, rect, fits, muFull, [&](size_t i, const SmoothedSurface& sm) {
      const float Dm = depth.depth_m[i];
      const float Dv = (smooth && sm.depth > 0.f) ? sm.depth : Dm;
      if (smooth) S[i] = Dv;
      if (useBand) F[i] = farLimit(Dv, sm, sigma_m[i], k, voxelF, muFull);
    });
  // The depths the voxels are updated from: the smoothed ones with VolumeOptions::smooth_depth.
  return {rect, smooth ? &smoothed : &depth, Wt, F};
}

IntegrationStats integrate(const DepthImage& depth, const Iso3& T_O_C, const CameraIntrinsics& K,
                           const std::vector<float>& sigma_m, TsdfVolume* volume,
                           const std::vector<uint8_t>* carve_only, bool skip_unchanged_bricks) {
  checkInputs(depth, K, sigma_m, carve_only);
  const int w = K.width, h = K.height;
  const PreparedPixels pixels = preparePixels(depth, T_O_C, K, sigma_m, *volume, carve_only);
  const PixelRect& rect = pixels.rect;
  const float muFull = float(volume->truncation());
  const bool useBand = volume->bandSigmas() > 0;
  const Iso3 T_C_O = T_O_C.inverse();
  const DepthImage& used = *pixels.depth;
  const float* F = pixels.farZ;
  const float* Wt = pixels.weight;
  const DepthTiles tiles(used, rect, carve_only ? carve_only->data() : nullptr);
  const Mat3 R = T_C_O.linear();
  const Vec3 step = R.col(0) * volume->voxelSize();  // camera-frame step along voxel x
  const Vec3i dims = volume->dims();
  const float fx = float(K.fx), fy = float(K.fy), cx = float(K.cx), cy = float(K.cy);
  const float* D = used.depth_m.data();
  const uint8_t* carve = carve_only ? carve_only->data() : nullptr;
  float* sumWD = volume->sumWD();
  float* sumW = volume->sumW();
  uint8_t* state = volume->states();
  std::atomic<int64_t> visited{0}, updated{0};
  // The four-voxel tests compute pixel indices in single precision: exact below 2^24 pixels.
  // Without skipping bricks every voxel goes through voxel() one at a time (the plain path the
  // tests compare against).
  const bool simdPixels = skip_unchanged_bricks && int64_t(w) * h < (int64_t(1) << 24);
  // Eight voxels at a time where the CPU has AVX2 (the same voxels as four at a time), then four.
#if INHAND_FAST_MATH_AVX2
  const bool eightWide = simdPixels && fastMathAvx2();
#endif
  // Bricks of kBrick³ voxels that this frame cannot change are skipped (BrickCull); the others are
  // processed row by row, consecutive ones as one span.
  const Vec3i bricks = (dims + Vec3i::Constant(kBrick - 1)) / kBrick;
  const BrickCull cull{*volume, T_C_O, K, tiles, muFull};
  const int brickRows = bricks.y() * bricks.z();
  tbb::parallel_for(tbb::blocked_range<int>(0, brickRows, 1), [&](const tbb::blocked_range<int>&
                                                                      r) {
    int64_t myVisited = 0, myUpdated = 0;
    std::vector<std::pair<int, int>> spans;  // voxel x ranges [first, last] of bricks to process
    for (int brickRow = r.begin(); brickRow != r.end(); ++brickRow) {
      const int by = brickRow % bricks.y(), bz = brickRow / bricks.y();
      spans.clear();
      for (int bx = 0; bx < bricks.x(); ++bx) {
        if (skip_unchanged_bricks && cull.skip(Vec3i(bx, by, bz))) continue;
        const int first = bx * kBrick, last = std::min(dims.x(), first + kBrick) - 1;
        if (!spans.empty() && spans.back().second + 1 == first)
          spans.back().second = last;  // consecutive bricks: one span
        else
          spans.emplace_back(first, last);
      }
      if (spans.empty()) continue;
      for (int z = bz * kBrick; z < std::min(dims.z(), (bz + 1) * kBrick); ++z)
        for (int y = by * kBrick; y < std::min(dims.y(), (by + 1) * kBrick); ++y) {
          const Vec3 a = T_C_O * volume->point(0, y, z);  // camera coords of voxel x = 0
          int rowX0, rowX1;
          if (!rowOnImage(a, step, K, dims.x(), &rowX0, &rowX1)) continue;
          const float ax = float(a.x()), ay = float(a.y()), az = float(a.z());
          const float sx = float(step.x()), sy = float(step.y()), sz = float(step.z());
          const size_t base = volume->index(0, y, z);
          const RowOfVoxels row{ax, ay,     az,      sx, sy, sz, fx,    fy,   cx,    cy,   w,
                                h,  muFull, useBand, D,  F,  Wt, carve, base, sumWD, sumW, state};
          for (const auto& [spanFirst, spanLast] : spans) {
            const int x0 = std::max(rowX0, spanFirst), x1 = std::min(rowX1, spanLast);
            int x = x0;
#if INHAND_FAST_MATH_AVX2
            if (eightWide) x = integrateEight(row, x, x1, &myVisited, &myUpdated);
#endif
            x = integrateFour(row, x, x1, simdPixels, &myVisited, &myUpdated);
            integrateOneByOne(row, x, x1, &myVisited, &myUpdated);
          }
        }
    }
    visited += myVisited;
    updated += myUpdated;
  });
  return {visited.load(), updated.load()};
}

IntegrationStats integrateReference(const DepthImage& depth, const Iso3& T_O_C,
                                    const CameraIntrinsics& K, const std::vector<float>& sigma_m,
                                    TsdfVolume* volume, const std::vector<uint8_t>* carve_only) {
  checkInputs(depth, K, sigma_m, carve_only);
  const Iso3 T_C_O = T_O_C.inverse();
  const Vec3i dims = volume->dims();
  const float mu = float(volume->truncation());
  const double k = volume->bandSigmas();
  IntegrationStats stats;
  for (int z = 0; z < dims.z(); ++z)
    for (int y = 0; y < dims.y(); ++y)
      for (int x = 0; x < dims.x(); ++x) {
        Vec3 p_C = T_C_O * volume->point(x, y, z);
        if (p_C.z() <= 0) continue;
        Vec2 uv = K.project(p_C);
        int u = int(std::floor(uv.x() + 0.5)), v = int(std::floor(uv.y() + 0.5));
        if (u < 0 || v < 0 || u >= K.width || v >= K.height) continue;
        float Dm = depth.at(u, v);
        if (!(Dm > 0)) continue;
        size_t p = size_t(v) * K.width + u;
        float s = sigma_m[p];
        const uint8_t carve = carve_only ? (*carve_only)[p] : uint8_t(0);
        const bool object = s > 0 && !carve;
        // The measured surface: the pixel's depth, or the plane fitted around it with
        // smooth_depth; with band_sigmas the reach behind the fitted plane is k·σ, at least a
        // voxel across the surface (voxel / cos θ along the ray), at most μ, and at most μ behind
        // the depth used (written out here, not shared with the fast kernel).
        double Dv = Dm;
        SmoothedSurface sm;
        if (object && (k > 0 || volume->smoothDepth())) sm = smoothedSurface(depth, K, u, v, mu);
        if (object && volume->smoothDepth() && sm.depth > 0) Dv = sm.depth;
        float d = float(Dv - p_C.z());
        if (k > 0 && object) {
          const double c = std::max(double(sm.cos_incidence), double(kMinBandCosine));
          const double band = std::min(double(mu), std::max(k * s, volume->voxelSize() / c));
          const double far = std::min(Dv + mu, double(sm.depth) + band);
          if (p_C.z() > far) continue;
        } else if (d < -mu) {
          continue;
        }
        ++stats.visited;
        size_t i = volume->index(x, y, z);
        float wgt = s > 0 ? 1.f / (s * s) : 0.f;
        stats.updated += updateVoxel(d, mu, wgt, carve, &volume->sumWD()[i], &volume->sumW()[i],
                                     &volume->states()[i]);
      }
  return stats;
}

}  // namespace inhand
