#include "inhand/geometry/stable_poses.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <optional>
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

namespace {
// Unique points (to 1e-7 of the extent), in a seeded random order (incremental hulls expect no
// adversarial order).
std::vector<Vec3> uniqueShuffled(const std::vector<Vec3>& input) {
  std::vector<Vec3> pts;
  Aabb b;
  for (const Vec3& p : input) b.extend(p);
  const double cell = std::max(1e-9, 1e-7 * b.size().maxCoeff());
  std::map<std::array<long long, 3>, bool> seen;
  for (const Vec3& p : input) {
    std::array<long long, 3> k{std::llround(p.x() / cell), std::llround(p.y() / cell),
                               std::llround(p.z() / cell)};
    if (seen.emplace(k, true).second) pts.push_back(p);
  }
  std::mt19937_64 rng(12345);
  std::shuffle(pts.begin(), pts.end(), rng);
  return pts;
}

// The initial tetrahedron spans as much as the points do (a flat one would make the inside
// point's side of its faces a matter of round-off): the lowest x, the farthest from it, the
// farthest from their line, the farthest from their plane. nullopt when the points are
// (nearly) collinear or coplanar.
std::optional<std::array<int, 4>> spanningTetrahedron(const std::vector<Vec3>& pts, double eps) {
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
  if (!(d1 > 1e3 * eps)) return std::nullopt;
  const Vec3 u = (pts[i1] - pts[i0]) / d1;
  const auto [i2, d2] = farthest([&](const Vec3& p) { return u.cross(p - pts[i0]).norm(); });
  if (!(d2 > 1e3 * eps)) return std::nullopt;
  const Vec3 n012 = (pts[i1] - pts[i0]).cross(pts[i2] - pts[i0]).normalized();
  const auto [i3, d3] = farthest([&](const Vec3& p) { return std::abs(n012.dot(p - pts[i0])); });
  if (!(d3 > 1e3 * eps)) return std::nullopt;
  return std::array<int, 4>{i0, i1, i2, i3};
}

// Quickhull: each face keeps the points outside it; the farthest of them is added next (so a
// point barely outside, where round-off decides visibility, comes last and is usually inside
// by then). Each directed edge (a, b) maps to the live face it bounds.
class Quickhull {
 public:
  Quickhull(const std::vector<Vec3>& pts, double eps, const std::array<int, 4>& tet)
      : pts_(pts),
        eps_(eps),
        inside_(0.25 * (pts[tet[0]] + pts[tet[1]] + pts[tet[2]] + pts[tet[3]])) {
    const auto [i0, i1, i2, i3] = tet;
    const std::vector<int> first{addFace(i0, i1, i2, true), addFace(i0, i1, i3, true),
                                 addFace(i0, i2, i3, true), addFace(i1, i2, i3, true)};
    for (size_t q = 0; q < pts.size(); ++q)
      if (int(q) != i0 && int(q) != i1 && int(q) != i2 && int(q) != i3) assign(int(q), first);
  }

  void run() {
    for (size_t f0 = 0; f0 < faces_.size(); ++f0)
      while (alive_[f0] && !outside_[f0].empty()) {
        // The farthest point outside this face, and every face it sees connected to this one.
        const std::vector<int>& out = outside_[f0];
        const int pi = *std::max_element(out.begin(), out.end(), [&](int a, int b) {
          return dist(int(f0), pts_[size_t(a)]) < dist(int(f0), pts_[size_t(b)]);
        });
        markVisible(int(f0), pts_[size_t(pi)]);
        replaceVisible(pi);
      }
  }

  // The live faces as a mesh of the points they use.
  ConvexHull mesh() const {
    ConvexHull hull;
    std::map<int, int> index;
    for (size_t f = 0; f < faces_.size(); ++f) {
      if (!alive_[f]) continue;
      Tri3 t;
      for (int k = 0; k < 3; ++k) {
        auto it = index.find(faces_[f][k]);
        if (it == index.end()) {
          it = index.emplace(faces_[f][k], int(hull.vertices.size())).first;
          hull.vertices.push_back(pts_[faces_[f][k]]);
        }
        t[k] = it->second;
      }
      hull.triangles.push_back(t);
    }
    return hull;
  }

