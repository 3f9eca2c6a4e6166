#include "inhand/sensor/render.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/internal/fast_math.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/random.h"

namespace inhand {

namespace {

constexpr double kSurfaceOffset_m = 2e-4;  // shadow rays start this far off the surface

// Pixels of [u0, u1) × [v0, v1) of a w-wide image, cast in 4×4 tiles so each 16-ray packet is
// coherent.
std::vector<int> tileOrder(int w, int u0, int v0, int u1, int v1) {
  std::vector<int> order;
  order.reserve(size_t(std::max(0, u1 - u0)) * size_t(std::max(0, v1 - v0)));
  for (int ty = v0; ty < v1; ty += 4)
    for (int tx = u0; tx < u1; tx += 4)
      for (int y = ty; y < std::min(ty + 4, v1); ++y)
        for (int x = tx; x < std::min(tx + 4, u1); ++x) order.push_back(y * w + x);
  return order;
}

Ray pixelRay(const Iso3& T_S_C, const CameraIntrinsics& K, double u, double v) {
  Ray r;
  r.origin = T_S_C.translation().cast<float>();
  r.dir = (T_S_C.linear() * K.rayZ1(u, v)).cast<float>();  // camera z = 1, so t is the depth z
  return r;
}

// Cosine of the angle between a surface normal and a direction, two-sided (0 when either is 0).
double cosIncidence(const Vec3& normal, const Vec3& dir) {
  double nn = normal.norm(), dn = dir.norm();
  if (nn == 0 || dn == 0) return 0;
  return std::min(1.0, std::abs(normal.dot(dir)) / (nn * dn));
}

// cosIncidence and the angle itself (rad) in single precision, for the noise's σ per pixel (in
// double precision the arccosine cost as much as casting the ray).
float cosIncidenceF(const Vec3f& normal, const Vec3f& dir) {
  // The products in double: Embree's unnormalised normal of a tiny triangle squared underflows a
  // float.
  const Vec3 n = normal.cast<double>(), d = dir.cast<double>();
  const double nn = n.squaredNorm() * d.squaredNorm();
  if (!(nn > 0)) return 0.f;
  return float(std::min(1.0, std::abs(n.dot(d)) / std::sqrt(nn)));
}
float incidenceF(const Vec3f& normal, const Vec3f& dir) {
  return acosUnitF(cosIncidenceF(normal, dir));
}

// Whether cosIncidence(normal, dir) < limit (limit in (0, 1)): by squares, with no square root
// or division, where the answer is certain, and by cosIncidence itself within a relative 1e-9 of
// the limit (both are exact to ~1e-15), so the answer is cosIncidence's, bit for bit.
bool cosBelow(const Vec3& normal, const Vec3& dir, double limit) {
  const double nd = normal.dot(dir);
  const double bound = limit * limit * (normal.squaredNorm() * dir.squaredNorm());
  if (nd * nd > bound * (1 + 1e-9)) return false;
  if (nd * nd < bound * (1 - 1e-9)) return true;
  return cosIncidence(normal, dir) < limit;
}

// Whether cosIncidenceF(normal, dir) ≥ c0 (c0 in (0, 1)) for certain, by squares: true only where
// the float cosine cannot round below c0 (a relative 1e-6 of margin against its 6e-8).
bool cosCertainlyAtLeastF(const Vec3f& normal, const Vec3f& dir, double c0) {
  const Vec3 n = normal.cast<double>(), d = dir.cast<double>();
  const double nn = n.squaredNorm() * d.squaredNorm(), nd = n.dot(d);
  return nn > 0 && nd * nd >= c0 * c0 * nn * (1 + 1e-6);
}

// The cosines of the sensor's incidence limits: an angle exceeds a limit when its cosine is
// below the limit's (acos falls as its argument rises), so no arccosine is needed per pixel.
struct IncidenceLimits {
  double camera, projector;
  explicit IncidenceLimits(const DepthCameraOptions& cam)
      : camera(std::cos(cam.max_incidence_deg * M_PI / 180)),
        projector(std::cos(cam.max_projector_incidence_deg * M_PI / 180)) {}
};

// The geometric part of whether the sensor returns a depth for this hit: in range, not too oblique
// for the camera or the projector. Returns the shadow ray towards the projector when it does.
bool acceptHit(const Hit& hit, const Ray& ray, const Vec3& projector_S,
               const DepthCameraOptions& cam, const IncidenceLimits& limits, Ray* shadow) {
  if (!hit.valid()) return false;
  double z = hit.t;
  if (z < cam.min_range_m || z > cam.max_range_m) return false;
  Vec3 n = hit.normal.cast<double>();
  if (cosBelow(n, ray.dir.cast<double>(), limits.camera)) return false;
  Vec3 x = (ray.origin + hit.t * ray.dir).cast<double>();
  Vec3 toProjector = projector_S - x;
  if (cosBelow(n, toProjector, limits.projector)) return false;
  double dist = toProjector.norm();
  shadow->origin = x.cast<float>();
  shadow->dir = (toProjector / dist).cast<float>();
  shadow->tnear = float(kSurfaceOffset_m);
  shadow->tfar = float(dist - kSurfaceOffset_m);
  return true;
}

// Rays that missed the scene hit the inside of the background sphere (when there is one): the far
// root of |o + t·d − c|² = r², the normal pointing back in. Rays that start outside it, or whose
// far root lies behind the ray's start, stay misses. Per ray, inside the pass that reads the hit
// next (a pass of its own over every ray cost as much in memory traffic as its arithmetic).
struct Background {
  int id;
  double r2;
  Vec3 centre;
  Background(const RayScene& scene, const RenderOptions& o)
      : id(scene.geometryCount()),
        r2(o.background_radius_m > 0 ? o.background_radius_m * o.background_radius_m : 0),
        centre(o.background_centre) {}
  void fill(const Ray& ray, Hit& h) const {
    if (h.valid() || !(r2 > 0)) return;
    const Vec3 d = ray.dir.cast<double>();
    const Vec3 oc = ray.origin.cast<double>() - centre;
    const double a = d.squaredNorm(), b = oc.dot(d), c = oc.squaredNorm() - r2;
    const double disc = b * b - a * c;
    if (!(a > 0) || disc < 0) return;
    const double t = (-b + std::sqrt(disc)) / a;
    if (!(t > ray.tnear) || !(t < ray.tfar)) return;
    h.t = float(t);
    h.geometry = id;
    h.normal = (-(oc + t * d)).cast<float>();
  }
};

#if INHAND_FAST_MATH_AVX2
// ---- four pixels at a time (AVX2)
// ---------------------------------------------------------------- Each function below takes four
// pixels of a band through one step with the same IEEE operations, in the same order, as the scalar
// code above (no FMA: the target is "avx2" alone), so the image is the same bit for bit
// (Render.VectorisedStepsMatchTheScalarOnes).

struct Four {
  __m256d x, y, z;
};

__attribute__((target("avx2"), always_inline)) inline __m256d set4(double a, double b, double c,
                                                                   double d) {
  return _mm256_set_pd(d, c, b, a);
}

// The rays' directions and the hits' normals of pixels k..k+3, in double.
__attribute__((target("avx2"), always_inline)) inline Four directions(const Ray* r) {
  return {set4(r[0].dir.x(), r[1].dir.x(), r[2].dir.x(), r[3].dir.x()),
          set4(r[0].dir.y(), r[1].dir.y(), r[2].dir.y(), r[3].dir.y()),
          set4(r[0].dir.z(), r[1].dir.z(), r[2].dir.z(), r[3].dir.z())};
}
__attribute__((target("avx2"), always_inline)) inline Four normals(const Hit* h) {
  return {set4(h[0].normal.x(), h[1].normal.x(), h[2].normal.x(), h[3].normal.x()),
          set4(h[0].normal.y(), h[1].normal.y(), h[2].normal.y(), h[3].normal.y()),
          set4(h[0].normal.z(), h[1].normal.z(), h[2].normal.z(), h[3].normal.z())};
}
// Eigen's order for a 3-vector's dot product: (x + y) + z.
__attribute__((target("avx2"), always_inline)) inline __m256d dot(const Four& a, const Four& b) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a.x, b.x), _mm256_mul_pd(a.y, b.y)),
                       _mm256_mul_pd(a.z, b.z));
}
// −x as the scalar's unary minus (the sign flipped, zeros included).
__attribute__((target("avx2"), always_inline)) inline __m256d negate(__m256d x) {
  return _mm256_xor_pd(x, _mm256_set1_pd(-0.0));
}
__attribute__((target("avx2"), always_inline)) inline int validLanes(const Hit* h) {
  return (h[0].geometry >= 0) | (h[1].geometry >= 0) << 1 | (h[2].geometry >= 0) << 2 |
         (h[3].geometry >= 0) << 3;
}
__attribute__((target("avx2"), always_inline)) inline void store4(__m256d v, double out[4]) {
  _mm256_storeu_pd(out, v);
}

