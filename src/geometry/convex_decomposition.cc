#include "inhand/geometry/convex_decomposition.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "inhand/core/internal/parallel.h"
#include "inhand/geometry/primitives.h"

namespace inhand {

MassProperties massProperties(const TriangleMesh& mesh) {
  MassProperties out;
  if (mesh.vertices.empty()) return out;
  Vec3 ref = Vec3::Zero();  // a point near the mesh: the sums stay well conditioned
  for (const Vec3f& v : mesh.vertices) ref += v.cast<double>();
  ref /= double(mesh.vertices.size());
  double volume = 0;
  Vec3 first = Vec3::Zero();
  Mat3 second = Mat3::Zero();  // ∫ r rᵀ dV about ref
  for (const Tri& t : mesh.triangles) {
    const Vec3 a = mesh.vertices[t[0]].cast<double>() - ref;
    const Vec3 b = mesh.vertices[t[1]].cast<double>() - ref;
    const Vec3 c = mesh.vertices[t[2]].cast<double>() - ref;
    const double v = a.dot(b.cross(c)) / 6;  // the tetrahedron (ref, a, b, c)
    volume += v;
    first += v * (a + b + c) / 4;
    const Vec3 s = a + b + c;
    second +=
        v / 20 * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
  }
  if (!(std::abs(volume) > 0)) return out;
  const Vec3 com = first / volume;
  // About the centre of mass (parallel axis), then the inertia tensor tr(C)·I − C.
  const Mat3 C = second - volume * com * com.transpose();
  out.volume_m3 = volume;
  out.com = ref + com;
  out.inertia_com = C.trace() * Mat3::Identity() - C;
  return out;
}

MassProperties massProperties(const std::vector<ConvexPiece>& pieces) {
  MassProperties mp;
  std::vector<MassProperties> each;
  for (const ConvexPiece& p : pieces) {
    TriangleMesh hull;
    for (const Vec3& v : p.hull.vertices) hull.vertices.push_back(v.cast<float>());
    for (const auto& t : p.hull.triangles) hull.triangles.push_back(Tri(t[0], t[1], t[2]));
    each.push_back(massProperties(hull));
    mp.volume_m3 += each.back().volume_m3;
    mp.com += each.back().volume_m3 * each.back().com;
  }
  if (!(mp.volume_m3 > 0)) return MassProperties{};
  mp.com /= mp.volume_m3;
  for (const MassProperties& e : each) {
    const Vec3 d = e.com - mp.com;
    mp.inertia_com +=
        e.inertia_com + e.volume_m3 * (d.squaredNorm() * Mat3::Identity() - d * d.transpose());
  }
  return mp;
}

double hullVolume(const ConvexHull& hull) {
  if (hull.triangles.empty()) return 0;
  const Vec3& o = hull.vertices[0];
  double v = 0;
  for (const auto& t : hull.triangles)
    v += (hull.vertices[t[0]] - o).dot((hull.vertices[t[1]] - o).cross(hull.vertices[t[2]] - o));
  return v / 6;
}

std::string ConvexDecompositionOptions::validate() const { return checkOptionRanges(*this); }

namespace {

// The solid as voxels (a cell is in when its centre is: parity of the mesh's crossings along
// x through the cell centres of each (y, z) row) with a summed-volume table for counts in boxes.
struct SolidGrid {
  Vec3 origin, top;  // the mesh's box
  double h = 0;
  std::array<int, 3> n{0, 0, 0};
  std::vector<uint8_t> in;     // nx·ny·nz, x fastest
  std::vector<int32_t> table;  // (nx+1)(ny+1)(nz+1) prefix sums

