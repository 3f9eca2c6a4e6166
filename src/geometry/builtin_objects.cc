#include "inhand/geometry/builtin_objects.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"

namespace inhand {

namespace {

constexpr char kPrefix[] = "builtin:";

TriangleMesh centred(TriangleMesh m) {
  Vec3 c = m.bounds().center();
  for (Vec3f& v : m.vertices) v -= c.cast<float>();
  return m;
}

// A rounded corner in a revolution profile: points on a quarter circle of radius r about
// (cr, cz), from angle a0 to a1 (radians).
void arc(std::vector<Vec2>* p, double cr, double cz, double r, double a0, double a1, int steps) {
  for (int i = 0; i <= steps; ++i) {
    double a = a0 + (a1 - a0) * i / steps;
    p->emplace_back(cr + r * std::cos(a), cz + r * std::sin(a));
  }
}

// About 1 litre: body Ø 88 mm, shoulder, neck Ø 32 mm, cap Ø 36 mm; 245 mm tall.
TriangleMesh juiceBottle() {
  std::vector<Vec2> p{{0, 0}};
  arc(&p, 0.036, 0.008, 0.008, -M_PI / 2, 0, 4);  // rounded base edge, body radius 44 mm
  p.emplace_back(0.044, 0.165);
  // Shoulder: smooth transition from r = 44 mm at z = 165 mm to r = 16 mm at z = 205 mm.
  for (int i = 1; i <= 10; ++i) {
    double s = i / 10.0, w = 0.5 - 0.5 * std::cos(M_PI * s);
    p.emplace_back(0.044 + (0.016 - 0.044) * w, 0.165 + 0.040 * s);
  }
  p.emplace_back(0.016, 0.222);  // neck
  p.emplace_back(0.018, 0.222);  // cap
  p.emplace_back(0.018, 0.245);
  p.emplace_back(0.0, 0.245);
  return makeRevolution(p, 72);
}

// Ø 40 mm × 80 mm with a slightly wider cap.
TriangleMesh pillBottle() {
  std::vector<Vec2> p{{0, 0}};
  arc(&p, 0.016, 0.003, 0.003, -M_PI / 2, 0, 3);
  p.emplace_back(0.019, 0.060);
  p.emplace_back(0.020, 0.060);  // cap rim
  arc(&p, 0.018, 0.078, 0.002, 0, M_PI / 2, 3);
  p.emplace_back(0.0, 0.080);
  return makeRevolution(p, 64);
}

// A mug: Ø 80 mm × 90 mm cup, 4 mm wall, 6 mm base, and a ring handle with a through-hole.
// Built as one implicit solid (cup shell ∪ handle torus, minus the cavity) so it is a single
// closed surface.
TriangleMesh mug() {
  const double R = 0.040, H = 0.090, wall = 0.004, base = 0.006;
  const Vec3 handleCentre(R + 0.012, 0.0, H / 2);
  const double major = 0.026, minor = 0.0055;
  auto cylinder = [](const Vec3& p, double r, double z0, double z1) {
    double dr = std::hypot(p.x(), p.y()) - r;
    double dz = std::max(z0 - p.z(), p.z() - z1);
    Vec2 outside(std::max(dr, 0.0), std::max(dz, 0.0));
    return std::min(std::max(dr, dz), 0.0) + outside.norm();
  };
  auto sdf = [&](const Vec3& p) {
    double outer = cylinder(p, R, 0.0, H);
    double cavity = cylinder(p, R - wall, base, H + 0.01);
    Vec3 q = p - handleCentre;  // torus in the x–z plane (axis along y)
    double torus = Vec2(std::hypot(q.x(), q.z()) - major, q.y()).norm() - minor;
    return std::max(std::min(outer, torus), -cavity);
  };
  Aabb box;
  box.extend(Vec3(-R - 0.004, -R - 0.004, -0.004));
  box.extend(Vec3(handleCentre.x() + major + minor + 0.004, R + 0.004, H + 0.004));
  return meshImplicit(sdf, box, 0.0015);
}

}  // namespace

std::vector<std::string> builtinObjectNames() {
  return {"cracker_box", "coffee_can", "juice_bottle", "pill_bottle", "mug"};
}

bool isBuiltinSpec(const std::string& spec) { return spec.rfind(kPrefix, 0) == 0; }

TriangleMesh loadObject(const std::string& spec) {
  if (!isBuiltinSpec(spec)) return importMesh(spec);
  std::string name = spec.substr(sizeof(kPrefix) - 1);
  if (name == "cracker_box") return centred(makeBox(Vec3(0.060, 0.158, 0.210)));
  if (name == "coffee_can") return centred(makeCylinder(0.051, 0.139, 96));
  if (name == "juice_bottle") return centred(juiceBottle());
  if (name == "pill_bottle") return centred(pillBottle());
  if (name == "mug") return centred(mug());
  std::string names;
  for (const auto& n : builtinObjectNames()) names += (names.empty() ? "" : ", ") + n;
  throw Error("unknown built-in object '" + spec + "'; built-in objects are: " + names);
}

}  // namespace inhand
