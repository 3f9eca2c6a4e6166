#include "inhand/geometry/surface_distance.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/random.h"

namespace inhand {

Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  // Regions of the triangle's plane, by barycentric tests (vertex, edge, then face).
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double den = va + vb + vc;
  if (!(std::abs(den) > 0)) return a;  // degenerate triangle (a point or a segment)
  const double v = vb / den, w = vc / den;
  return a + ab * v + ac * w;
}

std::vector<Vec3> sampleSurfaceUniform(const TriangleMesh& mesh, int count, uint64_t seed,
                                       const std::vector<uint8_t>& use) {
  INHAND_CHECK(use.empty() || use.size() == mesh.triangles.size(), "one flag per triangle");
  std::vector<double> cum;
  std::vector<int> ids;
  double total = 0;
  for (int t = 0; t < int(mesh.triangles.size()); ++t) {
    if (!use.empty() && !use[t]) continue;
    const double a = mesh.triangleArea(t);
    if (!(a > 0)) continue;
    total += a;
    cum.push_back(total);
    ids.push_back(t);
  }
  std::vector<Vec3> out;
  if (!(total > 0) || count <= 0) return out;
  out.reserve(count);
  Rng rng = makeRng(seed, 0x5a3f);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int i = 0; i < count; ++i) {
    const double r = U(rng) * total;
    size_t k = std::upper_bound(cum.begin(), cum.end(), r) - cum.begin();
    k = std::min(k, cum.size() - 1);
    const Tri& f = mesh.triangles[ids[k]];
    double s = U(rng), t = U(rng);
    if (s + t > 1) {  // fold the unit square onto the triangle: uniform by area
      s = 1 - s;
      t = 1 - t;
    }
    const Vec3 a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
               c = mesh.vertices[f[2]].cast<double>();
    out.push_back(a + s * (b - a) + t * (c - a));
  }
  return out;
}

