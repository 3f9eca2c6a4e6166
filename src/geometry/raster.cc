#include "inhand/geometry/raster.h"

#include <algorithm>
#include <cmath>

namespace inhand {

namespace {
// floor and ceil to int without a libm call (the baseline x86-64 has no SSE4.1 rounding);
// arguments are clamped to ±1e9 first, far outside any window.
inline int ifloor(double x) {
  x = std::clamp(x, -1e9, 1e9);
  const int i = int(x);
  return i - (x < double(i));
}
inline int iceil(double x) {
  x = std::clamp(x, -1e9, 1e9);
  const int i = int(x);
  return i + (x > double(i));
}
}  // namespace

void DepthRaster::reset(const PinholeProjection& K, const RasterWindow& window) {
  K_ = K;
  invFx_ = 1.0 / K.fx;
  invFy_ = 1.0 / K.fy;
  window_ = window;
  const size_t n = size_t(window.size());
  invZ_.assign(n, 0.f);
  id_.assign(n, -1);
}

void DepthRaster::draw(const TriangleMesh& mesh, const Iso3& T_C_mesh, int id_base,
                       bool cull_back_faces) {
  if (window_.size() == 0) return;
  // Each vertex into the camera frame and, in front of the near plane, to sample coordinates,
  // once (a vertex is shared by about six triangles).
  const size_t nv = mesh.vertices.size();
  scratch_.resize(nv);
  sx_.resize(nv);
  sy_.resize(nv);
  const Mat3 R = T_C_mesh.linear();
  const Vec3 t = T_C_mesh.translation();
  const double s = window_.stride;
  for (size_t i = 0; i < nv; ++i) {
    const Vec3 p = R * mesh.vertices[i].cast<double>() + t;
    scratch_[i] = p;
    if (p.z() >= kNear) {
      const double iz = 1.0 / p.z();
      sx_[i] = (K_.fx * p.x() * iz + K_.cx) / s;
      sy_[i] = (K_.fy * p.y() * iz + K_.cy) / s;
    }
  }
  const RasterWindow& w = window_;
  for (size_t k = 0; k < mesh.triangles.size(); ++k) {
    const Tri& f = mesh.triangles[k];
    const size_t a = size_t(f[0]), b = size_t(f[1]), c = size_t(f[2]);
    const int id = id_base + int(k);
    if (scratch_[a].z() < kNear || scratch_[b].z() < kNear || scratch_[c].z() < kNear) {
      if (!cull_back_faces ||
          (scratch_[b] - scratch_[a]).cross(scratch_[c] - scratch_[a]).dot(scratch_[a]) < 0)
        drawTriangle(scratch_[a], scratch_[b], scratch_[c], id);  // clips
      continue;
    }
    // Most triangles of a fine mesh cover no sample: rejected on their bounding box alone.
    const double xa = sx_[a], xb = sx_[b], xc = sx_[c];
    const int ia = std::max(w.i0, iceil((std::min({xa, xb, xc}))));
    const int ib = std::min(w.i1, ifloor((std::max({xa, xb, xc}))));
    if (ia > ib) continue;
    const double ya = sy_[a], yb = sy_[b], yc = sy_[c];
    const int ja = std::max(w.j0, iceil((std::min({ya, yb, yc}))));
    const int jb = std::min(w.j1, ifloor((std::max({ya, yb, yc}))));
    if (ja > jb) continue;
    // The projected area has the sign of det[a b c] = n·a: negative for a triangle whose
    // outward normal faces the camera.
    if (cull_back_faces && (xb - xa) * (yc - ya) - (yb - ya) * (xc - xa) > 0) continue;
    const double px[3] = {xa, xb, xc}, py[3] = {ya, yb, yc};
    fill(px, py, scratch_[a], scratch_[b], scratch_[c], id);
  }
}

void DepthRaster::drawTriangle(const Vec3& a, const Vec3& b, const Vec3& c, int id) {
  if (a.z() < kNear && b.z() < kNear && c.z() < kNear) return;
  const Vec3 in[3] = {a, b, c};
  // Sutherland–Hodgman against z = kNear: a triangle stays one or becomes a quad (a fan of two,
  // each still on the original triangle's plane).
  Vec3 poly[4];
  int m = 0;
  for (int k = 0; k < 3; ++k) {
    const Vec3& p = in[k];
    const Vec3& q = in[(k + 1) % 3];
    const bool pin = p.z() >= kNear, qin = q.z() >= kNear;
    if (pin) poly[m++] = p;
    if (pin != qin) poly[m++] = p + (q - p) * ((kNear - p.z()) / (q.z() - p.z()));
  }
  const double s = window_.stride;
  double px[4], py[4];
  for (int k = 0; k < m; ++k) {
    px[k] = (K_.fx * poly[k].x() / poly[k].z() + K_.cx) / s;
    py[k] = (K_.fy * poly[k].y() / poly[k].z() + K_.cy) / s;
  }
  for (int k = 1; k + 1 < m; ++k) {
    const double fx[3] = {px[0], px[k], px[k + 1]}, fy[3] = {py[0], py[k], py[k + 1]};
    fill(fx, fy, a, b, c, id);
  }
}

void DepthRaster::fill(const double* px, const double* py, const Vec3& a, const Vec3& b,
                       const Vec3& c, int id) {
  const RasterWindow& w = window_;
  const double x0 = px[0], y0 = py[0], x1 = px[1], y1 = py[1], x2 = px[2], y2 = py[2];
  const int ia = std::max(w.i0, iceil((std::min({x0, x1, x2}))));
  const int ib = std::min(w.i1, ifloor((std::max({x0, x1, x2}))));
  const int ja = std::max(w.j0, iceil((std::min({y0, y1, y2}))));
  const int jb = std::min(w.j1, ifloor((std::max({y0, y1, y2}))));
  if (ia > ib || ja > jb) return;
  const double area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0);
  if (area == 0) return;
  // 1/z on the triangle's plane n·p = d: with p = z·(x, y, 1), 1/z = n·(x, y, 1)/d; affine in
  // sample coordinates, where x = (s·i − cx)/fx and y = (s·j − cy)/fy.
  const Vec3 n = (b - a).cross(c - a);
  const double d = n.dot(a);
  if (!(std::abs(d) > 1e-18)) return;  // edge-on through the camera centre
  const Vec3 plane = n * (1.0 / d);
  const double s = w.stride;
  const double A = plane.x() * s * invFx_, B = plane.y() * s * invFy_;
  const double C = plane.z() - plane.x() * K_.cx * invFx_ - plane.y() * K_.cy * invFy_;
  {
    const double sg = area > 0 ? 1.0 : -1.0;
    // Edge functions e_k(i, j) = sg·((x_b − x_a)(j − y_a) − (y_b − y_a)(i − x_a)) ≥ 0 inside.
    const double ax[3] = {x1, x2, x0}, ay[3] = {y1, y2, y0};
    const double bx[3] = {x2, x0, x1}, by[3] = {y2, y0, y1};
    double ei[3], ej[3], e0[3];
    for (int e = 0; e < 3; ++e) {
      ei[e] = -sg * (by[e] - ay[e]);
      ej[e] = sg * (bx[e] - ax[e]);
      e0[e] = sg * ((bx[e] - ax[e]) * (ja - ay[e]) - (by[e] - ay[e]) * (ia - ax[e]));
    }
    for (int j = ja; j <= jb; ++j) {
      const int dj = j - ja;
      // The row's span from the three edges (one sample of margin for rounding), then the exact
      // test per sample: large triangles cost their covered samples, not their bounding box.
      double base[3];
      int lo = 0, hi = ib - ia;
      for (int e = 0; e < 3; ++e) base[e] = e0[e] + ej[e] * dj;
      for (int e = 0; e < 3 && lo <= hi && ib - ia >= 8; ++e) {
        if (ei[e] > 0)
          lo = std::max(lo, iceil(-base[e] / ei[e]) - 1);
        else if (ei[e] < 0)
          hi = std::min(hi, ifloor(-base[e] / ei[e]) + 1);
        else if (base[e] < 0)
          hi = -1;
      }
      if (lo > hi) continue;
      float* zrow = &invZ_[size_t(index(w.i0, j))];
      int* idrow = &id_[size_t(index(w.i0, j))];
      for (int di = lo; di <= hi; ++di) {
        if (base[0] + ei[0] * di < 0 || base[1] + ei[1] * di < 0 || base[2] + ei[2] * di < 0)
          continue;
        const int i = ia + di;
        const float iz = float(A * i + B * j + C);
        const int col = i - w.i0;
        if (iz > zrow[col]) {
          zrow[col] = iz;
          idrow[col] = id;
        }
      }
    }
  }
}

}  // namespace inhand
