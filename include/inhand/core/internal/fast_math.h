#pragma once
// Inline elementary functions for hot loops, where a libm call per element costs more than the
// arithmetic around it. Each is checked against libm in tests/test_core.cc.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define INHAND_FAST_MATH_AVX2 1
#else
#define INHAND_FAST_MATH_AVX2 0
#endif

namespace inhand {

// ln(1 + x) for x ≥ 0 (finite), relative error below 1e-12: below 1e-3 its series to x⁵, else
// ln(m·2^e) = e·ln 2 + 2·atanh((m − 1)/(m + 1)) with m in [√½, √2], the atanh series to s¹⁵.
inline double log1pNonNegative(double x) {
  if (x < 1e-3) return x * (1.0 - x * (0.5 - x * (1.0 / 3.0 - x * (0.25 - 0.2 * x))));
  const double u = 1.0 + x;
  uint64_t bits;
  std::memcpy(&bits, &u, sizeof bits);
  int e = int((bits >> 52) & 0x7FF) - 1023;
  bits = (bits & 0x000FFFFFFFFFFFFFull) | 0x3FF0000000000000ull;  // mantissa in [1, 2)
  double m;
  std::memcpy(&m, &bits, sizeof m);
  if (m > 1.4142135623730951) {
    m *= 0.5;
    ++e;
  }
  const double s = (m - 1.0) / (m + 1.0), s2 = s * s;
  const double series =
      1.0 +
      s2 * (1.0 / 3 +
            s2 * (1.0 / 5 +
                  s2 * (1.0 / 7 +
                        s2 * (1.0 / 9 + s2 * (1.0 / 11 + s2 * (1.0 / 13 + s2 * (1.0 / 15)))))));
  return double(e) * 0.6931471805599453 + 2.0 * s * series;
}

// ---- single precision, for per-pixel noise ------------------------------------------------------
// Each float function below has an AVX2 twin of eight lanes that takes the same IEEE steps (both
// branches computed, then chosen; no FMA), so the two agree bit for bit and a frame does not
// depend on the CPU that renders it.

// ln x for a positive normal float, within a few ulp: ln(m·2^e) = e·ln 2 + 2·atanh((m − 1)/(m + 1))
// with m in [√½, √2], the atanh series to s⁹.
inline float logPositiveF(float x) {
  uint32_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  int e = int(bits >> 23) - 127;
  bits = (bits & 0x007FFFFFu) | 0x3F800000u;  // mantissa in [1, 2)
  float m;
  std::memcpy(&m, &bits, sizeof m);
  if (m > 1.41421356f) {
    m *= 0.5f;
    e += 1;
  }
  const float s = (m - 1.f) / (m + 1.f), s2 = s * s;
  float p = 1.f / 9.f;
  p = 1.f / 7.f + s2 * p;
  p = 1.f / 5.f + s2 * p;
  p = 1.f / 3.f + s2 * p;
  p = 1.f + s2 * p;
  return float(e) * 0.693147182f + (2.f * s) * p;
}

// sin and cos of 2π·t for t in [0, 1) with 24 fractional bits (a uniform draw): the quarter turn
// nearest t, exactly, then Taylor polynomials on [−π/4, π/4] (to x⁹ and x⁸).
inline void sinCosTurnF(float t, float* sin_out, float* cos_out) {
  const float t4 = 4.f * t;
  const int q = int(t4 + 0.5f);
  const float x = (t4 - float(q)) * 1.57079637f, x2 = x * x;
  float sp = 1.f / 362880.f;
  sp = -1.f / 5040.f + x2 * sp;
  sp = 1.f / 120.f + x2 * sp;
  sp = -1.f / 6.f + x2 * sp;
  sp = 1.f + x2 * sp;
  const float sx = x * sp;
  float cp = 1.f / 40320.f;
  cp = -1.f / 720.f + x2 * cp;
  cp = 1.f / 24.f + x2 * cp;
  cp = -0.5f + x2 * cp;
  const float cx = 1.f + x2 * cp;
  float sv = (q & 1) ? cx : sx, cv = (q & 1) ? sx : cx;
  if (q & 2) sv = -sv;
  if ((q + 1) & 2) cv = -cv;
  *sin_out = sv;
  *cos_out = cv;
}

// Box–Muller from two uniforms (u1 in (0, 1), u2 in [0, 1) with 24 fractional bits): √(−2 ln u1)
// times cos and sin of 2π·u2.
inline void boxMullerF(float u1, float u2, float* g_cos, float* g_sin) {
  const float r = std::sqrt(-2.f * logPositiveF(u1));
  float sv, cv;
  sinCosTurnF(u2, &sv, &cv);
  *g_cos = r * cv;
  *g_sin = r * sv;
}

// arccos x for x in [0, 1]: √(1 − x) times a degree-7 polynomial (Abramowitz & Stegun 4.4.46,
// |error| ≤ 2e-8 before rounding).
inline float acosUnitF(float x) {
  float p = -0.0012624911f;
  p = 0.0066700901f + x * p;
  p = -0.0170881256f + x * p;
  p = 0.0308918810f + x * p;
  p = -0.0501743046f + x * p;
  p = 0.0889789874f + x * p;
  p = -0.2145988016f + x * p;
  p = 1.5707963050f + x * p;
  return std::sqrt(1.f - x) * p;
}

// INHAND_NO_AVX2 set to anything but "" or "0": every run-time AVX2 path of inhand is off, as
// on a CPU without AVX2 (with it, scripts/test.sh also turns off AVX2 and FMA in glibc's libm and
// in Embree; CI runs the suite both ways).
inline bool avx2TurnedOff() {
  static const bool off = [] {
    const char* v = std::getenv("INHAND_NO_AVX2");
    return v && *v && std::strcmp(v, "0") != 0;
  }();
  return off;
}

#if INHAND_FAST_MATH_AVX2
// Whether this CPU runs the AVX2 functions below (and INHAND_NO_AVX2 does not turn them off).
inline bool fastMathAvx2() {
  static const bool yes = __builtin_cpu_supports("avx2") && !avx2TurnedOff();
  return yes;
}

// log1pNonNegative of four lanes (AVX2): each lane takes the same IEEE steps as the scalar
// function (both branches computed, then chosen; no FMA), so the results agree bit for bit.
__attribute__((target("avx2"))) inline __m256d log1pNonNegativeFour(__m256d x) {
  const __m256d one = _mm256_set1_pd(1.0);
  // x < 1e-3: the series.
  __m256d t = _mm256_sub_pd(_mm256_set1_pd(0.25), _mm256_mul_pd(_mm256_set1_pd(0.2), x));
  t = _mm256_sub_pd(_mm256_set1_pd(1.0 / 3.0), _mm256_mul_pd(x, t));
  t = _mm256_sub_pd(_mm256_set1_pd(0.5), _mm256_mul_pd(x, t));
  t = _mm256_sub_pd(one, _mm256_mul_pd(x, t));
  const __m256d series5 = _mm256_mul_pd(x, t);
  // Else: exponent and mantissa of 1 + x.
  const __m256i bits = _mm256_castpd_si256(_mm256_add_pd(one, x));
  __m256i e =
      _mm256_sub_epi64(_mm256_and_si256(_mm256_srli_epi64(bits, 52), _mm256_set1_epi64x(0x7FF)),
                       _mm256_set1_epi64x(1023));
  __m256d m = _mm256_castsi256_pd(
      _mm256_or_si256(_mm256_and_si256(bits, _mm256_set1_epi64x(0x000FFFFFFFFFFFFFll)),
                      _mm256_set1_epi64x(0x3FF0000000000000ll)));
  const __m256d big = _mm256_cmp_pd(m, _mm256_set1_pd(1.4142135623730951), _CMP_GT_OQ);
  m = _mm256_blendv_pd(m, _mm256_mul_pd(m, _mm256_set1_pd(0.5)), big);
  e = _mm256_sub_epi64(e, _mm256_castpd_si256(big));  // big lanes are all ones: −(−1)
  const __m256d s = _mm256_div_pd(_mm256_sub_pd(m, one), _mm256_add_pd(m, one));
  const __m256d s2 = _mm256_mul_pd(s, s);
  __m256d q = _mm256_mul_pd(s2, _mm256_set1_pd(1.0 / 15));
  for (double k : {13.0, 11.0, 9.0, 7.0, 5.0})
    q = _mm256_mul_pd(s2, _mm256_add_pd(_mm256_set1_pd(1.0 / k), q));
  q = _mm256_add_pd(one, _mm256_mul_pd(s2, _mm256_add_pd(_mm256_set1_pd(1.0 / 3), q)));
  // The exponents (within ±1100) to double through their low 32 bits.
  const __m256i low = _mm256_permutevar8x32_epi32(e, _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6));
  const __m256d ed = _mm256_cvtepi32_pd(_mm256_castsi256_si128(low));
  const __m256d logs = _mm256_add_pd(_mm256_mul_pd(ed, _mm256_set1_pd(0.6931471805599453)),
                                     _mm256_mul_pd(_mm256_mul_pd(_mm256_set1_pd(2.0), s), q));
  return _mm256_blendv_pd(logs, series5, _mm256_cmp_pd(x, _mm256_set1_pd(1e-3), _CMP_LT_OQ));
}

