#include "inhand/geometry/internal/raster.h"

#include <algorithm>
#include <cmath>
#if INHAND_RASTER_AVX2
#include "inhand/core/internal/fast_math.h"
#include "raster_avx2.h"
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace inhand {

BoxInView boxInView(const Aabb& box, const Iso3& T_C_box, const PinholeProjection& K, int stride,
                    double shift_x_m, double near) {
  BoxInView v{1e300, -1e300, true, 1e300, -1e300, 1e300, -1e300};
  for (int k = 0; k < 8; ++k) {
    const Vec3 p = T_C_box * box.corner(k);
    v.zmin = std::min(v.zmin, p.z());
    v.zmax = std::max(v.zmax, p.z());
    if (p.z() < near) {
      v.allInFront = false;
      continue;
    }
    const double x = (K.fx * (p.x() - shift_x_m) / p.z() + K.cx) / stride;
    const double y = (K.fy * p.y() / p.z() + K.cy) / stride;
    v.xmin = std::min(v.xmin, x);
    v.xmax = std::max(v.xmax, x);
    v.ymin = std::min(v.ymin, y);
    v.ymax = std::max(v.ymax, y);
  }
  return v;
}

int clipToNearPlane(const Vec3& a, const Vec3& b, const Vec3& c, double near, Vec3 poly[4]) {
  if (a.z() < near && b.z() < near && c.z() < near) return 0;
  const Vec3 in[3] = {a, b, c};
  int m = 0;
  for (int k = 0; k < 3; ++k) {
    const Vec3& p = in[k];
    const Vec3& q = in[(k + 1) % 3];
    const bool pin = p.z() >= near, qin = q.z() >= near;
    if (pin) poly[m++] = p;
    if (pin != qin) poly[m++] = p + (q - p) * ((near - p.z()) / (q.z() - p.z()));
  }
  return m;
}

void DepthRaster::projectVertices(const TriangleMesh& mesh, const Iso3& T_C_mesh,
                                  const PinholeProjection& K, int stride,
                                  std::vector<ProjectedVertex>* out) {
  const size_t nv = mesh.vertices.size();
  out->resize(nv);
  const Mat3 R = T_C_mesh.linear();
  const Vec3 t = T_C_mesh.translation();
  const double s = stride;
  const double fxs = K.fx / s, fys = K.fy / s, cxs = K.cx / s, cys = K.cy / s;
  for (size_t i = 0; i < nv; ++i) {
    const Vec3 p = R * mesh.vertices[i].cast<double>() + t;
    ProjectedVertex& v = (*out)[i];
    if (p.z() >= kNear) {
      const double iz = 1.0 / p.z();
      v.x = fxs * p.x() * iz + cxs;
      v.y = fys * p.y() * iz + cys;
      v.iz = iz;
    } else {
      v.iz = -1;  // behind the near plane: the triangle is clipped
    }
  }
}

TriangleFacing::TriangleFacing(const TriangleMesh& mesh) {
  const size_t nt = mesh.triangles.size();
  nx_.resize(nt);
  ny_.resize(nt);
  nz_.resize(nt);
  offset_.resize(nt);
  for (const Vec3f& v : mesh.vertices) scale_ = std::max(scale_, v.cast<double>().norm());
  for (size_t k = 0; k < nt; ++k) {
    const Tri& f = mesh.triangles[k];
    const Vec3 a = mesh.vertices[size_t(f[0])].cast<double>();
    const Vec3 n = (mesh.vertices[size_t(f[1])].cast<double>() - a)
                       .cross(mesh.vertices[size_t(f[2])].cast<double>() - a);
    const double len = n.norm();
    const Vec3 u = len > 0 ? Vec3(n / len) : Vec3::Zero();
    nx_[k] = float(u.x());
    ny_[k] = float(u.y());
    nz_[k] = float(u.z());
    offset_[k] = float(u.dot(a));
  }
}

void TriangleFacing::mayFace(const Vec3& eye, std::vector<uint64_t>* bits) const {
  const size_t nt = nx_.size();
  bits->assign((nt + 63) / 64, 0);
  // n·e − offset in float is within a few 1e-7·(|e| + scale) of the exact value.
  const float ex = float(eye.x()), ey = float(eye.y()), ez = float(eye.z());
  const float slack = float(1e-5 * (eye.norm() + scale_));
  size_t k = 0;
#if defined(__SSE2__)
  // Four triangles at a time, their four bits from one movemask.
  const __m128 Ex = _mm_set1_ps(ex), Ey = _mm_set1_ps(ey), Ez = _mm_set1_ps(ez);
  const __m128 minus = _mm_set1_ps(-slack);
  auto four = [&](size_t at) {
    const __m128 s = _mm_sub_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_loadu_ps(&nx_[at]), Ex),
                                                      _mm_mul_ps(_mm_loadu_ps(&ny_[at]), Ey)),
                                           _mm_mul_ps(_mm_loadu_ps(&nz_[at]), Ez)),
                                _mm_loadu_ps(&offset_[at]));
    return uint64_t(_mm_movemask_ps(_mm_cmpgt_ps(s, minus)));
  };
  for (; k + 64 <= nt; k += 64) {  // a word's 64 bits gathered in a register, stored once
    uint64_t word = 0;
    for (size_t q = 0; q < 64; q += 4) word |= four(k + q) << q;
    (*bits)[k / 64] = word;
  }
  for (; k + 4 <= nt; k += 4) (*bits)[k / 64] |= four(k) << (k % 64);
