#include "inhand/geometry/triangle_mesh.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <unordered_map>

#include "inhand/core/error.h"

namespace inhand {

Aabb TriangleMesh::bounds() const {
  Aabb box;
  for (const Vec3f& v : vertices) box.extend(v.cast<double>());
  return box;
}

double TriangleMesh::triangleArea(int t) const {
  const Tri& f = triangles[t];
  Vec3 a = vertices[f[0]].cast<double>(), b = vertices[f[1]].cast<double>(),
       c = vertices[f[2]].cast<double>();
  return 0.5 * (b - a).cross(c - a).norm();
}

double TriangleMesh::area() const {
  double sum = 0;
  for (int t = 0; t < static_cast<int>(triangles.size()); ++t) sum += triangleArea(t);
  return sum;
}

double TriangleMesh::signedVolume() const {
  double sum = 0;
  for (const Tri& f : triangles) {
    Vec3 a = vertices[f[0]].cast<double>(), b = vertices[f[1]].cast<double>(),
         c = vertices[f[2]].cast<double>();
    sum += a.dot(b.cross(c));
  }
  return sum / 6.0;
}

Vec3 TriangleMesh::faceNormal(int t) const {
  const Tri& f = triangles[t];
  Vec3 a = vertices[f[0]].cast<double>(), b = vertices[f[1]].cast<double>(),
       c = vertices[f[2]].cast<double>();
  Vec3 n = (b - a).cross(c - a);
  double len = n.norm();
  return len > 0 ? Vec3(n / len) : Vec3::Zero();
}

void TriangleMesh::append(const TriangleMesh& other) {
  int base = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  for (const Tri& f : other.triangles) triangles.push_back(f + Tri::Constant(base));
}

namespace {
uint64_t edgeKey(int a, int b) { return (uint64_t(uint32_t(a)) << 32) | uint32_t(b); }
}  // namespace

namespace {
// How often each directed edge (a → b) is used.
std::unordered_map<uint64_t, int> directedEdgeCounts(const std::vector<Tri>& triangles) {
  std::unordered_map<uint64_t, int> directed;
  directed.reserve(triangles.size() * 3);
  for (const Tri& f : triangles)
    for (int k = 0; k < 3; ++k) ++directed[edgeKey(f[k], f[(k + 1) % 3])];
  return directed;
}

// Every directed edge used as often as its reverse, and (when `manifold`) exactly once.
bool edgesPaired(const std::vector<Tri>& triangles, bool manifold) {
  if (triangles.empty()) return false;
  const std::unordered_map<uint64_t, int> directed = directedEdgeCounts(triangles);
  for (const auto& [key, count] : directed) {
    if (manifold && count != 1) return false;
    int a = int(key >> 32), b = int(key & 0xffffffffu);
    auto it = directed.find(edgeKey(b, a));
    if (it == directed.end() || it->second != count) return false;
  }
  return true;
}
}  // namespace

bool TriangleMesh::isClosed() const { return edgesPaired(triangles, true); }

bool TriangleMesh::isWatertight() const { return edgesPaired(triangles, false); }

int TriangleMesh::boundaryEdgeCount() const {
  std::unordered_map<uint64_t, int> undirected;
  for (const Tri& f : triangles)
    for (int k = 0; k < 3; ++k) {
      int a = f[k], b = f[(k + 1) % 3];
      ++undirected[edgeKey(std::min(a, b), std::max(a, b))];
    }
  int n = 0;
  for (const auto& kv : undirected) n += kv.second == 1;
  return n;
}

TriangleMesh transformed(const TriangleMesh& mesh, const Iso3& T) {
  TriangleMesh out = mesh;
  for (Vec3f& v : out.vertices) v = (T * v.cast<double>()).cast<float>();
  if (T.linear().determinant() < 0)
    for (Tri& f : out.triangles) std::swap(f[1], f[2]);
  return out;
}

TriangleMesh welded(const TriangleMesh& mesh, double tolerance_m, std::vector<int>* kept_triangles,
                    std::vector<int>* vertex_remap) {
  struct KeyHash {
    size_t operator()(const std::array<int64_t, 3>& k) const {
      return size_t(uint64_t(k[0]) * 73856093u ^ uint64_t(k[1]) * 19349663u ^
                    uint64_t(k[2]) * 83492791u);
    }
  };
  std::unordered_map<std::array<int64_t, 3>, int, KeyHash> index;
  index.reserve(mesh.vertices.size());
  TriangleMesh out;
  std::vector<int> remap(mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Vec3f& v = mesh.vertices[i];
    std::array<int64_t, 3> key{std::llround(v.x() / tolerance_m), std::llround(v.y() / tolerance_m),
                               std::llround(v.z() / tolerance_m)};
    auto [it, inserted] = index.emplace(key, static_cast<int>(out.vertices.size()));
    if (inserted) out.vertices.push_back(v);
    remap[i] = it->second;
  }
  if (kept_triangles) kept_triangles->clear();
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri& f = mesh.triangles[t];
    Tri g(remap[f[0]], remap[f[1]], remap[f[2]]);
    if (g[0] != g[1] && g[1] != g[2] && g[0] != g[2]) {
      out.triangles.push_back(g);
      if (kept_triangles) kept_triangles->push_back(int(t));
    }
  }
  if (vertex_remap) *vertex_remap = std::move(remap);
  return out;
}

