#include "inhand/geometry/internal/projector_shadows.h"

#include <algorithm>
#include <cmath>
#include <limits>
#if INHAND_RASTER_AVX2
#include "raster_avx2.h"
#endif

namespace inhand {

void ProjectorShadows::reset(const PinholeProjection& K, const RasterWindow& window,
                             double baseline_x_m) {
  K_ = K;
  window_ = window;
  baseline_ = baseline_x_m;
  shift_ = K.fx * baseline_x_m / window.stride;
  minIzBlock_ = std::numeric_limits<double>::infinity();
  minW_ = std::numeric_limits<double>::infinity();
  maxW_ = -std::numeric_limits<double>::infinity();
  points_.clear();
}

void ProjectorShadows::index() {
  // Buckets of whole W on a grid of rows × pitch, [base, base + pitch) the points' W range.
  const int rows = std::max(0, window_.height());
  base_ = points_.empty() ? 0 : floorToInt(minW_);
  pitch_ = points_.empty() ? 0 : floorToInt(maxW_) - base_ + 1;
  const size_t buckets = size_t(rows) * size_t(pitch_);
  first_.assign(buckets + 1, 0);
  thread_local std::vector<int> bucketOf;
  bucketOf.resize(points_.size());
  for (size_t k = 0; k < points_.size(); ++k) {
    const Point& p = points_[k];
    bucketOf[k] = (p.j - window_.j0) * pitch_ + floorToInt(p.W) - base_;
    ++first_[size_t(bucketOf[k])];
  }
  // Running sums and minima in registers, not through memory element by element. first_[b]: the
  // end of bucket b, until the sort below moves it back to the bucket's start.
  for (size_t b = 0, sum = 0; b < buckets; ++b) first_[b] = int(sum += size_t(first_[b]));
  first_[buckets] = int(points_.size());
  rowMinIzBlock_.assign(size_t(rows), std::numeric_limits<double>::infinity());
  for (size_t k = 0; k < points_.size();) {  // by runs of points on one row
    const int j = points_[k].j;
    double m = points_[k].izBlock;
    for (++k; k < points_.size() && points_[k].j == j; ++k) m = std::min(m, points_[k].izBlock);
    double& row = rowMinIzBlock_[size_t(j - window_.j0)];
    row = std::min(row, m);
  }
  // Counting sort of the points into their buckets, last point first: each bucket's end moves
  // back to its start, and its points keep their order.
  sortedW_.resize(points_.size() + 4);
  sortedIzBlock_.resize(points_.size() + 4);
  position_.resize(points_.size());
  sortedBlocked_.assign(points_.size(), 0);
  for (size_t k = points_.size(); k-- > 0;) {
    const int at = --first_[size_t(bucketOf[k])];
    sortedW_[size_t(at)] = points_[k].W;
    sortedIzBlock_[size_t(at)] = points_[k].izBlock;
    position_[k] = at;
  }
  for (size_t k = points_.size(); k < sortedW_.size(); ++k) sortedW_[k] = sortedIzBlock_[k] = 0;
}

__attribute__((always_inline)) inline void ProjectorShadows::triangle(const double* W,
                                                                      const double* y,
                                                                      const double* iz, bool cull) {
  const double area = (W[1] - W[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (W[2] - W[0]);
  // Zero: edge-on to the projector (it meets a projector ray only along its own plane).
  if (area == 0 || (cull && area > 0)) return;
  if (std::max({iz[0], iz[1], iz[2]}) < minIzBlock_) return;  // behind every point
  const double Wmin = std::min({W[0], W[1], W[2]}), Wmax = std::max({W[0], W[1], W[2]});
  if (Wmax < minW_ || Wmin > maxW_) return;
  const int ja = std::max(window_.j0, ceilToInt(std::min({y[0], y[1], y[2]})));
  const int jb = std::min(window_.j1, floorToInt(std::max({y[0], y[1], y[2]})));
  if (ja > jb) return;
  // Edge functions as DepthRaster::fill's: e_k(W, y) ≥ 0 inside, e_k / |area| the barycentric
  // coordinate of corner k, so 1/z = Σ_k e_k·iz_k / |area|: compared as Σ_k e_k·iz_k against
  // iz_block·|area|, without a division.
  const double sg = area > 0 ? 1.0 : -1.0;
  double eW[3], eY[3], e0[3];
  for (int k = 0; k < 3; ++k) {
    const int a = (k + 1) % 3, b = (k + 2) % 3;  // edge k runs from corner a to corner b
    eW[k] = -sg * (y[b] - y[a]);
    eY[k] = sg * (W[b] - W[a]);
    e0[k] = sg * ((W[b] - W[a]) * -y[a] + (y[b] - y[a]) * W[a]);
  }
  const double absArea = std::abs(area);
  const double zW = eW[0] * iz[0] + eW[1] * iz[1] + eW[2] * iz[2];
  const double zY = eY[0] * iz[0] + eY[1] * iz[1] + eY[2] * iz[2];
  const double z0 = e0[0] * iz[0] + e0[1] * iz[1] + e0[2] * iz[2];
  triangleRows({eW, eY, e0, 1, zW, zY, z0, absArea, Wmin, Wmax, ja, jb});
}

__attribute__((always_inline)) inline bool ProjectorShadows::rowSpan(const RowWalk& t, bool wide,
                                                                     int c0, int c1, int j,
                                                                     double* base, double* zRow,
                                                                     int* s0, int* s1) const {
  for (int k = 0; k < 3; ++k) base[k] = t.e0[k * t.step] + t.eY[k * t.step] * j;
  int b0 = c0, b1 = c1;
  *zRow = t.z0 + t.zY * j;
  if (wide) {  // the row's span, one unit of margin for rounding
    double lo = t.Wmin, hi = t.Wmax;
    for (int k = 0; k < 3; ++k) {
      const double ew = t.eW[k * t.step];
      if (ew > 0)
        lo = std::max(lo, -base[k] / ew - 1);
      else if (ew < 0)
        hi = std::min(hi, -base[k] / ew + 1);
      else if (base[k] < 0)
        hi = lo - 1;
    }
    // Where the triangle lies behind every point of the row it blocks nothing: only the part
    // with 1/z ≥ the row's least iz_block (zRow + zW·W ≥ that·|area|).
    const double need = rowMinIzBlock_[size_t(j - window_.j0)] * t.absArea - *zRow;
    if (t.zW > 0)
      lo = std::max(lo, need / t.zW - 1);
    else if (t.zW < 0)
      hi = std::min(hi, need / t.zW + 1);
    else if (need > 0)
      hi = lo - 1;
    if (lo > hi) return false;
    b0 = std::max(b0, floorToInt(lo) - base_);
    b1 = std::min(b1, floorToInt(hi) - base_);
  }
  if (b0 > b1) return false;
  const int rowFirst = (j - window_.j0) * pitch_;
  *s0 = first_[size_t(rowFirst + b0)];
  *s1 = first_[size_t(rowFirst + b1) + 1];
  return true;
}

__attribute__((always_inline)) inline void ProjectorShadows::triangleRows(const RowWalk& t) {
  const bool wide = t.Wmax - t.Wmin > 4;
  const int c0 = std::max(0, floorToInt(t.Wmin) - base_),
            c1 = std::min(pitch_ - 1, floorToInt(t.Wmax) - base_);
  const double ew0 = t.eW[0], ew1 = t.eW[t.step], ew2 = t.eW[2 * t.step];
  for (int j = t.ja; j <= t.jb; ++j) {
    double base[3], zRow;
    int s0, s1;
    if (!rowSpan(t, wide, c0, c1, j, base, &zRow, &s0, &s1)) continue;
    for (int s = s0; s < s1; ++s) {
      const double w = sortedW_[size_t(s)];
      const bool hit = (base[0] + ew0 * w >= 0) & (base[1] + ew1 * w >= 0) &
                       (base[2] + ew2 * w >= 0) &
                       (zRow + t.zW * w >= sortedIzBlock_[size_t(s)] * t.absArea);
      sortedBlocked_[size_t(s)] |= uint8_t(hit);
    }
  }
}

void ProjectorShadows::triangleCamera(const Vec3& a, const Vec3& b, const Vec3& c, bool cull) {
  // Clipped as DepthRaster::drawTriangle clips: the projector's rays through the window all
  // run at z > 0, and nothing within a millimetre of the sensor is real.
  Vec3 poly[4];
  const int m = clipToNearPlane(a, b, c, DepthRaster::kNear, poly);
  const double s = window_.stride;
  double W[4], y[4], iz[4];
  for (int k = 0; k < m; ++k) {
    iz[k] = 1.0 / poly[k].z();
    W[k] = (K_.fx * poly[k].x() * iz[k] + K_.cx) / s - shift_ * iz[k];
    y[k] = (K_.fy * poly[k].y() * iz[k] + K_.cy) / s;
  }
  for (int k = 1; k + 1 < m; ++k) {
    const double fW[3] = {W[0], W[k], W[k + 1]}, fy[3] = {y[0], y[k], y[k + 1]};
    const double fz[3] = {iz[0], iz[k], iz[k + 1]};
    triangle(fW, fy, fz, cull);
  }
}

void ProjectorShadows::draw(const TriangleMesh& mesh, const Iso3& T_C_mesh, bool cull_back_faces,
                            const std::vector<DepthRaster::ProjectedVertex>* projected,
                            const Aabb* bounds, const std::vector<uint64_t>* only) {
  if (points_.empty()) return;
  if (bounds && !bounds->empty()) {
    // The projector is a pinhole too: with every corner in front of the sensor the hull of
    // their (W, y) holds the mesh's, and 1/z peaks at a corner.
    const BoxInView v =
        boxInView(*bounds, T_C_mesh, K_, window_.stride, baseline_, DepthRaster::kNear);
    if (v.zmax < DepthRaster::kNear) return;
    if (v.allInFront && (1.0 / v.zmin < minIzBlock_ || v.xmax < minW_ || v.xmin > maxW_ ||
                         v.ymax < window_.j0 || v.ymin > window_.j1))
      return;
  }
  const Mat3 R = T_C_mesh.linear();
  const Vec3 t = T_C_mesh.translation();
  const std::vector<DepthRaster::ProjectedVertex>* V = projected;
  if (!V || V->size() != mesh.vertices.size()) {
    DepthRaster::projectVertices(mesh, T_C_mesh, K_, window_.stride, &verts_);
    V = &verts_;
  }
  const size_t nt = mesh.triangles.size();
  const bool masked = cull_back_faces && only && only->size() == (nt + 63) / 64;
  auto one = [&](size_t k) {
    const Tri& f = mesh.triangles[k];
    const DepthRaster::ProjectedVertex &A = (*V)[size_t(f[0])], &B = (*V)[size_t(f[1])],
                                       &C = (*V)[size_t(f[2])];
    if (A.iz < 0 || B.iz < 0 || C.iz < 0) {
      triangleCamera(R * mesh.vertices[size_t(f[0])].cast<double>() + t,
                     R * mesh.vertices[size_t(f[1])].cast<double>() + t,
                     R * mesh.vertices[size_t(f[2])].cast<double>() + t, cull_back_faces);
      return;
    }
    const double W[3] = {A.x - shift_ * A.iz, B.x - shift_ * B.iz, C.x - shift_ * C.iz};
    const double y[3] = {A.y, B.y, C.y}, iz[3] = {A.iz, B.iz, C.iz};
    triangle(W, y, iz, cull_back_faces);
  };
#if INHAND_RASTER_AVX2
  if (vectorised_) {
    // Four triangles at a time through the set-up; drawFour hands back the clipped ones.
    forEachMarkedInFours(
        nt, masked ? only : nullptr,
        [&](const size_t* k) { return drawFour(mesh, V->data(), k, cull_back_faces); }, one);
    return;
  }
#endif
  forEachMarked(nt, masked ? only : nullptr, one);
}

#if INHAND_RASTER_AVX2
namespace {
// triangleRows' tests of the sorted points [s, s1) of one row, four at a time, each lane the same
// IEEE double operations as there (no FMA): point k is blocked where r_e + c_e·W_k ≥ 0 for the
// three edges e and r3 + c3·W_k ≥ iz_block_k·area. Runs once even for no point (every lane
// masked off): most rows reach four points or fewer, so its loop is predictable.
__attribute__((target("avx2"), always_inline)) inline void testPointsFour(
    const double* W, const double* izBlock, uint8_t* blocked, int s, int s1, __m256d r0, __m256d r1,
    __m256d r2, __m256d r3, __m256d c0, __m256d c1, __m256d c2, __m256d c3, __m256d area) {
  const __m256d zero = _mm256_setzero_pd();
  do {
    const __m256d w = _mm256_loadu_pd(W + s);
    __m256d in = _mm256_cmp_pd(_mm256_add_pd(r0, _mm256_mul_pd(c0, w)), zero, _CMP_GE_OQ);
    in =
        _mm256_and_pd(in, _mm256_cmp_pd(_mm256_add_pd(r1, _mm256_mul_pd(c1, w)), zero, _CMP_GE_OQ));
    in =
        _mm256_and_pd(in, _mm256_cmp_pd(_mm256_add_pd(r2, _mm256_mul_pd(c2, w)), zero, _CMP_GE_OQ));
    in = _mm256_and_pd(
        in, _mm256_cmp_pd(_mm256_add_pd(r3, _mm256_mul_pd(c3, w)),
                          _mm256_mul_pd(_mm256_loadu_pd(izBlock + s), area), _CMP_GE_OQ));
    const int lanes = std::clamp(s1 - s, 0, 4);
    int hit = _mm256_movemask_pd(in) & ((1 << lanes) - 1);
    for (; hit; hit &= hit - 1) blocked[size_t(s + __builtin_ctz(unsigned(hit)))] = 1;
    s += 4;
  } while (s < s1);
}
}  // namespace

// triangle()'s steps for four triangles in AVX2 lanes, each the same IEEE double operation as
// there (no FMA), so the same points come out blocked.
__attribute__((target("avx2"))) int ProjectorShadows::drawFour(
    const TriangleMesh& mesh, const DepthRaster::ProjectedVertex* verts, const size_t* k,
    bool cull) {
  __m256d W[3], Y[3], Z[3];
  const int clip = loadFourTriangles(mesh, verts, k, W, Y, Z);  // W holds x for now
  const __m256d shift = _mm256_set1_pd(shift_);
  for (int c = 0; c < 3; ++c) W[c] = _mm256_sub_pd(W[c], _mm256_mul_pd(shift, Z[c]));
  const __m256d Wa = W[0], Wb = W[1], Wc = W[2], ya = Y[0], yb = Y[1], yc = Y[2];
  const __m256d za = Z[0], zb = Z[1], zc = Z[2];
  const __m256d zero = _mm256_setzero_pd();
  const __m256d area = signedAreaFour(W, Y);
  __m256d dropped = _mm256_cmp_pd(area, zero, _CMP_EQ_OQ);
  if (cull) dropped = _mm256_or_pd(dropped, _mm256_cmp_pd(area, zero, _CMP_GT_OQ));
  const __m256d maxIz = _mm256_max_pd(_mm256_max_pd(za, zb), zc);
  dropped = _mm256_or_pd(dropped, _mm256_cmp_pd(maxIz, _mm256_set1_pd(minIzBlock_), _CMP_LT_OQ));
  const __m256d Wmin = _mm256_min_pd(_mm256_min_pd(Wa, Wb), Wc),
                Wmax = _mm256_max_pd(_mm256_max_pd(Wa, Wb), Wc);
  dropped = _mm256_or_pd(dropped, _mm256_cmp_pd(Wmax, _mm256_set1_pd(minW_), _CMP_LT_OQ));
  dropped = _mm256_or_pd(dropped, _mm256_cmp_pd(Wmin, _mm256_set1_pd(maxW_), _CMP_GT_OQ));
  const __m256d fja = _mm256_max_pd(_mm256_ceil_pd(_mm256_min_pd(_mm256_min_pd(ya, yb), yc)),
                                    _mm256_set1_pd(window_.j0));
  const __m256d fjb = _mm256_min_pd(_mm256_floor_pd(_mm256_max_pd(_mm256_max_pd(ya, yb), yc)),
                                    _mm256_set1_pd(window_.j1));
  dropped = _mm256_or_pd(dropped, _mm256_cmp_pd(fja, fjb, _CMP_GT_OQ));
  const int live = ~clip & ~_mm256_movemask_pd(dropped) & 15;
  if (!live) return clip;
  const __m256d signBit = _mm256_set1_pd(-0.0);
  const __m256d sg = signOfAreaFour(area);
  const __m256d nsg = _mm256_xor_pd(sg, signBit);
  alignas(32) double eW[3][4], eY[3][4], e0[3][4], zW[4], zY[4], z0[4], absArea[4], wmin[4],
      wmax[4], ja[4], jb[4];
  __m256d E[3][3];  // eW, eY, e0 per edge
  for (int e = 0; e < 3; ++e) {
    const int a = (e + 1) % 3, b = (e + 2) % 3;
    const __m256d dW = _mm256_sub_pd(W[b], W[a]), dy = _mm256_sub_pd(Y[b], Y[a]);
    E[0][e] = _mm256_mul_pd(nsg, dy);
    E[1][e] = _mm256_mul_pd(sg, dW);
    E[2][e] = _mm256_mul_pd(sg, _mm256_add_pd(_mm256_mul_pd(dW, _mm256_xor_pd(Y[a], signBit)),
                                              _mm256_mul_pd(dy, W[a])));
    _mm256_store_pd(eW[e], E[0][e]);
    _mm256_store_pd(eY[e], E[1][e]);
    _mm256_store_pd(e0[e], E[2][e]);
  }
  double* sums[3] = {zW, zY, z0};
  __m256d S[3];
  for (int q = 0; q < 3; ++q) {
    S[q] = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(E[q][0], Z[0]), _mm256_mul_pd(E[q][1], Z[1])),
                         _mm256_mul_pd(E[q][2], Z[2]));
    _mm256_store_pd(sums[q], S[q]);
  }
  _mm256_store_pd(absArea, _mm256_andnot_pd(signBit, area));
  _mm256_store_pd(wmin, Wmin);
  _mm256_store_pd(wmax, Wmax);
  _mm256_store_pd(ja, fja);
  _mm256_store_pd(jb, fjb);
  // Per triangle (transposed): (e_0, e_1, e_2, 1/z·|area|)'s coefficients of W, y and 1, so a
  // row's four values are one multiply and add; and the triangle's bucket range (as
  // floorToInt, exact: the values are clamped to ±1e9 first).
  alignas(32) double T[3][4][4];
  for (int q = 0; q < 3; ++q) {
    const __m256d r[4] = {E[q][0], E[q][1], E[q][2], S[q]};
    transposeFour(r, T[q]);
  }
  const __m256d lim = _mm256_set1_pd(1e9), base = _mm256_set1_pd(double(base_));
  __m128i bucket[2];  // ⌊x⌋ − base_ of Wmin and Wmax, clamped to ±1e9 first as floorToInt
  for (int q = 0; q < 2; ++q) {
    const __m256d x = _mm256_min_pd(_mm256_max_pd(q ? Wmax : Wmin, _mm256_sub_pd(zero, lim)), lim);
    bucket[q] = _mm256_cvttpd_epi32(_mm256_sub_pd(_mm256_floor_pd(x), base));
  }
  alignas(16) int c0[4], c1[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(c0), _mm_max_epi32(bucket[0], _mm_setzero_si128()));
  _mm_store_si128(reinterpret_cast<__m128i*>(c1),
                  _mm_min_epi32(bucket[1], _mm_set1_epi32(pitch_ - 1)));
  const double* Wp = sortedW_.data();
  const double* izBlock = sortedIzBlock_.data();
  for (int bits = live; bits; bits &= bits - 1) {
    const int l = __builtin_ctz(unsigned(bits));
    if (wmax[l] - wmin[l] > 4) {  // wide: each row's own span first (rowSpan)
      triangleRowsFour({&eW[0][l], &eY[0][l], &e0[0][l], 4, zW[l], zY[l], z0[l], absArea[l],
                        wmin[l], wmax[l], int(ja[l]), int(jb[l])});
      continue;
    }
    // triangleRows for a narrow triangle: every row's buckets c0..c1, its points four at a time.
    const __m256d ew = _mm256_load_pd(T[0][l]), ey = _mm256_load_pd(T[1][l]),
                  e00 = _mm256_load_pd(T[2][l]);
    const __m256d ew0 = _mm256_permute4x64_pd(ew, 0x00), ew1 = _mm256_permute4x64_pd(ew, 0x55),
                  ew2 = _mm256_permute4x64_pd(ew, 0xAA), zw = _mm256_permute4x64_pd(ew, 0xFF);
    const __m256d ar = _mm256_set1_pd(absArea[l]);
    const int first = int(ja[l]), last = int(jb[l]);
    for (int j = first, rowFirst = (first - window_.j0) * pitch_; j <= last;
         ++j, rowFirst += pitch_) {
      // (e_0, e_1, e_2, 1/z·|area|) at W = 0 of row j: rowSpan's base and zRow.
      const __m256d row = _mm256_add_pd(e00, _mm256_mul_pd(ey, _mm256_set1_pd(double(j))));
      const __m256d b0 = _mm256_permute4x64_pd(row, 0x00), b1 = _mm256_permute4x64_pd(row, 0x55),
                    b2 = _mm256_permute4x64_pd(row, 0xAA), zr = _mm256_permute4x64_pd(row, 0xFF);
      testPointsFour(Wp, izBlock, sortedBlocked_.data(), first_[size_t(rowFirst + c0[l])],
                     first_[size_t(rowFirst + c1[l]) + 1], b0, b1, b2, zr, ew0, ew1, ew2, zw, ar);
    }
  }
  return clip;
}

// triangleRows' tests four points at a time, each lane the same IEEE double operations as there
// (no FMA). Most rows reach four points or fewer, so their loop runs once, predictably.
__attribute__((target("avx2"), always_inline)) inline void ProjectorShadows::triangleRowsFour(
    const RowWalk& t) {
  const bool wide = t.Wmax - t.Wmin > 4;
  const int c0 = std::max(0, floorToInt(t.Wmin) - base_),
            c1 = std::min(pitch_ - 1, floorToInt(t.Wmax) - base_);
  const __m256d e[4] = {_mm256_set1_pd(t.eW[0]), _mm256_set1_pd(t.eW[t.step]),
                        _mm256_set1_pd(t.eW[2 * t.step]), _mm256_set1_pd(t.zW)};
  const __m256d area = _mm256_set1_pd(t.absArea);
  const double* W = sortedW_.data();
  const double* izBlock = sortedIzBlock_.data();
  for (int j = t.ja; j <= t.jb; ++j) {
    double base[3], zRow;
    int s0, s1;
    if (!rowSpan(t, wide, c0, c1, j, base, &zRow, &s0, &s1)) continue;
    testPointsFour(W, izBlock, sortedBlocked_.data(), s0, s1, _mm256_set1_pd(base[0]),
                   _mm256_set1_pd(base[1]), _mm256_set1_pd(base[2]), _mm256_set1_pd(zRow), e[0],
                   e[1], e[2], e[3], area);
  }
}
#endif

}  // namespace inhand