// Background::fill for the lanes of pixels k..k+3 that hold no hit; the rays all start at
// `oc` + the background's centre (the band's primary rays). Returns the lanes with a hit after.
__attribute__((target("avx2"), always_inline)) inline int fillFour(const Background& bg,
                                                                   const Vec3& oc, const Ray* rays,
                                                                   Hit* hits) {
  const int valid = validLanes(hits);
  if (valid == 0xF || !(bg.r2 > 0)) return valid;
  const Four d = directions(rays);
  const Four o{_mm256_set1_pd(oc.x()), _mm256_set1_pd(oc.y()), _mm256_set1_pd(oc.z())};
  const __m256d a = dot(d, d), b = dot(o, d);
  const __m256d c = _mm256_set1_pd(oc.squaredNorm() - bg.r2);
  const __m256d disc = _mm256_sub_pd(_mm256_mul_pd(b, b), _mm256_mul_pd(a, c));
  const __m256d t = _mm256_div_pd(_mm256_add_pd(negate(b), _mm256_sqrt_pd(disc)), a);
  double tt[4], nx[4], ny[4], nz[4];
  store4(t, tt);
  const __m256d zero = _mm256_setzero_pd();
  store4(negate(_mm256_add_pd(o.x, _mm256_mul_pd(t, d.x))), nx);
  store4(negate(_mm256_add_pd(o.y, _mm256_mul_pd(t, d.y))), ny);
  store4(negate(_mm256_add_pd(o.z, _mm256_mul_pd(t, d.z))), nz);
  const int pass = _mm256_movemask_pd(
      _mm256_and_pd(_mm256_cmp_pd(a, zero, _CMP_GT_OQ), _mm256_cmp_pd(disc, zero, _CMP_NLT_UQ)));
  int out = valid;
  for (int j = 0; j < 4; ++j) {
    if ((valid >> j & 1) || !(pass >> j & 1)) continue;
    if (!(tt[j] > rays[j].tnear) || !(tt[j] < rays[j].tfar)) continue;
    hits[j].t = float(tt[j]);
    hits[j].geometry = bg.id;
    hits[j].normal = Vec3f(float(nx[j]), float(ny[j]), float(nz[j]));
    out |= 1 << j;
  }
  return out;
}