 private:
  static uint64_t key(int a, int b) { return (uint64_t(uint32_t(a)) << 32) | uint32_t(b); }
  double dist(int f, const Vec3& p) const { return normal_[size_t(f)].dot(p) - offset_[size_t(f)]; }
  int addFace(int a, int b, int c, bool orient) {
    Vec3 n = (pts_[size_t(b)] - pts_[size_t(a)]).cross(pts_[size_t(c)] - pts_[size_t(a)]);
    if (orient && n.dot(pts_[size_t(a)] - inside_) < 0) {
      std::swap(b, c);
      n = -n;
    }
    const double len = n.norm();
    n = len > 0 ? Vec3(n / len) : Vec3::Zero();
    const int f = int(faces_.size());
    faces_.push_back({a, b, c});
    normal_.push_back(n);
    offset_.push_back(n.dot(pts_[size_t(a)]));
    alive_.push_back(1);
    outside_.emplace_back();
    edgeFace_[key(a, b)] = f;
    edgeFace_[key(b, c)] = f;
    edgeFace_[key(c, a)] = f;
    return f;
  }
  // Each point to the face (among `candidates`) it lies farthest outside of, if any.
  void assign(int q, const std::vector<int>& candidates) {
    int best = -1;
    double far = eps_;
    for (int f : candidates)
      if (const double d = dist(f, pts_[size_t(q)]); d > far) {
        far = d;
        best = f;
      }
    if (best >= 0) outside_[size_t(best)].push_back(q);
  }
  // visible_: the faces p sees, connected to f0 (isVisible_ marks them).
  void markVisible(int f0, const Vec3& p) {
    isVisible_.resize(faces_.size(), 0);
    visible_.clear();
    stack_.assign(1, f0);
    isVisible_[size_t(f0)] = 1;
    while (!stack_.empty()) {
      const int f = stack_.back();
      stack_.pop_back();
      visible_.push_back(f);
      for (int k = 0; k < 3; ++k) {
        const Tri3& t = faces_[size_t(f)];
        const auto it = edgeFace_.find(key(t[size_t((k + 1) % 3)], t[size_t(k)]));
        if (it == edgeFace_.end() || isVisible_[size_t(it->second)]) continue;
        if (dist(it->second, p) > eps_) {
          isVisible_[size_t(it->second)] = 1;
          stack_.push_back(it->second);
        }
      }
    }
  }
  // The visible faces replaced by a cone from point pi to their rim (edges of visible faces
  // whose other face is not visible; the new faces continue the visible faces' winding); the
  // points they kept assigned to the new faces.
  void replaceVisible(int pi) {
    std::vector<std::pair<int, int>> rim;
    orphans_.clear();
    for (int f : visible_) {
      const Tri3& t = faces_[size_t(f)];
      for (int k = 0; k < 3; ++k) {
        const int a = t[size_t(k)], b = t[size_t((k + 1) % 3)];
        const auto it = edgeFace_.find(key(b, a));
        if (it == edgeFace_.end() || !isVisible_[size_t(it->second)]) rim.emplace_back(a, b);
      }
      for (int q : outside_[size_t(f)])
        if (q != pi) orphans_.push_back(q);
      outside_[size_t(f)].clear();
    }
    for (int f : visible_) {
      alive_[size_t(f)] = 0;
      const Tri3& t = faces_[size_t(f)];
      for (int k = 0; k < 3; ++k) {
        const auto it = edgeFace_.find(key(t[size_t(k)], t[size_t((k + 1) % 3)]));
        if (it != edgeFace_.end() && it->second == f) edgeFace_.erase(it);
      }
    }
    added_.clear();
    for (const auto& [a, b] : rim) added_.push_back(addFace(a, b, pi, false));
    for (int q : orphans_) assign(q, added_);
  }

  const std::vector<Vec3>& pts_;
  double eps_;
  Vec3 inside_;
  std::vector<Tri3> faces_;
  std::vector<Vec3> normal_;
  std::vector<double> offset_;
  std::vector<uint8_t> alive_, isVisible_;
  std::vector<std::vector<int>> outside_;
  std::unordered_map<uint64_t, int> edgeFace_;
  std::vector<int> visible_, stack_, orphans_, added_;
};
}  // namespace