#endif
  for (; k < nt; ++k) {
    const float s = nx_[k] * ex + ny_[k] * ey + nz_[k] * ez - offset_[k];
    (*bits)[k / 64] |= uint64_t(s > -slack) << (k % 64);
  }
}

void DepthRaster::reset(const PinholeProjection& K, const RasterWindow& window) {
  K_ = K;
  window_ = window;
  const size_t n = size_t(window.size());
  invZ_.assign(n, 0.f);
  id_.assign(n, -1);
  extentsValid_ = false;
}

void DepthRaster::draw(const TriangleMesh& mesh, const Iso3& T_C_mesh, int id_base,
                       bool cull_back_faces, double max_depth, const Aabb* bounds,
                       const std::vector<uint64_t>* only) {
  extentsValid_ = false;
  drawMesh<false>(mesh, T_C_mesh, id_base, cull_back_faces, max_depth, bounds, only);
}

void DepthRaster::drawOccluder(const TriangleMesh& mesh, const Iso3& T_C_mesh, bool cull_back_faces,
                               double max_depth, const Aabb* bounds) {
  if (!extentsValid_) findRowExtents();
  drawMesh<true>(mesh, T_C_mesh, kOccluded, cull_back_faces, max_depth, bounds, nullptr);
}

void DepthRaster::findRowExtents() {
  const RasterWindow& w = window_;
  const int rows = std::max(0, w.height()), width = std::max(0, w.width());
  rowFirst_.assign(size_t(rows), 0);
  rowLast_.assign(size_t(rows), -1);
  for (int r = 0; r < rows && width > 0; ++r) {
    const int* row = &id_[size_t(r) * size_t(width)];
    int a = 0, b = width - 1;
    while (a < width && row[a] < 0) ++a;
    while (b > a && row[b] < 0) --b;
    rowFirst_[size_t(r)] = w.i0 + a;
    rowLast_[size_t(r)] = a < width ? w.i0 + b : w.i0 - 1;
  }
  extentsValid_ = true;
}