// cosIncidenceF of four lanes, as doubles holding the floats.
__attribute__((target("avx2"), always_inline)) inline __m256d cosIncidenceFour(const Four& n,
                                                                               const Four& d) {
  const __m256d nn = _mm256_mul_pd(dot(n, n), dot(d, d));
  const __m256d nd = dot(n, d);
  const __m256d absNd = _mm256_andnot_pd(_mm256_set1_pd(-0.0), nd);
  const __m256d q = _mm256_min_pd(_mm256_div_pd(absNd, _mm256_sqrt_pd(nn)), _mm256_set1_pd(1.0));
  const __m256d some = _mm256_cmp_pd(nn, _mm256_setzero_pd(), _CMP_GT_OQ);
  return _mm256_cvtps_pd(_mm256_cvtpd_ps(_mm256_and_pd(q, some)));
}

// acosUnitF of four floats (held as doubles), returned as doubles.
__attribute__((target("avx2"), always_inline)) inline __m256d acosUnitFour(__m256d xd) {
  const __m128 x = _mm256_cvtpd_ps(xd);
  __m128 p = _mm_set1_ps(-0.0012624911f);
  p = _mm_add_ps(_mm_set1_ps(0.0066700901f), _mm_mul_ps(x, p));
  p = _mm_add_ps(_mm_set1_ps(-0.0170881256f), _mm_mul_ps(x, p));
  p = _mm_add_ps(_mm_set1_ps(0.0308918810f), _mm_mul_ps(x, p));
  p = _mm_add_ps(_mm_set1_ps(-0.0501743046f), _mm_mul_ps(x, p));
  p = _mm_add_ps(_mm_set1_ps(0.0889789874f), _mm_mul_ps(x, p));
  p = _mm_add_ps(_mm_set1_ps(-0.2145988016f), _mm_mul_ps(x, p));
  p = _mm_add_ps(_mm_set1_ps(1.5707963050f), _mm_mul_ps(x, p));
  return _mm256_cvtps_pd(_mm_mul_ps(_mm_sqrt_ps(_mm_sub_ps(_mm_set1_ps(1.f), x)), p));
}

// What the lateral step needs of the frame.
struct LateralStep {
  const Background* background;
  Vec3 oc;  // the rays' origin − the background's centre
  double c0, c1, maxTheta;
  double cx, cy, fx, fy;
  Mat3 R;
  int w;
};