ConvexHull convexHull(const std::vector<Vec3>& input) {
  const std::vector<Vec3> pts = uniqueShuffled(input);
  if (pts.size() < 4) return {};
  Aabb box;
  for (const Vec3& p : pts) box.extend(p);
  const double eps = 1e-9 * std::max(1e-6, box.size().maxCoeff());
  const std::optional<std::array<int, 4>> tet = spanningTetrahedron(pts, eps);
  if (!tet) return {};
  Quickhull q(pts, eps, *tet);
  q.run();
  return q.mesh();
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

namespace {
// The centre of mass: of the enclosed solid when it lies inside the hull (a closed mesh), else
// of the hull (n: the hull triangles' outward normals).
Vec3 solidCentre(const TriangleMesh& mesh, const ConvexHull& hull, const std::vector<Vec3>& n) {
  const Vec3 com = centreOfMass(mesh);
  bool inside = true;
  for (size_t t = 0; t < n.size(); ++t)
    if (n[t].dot(com - hull.vertices[hull.triangles[t][0]]) > 0) inside = false;
  if (inside) return com;
  TriangleMesh h;
  for (const Vec3& v : hull.vertices) h.vertices.push_back(v.cast<float>());
  for (const auto& t : hull.triangles) h.triangles.push_back({t[0], t[1], t[2]});
  return centreOfMass(h);
}

// The hull's facets: its triangles merged over shared edges when coplanar (normals within
// 1e-4 rad, planes within 1e-6 of the size); per facet its probability (solid angle / 4π from
// the centre of mass), normal and distance from the centre of mass.
struct Facets {
  std::map<std::pair<int, int>, int> edgeFace;  // directed edge → the triangle it bounds
  std::vector<int> of;                          // each triangle's facet
  int count = 0;
  std::vector<double> prob, dist;
  std::vector<Vec3> normal;
};
Facets hullFacets(const ConvexHull& hull, const std::vector<Vec3>& n, const std::vector<double>& d,
                  const Vec3& com, double size) {
  const size_t nt = hull.triangles.size();
  Facets F;
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k)
      F.edgeFace[{hull.triangles[t][k], hull.triangles[t][(k + 1) % 3]}] = int(t);
  F.of.assign(nt, -1);
  for (size_t s = 0; s < nt; ++s) {
    if (F.of[s] >= 0) continue;
    std::vector<int> stack{int(s)};
    F.of[s] = F.count;
    while (!stack.empty()) {
      const int t = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        auto it = F.edgeFace.find({hull.triangles[t][(k + 1) % 3], hull.triangles[t][k]});
        if (it == F.edgeFace.end() || F.of[it->second] >= 0) continue;
        const int u = it->second;
        if (n[u].dot(n[s]) > 1 - 1e-8 && std::abs(d[u] - d[s]) < 1e-6 * size) {
          F.of[u] = F.count;
          stack.push_back(u);
        }
      }
    }
    ++F.count;
  }
  F.prob.assign(F.count, 0.0);
  F.dist.assign(F.count, 0.0);
  F.normal.assign(F.count, Vec3::Zero());
  for (size_t t = 0; t < nt; ++t) {
    const auto& T = hull.triangles[t];
    F.prob[F.of[t]] += solidAngle(hull.vertices[T[0]] - com, hull.vertices[T[1]] - com,
                                  hull.vertices[T[2]] - com) /
                       (4 * M_PI);
    F.normal[F.of[t]] = n[t];
    F.dist[F.of[t]] = d[t];
  }
  return F;
}