template <bool Over>
void DepthRaster::drawMesh(const TriangleMesh& mesh, const Iso3& T_C_mesh, int id_base,
                           bool cull_back_faces, double max_depth, const Aabb* bounds,
                           const std::vector<uint64_t>* only) {
  if (window_.size() == 0) return;
  if (bounds && !bounds->empty()) {
    const BoxInView v = boxInView(*bounds, T_C_mesh, K_, window_.stride, 0.0, kNear);
    if (v.zmax < kNear || (max_depth > 0 && v.zmin > max_depth)) return;
    if (v.allInFront &&
        (v.xmax < window_.i0 || v.xmin > window_.i1 || v.ymax < window_.j0 || v.ymin > window_.j1))
      return;
  }
  // Each vertex into the camera frame and, in front of the near plane, to sample coordinates
  // and 1/z, once (a vertex is shared by about six triangles).
  // (An occluder's go elsewhere: projected() stays the surfaces' for a ProjectorShadows pass.)
  std::vector<ProjectedVertex>& verts = Over ? occluderVerts_ : verts_;
  projectVertices(mesh, T_C_mesh, K_, window_.stride, &verts);
  const Mat3 R = T_C_mesh.linear();
  const Vec3 t = T_C_mesh.translation();
  const double minInvZ = max_depth > 0 ? 1.0 / max_depth : 0.0;
  minInvZ_ = minInvZ;
  const RasterWindow& w = window_;
  const size_t nt = mesh.triangles.size();
  const bool masked = cull_back_faces && only && only->size() == (nt + 63) / 64;
  auto one = [&](size_t k) {
    const Tri& f = mesh.triangles[k];
    const size_t a = size_t(f[0]), b = size_t(f[1]), c = size_t(f[2]);
    const int id = Over ? id_base : id_base + int(k);
    const ProjectedVertex &A = verts[a], &B = verts[b], &C = verts[c];
    if (A.iz < 0 || B.iz < 0 || C.iz < 0) {
      const Vec3 pa = R * mesh.vertices[a].cast<double>() + t;
      const Vec3 pb = R * mesh.vertices[b].cast<double>() + t;
      const Vec3 pc = R * mesh.vertices[c].cast<double>() + t;
      if (!cull_back_faces || (pb - pa).cross(pc - pa).dot(pa) < 0)
        drawClipped<Over>(pa, pb, pc, id);
      return;
    }
    // Entirely beyond max_depth: it can hide nothing that matters.
    if (A.iz < minInvZ && B.iz < minInvZ && C.iz < minInvZ) return;
    // The projected area has the sign of det[a b c] = n·a: negative for a triangle whose
    // outward normal faces the camera. Culling first drops half of a closed mesh before any
    // rounding.
    const double xa = A.x, xb = B.x, xc = C.x;
    const double ya = A.y, yb = B.y, yc = C.y;
    const double area = (xb - xa) * (yc - ya) - (yb - ya) * (xc - xa);
    if (cull_back_faces && area > 0) return;
    // Most triangles of a fine mesh cover no sample: rejected on their bounding box alone.
    const int ia = std::max(w.i0, ceilToInt((std::min({xa, xb, xc}))));
    const int ib = std::min(w.i1, floorToInt((std::max({xa, xb, xc}))));
    if (ia > ib) return;
    const int ja = std::max(w.j0, ceilToInt((std::min({ya, yb, yc}))));
    const int jb = std::min(w.j1, floorToInt((std::max({ya, yb, yc}))));
    if (ja > jb) return;
    const double px[3] = {xa, xb, xc}, py[3] = {ya, yb, yc}, piz[3] = {A.iz, B.iz, C.iz};
    fill<Over>(px, py, piz, ia, ib, ja, jb, area, id);
  };
#if INHAND_RASTER_AVX2
  if (!Over && vectorised_) {
    // Four triangles at a time through the set-up; drawFour hands back the ones it leaves to
    // the one-at-a-time path (clipped, or larger than fillSmall's box).
    forEachMarkedInFours(
        nt, masked ? only : nullptr,
        [&](const size_t* k) { return drawFour(mesh, k, id_base, cull_back_faces); }, one);
    minInvZ_ = 0;
    return;
  }
#endif
  forEachMarked(nt, masked ? only : nullptr, one);
  minInvZ_ = 0;
}

bool DepthRaster::avx2Available() {
#if INHAND_RASTER_AVX2
  static const bool has = __builtin_cpu_supports("avx2") && !avx2TurnedOff();
  return has;
#else
  return false;
#endif
}

#if INHAND_RASTER_AVX2