TriangleDistanceIndex::TriangleDistanceIndex(const TriangleMesh& mesh,
                                             const std::vector<uint8_t>& use, double cell_m) {
  INHAND_CHECK(use.empty() || use.size() == mesh.triangles.size(), "one flag per triangle");
  // The indexed triangles (in mesh order) filled on both cores; their box and summed edge
  // lengths in that order.
  std::vector<int> which;
  which.reserve(mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    if (use.empty() || use[t]) which.push_back(int(t));
  tris_.resize(which.size());
  std::vector<double> edges(which.size());
  parallelFor(
      0, int(which.size()),
      [&](int i) {
        const Tri& f = mesh.triangles[size_t(which[size_t(i)])];
        T& tri = tris_[size_t(i)];
        tri = T{mesh.vertices[f[0]].cast<double>(), mesh.vertices[f[1]].cast<double>(),
                mesh.vertices[f[2]].cast<double>()};
        edges[size_t(i)] = (tri.b - tri.a).norm() + (tri.c - tri.b).norm() + (tri.a - tri.c).norm();
      },
      4096);
  ids_ = std::move(which);
  if (tris_.empty()) return;
  Aabb box;
  double edge = 0;
  for (size_t i = 0; i < tris_.size(); ++i) {
    box.extend(tris_[i].a);
    box.extend(tris_[i].b);
    box.extend(tris_[i].c);
    edge += edges[i];
  }
  const Vec3 size = box.size().cwiseMax(Vec3::Constant(1e-6));
  // Cells about two mean edges wide, at most ~128 per axis.
  cell_ = cell_m > 0 ? cell_m
                     : std::max(2.0 * edge / (3.0 * double(tris_.size())), size.maxCoeff() / 128.0);
  origin_ = box.min;
  dims_ = ((size / cell_).array().floor() + 1).cast<int>().matrix().cwiseMax(Vec3i::Ones());
  const size_t cells = size_t(dims_.x()) * dims_.y() * dims_.z();
  auto cellRange = [&](const T& t, Vec3i* lo, Vec3i* hi) {
    const Vec3 mn = t.a.cwiseMin(t.b).cwiseMin(t.c), mx = t.a.cwiseMax(t.b).cwiseMax(t.c);
    for (int k = 0; k < 3; ++k) {
      (*lo)[k] = std::clamp(int(std::floor((mn[k] - origin_[k]) / cell_)), 0, dims_[k] - 1);
      (*hi)[k] = std::clamp(int(std::floor((mx[k] - origin_[k]) / cell_)), 0, dims_[k] - 1);
    }
  };
  // Each triangle's cells, then the cells counted and filled slab by slab of z on both cores:
  // a slab's cells are its own, and take their triangles in index order as one pass would.
  const int nt = int(tris_.size());
  std::vector<Vec3i> lo(tris_.size()), hi(tris_.size());
  parallelFor(
      0, nt, [&](int i) { cellRange(tris_[size_t(i)], &lo[size_t(i)], &hi[size_t(i)]); }, 4096);
  const int slabs = std::min(dims_.z(), 4 * threadCount());
  auto slabZ = [&](int s) { return int(int64_t(dims_.z()) * s / slabs); };
  std::vector<uint32_t> counts(cells + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    parallelFor(0, slabs, [&](int s) {
      const int z0 = slabZ(s), z1 = slabZ(s + 1);
      for (uint32_t i = 0; i < uint32_t(nt); ++i) {
        const Vec3i& l = lo[i];
        const Vec3i& h = hi[i];
        if (h.z() < z0 || l.z() >= z1) continue;
        for (int z = std::max(l.z(), z0); z <= std::min(h.z(), z1 - 1); ++z)
          for (int y = l.y(); y <= h.y(); ++y)
            for (int x = l.x(); x <= h.x(); ++x) {
              const size_t c = (size_t(z) * dims_.y() + y) * dims_.x() + x;
              if (pass == 0)
                ++counts[c + 1];
              else
                items_[counts[c]++] = i;
            }
      }
    });
    if (pass == 0) {
      for (size_t c = 0; c < cells; ++c) counts[c + 1] += counts[c];
      start_ = counts;
      items_.resize(counts[cells]);
    }
  }
}

double TriangleDistanceIndex::distanceReference(const Vec3& p) const {
  double best = std::numeric_limits<double>::infinity();
  for (const T& t : tris_)
    best = std::min(best, (closestPointOnTriangle(p, t.a, t.b, t.c) - p).norm());
  return best;
}

bool TriangleDistanceIndex::within(const Vec3& p, double r) const {
  if (tris_.empty() || !(r >= 0)) return false;
  const double r2 = r * r;
  auto near = [&](size_t c) {
    for (uint32_t j = start_[c]; j < start_[c + 1]; ++j) {
      const T& t = tris_[items_[j]];
      if ((closestPointOnTriangle(p, t.a, t.b, t.c) - p).squaredNorm() <= r2) return true;
    }
    return false;
  };
  Vec3i c0, lo, hi;
  for (int k = 0; k < 3; ++k) {
    c0[k] = std::clamp(int(std::floor((p[k] - origin_[k]) / cell_)), 0, dims_[k] - 1);
    // Cells beyond r of p hold no triangle within r (a triangle is listed in every cell its box
    // overlaps, so one within r of p overlaps a cell within r of p).
    lo[k] = std::clamp(int(std::floor((p[k] - r - origin_[k]) / cell_)), 0, dims_[k] - 1);
    hi[k] = std::clamp(int(std::floor((p[k] + r - origin_[k]) / cell_)), 0, dims_[k] - 1);
  }
  auto cell = [&](int x, int y, int z) { return (size_t(z) * dims_.y() + y) * dims_.x() + x; };
  if (near(cell(c0.x(), c0.y(), c0.z()))) return true;  // most often there
  for (int z = lo.z(); z <= hi.z(); ++z)
    for (int y = lo.y(); y <= hi.y(); ++y)
      for (int x = lo.x(); x <= hi.x(); ++x)
        if (Vec3i(x, y, z) != c0 && near(cell(x, y, z))) return true;
  return false;
}

double TriangleDistanceIndex::distance(const Vec3& p, double max_m) const {
  return nearest(p, nullptr, nullptr, max_m);
}

double TriangleDistanceIndex::nearest(const Vec3& p, int* triangle, Vec3* point,
                                      double max_m) const {
  double best2 = std::numeric_limits<double>::infinity();
  if (triangle) *triangle = -1;
  if (tris_.empty()) return best2;
  Vec3i c0;
  for (int k = 0; k < 3; ++k)
    c0[k] = std::clamp(int(std::floor((p[k] - origin_[k]) / cell_)), 0, dims_[k] - 1);
  auto visit = [&](int x, int y, int z) {
    const size_t c = (size_t(z) * dims_.y() + y) * dims_.x() + x;
    for (uint32_t j = start_[c]; j < start_[c + 1]; ++j) {
      const T& t = tris_[items_[j]];
      const Vec3 q = closestPointOnTriangle(p, t.a, t.b, t.c);
      const double d2 = (q - p).squaredNorm();
      if (d2 < best2) {
        best2 = d2;
        if (triangle) *triangle = ids_[items_[j]];
        if (point) *point = q;
      }
    }
  };
  const int rMax = dims_.maxCoeff();
  for (int r = 0; r <= rMax; ++r) {
    const int z0 = std::max(0, c0.z() - r), z1 = std::min(dims_.z() - 1, c0.z() + r);
    const int y0 = std::max(0, c0.y() - r), y1 = std::min(dims_.y() - 1, c0.y() + r);
    const int x0 = std::max(0, c0.x() - r), x1 = std::min(dims_.x() - 1, c0.x() + r);
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y) {
        const bool face = std::abs(z - c0.z()) == r || std::abs(y - c0.y()) == r;
        if (face) {
          for (int x = x0; x <= x1; ++x) visit(x, y, z);
        } else {  // only the two cells of the shell on this row
          if (c0.x() - r >= 0) visit(c0.x() - r, y, z);
          if (r > 0 && c0.x() + r < dims_.x()) visit(c0.x() + r, y, z);
        }
      }
    // Every cell not yet visited is at least r cells from p's cell along some axis (p lies in
    // its clamped cell's slab or beyond the grid on that side), so at least r·cell away.
    const double bound = r * cell_;
    if (best2 <= bound * bound || bound >= max_m) break;
  }
  return std::sqrt(best2);
}

}  // namespace inhand
