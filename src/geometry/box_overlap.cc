#include "inhand/geometry/internal/box_overlap.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace inhand {

bool triangleOverlapsBox(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& half) {
  // The box's own axes: the triangle's extent along each.
  for (int i = 0; i < 3; ++i) {
    if (std::min({a[i], b[i], c[i]}) > half[i]) return false;
    if (std::max({a[i], b[i], c[i]}) < -half[i]) return false;
  }
  const Vec3 e0 = b - a, e1 = c - b, e2 = a - c;
  // The triangle's plane.
  const Vec3 n = e0.cross(c - a);
  if (std::abs(n.dot(a)) > half.dot(n.cwiseAbs())) return false;
  // Box axis × triangle edge: the box projects to [-r, r], the triangle to its vertices'
  // projections (two of which coincide along an axis perpendicular to one of its edges).
  const std::array<const Vec3*, 3> edges{&e0, &e1, &e2};
  for (const Vec3* e : edges)
    for (int i = 0; i < 3; ++i) {
      Vec3 axis = Vec3::Zero();
      const int j = (i + 1) % 3, k = (i + 2) % 3;
      axis[j] = -(*e)[k];  // unit_i × e
      axis[k] = (*e)[j];
      const double pa = axis.dot(a), pb = axis.dot(b), pc = axis.dot(c);
      const double r = half[j] * std::abs(axis[j]) + half[k] * std::abs(axis[k]);
      if (std::min({pa, pb, pc}) > r || std::max({pa, pb, pc}) < -r) return false;
    }
  return true;
}

namespace {

bool insideBox(const Vec3& p, const Vec3& half) {
  return (p.cwiseAbs().array() <= half.array()).all();
}

// The segment p0–p1 meets the solid box [-half, half] (slabs).
bool segmentMeetsBox(const Vec3& p0, const Vec3& p1, const Vec3& half) {
  const Vec3 d = p1 - p0;
  double lo = 0, hi = 1;
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0) {
      if (std::abs(p0[i]) > half[i]) return false;
      continue;
    }
    double t1 = (-half[i] - p0[i]) / d[i], t2 = (half[i] - p0[i]) / d[i];
    if (t1 > t2) std::swap(t1, t2);
    lo = std::max(lo, t1);
    hi = std::min(hi, t2);
    if (lo > hi) return false;
  }
  return true;
}

// The segment p0–p1 crosses the triangle (a, b, c) (a segment in the triangle's plane is not
// counted: the other tests find those overlaps).
bool segmentMeetsTriangle(const Vec3& p0, const Vec3& p1, const Vec3& a, const Vec3& b,
                          const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double d0 = n.dot(p0 - a), d1 = n.dot(p1 - a);
  if ((d0 > 0 && d1 > 0) || (d0 < 0 && d1 < 0) || d0 == d1) return false;
  const Vec3 x = p0 + (d0 / (d0 - d1)) * (p1 - p0);
  return (b - a).cross(x - a).dot(n) >= 0 && (c - b).cross(x - b).dot(n) >= 0 &&
         (a - c).cross(x - c).dot(n) >= 0;
}

}  // namespace

bool triangleOverlapsBoxReference(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& half) {
  if (insideBox(a, half) || insideBox(b, half) || insideBox(c, half)) return true;
  if (segmentMeetsBox(a, b, half) || segmentMeetsBox(b, c, half) || segmentMeetsBox(c, a, half))
    return true;
  // The box's 12 edges: corners that differ in one coordinate.
  for (int k = 0; k < 8; ++k)
    for (int i = 0; i < 3; ++i) {
      if (k & (1 << i)) continue;
      auto corner = [&](int m) {
        return Vec3((m & 1) ? half.x() : -half.x(), (m & 2) ? half.y() : -half.y(),
                    (m & 4) ? half.z() : -half.z());
      };
      if (segmentMeetsTriangle(corner(k), corner(k | (1 << i)), a, b, c)) return true;
    }
  return false;
}

TriangleBoxIndex::TriangleBoxIndex(const TriangleMesh& mesh) {
  std::vector<Tri3> source;
  std::vector<Vec3> centroids;
  source.reserve(mesh.triangles.size());
  for (const Tri& t : mesh.triangles) {
    source.push_back({mesh.vertices[t[0]].cast<double>(), mesh.vertices[t[1]].cast<double>(),
                      mesh.vertices[t[2]].cast<double>()});
    centroids.push_back((source.back().a + source.back().b + source.back().c) / 3);
  }
  if (source.empty()) return;
  std::vector<int> ids(source.size());
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = int(i);
  nodes_.reserve(source.size() / 2 + 1);
  tris_.reserve(source.size());
  build(ids, 0, int(ids.size()), centroids, source);
}

int TriangleBoxIndex::build(std::vector<int>& ids, int begin, int end,
                            const std::vector<Vec3>& centroids, const std::vector<Tri3>& source) {
  Aabb box, centres;
  for (int i = begin; i < end; ++i) {
    const Tri3& t = source[ids[i]];
    box.extend(t.a);
    box.extend(t.b);
    box.extend(t.c);
    centres.extend(centroids[ids[i]]);
  }
  const int index = int(nodes_.size());
  nodes_.push_back({box.center(), 0.5 * box.size(), 0, 0});
  if (end - begin <= 4) {
    nodes_[index].first = int(tris_.size());
    nodes_[index].count = end - begin;
    for (int i = begin; i < end; ++i) tris_.push_back(source[ids[i]]);
    return index;
  }
  int axis = 0;
  centres.size().maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(ids.begin() + begin, ids.begin() + mid, ids.begin() + end,
                   [&](int p, int q) { return centroids[p][axis] < centroids[q][axis]; });
  build(ids, begin, mid, centroids, source);  // the first child follows its parent
  const int second = build(ids, mid, end, centroids, source);
  nodes_[index].first = second;
  return index;
}

bool TriangleBoxIndex::overlapsBox(const Iso3& T_O_box, const Vec3& half) const {
  if (nodes_.empty()) return false;
  const Mat3 R = T_O_box.linear();
  const Mat3 Rabs = R.cwiseAbs();
  const Vec3 c = T_O_box.translation();
  const Vec3 reach = Rabs * half;  // the box's axis-aligned half extents in O
  int stack[64];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    const Vec3 d = c - n.centre;
    // Separated along an axis of O, or along one of the box's: this node holds nothing it meets.
    if ((d.cwiseAbs() - n.half - reach).maxCoeff() > 0) continue;
    const Vec3 along = R.transpose() * d;
    const Vec3 nodeReach = Rabs.transpose() * n.half;
    if ((along.cwiseAbs() - half - nodeReach).maxCoeff() > 0) continue;
    if (n.count > 0) {
      for (int i = n.first; i < n.first + n.count; ++i) {
        const Tri3& t = tris_[i];
        if (triangleOverlapsBox(R.transpose() * (t.a - c), R.transpose() * (t.b - c),
                                R.transpose() * (t.c - c), half))
          return true;
      }
      continue;
    }
    // Depth is about log2(triangles / 4) + a few (median splits): far below 64 for any mesh
    // that fits in memory.
    stack[top++] = n.first;
    stack[top++] = int(&n - nodes_.data()) + 1;
  }
  return false;
}

bool TriangleBoxIndex::overlapsBoxReference(const Iso3& T_O_box, const Vec3& half) const {
  const Iso3 T = T_O_box.inverse();
  for (const Tri3& t : tris_)
    if (triangleOverlapsBox(T * t.a, T * t.b, T * t.c, half)) return true;
  return false;
}

}  // namespace inhand