// draw()'s per-triangle steps for four triangles in AVX2 lanes, each operation the same IEEE
// double operation as the one-at-a-time path's (no FMA: it would round differently), so the
// buffers come out bit for bit the same.
__attribute__((target("avx2"))) int DepthRaster::drawFour(const TriangleMesh& mesh, const size_t* k,
                                                          int id_base, bool cull) {
  __m256d cornerX[3], cornerY[3], cornerIz[3];
  const int clip = loadFourTriangles(mesh, verts_.data(), k, cornerX, cornerY, cornerIz);
  const __m256d xa = cornerX[0], xb = cornerX[1], xc = cornerX[2];
  const __m256d ya = cornerY[0], yb = cornerY[1], yc = cornerY[2];
  const __m256d za = cornerIz[0], zb = cornerIz[1], zc = cornerIz[2];
  const __m256d zero = _mm256_setzero_pd();
  const __m256d minIz = _mm256_set1_pd(minInvZ_);
  const __m256d beyond = _mm256_and_pd(
      _mm256_and_pd(_mm256_cmp_pd(za, minIz, _CMP_LT_OQ), _mm256_cmp_pd(zb, minIz, _CMP_LT_OQ)),
      _mm256_cmp_pd(zc, minIz, _CMP_LT_OQ));
  const __m256d area = signedAreaFour(cornerX, cornerY);
  __m256d dropped = _mm256_or_pd(beyond, _mm256_cmp_pd(area, zero, _CMP_EQ_OQ));
  if (cull) dropped = _mm256_or_pd(dropped, _mm256_cmp_pd(area, zero, _CMP_GT_OQ));
  const RasterWindow& w = window_;
  const __m256d fia =
      _mm256_max_pd(_mm256_ceil_pd(_mm256_min_pd(_mm256_min_pd(xa, xb), xc)), _mm256_set1_pd(w.i0));
  const __m256d fib = _mm256_min_pd(_mm256_floor_pd(_mm256_max_pd(_mm256_max_pd(xa, xb), xc)),
                                    _mm256_set1_pd(w.i1));
  const __m256d fja =
      _mm256_max_pd(_mm256_ceil_pd(_mm256_min_pd(_mm256_min_pd(ya, yb), yc)), _mm256_set1_pd(w.j0));
  const __m256d fjb = _mm256_min_pd(_mm256_floor_pd(_mm256_max_pd(_mm256_max_pd(ya, yb), yc)),
                                    _mm256_set1_pd(w.j1));
  const __m256d empty =
      _mm256_or_pd(_mm256_cmp_pd(fia, fib, _CMP_GT_OQ), _mm256_cmp_pd(fja, fjb, _CMP_GT_OQ));
  const __m256d four = _mm256_set1_pd(4);
  const __m256d small = _mm256_and_pd(
      _mm256_and_pd(_mm256_cmp_pd(_mm256_sub_pd(fib, fia), four, _CMP_LT_OQ),
                    _mm256_cmp_pd(_mm256_sub_pd(fjb, fja), four, _CMP_LT_OQ)),
      _mm256_cmp_pd(_mm256_add_pd(fia, _mm256_set1_pd(3)), _mm256_set1_pd(w.i1), _CMP_LE_OQ));
  const int live = ~clip & ~_mm256_movemask_pd(_mm256_or_pd(dropped, empty)) & 15;
  const int fillNow = live & _mm256_movemask_pd(small);
  const int rest = clip | (live & ~fillNow);
  if (!fillNow) return rest;
  // fillSmall's set-up: edges and 1/z relative to the box's corner (ia, ja).
  const __m256d x0 = _mm256_sub_pd(xa, fia), x1 = _mm256_sub_pd(xb, fia),
                x2 = _mm256_sub_pd(xc, fia);
  const __m256d y0 = _mm256_sub_pd(ya, fja), y1 = _mm256_sub_pd(yb, fja),
                y2 = _mm256_sub_pd(yc, fja);
  const __m256d signBit = _mm256_set1_pd(-0.0);
  const __m256d sg = signOfAreaFour(area);
  const __m256d nsg = _mm256_xor_pd(sg, signBit);
  const __m256d inv = _mm256_div_pd(_mm256_set1_pd(1.0), _mm256_andnot_pd(signBit, area));
  const __m256d X[3] = {x0, x1, x2}, Y[3] = {y0, y1, y2}, Z[3] = {za, zb, zc};
  alignas(32) double A[3][4], B[3][4], C[3][4], zi[4], zj[4], z0[4], ia[4], ib[4], ja[4], jb[4];
  __m256d Zi = zero, Zj = zero, Z0 = zero;
  for (int e = 0; e < 3; ++e) {
    const int a = (e + 1) % 3, b = (e + 2) % 3;
    const __m256d dx = _mm256_sub_pd(X[b], X[a]), dy = _mm256_sub_pd(Y[b], Y[a]);
    const __m256d Ae = _mm256_mul_pd(nsg, dy), Be = _mm256_mul_pd(sg, dx);
    const __m256d Ce =
        _mm256_mul_pd(sg, _mm256_sub_pd(_mm256_mul_pd(dx, _mm256_xor_pd(Y[a], signBit)),
                                        _mm256_mul_pd(dy, _mm256_xor_pd(X[a], signBit))));
    Zi = _mm256_add_pd(Zi, _mm256_mul_pd(_mm256_mul_pd(Ae, Z[e]), inv));
    Zj = _mm256_add_pd(Zj, _mm256_mul_pd(_mm256_mul_pd(Be, Z[e]), inv));
    Z0 = _mm256_add_pd(Z0, _mm256_mul_pd(_mm256_mul_pd(Ce, Z[e]), inv));
    _mm256_store_pd(A[e], Ae);
    _mm256_store_pd(B[e], Be);
    _mm256_store_pd(C[e], Ce);
  }
  _mm256_store_pd(zi, Zi);
  _mm256_store_pd(zj, Zj);
  _mm256_store_pd(z0, Z0);
  _mm256_store_pd(ia, fia);
  _mm256_store_pd(ib, fib);
  _mm256_store_pd(ja, fja);
  _mm256_store_pd(jb, fjb);
  // Per triangle (transposed): (A_0, A_1, A_2, zi), and likewise B with zj, C with z0, so that a
  // row's four values are one multiply and add and one conversion.
  alignas(32) double TA[4][4], TB[4][4], TC[4][4];
  const __m256d ra[4] = {_mm256_load_pd(A[0]), _mm256_load_pd(A[1]), _mm256_load_pd(A[2]), Zi};
  const __m256d rb[4] = {_mm256_load_pd(B[0]), _mm256_load_pd(B[1]), _mm256_load_pd(B[2]), Zj};
  const __m256d rc[4] = {_mm256_load_pd(C[0]), _mm256_load_pd(C[1]), _mm256_load_pd(C[2]), Z0};
  transposeFour(ra, TA);
  transposeFour(rb, TB);
  transposeFour(rc, TC);
  for (int bits = fillNow; bits; bits &= bits - 1) {
    const int l = __builtin_ctz(unsigned(bits));
    fillSmallRowsFour(TA[l], TB[l], TC[l], int(ia[l]), int(ib[l]), int(ja[l]), int(jb[l]),
                      id_base + int(k[l]));
  }
  return rest;
}