TriangleMesh clustered(const TriangleMesh& mesh, double cell_m) {
  std::vector<int> remap;
  TriangleMesh out = welded(mesh, cell_m, nullptr, &remap);
  std::vector<Vec3> sum(out.vertices.size(), Vec3::Zero());
  std::vector<int> count(out.vertices.size(), 0);
  for (size_t i = 0; i < remap.size(); ++i) {
    sum[size_t(remap[i])] += mesh.vertices[i].cast<double>();
    ++count[size_t(remap[i])];
  }
  for (size_t i = 0; i < out.vertices.size(); ++i)
    out.vertices[i] = (sum[i] / std::max(count[i], 1)).cast<float>();
  // Triangles on the same three vertices: a pair facing opposite ways is a sheet collapsed onto
  // itself (both go: the surface stays closed), one facing the same way as another repeats it.
  struct Count {
    int up = 0, down = 0;  // triangles facing each way
    bool done = false;     // one kept
  };
  std::map<std::array<int, 3>, Count> faces;  // by sorted vertices
  auto keyOf = [](const Tri& t, int* sign) {
    std::array<int, 3> k{t[0], t[1], t[2]};
    const int r = int(std::min_element(k.begin(), k.end()) - k.begin());
    std::rotate(k.begin(), k.begin() + r, k.end());  // smallest first, orientation kept
    *sign = k[1] < k[2] ? 1 : -1;
    if (k[1] > k[2]) std::swap(k[1], k[2]);
    return k;
  };
  for (const Tri& t : out.triangles) {
    int sign = 0;
    const auto k = keyOf(t, &sign);
    (sign > 0 ? faces[k].up : faces[k].down)++;
  }
  std::vector<Tri> kept;
  kept.reserve(out.triangles.size());
  for (const Tri& t : out.triangles) {
    int sign = 0;
    Count& c = faces[keyOf(t, &sign)];
    if (!c.done && (sign > 0 ? c.up > c.down : c.down > c.up)) {  // the orientation that wins
      kept.push_back(t);
      c.done = true;
    }
  }
  out.triangles = std::move(kept);
  return withoutUnusedVertices(out);
}

TriangleMesh simplifiedTo(const TriangleMesh& mesh, size_t max_triangles) {
  if (mesh.triangles.size() <= max_triangles || mesh.triangles.empty()) return mesh;
  double edges = 0;
  for (const Tri& t : mesh.triangles) edges += (mesh.vertices[t[1]] - mesh.vertices[t[0]]).norm();
  double cell = std::max(edges / double(mesh.triangles.size()), 1e-6);
  for (;;) {
    TriangleMesh out = clustered(mesh, cell);
    if (out.triangles.size() <= max_triangles) return out;
    cell *= 1.25;
  }
}

TriangleMesh withoutUnusedVertices(const TriangleMesh& mesh) {
  std::vector<int> remap(mesh.vertices.size(), -1);
  TriangleMesh out;
  out.triangles.reserve(mesh.triangles.size());
  for (const Tri& f : mesh.triangles) {
    Tri g;
    for (int k = 0; k < 3; ++k) {
      int& r = remap[size_t(f[k])];
      if (r < 0) {
        r = int(out.vertices.size());
        out.vertices.push_back(mesh.vertices[size_t(f[k])]);
      }
      g[k] = r;
    }
    out.triangles.push_back(g);
  }
  return out;
}