// The lateral step of pixels k..k+3: the background where nothing was hit, then each hit's ray
// moved to the displaced sub-pixel position (lateralSigmaPx of incidenceF, pixelRay).
__attribute__((target("avx2"))) void lateralFour(const LateralStep& s, const int* px,
                                                 const float* gu, const float* gv, Ray* rays,
                                                 Hit* hits) {
  const int valid = fillFour(*s.background, s.oc, rays, hits);
  if (valid == 0) return;
  const Four d = directions(rays), n = normals(hits);
  const __m256d theta =
      _mm256_min_pd(_mm256_set1_pd(s.maxTheta),
                    _mm256_andnot_pd(_mm256_set1_pd(-0.0), acosUnitFour(cosIncidenceFour(n, d))));
  const __m256d sigma = _mm256_add_pd(
      _mm256_set1_pd(s.c0), _mm256_div_pd(_mm256_mul_pd(_mm256_set1_pd(s.c1), theta),
                                          _mm256_sub_pd(_mm256_set1_pd(M_PI / 2), theta)));
  const __m256d du = _mm256_mul_pd(sigma, _mm256_cvtps_pd(_mm_loadu_ps(gu)));
  const __m256d dv = _mm256_mul_pd(sigma, _mm256_cvtps_pd(_mm_loadu_ps(gv)));
  const __m256d u = _mm256_add_pd(
      set4(double(px[0] % s.w), double(px[1] % s.w), double(px[2] % s.w), double(px[3] % s.w)), du);
  const __m256d v = _mm256_add_pd(
      set4(double(px[0] / s.w), double(px[1] / s.w), double(px[2] / s.w), double(px[3] / s.w)), dv);
  const __m256d x = _mm256_div_pd(_mm256_sub_pd(u, _mm256_set1_pd(s.cx)), _mm256_set1_pd(s.fx));
  const __m256d y = _mm256_div_pd(_mm256_sub_pd(v, _mm256_set1_pd(s.cy)), _mm256_set1_pd(s.fy));
  float out[3][4];
  for (int i = 0; i < 3; ++i)
    _mm_storeu_ps(out[i], _mm256_cvtpd_ps(_mm256_add_pd(
                              _mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(s.R(i, 0)), x),
                                            _mm256_mul_pd(_mm256_set1_pd(s.R(i, 1)), y)),
                              _mm256_mul_pd(_mm256_set1_pd(s.R(i, 2)), _mm256_set1_pd(1.0)))));
  for (int j = 0; j < 4; ++j)
    if (valid >> j & 1) rays[j].dir = Vec3f(out[0][j], out[1][j], out[2][j]);
}

// What the acceptance step needs of the frame.
struct AcceptStep {
  const Background* background;
  Vec3 oc;       // the rays' origin − the background's centre
  Vec3f origin;  // the rays' origin
  Vec3 projector;
  double minRange, maxRange, cosCamera, cosProjector;
  const DepthCameraOptions* camera;
  const IncidenceLimits* limits;
};

// cosBelow of four lanes: bit j of *below where the cosine is certainly below the limit, of
// *above where certainly not; neither where it is within the scalar test's margin.
__attribute__((target("avx2"), always_inline)) inline void cosBelowFour(__m256d nd, __m256d nn,
                                                                        __m256d dd, double limit,
                                                                        int* below, int* above) {
  const __m256d bound = _mm256_mul_pd(_mm256_set1_pd(limit * limit), _mm256_mul_pd(nn, dd));
  const __m256d nd2 = _mm256_mul_pd(nd, nd);
  *above = _mm256_movemask_pd(
      _mm256_cmp_pd(nd2, _mm256_mul_pd(bound, _mm256_set1_pd(1 + 1e-9)), _CMP_GT_OQ));
  *below = _mm256_movemask_pd(
      _mm256_cmp_pd(nd2, _mm256_mul_pd(bound, _mm256_set1_pd(1 - 1e-9)), _CMP_LT_OQ));
}

