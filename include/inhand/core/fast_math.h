#pragma once
// Inline elementary functions for hot loops, where a libm call per element costs more than the
// arithmetic around it. Each is checked against libm in tests/test_core.cc.
#include <cstdint>
#include <cstring>

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

}  // namespace inhand
