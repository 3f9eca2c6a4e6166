#pragma once
// Closed, outward-oriented primitive meshes (metres), centred at the origin unless stated.
#include <functional>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

TriangleMesh makeBox(const Vec3& size_m);
// Cylinder along z, from z = -height/2 to +height/2.
TriangleMesh makeCylinder(double radius_m, double height_m, int segments = 64);
// Icosphere: 20 · 4^subdivisions triangles.
TriangleMesh makeSphere(double radius_m, int subdivisions = 4);
// Solid of revolution about z. `profile` is a polyline of (radius, z) from the bottom pole
// (radius 0) to the top pole (radius 0); interior points must have radius > 0.
TriangleMesh makeRevolution(const std::vector<Vec2>& profile, int segments = 64);

// Iso-surface f = 0 of an implicit function (negative inside) sampled on a grid of `spacing_m`
// over `box` (which must enclose the surface with a margin). Closed when f > 0 on the box border.
TriangleMesh meshImplicit(const std::function<double(const Vec3&)>& f, const Aabb& box,
                          double spacing_m);

}  // namespace inhand