// acceptHit of pixels k..k+3 (after Background::fill): returns the lanes the sensor returns,
// their shadow rays in shadows[0..3]. Lanes within a cosine test's margin go through acceptHit.
__attribute__((target("avx2"))) int acceptFour(const AcceptStep& s, const Ray* rays, Hit* hits,
                                               Ray* shadows) {
  const int valid = fillFour(*s.background, s.oc, rays, hits);
  if (valid == 0) return 0;
  const __m256d z = set4(hits[0].t, hits[1].t, hits[2].t, hits[3].t);
  const int inRange = valid & _mm256_movemask_pd(_mm256_and_pd(
                                  _mm256_cmp_pd(z, _mm256_set1_pd(s.minRange), _CMP_NLT_UQ),
                                  _mm256_cmp_pd(z, _mm256_set1_pd(s.maxRange), _CMP_NGT_UQ)));
  if (inRange == 0) return 0;
  const Four n = normals(hits), d = directions(rays);
  const __m256d nn = dot(n, n);
  int camBelow, camAbove;
  cosBelowFour(dot(n, d), nn, dot(d, d), s.cosCamera, &camBelow, &camAbove);
  // The point hit, in single precision as the rays are: origin + t·dir.
  const __m128 t = _mm_set_ps(hits[3].t, hits[2].t, hits[1].t, hits[0].t);
  const __m128 dxf = _mm_set_ps(rays[3].dir.x(), rays[2].dir.x(), rays[1].dir.x(), rays[0].dir.x());
  const __m128 dyf = _mm_set_ps(rays[3].dir.y(), rays[2].dir.y(), rays[1].dir.y(), rays[0].dir.y());
  const __m128 dzf = _mm_set_ps(rays[3].dir.z(), rays[2].dir.z(), rays[1].dir.z(), rays[0].dir.z());
  const __m128 xf = _mm_add_ps(_mm_set1_ps(s.origin.x()), _mm_mul_ps(t, dxf));
  const __m128 yf = _mm_add_ps(_mm_set1_ps(s.origin.y()), _mm_mul_ps(t, dyf));
  const __m128 zf = _mm_add_ps(_mm_set1_ps(s.origin.z()), _mm_mul_ps(t, dzf));
  const Four toP{_mm256_sub_pd(_mm256_set1_pd(s.projector.x()), _mm256_cvtps_pd(xf)),
                 _mm256_sub_pd(_mm256_set1_pd(s.projector.y()), _mm256_cvtps_pd(yf)),
                 _mm256_sub_pd(_mm256_set1_pd(s.projector.z()), _mm256_cvtps_pd(zf))};
  const __m256d pp = dot(toP, toP);
  int projBelow, projAbove;
  cosBelowFour(dot(n, toP), nn, pp, s.cosProjector, &projBelow, &projAbove);
  const int ok = inRange & camAbove & projAbove;
  const int unsure = inRange & ((~camBelow & ~camAbove) | (camAbove & ~projBelow & ~projAbove));
  const __m256d dist = _mm256_sqrt_pd(pp);
  float dir[3][4], tfar[4], at[3][4];
  _mm_storeu_ps(dir[0], _mm256_cvtpd_ps(_mm256_div_pd(toP.x, dist)));
  _mm_storeu_ps(dir[1], _mm256_cvtpd_ps(_mm256_div_pd(toP.y, dist)));
  _mm_storeu_ps(dir[2], _mm256_cvtpd_ps(_mm256_div_pd(toP.z, dist)));
  _mm_storeu_ps(tfar, _mm256_cvtpd_ps(_mm256_sub_pd(dist, _mm256_set1_pd(kSurfaceOffset_m))));
  _mm_storeu_ps(at[0], xf);
  _mm_storeu_ps(at[1], yf);
  _mm_storeu_ps(at[2], zf);
  int out = ok;
  for (int j = 0; j < 4; ++j) {
    if (ok >> j & 1) {
      shadows[j].origin = Vec3f(at[0][j], at[1][j], at[2][j]);
      shadows[j].dir = Vec3f(dir[0][j], dir[1][j], dir[2][j]);
      shadows[j].tnear = float(kSurfaceOffset_m);
      shadows[j].tfar = tfar[j];
    } else if ((unsure >> j & 1) &&
               acceptHit(hits[j], rays[j], s.projector, *s.camera, *s.limits, &shadows[j])) {
      out |= 1 << j;
    }
  }
  return out;
}

// What the last step needs of the frame (noise on, grazing_start_deg > 0).
struct DepthStep {
  double cosGrazing, c0, c1, z0, fb, step, minRange, maxRange;
  bool quantize;
};

