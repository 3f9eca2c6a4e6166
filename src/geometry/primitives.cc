#include "inhand/geometry/primitives.h"

#include <cmath>
#include <map>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/geometry/internal/contour.h"

namespace inhand {

namespace {
// Makes the mesh outward-oriented (positive signed volume).
void orientOutward(TriangleMesh* m) {
  if (m->signedVolume() < 0)
    for (Tri& f : m->triangles) std::swap(f[1], f[2]);
}
}  // namespace

TriangleMesh makeBox(const Vec3& size_m) {
  TriangleMesh m;
  Vec3 h = 0.5 * size_m;
  for (int i = 0; i < 8; ++i)
    m.vertices.emplace_back(float((i & 1) ? h.x() : -h.x()), float((i & 2) ? h.y() : -h.y()),
                            float((i & 4) ? h.z() : -h.z()));
  // Each face as a quad of corner indices, counter-clockwise from outside.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.emplace_back(q[0], q[1], q[2]);
    m.triangles.emplace_back(q[0], q[2], q[3]);
  }
  orientOutward(&m);
  return m;
}

TriangleMesh makeRevolution(const std::vector<Vec2>& profile, int segments) {
  INHAND_CHECK(profile.size() >= 3, "revolution profile needs at least 3 points");
  INHAND_CHECK(profile.front().x() == 0 && profile.back().x() == 0,
               "revolution profile must start and end on the axis");
  TriangleMesh m;
  const int rings = static_cast<int>(profile.size()) - 2;
  m.vertices.emplace_back(0.f, 0.f, float(profile.front().y()));  // bottom pole: 0
  for (int r = 0; r < rings; ++r) {
    const Vec2& p = profile[r + 1];
    for (int s = 0; s < segments; ++s) {
      double a = 2.0 * M_PI * s / segments;
      m.vertices.emplace_back(float(p.x() * std::cos(a)), float(p.x() * std::sin(a)), float(p.y()));
    }
  }
  const int top = static_cast<int>(m.vertices.size());
  m.vertices.emplace_back(0.f, 0.f, float(profile.back().y()));
  auto ring = [&](int r, int s) { return 1 + r * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) m.triangles.emplace_back(0, ring(0, s + 1), ring(0, s));
  for (int r = 0; r + 1 < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      m.triangles.emplace_back(ring(r, s), ring(r, s + 1), ring(r + 1, s + 1));
      m.triangles.emplace_back(ring(r, s), ring(r + 1, s + 1), ring(r + 1, s));
    }
  for (int s = 0; s < segments; ++s)
    m.triangles.emplace_back(top, ring(rings - 1, s), ring(rings - 1, s + 1));
  orientOutward(&m);
  return m;
}

TriangleMesh makeCylinder(double radius_m, double height_m, int segments) {
  double h = 0.5 * height_m;
  return makeRevolution({{0, -h}, {radius_m, -h}, {radius_m, h}, {0, h}}, segments);
}

TriangleMesh makeSphere(double radius_m, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& p : v) p.normalize();
  std::vector<Tri> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      int id = static_cast<int>(v.size()) - 1;
      mid.emplace(key, id);
      return id;
    };
    std::vector<Tri> next;
    for (const Tri& tri : f) {
      int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      next.insert(next.end(), {{tri[0], a, c}, {tri[1], b, a}, {tri[2], c, b}, {a, b, c}});
    }
    f = std::move(next);
  }
  TriangleMesh m;
  for (const Vec3& p : v) m.vertices.push_back((p * radius_m).cast<float>());
  m.triangles = std::move(f);
  orientOutward(&m);
  return m;
}

TriangleMesh meshImplicit(const std::function<double(const Vec3&)>& f, const Aabb& box,
                          double spacing_m) {
  ScalarGrid grid;
  grid.origin = box.min;
  grid.spacing = spacing_m;
  Vec3 extent = box.size() / spacing_m;
  grid.dims = Vec3i(int(std::ceil(extent.x())) + 1, int(std::ceil(extent.y())) + 1,
                    int(std::ceil(extent.z())) + 1);
  grid.values.resize(size_t(grid.dims.prod()));
  parallelFor(0, grid.dims.z(), [&](int z) {
    for (int y = 0; y < grid.dims.y(); ++y)
      for (int x = 0; x < grid.dims.x(); ++x)
        grid.values[grid.index(x, y, z)] = float(f(grid.point(x, y, z)));
  });
  return contour(grid).mesh;
}

}  // namespace inhand