// logPositiveF of eight lanes.
__attribute__((target("avx2"))) inline __m256 logPositiveF8(__m256 x) {
  const __m256i bits = _mm256_castps_si256(x);
  __m256i e = _mm256_sub_epi32(_mm256_srli_epi32(bits, 23), _mm256_set1_epi32(127));
  __m256 m = _mm256_castsi256_ps(_mm256_or_si256(
      _mm256_and_si256(bits, _mm256_set1_epi32(0x007FFFFF)), _mm256_set1_epi32(0x3F800000)));
  const __m256 big = _mm256_cmp_ps(m, _mm256_set1_ps(1.41421356f), _CMP_GT_OQ);
  m = _mm256_blendv_ps(m, _mm256_mul_ps(m, _mm256_set1_ps(0.5f)), big);
  e = _mm256_sub_epi32(e, _mm256_castps_si256(big));  // big lanes are all ones: −(−1)
  const __m256 one = _mm256_set1_ps(1.f);
  const __m256 s = _mm256_div_ps(_mm256_sub_ps(m, one), _mm256_add_ps(m, one));
  const __m256 s2 = _mm256_mul_ps(s, s);
  __m256 p = _mm256_set1_ps(1.f / 9.f);
  p = _mm256_add_ps(_mm256_set1_ps(1.f / 7.f), _mm256_mul_ps(s2, p));
  p = _mm256_add_ps(_mm256_set1_ps(1.f / 5.f), _mm256_mul_ps(s2, p));
  p = _mm256_add_ps(_mm256_set1_ps(1.f / 3.f), _mm256_mul_ps(s2, p));
  p = _mm256_add_ps(one, _mm256_mul_ps(s2, p));
  return _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(e), _mm256_set1_ps(0.693147182f)),
                       _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(2.f), s), p));
}