// The noisy depth of pixels k..k+3 whose bit is set in `live` and whose incidence is certainly
// below grazing_start_deg (so the axial σ has no angle term): returns the lanes with a depth, in
// z[0..3]; lanes that need the angle or a disparity beyond 2^31 steps are left in *rest.
__attribute__((target("avx2"))) int depthFour(const DepthStep& s, const Ray* rays, const Hit* hits,
                                              const float* gz, int live, float zOut[4], int* rest) {
  const Four n = normals(hits), d = directions(rays);
  const __m256d nn = _mm256_mul_pd(dot(n, n), dot(d, d)), nd = dot(n, d);
  const __m256d zero = _mm256_setzero_pd();
  const int certain =
      _mm256_movemask_pd(_mm256_and_pd(
          _mm256_cmp_pd(nn, zero, _CMP_GT_OQ),
          _mm256_cmp_pd(
              _mm256_mul_pd(nd, nd),
              _mm256_mul_pd(_mm256_mul_pd(_mm256_set1_pd(s.cosGrazing * s.cosGrazing), nn),
                            _mm256_set1_pd(1 + 1e-6)),
              _CMP_GE_OQ))) &
      live;
  *rest = live & ~certain;
  if (certain == 0) return 0;
  __m256d z = set4(hits[0].t, hits[1].t, hits[2].t, hits[3].t);
  const __m256d dz = _mm256_sub_pd(z, _mm256_set1_pd(s.z0));
  const __m256d sigma = _mm256_add_pd(_mm256_set1_pd(s.c0),
                                      _mm256_mul_pd(_mm256_mul_pd(_mm256_set1_pd(s.c1), dz), dz));
  z = _mm256_add_pd(z, _mm256_mul_pd(sigma, _mm256_cvtps_pd(_mm_loadu_ps(gz))));
  int out = certain;
  if (s.quantize) {
    const __m256d step = _mm256_set1_pd(s.step);
    const __m256d steps = _mm256_div_pd(_mm256_set1_pd(s.fb), _mm256_mul_pd(z, step));
    const __m256d half = _mm256_add_pd(steps, _mm256_set1_pd(0.5));
    // Truncation through int32 is the scalar's through int64 for 0 <= steps + 0.5 < 2^31.
    const int small = _mm256_movemask_pd(
        _mm256_and_pd(_mm256_cmp_pd(steps, zero, _CMP_GE_OQ),
                      _mm256_cmp_pd(half, _mm256_set1_pd(2147483647.0), _CMP_LT_OQ)));
    const int positive = _mm256_movemask_pd(_mm256_cmp_pd(z, zero, _CMP_GT_OQ));
    // z ≤ 0 or NaN keeps its z; the rest must be in int32's range.
    *rest |= certain & positive & ~small;
    out &= ~(positive & ~small);
    const __m256d q = _mm256_mul_pd(_mm256_cvtepi32_pd(_mm256_cvttpd_epi32(half)), step);
    const __m256d quantised = _mm256_div_pd(_mm256_set1_pd(s.fb), q);
    const __m256d use =
        _mm256_and_pd(_mm256_cmp_pd(z, zero, _CMP_GT_OQ), _mm256_cmp_pd(q, zero, _CMP_GT_OQ));
    z = _mm256_blendv_pd(z, quantised, use);
  }
  const int inRange =
      _mm256_movemask_pd(_mm256_and_pd(_mm256_cmp_pd(z, _mm256_set1_pd(s.minRange), _CMP_NLT_UQ),
                                       _mm256_cmp_pd(z, _mm256_set1_pd(s.maxRange), _CMP_NGT_UQ)));
  _mm_storeu_ps(zOut, _mm256_cvtpd_ps(z));
  return out & inRange;
}
#endif

}  // namespace

namespace {
// One band's working set (renderDepth): its rays, hits and shadow rays, and each pixel's noise
// draws.
constexpr int kBand = 1024;
struct Band {
  Ray rays[kBand], shadows[kBand];
  Hit hits[kBand];
  uint8_t ok[kBand], blocked[kBand], packedBlocked[kBand];
  int shadowIndex[kBand];
  uint64_t lateral[kBand], axial[kBand];
  float gu[kBand], gv[kBand], gz[kBand];  // each pixel's standard normal draws
};

// A frame's rendering: what every band of pixels shares, and the steps each band goes through
// (primary rays, lateral noise, the acceptance and projector-shadow test, the depths written).
struct FrameRender {
  const RayScene& scene;
  const Iso3& T_S_C;
  const CameraIntrinsics& K;
  const DepthCameraOptions& camera;
  const NoiseModelOptions& noise;
  const RenderOptions& options;
  int w;
  Vec3 projector_S;
  std::vector<double> xs, ys;  // the pixel centres' rays: K.rayZ1's per-column and per-row terms
  Vec3f origin;
  Mat3 R;
  Background background;
  IncidenceLimits limits;
  double f, cosGrazing;
  DepthImage* out;
  std::vector<int>* geometry_out;
#if INHAND_FAST_MATH_AVX2
  bool vectorised;
  LateralStep lateralStep;
  AcceptStep acceptStep;
  DepthStep depthStep;
#endif

  FrameRender(const RayScene& scene_, const Iso3& T_S_C_, const DepthCameraOptions& camera_,
              const NoiseModelOptions& noise_, const RenderOptions& options_, DepthImage* out_,
              std::vector<int>* geometry_out_)
      : scene(scene_),
        T_S_C(T_S_C_),
        K(camera_.intrinsics),
        camera(camera_),
        noise(noise_),
        options(options_),
        w(K.width),
        projector_S(T_S_C * camera.projector_C),
        xs(size_t(K.width)),
        ys(size_t(K.height)),
        origin(T_S_C.translation().cast<float>()),
        R(T_S_C.linear()),
        background(scene, options),
        limits(camera),
        f(K.fx),
        cosGrazing(std::cos(noise.grazing_start_deg * M_PI / 180)),
        out(out_),
        geometry_out(geometry_out_)
#if INHAND_FAST_MATH_AVX2
        ,
        vectorised(options.vectorised && fastMathAvx2()),
        lateralStep{&background,
                    origin.cast<double>() - background.centre,
                    noise.lateral_c0_px,
                    noise.lateral_c1_px,
                    noise.max_incidence_deg * M_PI / 180.0,
                    K.cx,
                    K.cy,
                    K.fx,
                    K.fy,
                    R,
                    w},
        acceptStep{&background,
                   origin.cast<double>() - background.centre,
                   origin,
                   projector_S,
                   camera.min_range_m,
                   camera.max_range_m,
                   limits.camera,
                   limits.projector,
                   &camera,
                   &limits},
        depthStep{cosGrazing,         noise.axial_c0_m,        noise.axial_c1,
                  noise.axial_z0_m,   f * camera.baseline_m(), noise.disparity_step_px,
                  camera.min_range_m, camera.max_range_m,      noise.quantize}
#endif
  {
    for (int u = 0; u < K.width; ++u) xs[size_t(u)] = K.rayZ1(u, 0).x();
    for (int v = 0; v < K.height; ++v) ys[size_t(v)] = K.rayZ1(0, v).y();
  }
  FrameRender(const FrameRender&) = delete;  // the steps point at background and limits