  size_t cell(int i, int j, int k) const { return (size_t(k) * n[1] + j) * n[0] + i; }
  size_t node(int i, int j, int k) const { return (size_t(k) * (n[1] + 1) + j) * (n[0] + 1) + i; }
  // Cells in in the box [lo, hi) of cell indices.
  int64_t count(const std::array<int, 3>& lo, const std::array<int, 3>& hi) const {
    auto S = [&](int i, int j, int k) { return int64_t(table[node(i, j, k)]); };
    return S(hi[0], hi[1], hi[2]) - S(lo[0], hi[1], hi[2]) - S(hi[0], lo[1], hi[2]) -
           S(hi[0], hi[1], lo[2]) + S(lo[0], lo[1], hi[2]) + S(lo[0], hi[1], lo[2]) +
           S(hi[0], lo[1], lo[2]) - S(lo[0], lo[1], lo[2]);
  }
  Vec3 nodePoint(int i, int j, int k) const { return origin + h * Vec3(i, j, k); }
};

SolidGrid voxelise(const TriangleMesh& mesh, int resolution) {
  SolidGrid g;
  const Aabb b = mesh.bounds();
  g.h = std::max(b.size().maxCoeff(), 1e-9) / resolution;
  for (int a = 0; a < 3; ++a) g.n[a] = std::max(1, int(std::ceil(b.size()[a] / g.h - 1e-9)));
  g.origin = b.min;
  g.top = b.max;
  g.in.assign(size_t(g.n[0]) * g.n[1] * g.n[2], 0);
  // Crossings per row; rows through cell centres, nudged off exact edge hits.
  std::vector<std::vector<double>> rows(size_t(g.n[1]) * g.n[2]);
  const double dy = g.h * 1.3e-5, dz = g.h * 0.7e-5;
  for (const Tri& t : mesh.triangles) {
    const Vec3 p0 = mesh.vertices[t[0]].cast<double>(), p1 = mesh.vertices[t[1]].cast<double>(),
               p2 = mesh.vertices[t[2]].cast<double>();
    const double ymin = std::min({p0.y(), p1.y(), p2.y()}),
                 ymax = std::max({p0.y(), p1.y(), p2.y()});
    const double zmin = std::min({p0.z(), p1.z(), p2.z()}),
                 zmax = std::max({p0.z(), p1.z(), p2.z()});
    const int j0 = std::max(0, int(std::ceil((ymin - g.origin.y() - dy) / g.h - 0.5)));
    const int j1 = std::min(g.n[1] - 1, int(std::floor((ymax - g.origin.y() - dy) / g.h - 0.5)));
    const int k0 = std::max(0, int(std::ceil((zmin - g.origin.z() - dz) / g.h - 0.5)));
    const int k1 = std::min(g.n[2] - 1, int(std::floor((zmax - g.origin.z() - dz) / g.h - 0.5)));
    const double area =
        (p1.y() - p0.y()) * (p2.z() - p0.z()) - (p2.y() - p0.y()) * (p1.z() - p0.z());
    if (area == 0) continue;
    for (int k = k0; k <= k1; ++k)
      for (int j = j0; j <= j1; ++j) {
        const double y = g.origin.y() + (j + 0.5) * g.h + dy;
        const double z = g.origin.z() + (k + 0.5) * g.h + dz;
        auto edge = [&](const Vec3& a, const Vec3& c) {
          return (c.y() - a.y()) * (z - a.z()) - (c.z() - a.z()) * (y - a.y());
        };
        const double w0 = edge(p1, p2), w1 = edge(p2, p0), w2 = edge(p0, p1);
        if (!((w0 > 0 && w1 > 0 && w2 > 0) || (w0 < 0 && w1 < 0 && w2 < 0))) continue;
        const double x = (w0 * p0.x() + w1 * p1.x() + w2 * p2.x()) / (w0 + w1 + w2);
        rows[size_t(k) * g.n[1] + j].push_back(x);
      }
  }
  for (int k = 0; k < g.n[2]; ++k)
    for (int j = 0; j < g.n[1]; ++j) {
      std::vector<double>& r = rows[size_t(k) * g.n[1] + j];
      std::sort(r.begin(), r.end());
      for (size_t e = 0; e + 1 < r.size(); e += 2) {
        const int i0 = std::max(0, int(std::ceil((r[e] - g.origin.x()) / g.h - 0.5)));
        const int i1 = std::min(g.n[0] - 1, int(std::floor((r[e + 1] - g.origin.x()) / g.h - 0.5)));
        for (int i = i0; i <= i1; ++i) g.in[g.cell(i, j, k)] = 1;
      }
    }
  g.table.assign(size_t(g.n[0] + 1) * (g.n[1] + 1) * (g.n[2] + 1), 0);
  for (int k = 1; k <= g.n[2]; ++k)
    for (int j = 1; j <= g.n[1]; ++j)
      for (int i = 1; i <= g.n[0]; ++i)
        g.table[g.node(i, j, k)] =
            g.in[g.cell(i - 1, j - 1, k - 1)] + g.table[g.node(i - 1, j, k)] +
            g.table[g.node(i, j - 1, k)] + g.table[g.node(i, j, k - 1)] -
            g.table[g.node(i - 1, j - 1, k)] - g.table[g.node(i - 1, j, k - 1)] -
            g.table[g.node(i, j - 1, k - 1)] + g.table[g.node(i - 1, j - 1, k - 1)];
  return g;
}

// A box of the partition: cells [lo, hi), the triangles that may reach into it, and its hull.
struct Piece {
  std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
  std::vector<int> triangles;
  ConvexHull hull;
  double hull_m3 = 0, solid_m3 = 0;
  double excess() const { return std::max(0.0, hull_m3 - solid_m3); }
};

// Sutherland–Hodgman: the polygon clipped to coordinate `axis` ≥ v (sign +1) or ≤ v (−1).
void clipPolygon(std::vector<Vec3>& poly, int axis, double v, double sign) {
  std::vector<Vec3> out;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec3& a = poly[i];
    const Vec3& b = poly[(i + 1) % poly.size()];
    const double da = sign * (a[axis] - v), db = sign * (b[axis] - v);
    if (da >= 0) out.push_back(a);
    if ((da >= 0) != (db >= 0)) {
      Vec3 p = a + (b - a) * (da / (da - db));
      p[axis] = v;
      out.push_back(p);
    }
  }
  poly.swap(out);
}

void buildPiece(const TriangleMesh& mesh, const std::vector<Aabb>& triBox, const SolidGrid& g,
                const std::vector<int>& parentTriangles, Piece* piece) {
  Piece& p = *piece;
  const Vec3 bmin = g.nodePoint(p.lo[0], p.lo[1], p.lo[2]);
  const Vec3 bmax = g.nodePoint(p.hi[0], p.hi[1], p.hi[2]);
  std::vector<Vec3> points;
  p.triangles.clear();
  for (int t : parentTriangles) {
    const Aabb& tb = triBox[t];
    if ((tb.max.array() < bmin.array()).any() || (tb.min.array() > bmax.array()).any()) continue;
    p.triangles.push_back(t);
    std::vector<Vec3> poly;
    for (int c = 0; c < 3; ++c) poly.push_back(mesh.vertices[mesh.triangles[t][c]].cast<double>());
    for (int a = 0; a < 3 && !poly.empty(); ++a) {
      if (tb.min[a] < bmin[a]) clipPolygon(poly, a, bmin[a], +1);
      if (!poly.empty() && tb.max[a] > bmax[a]) clipPolygon(poly, a, bmax[a], -1);
    }
    points.insert(points.end(), poly.begin(), poly.end());
  }
  // The box's corners inside the solid (the cell at the corner, inside the box, is in).
  for (int c = 0; c < 8; ++c) {
    const int i = (c & 1) ? p.hi[0] - 1 : p.lo[0], j = (c & 2) ? p.hi[1] - 1 : p.lo[1],
              k = (c & 4) ? p.hi[2] - 1 : p.lo[2];
    if (g.in[g.cell(i, j, k)])
      points.push_back(g.nodePoint((c & 1) ? p.hi[0] : p.lo[0], (c & 2) ? p.hi[1] : p.lo[1],
                                   (c & 4) ? p.hi[2] : p.lo[2])
                           .cwiseMin(g.top));  // the grid reaches past the mesh's box
  }
  // Only the extreme points along each axis per row of cells can be hull vertices (up to a
  // cell): fewer points for the incremental hull.
  std::vector<Vec3> extremes;
  if (points.size() > 64) {
    const double q = 2 * g.h;  // rows two cells wide
    for (int a = 0; a < 3; ++a) {
      const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
      std::unordered_map<int64_t, std::pair<int, int>> rows;
      for (int i = 0; i < int(points.size()); ++i) {
        const int64_t key =
            (int64_t(std::floor((points[i][b1] - g.origin[b1]) / q)) << 32) ^
            int64_t(uint32_t(int32_t(std::floor((points[i][b2] - g.origin[b2]) / q))));
        auto [it, fresh] = rows.emplace(key, std::make_pair(i, i));
        if (fresh) continue;
        if (points[i][a] < points[it->second.first][a]) it->second.first = i;
        if (points[i][a] > points[it->second.second][a]) it->second.second = i;
      }
      std::vector<std::pair<int64_t, std::pair<int, int>>> sorted(rows.begin(), rows.end());
      std::sort(sorted.begin(), sorted.end());
      for (const auto& [key, ends] : sorted) {
        extremes.push_back(points[ends.first]);
        extremes.push_back(points[ends.second]);
      }
    }
  } else {
    extremes = points;
  }
  // Many points left (a large piece of a fine mesh): those extreme along 642 directions, the
  // hull's vertices but for a sliver of at most R·(1 − cos 4°) (the directions' spacing).
  if (extremes.size() > 800) {
    static const TriangleMesh directions = makeSphere(1.0, 3);
    std::vector<int> best(directions.vertices.size(), 0);
    std::vector<double> top(directions.vertices.size(), -1e300);
    for (int i = 0; i < int(extremes.size()); ++i)
      for (size_t d = 0; d < directions.vertices.size(); ++d) {
        const double v = directions.vertices[d].cast<double>().dot(extremes[size_t(i)]);
        if (v > top[d]) {
          top[d] = v;
          best[d] = i;
        }
      }
    std::sort(best.begin(), best.end());
    best.erase(std::unique(best.begin(), best.end()), best.end());
    std::vector<Vec3> support;
    for (int i : best) support.push_back(extremes[size_t(i)]);
    extremes.swap(support);
  }
  p.hull = convexHull(extremes);
  p.hull_m3 = hullVolume(p.hull);
  p.solid_m3 = double(g.count(p.lo, p.hi)) * g.h * g.h * g.h;
}

// The occupied cells' extent of the piece along `axis`: [first, last] slab with cells in.
std::pair<int, int> occupiedExtent(const SolidGrid& g, const Piece& p, int axis) {
  int first = p.hi[axis], last = p.lo[axis] - 1;
  for (int s = p.lo[axis]; s < p.hi[axis]; ++s) {
    std::array<int, 3> lo = p.lo, hi = p.hi;
    lo[axis] = s;
    hi[axis] = s + 1;
    if (g.count(lo, hi) > 0) {
      first = std::min(first, s);
      last = s;
    }
  }
  return {first, last};
}

}  // namespace

