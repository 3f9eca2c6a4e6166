#pragma once
// Deterministic random streams. Each parallel work item derives its own generator from
// (seed, item index), so results do not depend on thread count or scheduling.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <utility>

#include "inhand/core/internal/fast_math.h"

namespace inhand {

// SplitMix64 finaliser: a good 64-bit mix of a seed and a stream index.
inline uint64_t mixSeed(uint64_t seed, uint64_t stream) {
  uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

using Rng = std::mt19937_64;
inline Rng makeRng(uint64_t seed, uint64_t stream = 0) { return Rng(mixSeed(seed, stream)); }

}  // namespace inhand

namespace inhand {

// Counter-based standard normal sample: the same (seed, index) always gives the same value, at no
// set-up cost, so per-pixel noise is reproducible under any parallel schedule (Box–Muller).
inline double gaussianAt(uint64_t seed, uint64_t index) {
  uint64_t a = mixSeed(seed, 2 * index), b = mixSeed(seed, 2 * index + 1);
  double u1 = (double(a >> 11) + 0.5) * (1.0 / 9007199254740992.0);  // (0, 1)
  double u2 = double(b >> 11) * (1.0 / 9007199254740992.0);          // [0, 1)
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
}

// Two independent standard normal samples from one (seed, index), both outputs of Box–Muller:
// the first is gaussianAt(seed, index), the second its sine partner (for half the cost of two).
inline std::pair<double, double> gaussianPairAt(uint64_t seed, uint64_t index) {
  uint64_t a = mixSeed(seed, 2 * index), b = mixSeed(seed, 2 * index + 1);
  double u1 = (double(a >> 11) + 0.5) * (1.0 / 9007199254740992.0);  // (0, 1)
  double u2 = double(b >> 11) * (1.0 / 9007199254740992.0);          // [0, 1)
  const double r = std::sqrt(-2.0 * std::log(u1)), phi = 6.283185307179586 * u2;
  return {r * std::cos(phi), r * std::sin(phi)};
}

// The same Box–Muller pair in single precision from the same two hashes (their top 24 bits), for
// per-pixel noise where the double-precision libm calls cost more than the ray casting, with the
// elementary functions of fast_math.h (boxMullerF: the batch below gives the same bits): within
// 1e-4 of gaussianPairAt(seed, index) wherever |r| < 3.7 (uniforms above 1e-3), its tails cut at
// 5.9 (the smallest uniform is 2^-25).
inline void uniformPairF(uint64_t seed, uint64_t index, float* u1, float* u2) {
  const uint64_t a = mixSeed(seed, 2 * index), b = mixSeed(seed, 2 * index + 1);
  *u1 = (float(int32_t(a >> 40)) + 0.5f) * 0x1.0p-24f;  // (0, 1)
  *u2 = float(int32_t(b >> 40)) * 0x1.0p-24f;           // [0, 1)
}
inline std::pair<float, float> gaussianPairAtF(uint64_t seed, uint64_t index) {
  float u1, u2, g0, g1;
  uniformPairF(seed, index, &u1, &u2);
  boxMullerF(u1, u2, &g0, &g1);
  return {g0, g1};
}

// The first of that pair alone (gaussianAt in single precision).
inline float gaussianAtF(uint64_t seed, uint64_t index) {
  return gaussianPairAtF(seed, index).first;
}

// gaussianPairAtF(seed, index[k]) for k < n into first[k] and second[k] (second may be null), eight
// at a time where the CPU has AVX2: the same bits either way.
void gaussianPairsF(uint64_t seed, const uint64_t* index, size_t n, float* first, float* second);

}  // namespace inhand