// fillSmallRows<false> from a transposed set-up (a = (A_0, A_1, A_2, zi), b and c likewise): each
// row's edge and 1/z offsets in one double multiply-add and one conversion to float, the same
// values as there, then the same float steps per sample.
__attribute__((target("avx2"), always_inline)) inline void DepthRaster::fillSmallRowsFour(
    const double* a, const double* b, const double* c, int ia, int ib, int ja, int jb, int id) {
  const __m128 I = _mm_setr_ps(0.f, 1.f, 2.f, 3.f);
  const __m128 inBox = _mm_cmple_ps(I, _mm_set1_ps(float(ib - ia)));
  const __m128 zero = _mm_setzero_ps();
  const __m128 af = _mm256_cvtpd_ps(_mm256_load_pd(a));
  const __m128 eI0 = _mm_mul_ps(_mm_shuffle_ps(af, af, 0x00), I),
               eI1 = _mm_mul_ps(_mm_shuffle_ps(af, af, 0x55), I),
               eI2 = _mm_mul_ps(_mm_shuffle_ps(af, af, 0xAA), I),
               zI = _mm_mul_ps(_mm_shuffle_ps(af, af, 0xFF), I);
  const __m256d bv = _mm256_load_pd(b), cv = _mm256_load_pd(c);
  const __m128i ids = _mm_set1_epi32(id);
  for (int j = ja; j <= jb; ++j) {
    const __m128 r = _mm256_cvtpd_ps(_mm256_add_pd(_mm256_mul_pd(bv, _mm256_set1_pd(j - ja)), cv));
    __m128 cover =
        _mm_and_ps(inBox, _mm_cmpge_ps(_mm_add_ps(eI0, _mm_shuffle_ps(r, r, 0x00)), zero));
    cover = _mm_and_ps(cover, _mm_cmpge_ps(_mm_add_ps(eI1, _mm_shuffle_ps(r, r, 0x55)), zero));
    cover = _mm_and_ps(cover, _mm_cmpge_ps(_mm_add_ps(eI2, _mm_shuffle_ps(r, r, 0xAA)), zero));
    float* zrow = &invZ_[size_t(index(ia, j))];
    int* idrow = &id_[size_t(index(ia, j))];
    const __m128 iz = _mm_add_ps(zI, _mm_shuffle_ps(r, r, 0xFF));
    const __m128 old = _mm_loadu_ps(zrow);
    const __m128i oldId = _mm_loadu_si128(reinterpret_cast<const __m128i*>(idrow));
    const __m128 win = _mm_and_ps(cover, _mm_cmpgt_ps(iz, old));
    _mm_storeu_ps(zrow, _mm_blendv_ps(old, iz, win));
    _mm_storeu_si128(
        reinterpret_cast<__m128i*>(idrow),
        _mm_castps_si128(_mm_blendv_ps(_mm_castsi128_ps(oldId), _mm_castsi128_ps(ids), win)));
  }
}
#endif

void DepthRaster::drawTriangle(const Vec3& a, const Vec3& b, const Vec3& c, int id) {
  extentsValid_ = false;
  drawClipped<false>(a, b, c, id);
}