// Per facet: -1 when the centre of mass projects inside it (stable), else the facet it rolls
// to (across the edge the projection lies beyond most).
std::vector<int> rollTargets(const ConvexHull& hull, const Facets& F, const Vec3& com,
                             double size) {
  std::vector<int> rollsTo(F.count, -1);
  for (int f = 0; f < F.count; ++f) {
    // Boundary edges of the facet; the projection p of the COM onto its plane.
    const Vec3 p = com + F.dist[f] * F.normal[f];
    double worst = 0;
    for (size_t t = 0; t < hull.triangles.size(); ++t) {
      if (F.of[t] != f) continue;
      for (int k = 0; k < 3; ++k) {
        const int a = hull.triangles[t][k], b = hull.triangles[t][(k + 1) % 3];
        auto it = F.edgeFace.find({b, a});
        if (it == F.edgeFace.end() || F.of[it->second] == f) continue;
        // Outward in-plane direction of the edge; p beyond it by `out` metres.
        const Vec3 e = (hull.vertices[b] - hull.vertices[a]).normalized();
        const Vec3 outward = e.cross(F.normal[f]);
        const double out = outward.dot(p - hull.vertices[a]);
        if (out > worst + 1e-9 * size) {
          worst = out;
          rollsTo[f] = F.of[it->second];
        }
      }
    }
  }
  return rollsTo;
}

// The stable facets, most probable first, adjacent ones of a neutral family (equal centre of
// mass height, within 15°) merged into one pose; `rest`: each facet's probability with what
// rolls onto it.
std::vector<StablePose> neutralFamilies(const ConvexHull& hull, const Facets& F,
                                        const std::vector<int>& rollsTo,
                                        const std::vector<double>& rest) {
  std::vector<int> group(F.count, -1);
  std::vector<StablePose> poses;
  std::vector<std::vector<int>> adjacent(F.count);
  for (size_t t = 0; t < hull.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      auto it = F.edgeFace.find({hull.triangles[t][(k + 1) % 3], hull.triangles[t][k]});
      if (it != F.edgeFace.end() && F.of[it->second] != F.of[t])
        adjacent[F.of[t]].push_back(F.of[it->second]);
    }
  std::vector<int> order(F.count);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return rest[a] > rest[b]; });
  for (int s : order) {
    if (rollsTo[s] >= 0 || group[s] >= 0 || rest[s] <= 0) continue;
    StablePose pose;
    pose.down_O = F.normal[s];
    pose.height_m = F.dist[s];
    std::vector<int> stack{s};
    group[s] = int(poses.size());
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      pose.probability += rest[f];
      for (int g : adjacent[f]) {
        if (group[g] >= 0 || rollsTo[g] >= 0) continue;
        const double tol = std::max(1e-3, 0.01 * std::abs(F.dist[f]));
        if (std::abs(F.dist[g] - F.dist[f]) < tol &&
            F.normal[g].dot(F.normal[f]) > std::cos(15 * M_PI / 180)) {
          group[g] = group[s];
          stack.push_back(g);
        }
      }
    }
    // The rotation taking down_O to −z (the shortest one).
    pose.R_B_O = Eigen::Quaterniond::FromTwoVectors(pose.down_O, -Vec3::UnitZ()).toRotationMatrix();
    poses.push_back(pose);
  }
  return poses;
}
}  // namespace

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
  const Vec3 com = solidCentre(mesh, hull, n);
  for (size_t t = 0; t < nt; ++t)  // distance of each plane from the COM
    d[t] = n[t].dot(hull.vertices[hull.triangles[t][0]] - com);
  const Facets F = hullFacets(hull, n, d, com, size);
  const std::vector<int> rollsTo = rollTargets(hull, F, com, size);
  // Carry unstable facets' probability down to where they come to rest.
  std::vector<double> rest(F.count, 0.0);
  for (int f = 0; f < F.count; ++f) {
    int g = f;
    for (int hops = 0; rollsTo[g] >= 0 && hops < F.count; ++hops) g = rollsTo[g];
    if (rollsTo[g] >= 0) continue;  // a cycle (numerically degenerate): dropped
    rest[g] += F.prob[f];
  }
  std::vector<StablePose> poses = neutralFamilies(hull, F, rollsTo, rest);
  double total = 0;
  for (const StablePose& p : poses) total += p.probability;
  for (StablePose& p : poses) p.probability /= total;
  std::stable_sort(poses.begin(), poses.end(), [](const StablePose& a, const StablePose& b) {
    return a.probability > b.probability;
  });
  return poses;
}

}  // namespace inhand
