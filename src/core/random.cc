#include "inhand/core/random.h"

namespace inhand {

namespace {
#if INHAND_FAST_MATH_AVX2
// Eight pairs from their uniforms (boxMullerF8); returns how many it did (a multiple of 8).
__attribute__((target("avx2"))) size_t gaussianPairsEight(uint64_t seed, const uint64_t* index,
                                                          size_t n, float* first, float* second) {
  size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    alignas(32) float u1[8], u2[8];
    for (int l = 0; l < 8; ++l) uniformPairF(seed, index[k + size_t(l)], &u1[l], &u2[l]);
    __m256 g0, g1;
    boxMullerF8(_mm256_load_ps(u1), _mm256_load_ps(u2), &g0, &g1);
    _mm256_storeu_ps(first + k, g0);
    if (second) _mm256_storeu_ps(second + k, g1);
  }
  return k;
}
#endif
}  // namespace

void gaussianPairsF(uint64_t seed, const uint64_t* index, size_t n, float* first, float* second) {
  size_t k = 0;
#if INHAND_FAST_MATH_AVX2
  if (fastMathAvx2()) k = gaussianPairsEight(seed, index, n, first, second);
#endif
  for (; k < n; ++k) {
    float u1, u2, g1;
    uniformPairF(seed, index[k], &u1, &u2);
    boxMullerF(u1, u2, &first[k], &g1);
    if (second) second[k] = g1;
  }
}

}  // namespace inhand