// boxMullerF of eight lanes.
__attribute__((target("avx2"))) inline void boxMullerF8(__m256 u1, __m256 u2, __m256* g_cos,
                                                        __m256* g_sin) {
  const __m256 r = _mm256_sqrt_ps(_mm256_mul_ps(_mm256_set1_ps(-2.f), logPositiveF8(u1)));
  const __m256 t4 = _mm256_mul_ps(_mm256_set1_ps(4.f), u2);
  const __m256i q = _mm256_cvttps_epi32(_mm256_add_ps(t4, _mm256_set1_ps(0.5f)));
  const __m256 x =
      _mm256_mul_ps(_mm256_sub_ps(t4, _mm256_cvtepi32_ps(q)), _mm256_set1_ps(1.57079637f));
  const __m256 x2 = _mm256_mul_ps(x, x);
  __m256 sp = _mm256_set1_ps(1.f / 362880.f);
  sp = _mm256_add_ps(_mm256_set1_ps(-1.f / 5040.f), _mm256_mul_ps(x2, sp));
  sp = _mm256_add_ps(_mm256_set1_ps(1.f / 120.f), _mm256_mul_ps(x2, sp));
  sp = _mm256_add_ps(_mm256_set1_ps(-1.f / 6.f), _mm256_mul_ps(x2, sp));
  sp = _mm256_add_ps(_mm256_set1_ps(1.f), _mm256_mul_ps(x2, sp));
  const __m256 sx = _mm256_mul_ps(x, sp);
  __m256 cp = _mm256_set1_ps(1.f / 40320.f);
  cp = _mm256_add_ps(_mm256_set1_ps(-1.f / 720.f), _mm256_mul_ps(x2, cp));
  cp = _mm256_add_ps(_mm256_set1_ps(1.f / 24.f), _mm256_mul_ps(x2, cp));
  cp = _mm256_add_ps(_mm256_set1_ps(-0.5f), _mm256_mul_ps(x2, cp));
  const __m256 cx = _mm256_add_ps(_mm256_set1_ps(1.f), _mm256_mul_ps(x2, cp));
  const __m256i one = _mm256_set1_epi32(1), two = _mm256_set1_epi32(2);
  const __m256 swap = _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(q, one), one));
  // Sign bits: sin's flips when q & 2, cos's when (q + 1) & 2 (bit 1 moved to bit 31).
  const __m256 sinSign = _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_and_si256(q, two), 30));
  const __m256 cosSign =
      _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_and_si256(_mm256_add_epi32(q, one), two), 30));
  const __m256 sv = _mm256_xor_ps(_mm256_blendv_ps(sx, cx, swap), sinSign);
  const __m256 cv = _mm256_xor_ps(_mm256_blendv_ps(cx, sx, swap), cosSign);
  *g_cos = _mm256_mul_ps(r, cv);
  *g_sin = _mm256_mul_ps(r, sv);
}
#endif

}  // namespace inhand