template <bool Over>
void DepthRaster::drawClipped(const Vec3& a, const Vec3& b, const Vec3& c, int id) {
  Vec3 poly[4];
  const int m = clipToNearPlane(a, b, c, kNear, poly);
  const double s = window_.stride;
  double px[4], py[4], piz[4];
  for (int k = 0; k < m; ++k) {
    piz[k] = 1.0 / poly[k].z();
    px[k] = (K_.fx * poly[k].x() * piz[k] + K_.cx) / s;
    py[k] = (K_.fy * poly[k].y() * piz[k] + K_.cy) / s;
  }
  const RasterWindow& w = window_;
  for (int k = 1; k + 1 < m; ++k) {
    const double fx[3] = {px[0], px[k], px[k + 1]}, fy[3] = {py[0], py[k], py[k + 1]};
    const double fz[3] = {piz[0], piz[k], piz[k + 1]};
    const int ia = std::max(w.i0, ceilToInt((std::min({fx[0], fx[1], fx[2]}))));
    const int ib = std::min(w.i1, floorToInt((std::max({fx[0], fx[1], fx[2]}))));
    const int ja = std::max(w.j0, ceilToInt((std::min({fy[0], fy[1], fy[2]}))));
    const int jb = std::min(w.j1, floorToInt((std::max({fy[0], fy[1], fy[2]}))));
    if (ia > ib || ja > jb) continue;
    const double area = (fx[1] - fx[0]) * (fy[2] - fy[0]) - (fy[1] - fy[0]) * (fx[2] - fx[0]);
    fill<Over>(fx, fy, fz, ia, ib, ja, jb, area, id);
  }
}

#if INHAND_RASTER_AVX2
namespace {
// fill()'s loop over the samples lo..hi of one row, four at a time (AVX2): each lane takes the
// same IEEE steps as the one-at-a-time loop (no FMA), so the same samples win with the same
// depths. Returns the first sample left (fewer than four remain) for that loop.
template <bool Over>
__attribute__((target("avx2"))) int fillRowFour(float* zrow, int* idrow, int lo, int hi,
                                                const double* base, const double* ei,
                                                double zrowBase, double zi, int id) {
  const __m256d b0 = _mm256_set1_pd(base[0]), b1 = _mm256_set1_pd(base[1]),
                b2 = _mm256_set1_pd(base[2]), e0 = _mm256_set1_pd(ei[0]),
                e1 = _mm256_set1_pd(ei[1]), e2 = _mm256_set1_pd(ei[2]),
                zb = _mm256_set1_pd(zrowBase), z = _mm256_set1_pd(zi), zero = _mm256_setzero_pd();
  const __m256d step = _mm256_setr_pd(0, 1, 2, 3);
  const __m256i low = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6);  // each lane's low half
  const __m128i ids = _mm_set1_epi32(id);
  int di = lo;
  for (; di + 3 <= hi; di += 4) {
    const __m256d dd = _mm256_add_pd(_mm256_set1_pd(double(di)), step);  // exact integers
    const __m128 iz = _mm256_cvtpd_ps(_mm256_add_pd(zb, _mm256_mul_pd(z, dd)));
    __m256d in = _mm256_cmp_pd(_mm256_add_pd(b0, _mm256_mul_pd(e0, dd)), zero, _CMP_GE_OQ);
    in = _mm256_and_pd(in,
                       _mm256_cmp_pd(_mm256_add_pd(b1, _mm256_mul_pd(e1, dd)), zero, _CMP_GE_OQ));
    in = _mm256_and_pd(in,
                       _mm256_cmp_pd(_mm256_add_pd(b2, _mm256_mul_pd(e2, dd)), zero, _CMP_GE_OQ));
    const __m128 inside = _mm_castsi128_ps(
        _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(_mm256_castpd_si256(in), low)));
    const __m128 old = _mm_loadu_ps(zrow + di);
    const __m128i oldId = _mm_loadu_si128(reinterpret_cast<const __m128i*>(idrow + di));
    __m128 win = _mm_and_ps(inside, _mm_cmpgt_ps(iz, old));
    if (Over) win = _mm_and_ps(win, _mm_castsi128_ps(_mm_cmpgt_epi32(oldId, _mm_set1_epi32(-1))));
    _mm_storeu_ps(zrow + di, _mm_blendv_ps(old, iz, win));
    _mm_storeu_si128(
        reinterpret_cast<__m128i*>(idrow + di),
        _mm_castps_si128(_mm_blendv_ps(_mm_castsi128_ps(oldId), _mm_castsi128_ps(ids), win)));
  }
  return di;
}
}  // namespace
#endif