  // The band's m pixels `px` rendered into `out`.
  void render(Band& band, const int* px, int m) const {
    for (int k = 0; k < m; ++k) {
      const int p = px[k];
      band.rays[k] = Ray{};
      band.rays[k].origin = origin;
      band.rays[k].dir = (R * Vec3(xs[size_t(p % w)], ys[size_t(p / w)], 1.0)).cast<float>();
    }
    scene.intersect(band.rays, band.hits, size_t(m), false);
    if (options.noise) lateralNoise(band, px, m);
    acceptAndShadow(band, m);
    writeDepths(band, px, m);
  }

 private:
  // Each pixel's draws (the lateral pair at index 3p, the axial one at 3p + 2). Lateral noise:
  // the return comes from a point displaced by N(0, σ_L(θ)) pixels, so the ray is cast again
  // through the displaced sub-pixel position (this also makes ragged, mixed depth edges).
  void lateralNoise(Band& band, const int* px, int m) const {
    Ray* rays = band.rays;
    Hit* hits = band.hits;
    for (int k = 0; k < m; ++k) {
      band.lateral[k] = 3 * uint64_t(px[k]);
      band.axial[k] = band.lateral[k] + 2;
    }
    gaussianPairsF(options.seed, band.lateral, size_t(m), band.gu, band.gv);
    gaussianPairsF(options.seed, band.axial, size_t(m), band.gz, nullptr);
    int k = 0;
#if INHAND_FAST_MATH_AVX2
    if (vectorised)
      for (; k + 4 <= m; k += 4)
        lateralFour(lateralStep, px + k, band.gu + k, band.gv + k, rays + k, hits + k);
#endif
    for (; k < m; ++k) {
      background.fill(rays[k], hits[k]);
      if (!hits[k].valid()) continue;
      const int p = px[k];
      const double theta = incidenceF(hits[k].normal, rays[k].dir);
      const double s = lateralSigmaPx(noise, theta);
      const double du = s * band.gu[k], dv = s * band.gv[k];
      rays[k] = pixelRay(T_S_C, K, p % w + du, p / w + dv);
    }
    scene.intersect(rays, hits, size_t(m), false);
  }

  // Which hits the sensor accepts (band.ok), and which of those the projector cannot see
  // (band.blocked): the shadow rays packed in pixel order (over the band's own), so packets
  // stay full.
  void acceptAndShadow(Band& band, int m) const {
    int shadowCount = 0;
    auto pack = [&](int k) {
      band.blocked[k] = 0;
      if (band.ok[k] && options.projector_shadows) {
        band.shadows[shadowCount] = band.shadows[k];
        band.shadowIndex[shadowCount++] = k;
      }
    };
    int k = 0;
#if INHAND_FAST_MATH_AVX2
    if (vectorised)
      for (; k + 4 <= m; k += 4) {
        const int ok = acceptFour(acceptStep, band.rays + k, band.hits + k, band.shadows + k);
        for (int j = 0; j < 4; ++j) {
          band.ok[k + j] = uint8_t(ok >> j & 1);
          pack(k + j);
        }
      }
#endif
    for (; k < m; ++k) {
      background.fill(band.rays[k], band.hits[k]);
      band.ok[k] =
          acceptHit(band.hits[k], band.rays[k], projector_S, camera, limits, &band.shadows[k]);
      pack(k);
    }
    if (shadowCount > 0) {
      scene.occluded(band.shadows, band.packedBlocked, size_t(shadowCount), false);
      for (int j = 0; j < shadowCount; ++j)
        band.blocked[band.shadowIndex[j]] = band.packedBlocked[j];
    }
  }

