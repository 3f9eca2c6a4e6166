#pragma once
// Shared by the rasterisers' four-triangle set-ups (DepthRaster::drawFour,
// ProjectorShadows::drawFour); private to the geometry module.
#include "inhand/geometry/internal/raster.h"

#if INHAND_RASTER_AVX2
#include <immintrin.h>

namespace inhand {

// The corners of triangles k[0..3] of `mesh`, as `verts` projected them, in AVX2 lanes: x[c],
// y[c], iz[c] for corner c. Built from scalar loads: on the AMD cores this was measured on,
// nine vgatherdpd cost more. Returns a bit per triangle with a corner behind the near plane
// (iz < 0: the one-at-a-time path clips it).
__attribute__((target("avx2"), always_inline)) inline int loadFourTriangles(
    const TriangleMesh& mesh, const DepthRaster::ProjectedVertex* verts, const size_t* k,
    __m256d x[3], __m256d y[3], __m256d iz[3]) {
  const Tri* T = mesh.triangles.data();
  const __m256d zero = _mm256_setzero_pd();
  __m256d behind = zero;
  for (int c = 0; c < 3; ++c) {
    const DepthRaster::ProjectedVertex &v0 = verts[T[k[0]][c]], &v1 = verts[T[k[1]][c]],
                                       &v2 = verts[T[k[2]][c]], &v3 = verts[T[k[3]][c]];
    x[c] = _mm256_setr_pd(v0.x, v1.x, v2.x, v3.x);
    y[c] = _mm256_setr_pd(v0.y, v1.y, v2.y, v3.y);
    iz[c] = _mm256_setr_pd(v0.iz, v1.iz, v2.iz, v3.iz);
    behind = _mm256_or_pd(behind, _mm256_cmp_pd(iz[c], zero, _CMP_LT_OQ));
  }
  return _mm256_movemask_pd(behind);
}

// Twice the signed area of the four triangles (x[c], y[c]), as the one-at-a-time paths compute
// it: (x1 − x0)(y2 − y0) − (y1 − y0)(x2 − x0).
__attribute__((target("avx2"), always_inline)) inline __m256d signedAreaFour(const __m256d* x,
                                                                             const __m256d* y) {
  return _mm256_sub_pd(_mm256_mul_pd(_mm256_sub_pd(x[1], x[0]), _mm256_sub_pd(y[2], y[0])),
                       _mm256_mul_pd(_mm256_sub_pd(y[1], y[0]), _mm256_sub_pd(x[2], x[0])));
}

// ±1 by the sign of the area (+1 where it is positive), as the one-at-a-time paths' sg.
__attribute__((target("avx2"), always_inline)) inline __m256d signOfAreaFour(__m256d area) {
  return _mm256_blendv_pd(_mm256_set1_pd(-1.0), _mm256_set1_pd(1.0),
                          _mm256_cmp_pd(area, _mm256_setzero_pd(), _CMP_GT_OQ));
}

// out[l] = (r[0][l], r[1][l], r[2][l], r[3][l]): four lanes of four vectors, regrouped by lane.
__attribute__((target("avx2"), always_inline)) inline void transposeFour(const __m256d* r,
                                                                         double (*out)[4]) {
  const __m256d t0 = _mm256_unpacklo_pd(r[0], r[1]), t1 = _mm256_unpackhi_pd(r[0], r[1]);
  const __m256d t2 = _mm256_unpacklo_pd(r[2], r[3]), t3 = _mm256_unpackhi_pd(r[2], r[3]);
  _mm256_store_pd(out[0], _mm256_permute2f128_pd(t0, t2, 0x20));
  _mm256_store_pd(out[1], _mm256_permute2f128_pd(t1, t3, 0x20));
  _mm256_store_pd(out[2], _mm256_permute2f128_pd(t0, t2, 0x31));
  _mm256_store_pd(out[3], _mm256_permute2f128_pd(t1, t3, 0x31));
}

}  // namespace inhand
#endif