template <bool Over>
void DepthRaster::fill(const double* px, const double* py, const double* piz, int ia, int ib,
                       int ja, int jb, double area, int id) {
  if (area == 0) return;  // degenerate, or edge-on through the camera centre
#if defined(__SSE2__)
  if (ib - ia < 4 && jb - ja < 4 && ia + 3 <= window_.i1) {
    fillSmall<Over>(px, py, piz, ia, ib, ja, jb, area, id);
    return;
  }
#endif
  const double x0 = px[0], y0 = py[0], x1 = px[1], y1 = py[1], x2 = px[2], y2 = py[2];
  const double sg = area > 0 ? 1.0 : -1.0;
  // Edge functions e_k(i, j) = sg·((x_b − x_a)(j − y_a) − (y_b − y_a)(i − x_a)) ≥ 0 inside,
  // edge k opposite vertex k; e_k / |area| is vertex k's barycentric coordinate, and 1/z, affine
  // in the image, is Σ_k e_k·(1/z_k) / |area|.
  const double ax[3] = {x1, x2, x0}, ay[3] = {y1, y2, y0};
  const double bx[3] = {x2, x0, x1}, by[3] = {y2, y0, y1};
  double ei[3], ej[3], e0[3];
  for (int e = 0; e < 3; ++e) {
    ei[e] = -sg * (by[e] - ay[e]);
    ej[e] = sg * (bx[e] - ax[e]);
    e0[e] = sg * ((bx[e] - ax[e]) * (ja - ay[e]) - (by[e] - ay[e]) * (ia - ax[e]));
  }
  const double inv = 1.0 / std::abs(area);
  const double zi = (ei[0] * piz[0] + ei[1] * piz[1] + ei[2] * piz[2]) * inv;
  const double zj = (ej[0] * piz[0] + ej[1] * piz[1] + ej[2] * piz[2]) * inv;
  const double z0 = (e0[0] * piz[0] + e0[1] * piz[1] + e0[2] * piz[2]) * inv;
  const bool wide = ib - ia >= 8;
  for (int j = ja; j <= jb; ++j) {
    const int dj = j - ja;
    // For wide triangles, the row's span from the three edges (one sample of margin for
    // rounding), then the exact test per sample: they cost their covered samples, not their
    // bounding box.
    double base[3];
    int lo = 0, hi = ib - ia;
    for (int e = 0; e < 3; ++e) base[e] = e0[e] + ej[e] * dj;
    for (int e = 0; e < 3 && wide && lo <= hi; ++e) {
      if (ei[e] > 0)
        lo = std::max(lo, ceilToInt(-base[e] / ei[e]) - 1);
      else if (ei[e] < 0)
        hi = std::min(hi, floorToInt(-base[e] / ei[e]) + 1);
      else if (base[e] < 0)
        hi = -1;
    }
    const double zrowBase = z0 + zj * dj;
    // Samples beyond max_depth (1/z below minInvZ_) hide nothing that matters: the part of the
    // row nearer than it, with a sample of margin.
    if (wide && minInvZ_ > 0 && lo <= hi) {
      const double over = zrowBase - minInvZ_;  // iz(dd) − minInvZ = over + zi·dd ≥ 0
      if (zi > 0)
        lo = std::max(lo, ceilToInt(-over / zi) - 1);
      else if (zi < 0)
        hi = std::min(hi, floorToInt(-over / zi) + 1);
      else if (over < 0)
        hi = -1;
    }
    if (Over) {  // only between the row's first and last surface sample
      lo = std::max(lo, rowFirst_[size_t(j - window_.j0)] - ia);
      hi = std::min(hi, rowLast_[size_t(j - window_.j0)] - ia);
    }
    if (lo > hi) continue;
    float* zrow = &invZ_[size_t(index(ia, j))];
    int* idrow = &id_[size_t(index(ia, j))];
    int from = lo;
#if INHAND_RASTER_AVX2
    if (vectorised_ && hi - lo >= 3)
      from = fillRowFour<Over>(zrow, idrow, lo, hi, base, ei, zrowBase, zi, id);
#endif
    // Branch-free: whether a sample of a small triangle is covered is a coin toss for the
    // branch predictor.
    double dd = from;
    for (int di = from; di <= hi; ++di, dd += 1.0) {
      const float iz = float(zrowBase + zi * dd);
      const bool win = (base[0] + ei[0] * dd >= 0) & (base[1] + ei[1] * dd >= 0) &
                       (base[2] + ei[2] * dd >= 0) & (iz > zrow[di]) & (!Over || idrow[di] >= 0);
      zrow[di] = win ? iz : zrow[di];
      idrow[di] = win ? id : idrow[di];
    }
  }
}

