#pragma once
// Inline elementary functions for hot loops, where a libm call per element costs more than the
// arithmetic around it. Each is checked against libm in tests/test_core.cc.
#include <cstdint>
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

#if INHAND_FAST_MATH_AVX2
// Whether this CPU runs the AVX2 functions below.
inline bool fastMathAvx2() {
  static const bool yes = __builtin_cpu_supports("avx2");
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
#endif

}  // namespace inhand