TriangleMesh withHolesClosed(const TriangleMesh& mesh, int* loops_closed) {
  // Boundary half-edges: a directed edge whose undirected edge only one triangle uses.
  std::unordered_map<uint64_t, int> undirected;
  for (const Tri& f : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const int a = f[k], b = f[(k + 1) % 3];
      ++undirected[edgeKey(std::min(a, b), std::max(a, b))];
    }
  std::unordered_multimap<int, int> from;  // start vertex → end vertex of each boundary half-edge
  for (const Tri& f : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const int a = f[k], b = f[(k + 1) % 3];
      if (undirected[edgeKey(std::min(a, b), std::max(a, b))] == 1) from.emplace(a, b);
    }
  TriangleMesh out = mesh;
  int closed = 0;
  // Walk each loop along the triangles' own direction; a vertex where loops touch has several
  // ways on (any unused one closes a loop). A chain that ends (inconsistently oriented
  // triangles) is left open.
  while (!from.empty()) {
    std::vector<int> loop{from.begin()->first};
    int at = from.begin()->second;
    from.erase(from.begin());
    while (at != loop.front()) {
      loop.push_back(at);
      const auto next = from.find(at);
      if (next == from.end()) break;
      at = next->second;
      from.erase(next);
    }
    if (at != loop.front() || loop.size() < 3) continue;
    // A fan about the loop's centroid, turned against the loop (the triangles beside each
    // boundary edge run along it): the filled surface faces the same way as the rest.
    Vec3 c = Vec3::Zero();
    for (int v : loop) c += out.vertices[size_t(v)].cast<double>();
    const int centre = int(out.vertices.size());
    out.vertices.push_back((c / double(loop.size())).cast<float>());
    for (size_t i = 0; i < loop.size(); ++i)
      out.triangles.push_back(Tri(loop[(i + 1) % loop.size()], loop[i], centre));
    ++closed;
  }
  if (loops_closed) *loops_closed = closed;
  return out;
}

std::string validateMesh(const TriangleMesh& mesh) {
  if (mesh.triangles.empty()) return "has no triangles";
  for (const Vec3f& v : mesh.vertices) {
    if (!v.allFinite()) return "has a vertex with a non-finite coordinate";
    if (v.cwiseAbs().maxCoeff() > 1e6f) return "has a vertex more than 10^6 m from the origin";
  }
  const int n = static_cast<int>(mesh.vertices.size());
  for (const Tri& f : mesh.triangles)
    for (int k = 0; k < 3; ++k)
      if (f[k] < 0 || f[k] >= n) return "has a triangle with an out-of-range vertex index";
  return {};
}

std::vector<SurfacePoint> surfaceSamples(const TriangleMesh& mesh, double spacing) {
  std::vector<SurfacePoint> samples(mesh.vertices.size());
  for (size_t k = 0; k < mesh.vertices.size(); ++k)
    samples[k] = {mesh.vertices[k].cast<double>(), Vec3::Zero()};
  for (const Tri& f : mesh.triangles) {
    const Vec3 a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
               c = mesh.vertices[f[2]].cast<double>();
    const Vec3 n = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) samples[f[k]].n += n;
    const int steps =
        int(std::ceil(std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()}) / spacing));
    if (steps < 2 || n.norm() == 0) continue;
    for (int i = 0; i <= steps; ++i)
      for (int j = 0; i + j <= steps; ++j) {
        if ((i == 0 && j == 0) || i == steps || j == steps) continue;  // the corners
        samples.push_back(
            {a + (b - a) * (double(i) / steps) + (c - a) * (double(j) / steps), n.normalized()});
      }
  }
  for (SurfacePoint& sm : samples) sm.n = sm.n.norm() > 0 ? sm.n.normalized() : Vec3::UnitZ();
  return samples;
}

std::vector<SurfacePoint> evenSurfaceSamples(const TriangleMesh& mesh, double spacing) {
  std::vector<SurfacePoint> samples;
  if (!(spacing > 0)) return samples;
  struct Key {
    int64_t x, y, z;
    int side;
    bool operator==(const Key& k) const {
      return x == k.x && y == k.y && z == k.z && side == k.side;
    }
  };
  struct Hash {
    size_t operator()(const Key& k) const {
      return size_t(k.x * 73856093) ^ size_t(k.y * 19349663) ^ size_t(k.z * 83492791) ^
             size_t(k.side);
    }
  };
  std::unordered_map<Key, char, Hash> taken;
  auto keep = [&](const Vec3& p, const Vec3& n) {
    int axis = 0;
    n.cwiseAbs().maxCoeff(&axis);
    const Key k{int64_t(std::floor(p.x() / spacing)), int64_t(std::floor(p.y() / spacing)),
                int64_t(std::floor(p.z() / spacing)), 2 * axis + (n[axis] < 0)};
    if (taken.emplace(k, 0).second) samples.push_back({p, n});
  };
  struct Piece {
    Vec3 a, b, c;
  };
  std::vector<Piece> stack;
  for (const Tri& f : mesh.triangles) {
    const Vec3 a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
               c = mesh.vertices[f[2]].cast<double>();
    const Vec3 cross = (b - a).cross(c - a);
    if (!(cross.norm() > 0)) continue;
    const Vec3 n = cross.normalized();
    stack.assign(1, {a, b, c});
    while (!stack.empty()) {
      const Piece t = stack.back();
      stack.pop_back();
      const double ab = (t.b - t.a).squaredNorm(), bc = (t.c - t.b).squaredNorm(),
                   ca = (t.a - t.c).squaredNorm();
      const double longest = std::max({ab, bc, ca});
      if (longest <= spacing * spacing) {
        keep((t.a + t.b + t.c) / 3.0, n);
      } else if (longest == ab) {  // split the longest edge at its midpoint
        const Vec3 m = 0.5 * (t.a + t.b);
        stack.push_back({t.a, m, t.c});
        stack.push_back({m, t.b, t.c});
      } else if (longest == bc) {
        const Vec3 m = 0.5 * (t.b + t.c);
        stack.push_back({t.a, t.b, m});
        stack.push_back({t.a, m, t.c});
      } else {
        const Vec3 m = 0.5 * (t.c + t.a);
        stack.push_back({t.a, t.b, m});
        stack.push_back({m, t.b, t.c});
      }
    }
  }
  return samples;
}