template <bool Over>
void DepthRaster::fillSmall(const double* px, const double* py, const double* piz, int ia, int ib,
                            int ja, int jb, double area, int id) {
#if defined(__SSE2__)
  const double sg = area > 0 ? 1.0 : -1.0;
  // As fill(), with (i, j) relative to (ia, ja): e_k = A_k·i + B_k·j + C_k, and 1/z likewise.
  const double x[3] = {px[0] - ia, px[1] - ia, px[2] - ia};
  const double y[3] = {py[0] - ja, py[1] - ja, py[2] - ja};
  const double inv = 1.0 / std::abs(area);
  double A[3], B[3], C[3];
  double zi = 0, zj = 0, z0 = 0;
  for (int e = 0; e < 3; ++e) {
    const int a = (e + 1) % 3, b = (e + 2) % 3;  // edge e runs from vertex a to vertex b
    A[e] = -sg * (y[b] - y[a]);
    B[e] = sg * (x[b] - x[a]);
    C[e] = sg * ((x[b] - x[a]) * -y[a] - (y[b] - y[a]) * -x[a]);
    zi += A[e] * piz[e] * inv;
    zj += B[e] * piz[e] * inv;
    z0 += C[e] * piz[e] * inv;
  }
  fillSmallRows<Over>(A, B, C, 1, zi, zj, z0, ia, ib, ja, jb, id);
#else
  (void)px, (void)py, (void)piz, (void)ia, (void)ib, (void)ja, (void)jb, (void)area, (void)id;
#endif
}

template <bool Over>
void DepthRaster::fillSmallRows(const double* A, const double* B, const double* C, int step,
                                double zi, double zj, double z0, int ia, int ib, int ja, int jb,
                                int id) {
#if defined(__SSE2__)
  const __m128 I = _mm_setr_ps(0.f, 1.f, 2.f, 3.f);
  const __m128 inBox = _mm_cmple_ps(I, _mm_set1_ps(float(ib - ia)));
  const __m128 zero = _mm_setzero_ps();
  __m128 eI[3];
  for (int e = 0; e < 3; ++e) eI[e] = _mm_mul_ps(_mm_set1_ps(float(A[e * step])), I);
  const __m128 zI = _mm_mul_ps(_mm_set1_ps(float(zi)), I);
  const __m128i ids = _mm_set1_epi32(id);
  for (int j = ja; j <= jb; ++j) {
    const double dj = j - ja;
    __m128 cover = inBox;
    for (int e = 0; e < 3; ++e) {
      const __m128 ee = _mm_add_ps(eI[e], _mm_set1_ps(float(B[e * step] * dj + C[e * step])));
      cover = _mm_and_ps(cover, _mm_cmpge_ps(ee, zero));
    }
    // No test for an empty row: whether one is empty is a coin toss for triangles this small,
    // and writing back what is there costs less than the mispredicted branch.
    float* zrow = &invZ_[size_t(index(ia, j))];
    int* idrow = &id_[size_t(index(ia, j))];
    const __m128 iz = _mm_add_ps(zI, _mm_set1_ps(float(zj * dj + z0)));
    const __m128 old = _mm_loadu_ps(zrow);
    const __m128i oldId = _mm_loadu_si128(reinterpret_cast<const __m128i*>(idrow));
    __m128 win = _mm_and_ps(cover, _mm_cmpgt_ps(iz, old));
    if (Over) win = _mm_and_ps(win, _mm_castsi128_ps(_mm_cmpgt_epi32(oldId, _mm_set1_epi32(-1))));
    _mm_storeu_ps(zrow, _mm_or_ps(_mm_and_ps(win, iz), _mm_andnot_ps(win, old)));
    const __m128i w = _mm_castps_si128(win);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(idrow),
                     _mm_or_si128(_mm_and_si128(w, ids), _mm_andnot_si128(w, oldId)));
  }
#else
  (void)A, (void)B, (void)C, (void)step, (void)zi, (void)zj, (void)z0, (void)ia, (void)ib;
  (void)ja, (void)jb, (void)id;
#endif
}

}  // namespace inhand