  // One accepted pixel's depth with axial noise (the angle matters to the axial σ only beyond
  // grazing_start_deg) and quantisation; none outside the sensor's range.
  void writeDepth(const Band& band, const int* px, int k) const {
    if (!band.ok[k] || band.blocked[k]) return;
    const int p = px[k];
    double z = band.hits[k].t;
    if (options.noise) {
      double theta = 0;
      if (!(cosGrazing > 0) ||
          !cosCertainlyAtLeastF(band.hits[k].normal, band.rays[k].dir, cosGrazing)) {
        const double c = cosIncidenceF(band.hits[k].normal, band.rays[k].dir);
        theta = c < cosGrazing ? std::acos(c) : 0.0;
      }
      z += axialSigma(noise, z, theta) * band.gz[k];
      if (noise.quantize) z = quantizeDepth(z, f, camera.baseline_m(), noise.disparity_step_px);
      if (z < camera.min_range_m || z > camera.max_range_m) return;
    }
    out->depth_m[size_t(p)] = float(z);
    if (geometry_out) (*geometry_out)[size_t(p)] = band.hits[k].geometry;
  }

  void writeDepths(const Band& band, const int* px, int m) const {
    int k = 0;
#if INHAND_FAST_MATH_AVX2
    if (vectorised && options.noise && cosGrazing > 0)
      for (; k + 4 <= m; k += 4) {
        int live = 0;
        for (int j = 0; j < 4; ++j) live |= (band.ok[k + j] && !band.blocked[k + j]) << j;
        if (live == 0) continue;
        float z[4];
        int rest = 0;
        const int written =
            depthFour(depthStep, band.rays + k, band.hits + k, band.gz + k, live, z, &rest);
        for (int j = 0; j < 4; ++j) {
          if (rest >> j & 1) {
            writeDepth(band, px, k + j);
          } else if (written >> j & 1) {
            out->depth_m[size_t(px[k + j])] = z[j];
            if (geometry_out) (*geometry_out)[size_t(px[k + j])] = band.hits[k + j].geometry;
          }
        }
      }
#endif
    for (; k < m; ++k) writeDepth(band, px, k);
  }
};
}  // namespace

DepthImage renderDepth(const RayScene& scene, const Iso3& T_S_C, const DepthCameraOptions& camera,
                       const NoiseModelOptions& noise, const RenderOptions& options,
                       std::vector<int>* geometry_out) {
  const CameraIntrinsics& K = camera.intrinsics;
  const int w = K.width, h = K.height;
  // The whole image's tile order is kept per thread (it is the same for every frame).
  thread_local std::vector<int> wholeOrder;
  thread_local int orderW = 0, orderH = 0;
  const bool whole = options.region_u1 < 0 || options.region_v1 < 0;
  if (whole && (orderW != w || orderH != h)) {
    wholeOrder = tileOrder(w, 0, 0, w, h);
    orderW = w;
    orderH = h;
  }
  std::vector<int> regionOrder;
  if (!whole)
    regionOrder =
        tileOrder(w, std::clamp(options.region_u0, 0, w), std::clamp(options.region_v0, 0, h),
                  std::clamp(options.region_u1, 0, w), std::clamp(options.region_v1, 0, h));
  const std::vector<int>& order = whole ? wholeOrder : regionOrder;
  const int n = int(order.size());
  DepthImage out(w, h);
  if (geometry_out) geometry_out->assign(size_t(w) * h, -1);
  const FrameRender frame(scene, T_S_C, camera, noise, options, &out, geometry_out);
  // Each task takes a band of pixels through every step, rays cast in packets on its own core:
  // the band's rays, hits and shadow rays (~100 KB) stay in the core's cache from one step to the
  // next (passes over the whole image's ~25 MB of them cost as much in memory traffic as the
  // ray casting). A band starts at a multiple of kBand, so the noise draws are the same ones.
  parallelFor(0, (n + kBand - 1) / kBand, [&](int b) {
    thread_local Band band;
    const int i0 = b * kBand, m = std::min(n, i0 + kBand) - i0;
    frame.render(band, order.data() + i0, m);
  });
  return out;
}

DepthImage renderDepthReference(const RayScene& scene, const Iso3& T_S_C,
                                const DepthCameraOptions& camera) {
  const CameraIntrinsics& K = camera.intrinsics;
  const Vec3 projector_S = T_S_C * camera.projector_C;
  DepthImage out(K.width, K.height);
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      Ray ray = pixelRay(T_S_C, K, u, v);
      Hit hit = scene.intersectOne(ray);
      Ray shadow;
      if (!acceptHit(hit, ray, projector_S, camera, IncidenceLimits(camera), &shadow)) continue;
      if (scene.intersectOne(shadow).valid()) continue;  // projector cannot see the point
      out.at(u, v) = hit.t;
    }
  return out;
}

}  // namespace inhand
