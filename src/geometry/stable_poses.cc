#include "inhand/geometry/stable_poses.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <random>
#include <unordered_map>

#include "inhand/core/error.h"

namespace inhand {

namespace {
using Tri3 = std::array<int, 3>;

// Solid angle of triangle (a, b, c) seen from the origin (Van Oosterom & Strackee).
double solidAngle(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double la = a.norm(), lb = b.norm(), lc = c.norm();
  const double num = a.dot(b.cross(c));
  const double den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
  return std::abs(2 * std::atan2(num, den));
}
}  // namespace

ConvexHull convexHull(const std::vector<Vec3>& input) {
  ConvexHull hull;
  // Unique points, in a seeded random order (incremental hulls expect no adversarial order).
  std::vector<Vec3> pts;
  {
    Aabb b;
    for (const Vec3& p : input) b.extend(p);
    const double cell = std::max(1e-9, 1e-7 * b.size().maxCoeff());
    std::map<std::array<long long, 3>, bool> seen;
    for (const Vec3& p : input) {
      std::array<long long, 3> k{std::llround(p.x() / cell), std::llround(p.y() / cell),
                                 std::llround(p.z() / cell)};
      if (seen.emplace(k, true).second) pts.push_back(p);
    }
  }
  if (pts.size() < 4) return hull;
  std::mt19937_64 rng(12345);
  std::shuffle(pts.begin(), pts.end(), rng);
  Aabb box;
  for (const Vec3& p : pts) box.extend(p);
  const double eps = 1e-9 * std::max(1e-6, box.size().maxCoeff());
  // The initial tetrahedron spans as much as the points do (a flat one would make the inside
  // point's side of its faces a matter of round-off): the lowest x, the farthest from it, the
  // farthest from their line, the farthest from their plane.
  auto farthest = [&](const std::function<double(const Vec3&)>& distance) {
    int best = 0;
    double d = -1;
    for (size_t i = 0; i < pts.size(); ++i)
      if (const double di = distance(pts[i]); di > d) {
        d = di;
        best = int(i);
      }
    return std::make_pair(best, d);
  };
  const int i0 = farthest([](const Vec3& p) { return -p.x(); }).first;
  const auto [i1, d1] = farthest([&](const Vec3& p) { return (p - pts[i0]).norm(); });
  if (!(d1 > 1e3 * eps)) return hull;
  const Vec3 u = (pts[i1] - pts[i0]) / d1;
  const auto [i2, d2] = farthest([&](const Vec3& p) { return u.cross(p - pts[i0]).norm(); });
  if (!(d2 > 1e3 * eps)) return hull;
  const Vec3 n012 = (pts[i1] - pts[i0]).cross(pts[i2] - pts[i0]).normalized();
  const auto [i3, d3] = farthest([&](const Vec3& p) { return std::abs(n012.dot(p - pts[i0])); });
  if (!(d3 > 1e3 * eps)) return hull;
  // Quickhull: each face keeps the points outside it; the farthest of them is added next (so a
  // point barely outside, where round-off decides visibility, comes last and is usually inside
  // by then). Each directed edge (a, b) maps to the live face it bounds.
  std::vector<Tri3> faces;
  std::vector<Vec3> normal;
  std::vector<double> offset;
  std::vector<uint8_t> alive;
  std::vector<std::vector<int>> outside;
  std::unordered_map<uint64_t, int> edgeFace;
  auto key = [](int a, int b) { return (uint64_t(uint32_t(a)) << 32) | uint32_t(b); };
  auto dist = [&](int f, const Vec3& p) { return normal[size_t(f)].dot(p) - offset[size_t(f)]; };
  const Vec3 inside = 0.25 * (pts[i0] + pts[i1] + pts[i2] + pts[i3]);
  auto addFace = [&](int a, int b, int c, bool orient) {
    Vec3 n = (pts[size_t(b)] - pts[size_t(a)]).cross(pts[size_t(c)] - pts[size_t(a)]);
    if (orient && n.dot(pts[size_t(a)] - inside) < 0) {
      std::swap(b, c);
      n = -n;
    }
    const double len = n.norm();
    n = len > 0 ? Vec3(n / len) : Vec3::Zero();
    const int f = int(faces.size());
    faces.push_back({a, b, c});
    normal.push_back(n);
    offset.push_back(n.dot(pts[size_t(a)]));
    alive.push_back(1);
    outside.emplace_back();
    edgeFace[key(a, b)] = f;
    edgeFace[key(b, c)] = f;
    edgeFace[key(c, a)] = f;
    return f;
  };
  // Each point to the face (among `candidates`) it lies farthest outside of, if any.
  auto assign = [&](int q, const std::vector<int>& candidates) {
    int best = -1;
    double far = eps;
    for (int f : candidates)
      if (const double d = dist(f, pts[size_t(q)]); d > far) {
        far = d;
        best = f;
      }
    if (best >= 0) outside[size_t(best)].push_back(q);
  };
  const std::vector<int> first{addFace(i0, i1, i2, true), addFace(i0, i1, i3, true),
                               addFace(i0, i2, i3, true), addFace(i1, i2, i3, true)};
  for (size_t q = 0; q < pts.size(); ++q)
    if (int(q) != i0 && int(q) != i1 && int(q) != i2 && int(q) != i3) assign(int(q), first);
  std::vector<int> visible, stack, orphans, added;
  std::vector<uint8_t> isVisible;
  for (size_t f0 = 0; f0 < faces.size(); ++f0) {
    while (alive[f0] && !outside[f0].empty()) {
      // The farthest point outside this face, and every face it sees connected to this one.
      const std::vector<int>& out = outside[f0];
      const int pi = *std::max_element(out.begin(), out.end(), [&](int a, int b) {
        return dist(int(f0), pts[size_t(a)]) < dist(int(f0), pts[size_t(b)]);
      });
      const Vec3& p = pts[size_t(pi)];
      isVisible.resize(faces.size(), 0);
      visible.clear();
      stack.assign(1, int(f0));
      isVisible[f0] = 1;
      while (!stack.empty()) {
        const int f = stack.back();
        stack.pop_back();
        visible.push_back(f);
        for (int k = 0; k < 3; ++k) {
          const Tri3& t = faces[size_t(f)];
          const auto it = edgeFace.find(key(t[size_t((k + 1) % 3)], t[size_t(k)]));
          if (it == edgeFace.end() || isVisible[size_t(it->second)]) continue;
          if (dist(it->second, p) > eps) {
            isVisible[size_t(it->second)] = 1;
            stack.push_back(it->second);
          }
        }
      }
      // The rim: edges of visible faces whose other face is not visible; the new faces continue
      // the visible faces' winding.
      std::vector<std::pair<int, int>> rim;
      orphans.clear();
      for (int f : visible) {
        const Tri3& t = faces[size_t(f)];
        for (int k = 0; k < 3; ++k) {
          const int a = t[size_t(k)], b = t[size_t((k + 1) % 3)];
          const auto it = edgeFace.find(key(b, a));
          if (it == edgeFace.end() || !isVisible[size_t(it->second)]) rim.emplace_back(a, b);
        }
        for (int q : outside[size_t(f)])
          if (q != pi) orphans.push_back(q);
        outside[size_t(f)].clear();
      }
      for (int f : visible) {
        alive[size_t(f)] = 0;
        const Tri3& t = faces[size_t(f)];
        for (int k = 0; k < 3; ++k) {
          const auto it = edgeFace.find(key(t[size_t(k)], t[size_t((k + 1) % 3)]));
          if (it != edgeFace.end() && it->second == f) edgeFace.erase(it);
        }
      }
      added.clear();
      for (const auto& [a, b] : rim) added.push_back(addFace(a, b, pi, false));
      for (int q : orphans) assign(q, added);
    }
  }
  std::map<int, int> index;
  for (size_t f = 0; f < faces.size(); ++f) {
    if (!alive[f]) continue;
    Tri3 t;
    for (int k = 0; k < 3; ++k) {
      auto it = index.find(faces[f][k]);
      if (it == index.end()) {
        it = index.emplace(faces[f][k], int(hull.vertices.size())).first;
        hull.vertices.push_back(pts[faces[f][k]]);
      }
      t[k] = it->second;
    }
    hull.triangles.push_back(t);
  }
  return hull;
}

Vec3 centreOfMass(const TriangleMesh& mesh) {
  double volume = 0;
  Vec3 moment = Vec3::Zero(), mean = Vec3::Zero();
  for (const Vec3f& v : mesh.vertices) mean += v.cast<double>();
  if (!mesh.vertices.empty()) mean /= double(mesh.vertices.size());
  for (const Tri& t : mesh.triangles) {
    const Vec3 a = mesh.vertices[t[0]].cast<double>() - mean;
    const Vec3 b = mesh.vertices[t[1]].cast<double>() - mean;
    const Vec3 c = mesh.vertices[t[2]].cast<double>() - mean;
    const double v = a.dot(b.cross(c)) / 6;
    volume += v;
    moment += v * (a + b + c) / 4;
  }
  const double scale = mesh.bounds().size().prod();
  if (!(std::abs(volume) > 1e-6 * scale)) return mean;
  return mean + moment / volume;
}

std::vector<StablePose> stablePoses(const TriangleMesh& mesh) {
  std::vector<Vec3> points;
  for (const Vec3f& v : mesh.vertices) points.push_back(v.cast<double>());
  const ConvexHull hull = convexHull(points);
  if (hull.triangles.empty())
    throw Error("the mesh spans no volume (flat or fewer than 4 distinct points): no stable poses");
  // Hull triangle normals (outward).
  const size_t nt = hull.triangles.size();
  const double size = (mesh.bounds().size()).maxCoeff();
  std::vector<Vec3> n(nt);
  std::vector<double> d(nt);
  for (size_t t = 0; t < nt; ++t) {
    const auto& T = hull.triangles[t];
    n[t] = (hull.vertices[T[1]] - hull.vertices[T[0]])
               .cross(hull.vertices[T[2]] - hull.vertices[T[0]])
               .normalized();
  }
  // The centre of mass: of the enclosed solid when it lies inside the hull (a closed mesh), else
  // of the hull.
  Vec3 com = centreOfMass(mesh);
  bool inside = true;
  for (size_t t = 0; t < nt; ++t)
    if (n[t].dot(com - hull.vertices[hull.triangles[t][0]]) > 0) inside = false;
  if (!inside) {
    TriangleMesh h;
    for (const Vec3& v : hull.vertices) h.vertices.push_back(v.cast<float>());
    for (const auto& t : hull.triangles) h.triangles.push_back({t[0], t[1], t[2]});
    com = centreOfMass(h);
  }
  for (size_t t = 0; t < nt; ++t)  // distance of each plane from the COM
    d[t] = n[t].dot(hull.vertices[hull.triangles[t][0]] - com);
  // Facets: hull triangles merged over shared edges when coplanar (normals within 1e-4 rad,
  // planes within 1e-6 of the size).
  std::map<std::pair<int, int>, int> edgeFace;
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k)
      edgeFace[{hull.triangles[t][k], hull.triangles[t][(k + 1) % 3]}] = int(t);
  std::vector<int> facet(nt, -1);
  int facets = 0;
  for (size_t s = 0; s < nt; ++s) {
    if (facet[s] >= 0) continue;
    std::vector<int> stack{int(s)};
    facet[s] = facets;
    while (!stack.empty()) {
      const int t = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        auto it = edgeFace.find({hull.triangles[t][(k + 1) % 3], hull.triangles[t][k]});
        if (it == edgeFace.end() || facet[it->second] >= 0) continue;
        const int u = it->second;
        if (n[u].dot(n[s]) > 1 - 1e-8 && std::abs(d[u] - d[s]) < 1e-6 * size) {
          facet[u] = facets;
          stack.push_back(u);
        }
      }
    }
    ++facets;
  }
  // Per facet: probability (solid angle / 4π), normal, distance, and whether the COM's
  // projection lies inside; else the facet it rolls to (across the edge it lies beyond most).
  std::vector<double> prob(facets, 0.0), dist(facets, 0.0);
  std::vector<Vec3> fn(facets, Vec3::Zero());
  for (size_t t = 0; t < nt; ++t) {
    const auto& T = hull.triangles[t];
    prob[facet[t]] += solidAngle(hull.vertices[T[0]] - com, hull.vertices[T[1]] - com,
                                 hull.vertices[T[2]] - com) /
                      (4 * M_PI);
    fn[facet[t]] = n[t];
    dist[facet[t]] = d[t];
  }
  std::vector<int> rollsTo(facets, -1);  // -1: stable
  for (int f = 0; f < facets; ++f) {
    // Boundary edges of the facet; the projection p of the COM onto its plane.
    const Vec3 p = com + dist[f] * fn[f];
    double worst = 0;
    for (size_t t = 0; t < nt; ++t) {
      if (facet[t] != f) continue;
      for (int k = 0; k < 3; ++k) {
        const int a = hull.triangles[t][k], b = hull.triangles[t][(k + 1) % 3];
        auto it = edgeFace.find({b, a});
        if (it == edgeFace.end() || facet[it->second] == f) continue;
        // Outward in-plane direction of the edge; p beyond it by `out` metres.
        const Vec3 e = (hull.vertices[b] - hull.vertices[a]).normalized();
        const Vec3 outward = e.cross(fn[f]);
        const double out = outward.dot(p - hull.vertices[a]);
        if (out > worst + 1e-9 * size) {
          worst = out;
          rollsTo[f] = facet[it->second];
        }
      }
    }
  }
  // Carry unstable facets' probability down to where they come to rest.
  std::vector<double> rest(facets, 0.0);
  for (int f = 0; f < facets; ++f) {
    int g = f;
    for (int hops = 0; rollsTo[g] >= 0 && hops < facets; ++hops) g = rollsTo[g];
    if (rollsTo[g] >= 0) continue;  // a cycle (numerically degenerate): dropped
    rest[g] += prob[f];
  }
  // Merge adjacent stable facets of a neutral family (equal COM height, within 15°).
  std::vector<int> group(facets, -1);
  std::vector<StablePose> poses;
  std::vector<std::vector<int>> adjacent(facets);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      auto it = edgeFace.find({hull.triangles[t][(k + 1) % 3], hull.triangles[t][k]});
      if (it != edgeFace.end() && facet[it->second] != facet[t])
        adjacent[facet[t]].push_back(facet[it->second]);
    }
  std::vector<int> order(facets);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return rest[a] > rest[b]; });
  for (int s : order) {
    if (rollsTo[s] >= 0 || group[s] >= 0 || rest[s] <= 0) continue;
    StablePose pose;
    pose.down_O = fn[s];
    pose.height_m = dist[s];
    std::vector<int> stack{s};
    group[s] = int(poses.size());
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      pose.probability += rest[f];
      for (int g : adjacent[f]) {
        if (group[g] >= 0 || rollsTo[g] >= 0) continue;
        const double tol = std::max(1e-3, 0.01 * std::abs(dist[f]));
        if (std::abs(dist[g] - dist[f]) < tol && fn[g].dot(fn[f]) > std::cos(15 * M_PI / 180)) {
          group[g] = group[s];
          stack.push_back(g);
        }
      }
    }
    // The rotation taking down_O to −z (the shortest one).
    pose.R_B_O = Eigen::Quaterniond::FromTwoVectors(pose.down_O, -Vec3::UnitZ()).toRotationMatrix();
    poses.push_back(pose);
  }
  double total = 0;
  for (const StablePose& p : poses) total += p.probability;
  for (StablePose& p : poses) p.probability /= total;
  std::stable_sort(poses.begin(), poses.end(), [](const StablePose& a, const StablePose& b) {
    return a.probability > b.probability;
  });
  return poses;
}

}  // namespace inhand