TriangleMesh subdivided(const TriangleMesh& mesh, double max_edge_m, std::vector<uint8_t>* flags) {
  if (!(max_edge_m > 0)) throw Error("subdivided: the edge length must be positive");
  TriangleMesh out = mesh;
  const float max2 = float(max_edge_m * max_edge_m);
  for (int pass = 0; pass < 64; ++pass) {
    // The midpoint of every edge too long, shared by the two triangles on it.
    std::map<std::pair<int, int>, int> mid;
    auto split = [&](int a, int b) -> int {
      if ((out.vertices[size_t(a)] - out.vertices[size_t(b)]).squaredNorm() <= max2) return -1;
      const auto key = std::minmax(a, b);
      if (auto it = mid.find(key); it != mid.end()) return it->second;
      const int m = int(out.vertices.size());
      out.vertices.push_back(0.5f * (out.vertices[size_t(a)] + out.vertices[size_t(b)]));
      if (flags) flags->push_back((*flags)[size_t(a)] && (*flags)[size_t(b)]);
      mid.emplace(key, m);
      return m;
    };
    std::vector<Tri> next;
    next.reserve(out.triangles.size());
    for (const Tri& t : out.triangles) {
      const int v[3] = {t[0], t[1], t[2]};
      const int m[3] = {split(v[0], v[1]), split(v[1], v[2]), split(v[2], v[0])};
      const int n = (m[0] >= 0) + (m[1] >= 0) + (m[2] >= 0);
      if (n == 0) {
        next.push_back(t);
      } else if (n == 3) {
        next.push_back(Tri(v[0], m[0], m[2]));
        next.push_back(Tri(m[0], v[1], m[1]));
        next.push_back(Tri(m[2], m[1], v[2]));
        next.push_back(Tri(m[0], m[1], m[2]));
      } else if (n == 1) {
        const int k = m[0] >= 0 ? 0 : m[1] >= 0 ? 1 : 2;  // the split edge, from v[k]
        const int a = v[k], b = v[(k + 1) % 3], c = v[(k + 2) % 3];
        next.push_back(Tri(a, m[k], c));
        next.push_back(Tri(m[k], b, c));
      } else {
        const int k = m[0] < 0 ? 0 : m[1] < 0 ? 1 : 2;  // the edge not split
        const int s = (k + 1) % 3;                      // edges s and s+1 are split
        const int a = v[s], b = v[(s + 1) % 3], c = v[(s + 2) % 3];
        const int ab = m[s], bc = m[(s + 1) % 3];
        next.push_back(Tri(ab, b, bc));
        next.push_back(Tri(a, ab, bc));
        next.push_back(Tri(a, bc, c));
      }
    }
    const bool changed = !mid.empty();
    out.triangles = std::move(next);
    if (!changed) break;
  }
  return out;
}

std::vector<Vec3f> vertexNormals(const TriangleMesh& mesh) {
  std::vector<Vec3f> n(mesh.vertices.size(), Vec3f::Zero());
  for (const Tri& f : mesh.triangles) {
    const Vec3f a = mesh.vertices[size_t(f[0])], b = mesh.vertices[size_t(f[1])],
                c = mesh.vertices[size_t(f[2])];
    const Vec3f w = (b - a).cross(c - a);  // length: twice the area
    for (int k = 0; k < 3; ++k) n[size_t(f[k])] += w;
  }
  for (Vec3f& v : n) v = v.norm() > 0 ? Vec3f(v.normalized()) : Vec3f(0, 0, 1);
  return n;
}

}  // namespace inhand