std::vector<ConvexPiece> convexDecomposition(const TriangleMesh& mesh,
                                             const ConvexDecompositionOptions& options) {
  if (mesh.triangles.empty()) return {};
  const SolidGrid g = voxelise(mesh, options.resolution);
  std::vector<Aabb> triBox(mesh.triangles.size());
  std::vector<int> all(mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (int c = 0; c < 3; ++c)
      triBox[t].extend(mesh.vertices[mesh.triangles[t][c]].cast<double>());
    all[t] = int(t);
  }
  const double solid =
      std::max(std::abs(mesh.signedVolume()), double(g.count({0, 0, 0}, g.n)) * g.h * g.h * g.h);
  std::vector<Piece> pieces(1);
  pieces[0].hi = g.n;
  buildPiece(mesh, triBox, g, all, &pieces[0]);
  std::vector<uint8_t> final(1, 0);  // a piece that no cut improves
  // Excesses that differ by round-off (the hull of a symmetric part, built in another order) are
  // equal: the first in order wins, whatever the last bit says.
  const double tie = 1e-9 * solid;
  while (int(pieces.size()) < options.max_pieces) {
    double total = 0;
    int worst = -1;
    for (size_t i = 0; i < pieces.size(); ++i) {
      total += pieces[i].excess();
      if (!final[i] && (worst < 0 || pieces[i].excess() > pieces[size_t(worst)].excess() + tie))
        worst = int(i);
    }
    if (worst < 0 || total <= options.max_excess * solid) break;
    const Piece& p = pieces[size_t(worst)];
    // Cuts at the quarters of the occupied extent along each axis.
    std::vector<std::pair<int, int>> cuts;  // (axis, cell index of the plane)
    for (int a = 0; a < 3; ++a) {
      const auto [first, last] = occupiedExtent(g, p, a);
      const int len = last - first + 1;
      if (len < 2) continue;
      for (int q = 1; q <= 3; ++q) {
        const int at = first + std::max(1, std::min(len - 1, int(std::lround(len * q / 4.0))));
        if (cuts.empty() || cuts.back() != std::make_pair(a, at)) cuts.emplace_back(a, at);
      }
    }
    if (cuts.empty()) {
      final[size_t(worst)] = 1;
      continue;
    }
    std::vector<std::array<Piece, 2>> children(cuts.size());
    parallelFor(0, int(cuts.size()), [&](int c) {
      const auto [a, at] = cuts[size_t(c)];
      Piece& left = children[size_t(c)][0];
      Piece& right = children[size_t(c)][1];
      left.lo = right.lo = p.lo;
      left.hi = right.hi = p.hi;
      left.hi[a] = at;
      right.lo[a] = at;
      buildPiece(mesh, triBox, g, p.triangles, &left);
      buildPiece(mesh, triBox, g, p.triangles, &right);
    });
    size_t best = 0;
    for (size_t c = 1; c < cuts.size(); ++c)
      if (children[c][0].excess() + children[c][1].excess() <
          children[best][0].excess() + children[best][1].excess() - tie)
        best = c;
    pieces[size_t(worst)] = std::move(children[best][0]);
    final[size_t(worst)] = 0;
    pieces.push_back(std::move(children[best][1]));
    final.push_back(0);
  }
  std::vector<ConvexPiece> out;
  for (Piece& p : pieces)
    if (p.hull_m3 > 0) out.push_back({std::move(p.hull), p.hull_m3});
  return out;
}

std::optional<ConvexPiece> clipPiece(const ConvexPiece& piece, const Vec3& n, double d) {
  const std::vector<Vec3>& v = piece.hull.vertices;
  std::vector<Vec3> kept;
  for (const Vec3& p : v)
    if (n.dot(p) >= d) kept.push_back(p);
  if (kept.size() == v.size()) return piece;
  for (const auto& t : piece.hull.triangles)
    for (int k = 0; k < 3; ++k) {
      const Vec3& a = v[size_t(t[size_t(k)])];
      const Vec3& b = v[size_t(t[size_t((k + 1) % 3)])];
      const double sa = n.dot(a) - d, sb = n.dot(b) - d;
      if ((sa < 0) != (sb < 0)) kept.push_back(a + (sa / (sa - sb)) * (b - a));
    }
  if (kept.size() < 4) return std::nullopt;
  ConvexPiece out;
  out.hull = convexHull(kept);
  out.volume_m3 = hullVolume(out.hull);
  if (!(out.volume_m3 >= 1e-9)) return std::nullopt;
  return out;
}

}  // namespace inhand
