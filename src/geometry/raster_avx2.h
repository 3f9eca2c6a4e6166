#pragma once
// Shared by the rasterisers' four-triangle set-ups (DepthRaster::drawFour,
// ProjectorShadows::drawFour); private to the geometry module.
#include "inhand/geometry/raster.h"

#if INHAND_RASTER_AVX2
#include <immintrin.h>

namespace inhand {

// The corners of triangles k[0..3] of `mesh`, as `verts` projected them, in AVX2 lanes: x[c],
// y[c], iz[c] for corner c. Built from scalar loads: on the AMD cores this was measured on,
// nine vgatherdpd cost more.
__attribute__((target("avx2"), always_inline)) inline void loadFourTriangles(
    const TriangleMesh& mesh, const DepthRaster::ProjectedVertex* verts, const size_t* k,
    __m256d x[3], __m256d y[3], __m256d iz[3]) {
  const Tri* T = mesh.triangles.data();
  for (int c = 0; c < 3; ++c) {
    const DepthRaster::ProjectedVertex &v0 = verts[T[k[0]][c]], &v1 = verts[T[k[1]][c]],
                                       &v2 = verts[T[k[2]][c]], &v3 = verts[T[k[3]][c]];
    x[c] = _mm256_setr_pd(v0.x, v1.x, v2.x, v3.x);
    y[c] = _mm256_setr_pd(v0.y, v1.y, v2.y, v3.y);
    iz[c] = _mm256_setr_pd(v0.iz, v1.iz, v2.iz, v3.iz);
  }
}

}  // namespace inhand
#endif
