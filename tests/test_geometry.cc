#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <random>

#include "inhand/core/error.h"
#include "inhand/core/random.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/convex_decomposition.h"
#include "inhand/geometry/internal/box_overlap.h"
#include "inhand/geometry/internal/contour.h"
#include "inhand/geometry/internal/projector_shadows.h"
#include "inhand/geometry/internal/raster.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/geometry/stable_poses.h"
#include "test_util.h"

using namespace inhand;

namespace {
Mat3 randomRotation(Rng& rng) {
  std::normal_distribution<double> N(0, 1);
  return Eigen::Quaterniond(N(rng), N(rng), N(rng), N(rng)).normalized().toRotationMatrix();
}
}  // namespace

// The separating-axis test against vertex-in-box, edge-through-box and box-edge-through-triangle
// tests on random triangles near random boxes (both answers occur often).
TEST(BoxOverlap, SeparatingAxesAgreeWithEdgeAndVertexTests) {
  Rng rng = makeRng(11);
  std::uniform_real_distribution<double> U(-1, 1), S(0.05, 0.6);
  int overlaps = 0, separate = 0, vertexOutside = 0;
  for (int i = 0; i < 20000; ++i) {
    const Vec3 half(S(rng), S(rng), S(rng));
    // Triangles of every size: slivers, ones larger than the box, ones far off.
    const double scale = i % 3 == 0 ? 0.1 : (i % 3 == 1 ? 0.6 : 2.0);
    const Vec3 centre(U(rng), U(rng), U(rng));
    const Vec3 a = centre + scale * Vec3(U(rng), U(rng), U(rng)),
               b = centre + scale * Vec3(U(rng), U(rng), U(rng)),
               c = centre + scale * Vec3(U(rng), U(rng), U(rng));
    const bool fast = triangleOverlapsBox(a, b, c, half);
    ASSERT_EQ(fast, triangleOverlapsBoxReference(a, b, c, half))
        << "triangle " << a.transpose() << " | " << b.transpose() << " | " << c.transpose()
        << " box half " << half.transpose();
    (fast ? overlaps : separate)++;
    auto inside = [&](const Vec3& p) { return (p.cwiseAbs().array() <= half.array()).all(); };
    if (fast && !inside(a) && !inside(b) && !inside(c)) ++vertexOutside;
  }
  EXPECT_GT(overlaps, 2000);
  EXPECT_GT(separate, 3000);
  EXPECT_GT(vertexOutside, 1000);  // overlaps found through edges and faces, not only vertices
  // Exact cases: a large triangle through the box's middle with every vertex outside; one just
  // beyond a face; one beyond an edge, off every face's slab only diagonally.
  const Vec3 h(0.1, 0.2, 0.3);
  EXPECT_TRUE(triangleOverlapsBox(Vec3(-5, -5, 0), Vec3(5, -5, 0), Vec3(0, 5, 0), h));
  EXPECT_FALSE(triangleOverlapsBox(Vec3(-5, -5, 0.31), Vec3(5, -5, 0.31), Vec3(0, 5, 0.31), h));
  // The plane x + y = 0.31 passes the edge (0.1, 0.2, z) at distance 0.01/sqrt(2) outside.
  EXPECT_FALSE(triangleOverlapsBox(Vec3(0.31, 0, -5), Vec3(0.31, 0, 5), Vec3(0, 0.31, 0), h));
  EXPECT_TRUE(triangleOverlapsBox(Vec3(0.29, 0, -5), Vec3(0.29, 0, 5), Vec3(0, 0.29, 0), h));
}

// The hierarchy answers as the brute force does, for boxes at random poses about a mesh
// (inside it, across its surface, outside), and for a box wholly inside a closed mesh: no
// triangle meets it.
TEST(BoxOverlap, IndexMatchesBruteForceOnAMesh) {
  const TriangleMesh sphere = makeSphere(0.1, 4);
  const TriangleMesh mesh = [&] {
    TriangleMesh m = sphere;
    m.append(transformed(makeBox(Vec3(0.05, 0.3, 0.02)), Iso3(Eigen::Translation3d(0.12, 0, 0))));
    return m;
  }();
  const TriangleBoxIndex index(mesh);
  Rng rng = makeRng(12);
  std::uniform_real_distribution<double> U(-0.2, 0.2), S(0.002, 0.04);
  int hits = 0;
  for (int i = 0; i < 4000; ++i) {
    Iso3 T = Iso3::Identity();
    T.linear() = randomRotation(rng);
    T.translation() = Vec3(U(rng), U(rng), U(rng));
    const Vec3 half(S(rng), S(rng), S(rng));
    const bool fast = index.overlapsBox(T, half);
    ASSERT_EQ(fast, index.overlapsBoxReference(T, half)) << "box " << i;
    hits += fast;
  }
  EXPECT_GT(hits, 400);
  EXPECT_LT(hits, 3600);
  EXPECT_FALSE(index.overlapsBox(Iso3::Identity(), Vec3(0.05, 0.05, 0.05)));  // inside the sphere
  EXPECT_TRUE(index.overlapsBox(Iso3(Eigen::Translation3d(0.1, 0, 0)), Vec3(0.01, 0.01, 0.01)));
  EXPECT_FALSE(TriangleBoxIndex(TriangleMesh()).overlapsBox(Iso3::Identity(), Vec3::Ones()));
}

TEST(Primitives, ClosedWithExactVolumes) {
  TriangleMesh box = makeBox(Vec3(0.1, 0.2, 0.3));
  EXPECT_TRUE(box.isClosed());
  EXPECT_NEAR(box.signedVolume(), 0.006, 1e-8);
  EXPECT_NEAR(box.area(), 2 * (0.02 + 0.03 + 0.06), 1e-7);
  TriangleMesh cyl = makeCylinder(0.05, 0.1, 256);
  EXPECT_TRUE(cyl.isClosed());
  EXPECT_NEAR(cyl.signedVolume(), M_PI * 0.0025 * 0.1, 2e-4 * M_PI * 0.0025 * 0.1 * 10);
  TriangleMesh sphere = makeSphere(0.1, 5);
  EXPECT_TRUE(sphere.isClosed());
  EXPECT_NEAR(sphere.signedVolume(), 4.0 / 3.0 * M_PI * 1e-3, 1e-5);
}

// Holes closed: a box without its top and a cylinder without its caps become the closed solids
// they were (the fans face outwards: the same volume), a closed mesh stays as it is.
TEST(Primitives, HolesClosedGiveTheSolidBack) {
  // The mesh without its faces whose normal's z is above `z` (or below −z with both_ends).
  auto without = [](const TriangleMesh& m, double z, bool both_ends) {
    TriangleMesh out = m;
    out.triangles.clear();
    for (int t = 0; t < int(m.triangles.size()); ++t) {
      const double nz = m.faceNormal(t).z();
      if (!(nz > z || (both_ends && nz < -z))) out.triangles.push_back(m.triangles[t]);
    }
    return out;
  };
  const TriangleMesh open = without(makeBox(Vec3(0.1, 0.2, 0.3)), 0.99, false);
  ASSERT_EQ(open.boundaryEdgeCount(), 4);
  int loops = -1;
  const TriangleMesh boxClosed = withHolesClosed(open, &loops);
  EXPECT_EQ(loops, 1);
  EXPECT_TRUE(boxClosed.isClosed());
  EXPECT_NEAR(boxClosed.signedVolume(), 0.006, 1e-8);
  const TriangleMesh cyl = makeCylinder(0.05, 0.1, 64);
  const TriangleMesh tube = without(cyl, 0.99, true);
  ASSERT_EQ(tube.boundaryEdgeCount(), 128);
  const TriangleMesh cylClosed = withHolesClosed(tube, &loops);
  EXPECT_EQ(loops, 2);
  EXPECT_TRUE(cylClosed.isClosed());
  EXPECT_NEAR(cylClosed.signedVolume(), cyl.signedVolume(), 1e-9);
  const TriangleMesh same = withHolesClosed(cyl, &loops);
  EXPECT_EQ(loops, 0);
  EXPECT_EQ(same.vertices.size(), cyl.vertices.size());
  EXPECT_EQ(same.triangles.size(), cyl.triangles.size());
}

TEST(Contour, ImplicitSphereIsWatertightAndAccurate) {
  Aabb box;
  box.extend(Vec3::Constant(-0.06));
  box.extend(Vec3::Constant(0.06));
  TriangleMesh m = meshImplicit([](const Vec3& p) { return p.norm() - 0.05; }, box, 0.002);
  EXPECT_TRUE(m.isClosed());
  EXPECT_EQ(m.boundaryEdgeCount(), 0);
  double maxErr = 0;
  for (const Vec3f& v : m.vertices)
    maxErr = std::max(maxErr, std::abs(v.cast<double>().norm() - 0.05));
  EXPECT_LT(maxErr, 1e-4);  // linear interpolation of an exact distance field
  EXPECT_NEAR(m.signedVolume(), 4.0 / 3.0 * M_PI * 1.25e-4, 0.01 * 4.0 / 3.0 * M_PI * 1.25e-4);
}

TEST(Contour, TwoSeparateBlobsBothClosed) {
  Aabb box;
  box.extend(Vec3(-0.1, -0.05, -0.05));
  box.extend(Vec3(0.1, 0.05, 0.05));
  auto f = [](const Vec3& p) {
    return std::min((p - Vec3(-0.05, 0, 0)).norm() - 0.03, (p - Vec3(0.05, 0, 0)).norm() - 0.03);
  };
  TriangleMesh m = meshImplicit(f, box, 0.003);
  EXPECT_TRUE(m.isClosed());
  EXPECT_GT(m.signedVolume(), 0);
}

namespace {
ScalarGrid sampledGrid(const std::function<double(const Vec3&)>& f, double half, double h) {
  ScalarGrid g;
  const int n = int(std::ceil(2 * half / h)) + 1;
  g.dims = Vec3i::Constant(n);
  g.origin = Vec3::Constant(-half);
  g.spacing = h;
  g.values.resize(size_t(n) * n * n);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) g.values[g.index(x, y, z)] = float(f(g.point(x, y, z)));
  return g;
}
}  // namespace

TEST(Contour, SurfaceNetsSphereIsClosedOutwardAndWithinACell) {
  const double r = 0.05, h = 0.002;
  ScalarGrid g = sampledGrid([&](const Vec3& p) { return p.norm() - r; }, 0.06, h);
  ContourResult nets = surfaceNets(g);
  ContourResult tets = contour(g);
  const TriangleMesh& m = nets.mesh;
  EXPECT_TRUE(m.isClosed());
  EXPECT_EQ(m.boundaryEdgeCount(), 0);
  // Each vertex is the mean of crossings of its own cube: within half a cube diagonal of the
  // sphere, and (a convex surface) never farther out than the cube's crossings.
  double maxErr = 0;
  for (const Vec3f& v : m.vertices)
    maxErr = std::max(maxErr, std::abs(v.cast<double>().norm() - r));
  EXPECT_LT(maxErr, 0.5 * std::sqrt(3.0) * h);
  // Outward and close in volume (mean-of-crossings vertices sit slightly inside a convex body).
  const double exact = 4.0 / 3.0 * M_PI * r * r * r;
  EXPECT_NEAR(m.signedVolume(), exact, 0.02 * exact);
  // Every vertex knows its crossings (2 to 12 axis edges of its cube, each crossing zero).
  ASSERT_EQ(nets.first.size(), m.vertices.size() + 1);
  for (size_t k = 0; k < m.vertices.size(); ++k) {
    const uint32_t n = nets.first[k + 1] - nets.first[k];
    ASSERT_GE(n, 2u);
    ASSERT_LE(n, 12u);
    for (uint32_t s = nets.first[k]; s < nets.first[k + 1]; ++s) {
      const EdgeVertex& e = nets.sources[s];
      EXPECT_NE(g.values[e.a] < 0, g.values[e.b] < 0);
    }
  }
  // The point of it: far fewer triangles to ray cast than marching tetrahedra.
  EXPECT_LT(3 * m.triangles.size(), tets.mesh.triangles.size());
  EXPECT_EQ(tets.first.size(), tets.mesh.vertices.size() + 1);
}

TEST(Contour, VectorisedEdgeMasksGiveTheReferenceMeshBitForBit) {
  // Grids of every small size (the last sample of a row, the last row and the last slice have
  // no neighbour that way), blobs and noise, with exact zeros, −0 and NaN (none of them inside).
  std::mt19937 rng(24);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  int compared = 0;
  for (int trial = 0; trial < 60; ++trial) {
    ScalarGrid g;
    g.dims = Vec3i(2 + int(rng() % 19), 2 + int(rng() % 7), 2 + int(rng() % 5));
    if (trial == 0) g.dims = Vec3i(2, 2, 2);
    g.spacing = 0.002 + 0.001 * (trial % 3);
    g.origin = Vec3(0.01 * trial, -0.02, 0.03);
    g.values.resize(size_t(g.dims.prod()));
    const Vec3 centre(u(rng) * g.dims.x(), u(rng) * g.dims.y(), u(rng) * g.dims.z());
    for (int z = 0; z < g.dims.z(); ++z)
      for (int y = 0; y < g.dims.y(); ++y)
        for (int x = 0; x < g.dims.x(); ++x) {
          float v = trial % 2 ? u(rng) : float((Vec3(x, y, z) - centre).norm() - 3.0);
          const unsigned special = rng() % 16;
          if (special == 0) v = 0.f;
          if (special == 1) v = -0.f;
          if (special == 2) v = std::nanf("");
          g.values[g.index(x, y, z)] = v;
        }
    const ContourResult fast = contour(g), ref = contour(g, ContourOptions{false});
    ASSERT_EQ(fast.mesh.vertices.size(), ref.mesh.vertices.size()) << "trial " << trial;
    ASSERT_EQ(fast.mesh.triangles.size(), ref.mesh.triangles.size()) << "trial " << trial;
    ASSERT_EQ(fast.sources.size(), ref.sources.size());
    if (!fast.mesh.vertices.empty()) {  // (memcmp of no bytes still wants real pointers)
      EXPECT_EQ(0, std::memcmp(fast.mesh.vertices.data(), ref.mesh.vertices.data(),
                               fast.mesh.vertices.size() * sizeof(Vec3f)));
    }
    for (size_t k = 0; k < fast.sources.size(); ++k) {
      EXPECT_EQ(fast.sources[k].a, ref.sources[k].a);
      EXPECT_EQ(fast.sources[k].b, ref.sources[k].b);
    }
    EXPECT_TRUE(fast.mesh.triangles == ref.mesh.triangles) << "trial " << trial;
    EXPECT_TRUE(fast.first == ref.first);
    compared += !fast.mesh.triangles.empty();
  }
  EXPECT_GT(compared, 40);
}

TEST(Contour, SurfaceNetsAxisAlignedBoxHasTwoTrianglesPerCellFace) {
  // A box with faces midway between samples: every face cell gives exactly one quad.
  const double h = 0.01, a = 0.045;  // half-size: 4.5 cells
  ScalarGrid g = sampledGrid(
      [&](const Vec3& p) { return (p.cwiseAbs() - Vec3::Constant(a)).maxCoeff(); }, 0.07, h);
  TriangleMesh m = surfaceNets(g).mesh;
  EXPECT_TRUE(m.isClosed());
  // 9 × 9 sample edges cross on each face: 2 triangles each.
  EXPECT_EQ(m.triangles.size(), 6u * 9 * 9 * 2);
  // Faces are exact; sharp edges are cut by the mean of crossings: each of the 12 edges loses
  // at most h²/4 of cross-section (2.5·10⁻⁵ m² here) over its length.
  int onFace = 0;
  for (const Vec3f& v : m.vertices) {
    const Vec3 p = v.cast<double>().cwiseAbs();
    if ((p.array() < a - 0.5 * h).count() == 2) {  // a face vertex, away from edges
      EXPECT_NEAR(p.maxCoeff(), a, 1e-6);
      ++onFace;
    }
  }
  EXPECT_EQ(onFace, 6 * 8 * 8);  // 10 × 10 cubes cross each face; the outer ring is edge
  const double box = std::pow(2 * a, 3), chamfers = 12 * (2 * a) * (0.25 * h * h);
  EXPECT_LT(m.signedVolume(), box);
  EXPECT_GT(m.signedVolume(), box - chamfers);
}

TEST(BuiltinObjects, ClosedAtRealSize) {
  std::map<std::string, Vec3> size = {{"cracker_box", {0.060, 0.158, 0.210}},
                                      {"coffee_can", {0.102, 0.102, 0.139}},
                                      {"pill_bottle", {0.040, 0.040, 0.080}}};
  for (const std::string& name : builtinObjectNames()) {
    SCOPED_TRACE(name);
    TriangleMesh m = loadObject("builtin:" + name);
    EXPECT_TRUE(m.isClosed());
    EXPECT_GT(m.signedVolume(), 0);
    EXPECT_LT(m.bounds().center().norm(), 1e-6);
    if (size.count(name)) {
      EXPECT_LT((m.bounds().size() - size[name]).cwiseAbs().maxCoeff(), 1e-4);
    }
  }
  // Juice bottle: about one litre.
  double litres = loadObject("builtin:juice_bottle").signedVolume() * 1000;
  EXPECT_GT(litres, 0.9);
  EXPECT_LT(litres, 1.3);
  EXPECT_THROW(loadObject("builtin:teapot"), Error);
}

TEST(BuiltinObjects, MugHandleHasAThroughHole) {
  TriangleMesh mug = loadObject("builtin:mug");
  RayScene scene;
  scene.addMesh(mug);
  scene.commit();
  // A ray along y through the middle of the handle's opening (between the cup wall and the
  // handle's far side) must pass; rays through the cup body must hit.
  Aabb b = mug.bounds();
  const double cupRight = b.min.x() + 0.080;  // cup is Ø 80 mm, the handle sticks out in +x
  Ray through;
  through.origin = Vec3f(float(cupRight + 0.012), -0.2f, float(b.center().z()));
  through.dir = Vec3f(0, 1, 0);
  EXPECT_FALSE(scene.intersectOne(through).valid());
  Ray body = through;
  body.origin.x() = float(b.min.x() + 0.04);
  EXPECT_TRUE(scene.intersectOne(body).valid());
  Ray handle = through;
  handle.origin.z() = float(b.center().z() + 0.026);  // the top of the ring
  EXPECT_TRUE(scene.intersectOne(handle).valid());
}

TEST(MeshIo, PlyRoundTripKeepsVarianceAndColour) {
  test::TempDir dir;
  TriangleMesh m = makeSphere(0.05, 2);
  std::vector<float> var(m.vertices.size());
  for (size_t i = 0; i < var.size(); ++i) var[i] = float(1e-7 * (i + 1));
  var[0] = 0.0025f;
  writePly(dir.path() / "m.ply", m, &var);
  PlyData back = readPly(dir.path() / "m.ply");
  ASSERT_EQ(back.mesh.vertices.size(), m.vertices.size());
  ASSERT_EQ(back.mesh.triangles.size(), m.triangles.size());
  for (size_t i = 0; i < var.size(); ++i) {
    EXPECT_EQ(back.mesh.vertices[i], m.vertices[i]);
    EXPECT_EQ(back.vertexProperties["variance"][i], var[i]);
  }
  EXPECT_EQ(back.mesh.triangles, m.triangles);
  EXPECT_EQ(back.vertexProperties["red"][0], 220);  // σ = 5 cm: red
  EXPECT_EQ(back.vertexProperties["green"][0], 20);
  // assimp reads the same file.
  TriangleMesh viaAssimp = importMesh(dir.path() / "m.ply");
  EXPECT_EQ(viaAssimp.triangles.size(), m.triangles.size());
}

// readPly over the value types, list count types and byte orders of the format, with an element
// it does not use between vertices and faces and a quad split in two: the same mesh and vertex
// properties from ASCII, little- and big-endian bodies.
TEST(MeshIo, PlyReaderTakesEveryTypeAndByteOrder) {
  test::TempDir dir;
  for (const std::string format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    const bool big = format == "binary_big_endian";
    std::string body;
    auto put = [&](auto v) {
      if (format == "ascii") {
        body += std::to_string(v) + " ";
        return;
      }
      char b[sizeof(v)];
      std::memcpy(b, &v, sizeof(v));
      if (big) std::reverse(b, b + sizeof(v));
      body.append(b, sizeof(v));
    };
    for (int i = 0; i < 4; ++i) {
      put(float(0.5f * float(i)));
      put(double(-1.25 * i));
      put(int16_t(-3 * i));
      put(uint8_t(10 * i));
      put(int32_t(-100000 * i));
      put(uint16_t(7 * i));
      if (format == "ascii") body += "\n";
    }
    put(int32_t(1));  // the edge
    put(int8_t(-2));
    if (format == "ascii") body += "\n";
    put(uint16_t(4));  // the quad
    for (uint32_t k : {0u, 1u, 2u, 3u}) put(k);
    put(uint16_t(3));  // a triangle
    for (uint32_t k : {3u, 2u, 1u}) put(k);
    const std::string header = "ply\nformat " + format +
                               " 1.0\nelement vertex 4\nproperty float x\nproperty double "
                               "y\nproperty short z\nproperty uchar intensity\nproperty int "
                               "q\nproperty ushort n\nelement edge 1\nproperty int a\nproperty "
                               "char b\nelement face 2\nproperty list ushort uint "
                               "vertex_indices\nend_header\n";
    const std::filesystem::path f = dir.path() / (format + ".ply");
    std::ofstream(f, std::ios::binary) << header << body;
    const PlyData d = readPly(f);
    ASSERT_EQ(d.mesh.vertices.size(), 4u) << format;
    for (int i = 0; i < 4; ++i) {
      EXPECT_EQ(d.mesh.vertices[size_t(i)], Vec3f(0.5f * float(i), float(-1.25 * i), float(-3 * i)))
          << format;
      EXPECT_EQ(d.vertexProperties.at("intensity")[size_t(i)], float(10 * i)) << format;
      EXPECT_EQ(d.vertexProperties.at("q")[size_t(i)], float(-100000 * i)) << format;
      EXPECT_EQ(d.vertexProperties.at("n")[size_t(i)], float(7 * i)) << format;
    }
    EXPECT_EQ(d.vertexProperties.size(), 3u) << format;
    const std::vector<Tri> tris = {Tri(0, 1, 2), Tri(0, 2, 3), Tri(3, 2, 1)};
    EXPECT_EQ(d.mesh.triangles, tris) << format;
    // Cut one byte short (a binary body) or one number short (ASCII): refused.
    const std::string cut = header + body.substr(0, body.size() - (format == "ascii" ? 2 : 1));
    std::ofstream(f, std::ios::binary | std::ios::trunc) << cut;
    EXPECT_THROW(readPly(f), Error) << format;
  }
  // A type the format does not have, as a value or a list's count: refused, naming the line.
  for (const std::string prop :
       {"property float128 x", "property list uint128 int vertex_indices"}) {
    const std::filesystem::path f = dir.path() / "odd.ply";
    std::ofstream(f, std::ios::binary | std::ios::trunc)
        << "ply\nformat ascii 1.0\nelement vertex 1\n"
        << prop << "\nend_header\n1\n";
    try {
      readPly(f);
      ADD_FAILURE() << prop;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(prop), std::string::npos) << e.what();
    }
  }
}

TEST(MeshIo, ConfidenceColourRunsGreyToRed) {
  auto grey = confidenceColor(1e-8f), red = confidenceColor(0.0025f), mid = confidenceColor(1e-5f);
  EXPECT_EQ(grey[0], grey[1]);
  EXPECT_EQ(red[0], 220);
  EXPECT_GT(mid[0], mid[1]);
  EXPECT_LT(mid[0], 220);
}

TEST(MeshIo, StlIsWeldedAndBadFilesNamed) {
  test::TempDir dir;
  // ASCII STL of a tetrahedron: 4 facets, 12 corner copies of 4 points.
  std::ofstream stl(dir.path() / "t.stl");
  const char* facets[4][3] = {{"0 0 0", "0 1 0", "1 0 0"},
                              {"0 0 0", "1 0 0", "0 0 1"},
                              {"0 0 0", "0 0 1", "0 1 0"},
                              {"1 0 0", "0 1 0", "0 0 1"}};
  stl << "solid t\n";
  for (auto& f : facets) {
    stl << "facet normal 0 0 0\nouter loop\n";
    for (auto* v : f) stl << "vertex " << v << "\n";
    stl << "endloop\nendfacet\n";
  }
  stl << "endsolid t\n";
  stl.close();
  TriangleMesh t = importMesh(dir.path() / "t.stl");
  EXPECT_EQ(t.vertices.size(), 4u);
  EXPECT_TRUE(t.isClosed());
  std::ofstream(dir.path() / "garbage.obj") << "this is not a mesh\n";
  EXPECT_THROW(importMesh(dir.path() / "garbage.obj"), Error);
  try {
    importMesh(dir.path() / "missing.obj");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing.obj"), std::string::npos);
  }
}

// Every shared mesh loads with the bounding box SOURCES.md lists.
TEST(MeshIo, SharedObjectsLoadWithListedBoundingBoxes) {
  const std::filesystem::path dir = INHAND_SHARED_OBJECTS;
  if (!std::filesystem::is_directory(dir))
    GTEST_SKIP() << "shared objects not found at " << dir << " (they are not part of the project)";
  const std::map<std::string, Vec3> listed = {{"002_master_chef_can.obj", {0.1023, 0.1024, 0.1401}},
                                              {"003_cracker_box.obj", {0.0717, 0.1640, 0.2135}},
                                              {"005_tomato_soup_can.obj", {0.0679, 0.0678, 0.1020}},
                                              {"006_mustard_bottle.obj", {0.0964, 0.0581, 0.1915}},
                                              {"009_gelatin_box.obj", {0.0715, 0.0675, 0.0892}},
                                              {"010_potted_meat_can.obj", {0.1011, 0.0900, 0.0845}},
                                              {"035_power_drill.obj", {0.1630, 0.1232, 0.1874}},
                                              {"019_pitcher_base.obj", {0.1887, 0.1331, 0.2424}},
                                              {"021_bleach_cleanser.obj", {0.0677, 0.1024, 0.2506}},
                                              {"025_mug.obj", {0.1169, 0.0932, 0.0813}},
                                              {"stanford_bunny.obj", {0.1557, 0.1543, 0.1207}}};
  int found = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".obj") continue;
    const std::string name = entry.path().filename().string();
    SCOPED_TRACE(name);
    ASSERT_TRUE(listed.count(name)) << "not listed in this test";
    TriangleMesh m = importMesh(entry.path());
    EXPECT_GT(m.triangles.size(), 10000u);
    EXPECT_LT((m.bounds().size() - listed.at(name)).cwiseAbs().maxCoeff(), 1e-4);
    ++found;
  }
  EXPECT_EQ(found, int(listed.size()));
}

TEST(RayScene, PacketsMatchScalarReferenceAndAnalyticSphere) {
  const double r = 0.1;
  RayScene scene;
  scene.addMesh(makeSphere(r, 6));
  scene.commit();
  Rng rng = makeRng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  // Some rays start past the near side or end before it (the packets carry tnear and tfar);
  // the last packet is a partial one.
  std::vector<Ray> rays(5003);
  for (size_t i = 0; i < rays.size(); ++i) {
    Ray& ray = rays[i];
    Vec3 o = Vec3(U(rng), U(rng), U(rng)).normalized() * 0.5;
    Vec3 target = Vec3(U(rng), U(rng), U(rng)) * 0.12;
    ray.origin = o.cast<float>();
    ray.dir = (target - o).normalized().cast<float>();
    if (i % 3 == 1) ray.tnear = 0.45f;
    if (i % 5 == 2) ray.tfar = 0.42f;
  }
  std::vector<Hit> hits(rays.size());
  scene.intersect(rays.data(), hits.data(), rays.size());
  int hitCount = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    Hit ref = scene.intersectOne(rays[i]);
    ASSERT_EQ(hits[i].valid(), ref.valid());
    if (!ref.valid()) continue;
    ++hitCount;
    EXPECT_EQ(hits[i].triangle, ref.triangle);
    EXPECT_FLOAT_EQ(hits[i].t, ref.t);
    // Analytic ray–sphere intersection (the mesh is inscribed: error < r(1 − cos(edge angle/2))).
    Vec3 o = rays[i].origin.cast<double>(), d = rays[i].dir.cast<double>();
    double b = o.dot(d), c = o.squaredNorm() - r * r, disc = b * b - c;
    if (disc < 0.04 * r * r) continue;  // near grazing: the tessellation decides
    const double t =
        -b - std::sqrt(disc) >= rays[i].tnear ? -b - std::sqrt(disc) : -b + std::sqrt(disc);
    EXPECT_NEAR(ref.t, t, 1e-4);
  }
  EXPECT_GT(hitCount, 1000);
  std::vector<uint8_t> blocked(rays.size());
  scene.occluded(rays.data(), blocked.data(), rays.size());
  for (size_t i = 0; i < rays.size(); ++i) EXPECT_EQ(bool(blocked[i]), hits[i].valid());
}

TEST(RayScene, InstanceMatchesTransformedCopy) {
  TriangleMesh box = makeBox(Vec3(0.1, 0.2, 0.3));
  Iso3 T = Iso3(Eigen::Translation3d(0.3, -0.1, 0.2)) *
           Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized());
  RayScene inner;
  inner.addMesh(box);
  inner.commit();
  RayScene viaInstance, viaCopy;
  viaInstance.addMesh(makeSphere(0.01, 1), Iso3(Eigen::Translation3d(5, 5, 5)));  // id 0
  EXPECT_EQ(viaInstance.addInstance(inner, T), 1);
  viaInstance.commit();
  viaCopy.addMesh(box, T);
  viaCopy.commit();
  Rng rng = makeRng(2);
  std::uniform_real_distribution<double> U(-1, 1);
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    Ray r;
    r.origin = Vec3f(1.0f, float(U(rng)) * 0.1f, float(U(rng)) * 0.1f);
    r.dir = (T.translation().cast<float>() +
             Vec3f(float(U(rng)), float(U(rng)), float(U(rng))) * 0.1f - r.origin)
                .normalized();
    Hit a = viaInstance.intersectOne(r), b = viaCopy.intersectOne(r);
    ASSERT_EQ(a.valid(), b.valid());
    if (!a.valid()) continue;
    ++hits;
    EXPECT_EQ(a.geometry, 1);
    EXPECT_EQ(a.inner, 0);
    EXPECT_EQ(a.triangle, b.triangle);
    EXPECT_NEAR(a.t, b.t, 1e-5);
    EXPECT_GT(a.normal.normalized().dot(b.normal.normalized()), 0.9999f);
  }
  EXPECT_GT(hits, 500);
}

TEST(SurfaceSamples, CoverACoarseBoxOnItsSurfaceWithOutwardNormals) {
  TriangleMesh box = makeBox(Vec3(0.1, 0.2, 0.3));
  std::vector<SurfacePoint> s = surfaceSamples(box, 0.02);
  ASSERT_GT(s.size(), 100u);
  int perFace[6] = {0, 0, 0, 0, 0, 0};
  const Vec3 half(0.05, 0.1, 0.15);
  for (const SurfacePoint& p : s) {
    // On the surface: inside the box, and on (at least) one face plane.
    double onFace = ((p.p.cwiseAbs() - half).cwiseAbs()).minCoeff();
    EXPECT_LT(onFace, 1e-6);
    EXPECT_TRUE((p.p.cwiseAbs().array() <= half.array() + 1e-6).all());
    EXPECT_NEAR(p.n.norm(), 1.0, 1e-9);
    EXPECT_GT(p.n.dot(p.p), 0.0);  // outward
    for (int a = 0; a < 3; ++a)
      if (std::abs(std::abs(p.p[a]) - half[a]) < 1e-6 && std::abs(p.n[a]) > 0.99)
        ++perFace[2 * a + (p.p[a] > 0)];
  }
  for (int f = 0; f < 6; ++f) EXPECT_GT(perFace[f], 10) << f;
}

// About one point per spacing² of area whatever the tessellation: a cylinder of 256 long slivers
// and one of 16 faces get about the same count, and so the area over the spacing squared (the
// lattice of surfaceSamples puts (L/s)²/2 points on every sliver of length L).
TEST(SurfaceSamples, EvenSamplesFollowTheAreaNotTheTriangles) {
  const double r = 0.02, h = 0.3, s = 0.005;
  const double area = 2 * M_PI * r * h + 2 * M_PI * r * r;
  std::vector<size_t> counts;
  for (int segments : {16, 256}) {
    const TriangleMesh cyl = makeCylinder(r, h, segments);
    const std::vector<SurfacePoint> e = evenSurfaceSamples(cyl, s);
    counts.push_back(e.size());
    EXPECT_GT(double(e.size()), 0.6 * area / (s * s)) << segments;
    EXPECT_LT(double(e.size()), 1.5 * area / (s * s)) << segments;
    for (const SurfacePoint& p : e) {
      const double radial = p.p.head<2>().norm();
      const bool side = std::abs(radial - r) < 1e-3 * r + r * (1 - std::cos(M_PI / segments));
      const bool cap = std::abs(std::abs(p.p.z()) - 0.5 * h) < 1e-6 && radial <= r + 1e-6;
      EXPECT_TRUE(side || cap) << p.p.transpose();
      EXPECT_NEAR(p.n.norm(), 1.0, 1e-9);
      if (cap)
        EXPECT_GT(p.n.z() * p.p.z(), 0.0);
      else
        EXPECT_GT(p.n.head<2>().dot(p.p.head<2>()), 0.0);
    }
  }
  EXPECT_LT(std::abs(double(counts[0]) - double(counts[1])), 0.25 * double(counts[1]));
  EXPECT_GT(surfaceSamples(makeCylinder(r, h, 256), s).size(), 10 * counts[1]);
  // A 1 mm plate keeps both faces.
  const std::vector<SurfacePoint> plate = evenSurfaceSamples(makeBox(Vec3(0.1, 0.1, 0.001)), s);
  int up = 0, down = 0;
  for (const SurfacePoint& p : plate) {
    up += p.n.z() > 0.99;
    down += p.n.z() < -0.99;
  }
  EXPECT_GT(up, 0.8 * 0.01 / (s * s));
  EXPECT_GT(down, 0.8 * 0.01 / (s * s));
  EXPECT_TRUE(evenSurfaceSamples(makeBox(Vec3(0.1, 0.1, 0.1)), 0.0).empty());
}

// ---- rasteriser ---------------------------------------------------------------------------------

namespace {

// Compares the rasteriser with one Embree ray per sample (ray through the sample pixel, camera
// at the origin looking along +z): returns the fraction of samples where one hits and the other
// does not, or both hit at depths more than 1e-5 apart (on a shared edge either triangle may be
// reported, at the same depth).
double rasterDisagreement(const TriangleMesh& mesh, const Iso3& T_C_mesh, const RasterWindow& w,
                          bool cull, int* hitSamples) {
  const PinholeProjection K{525, 525, 319.5, 239.5};
  DepthRaster r;
  r.reset(K, w);
  r.draw(mesh, T_C_mesh, 0, cull);
  RayScene scene;
  scene.addMesh(mesh, T_C_mesh);
  scene.commit();
  int differ = 0, n = 0, hits = 0;
  for (int j = w.j0; j <= w.j1; ++j)
    for (int i = w.i0; i <= w.i1; ++i) {
      Ray ray;
      ray.dir =
          Vec3f(float((i * w.stride - K.cx) / K.fx), float((j * w.stride - K.cy) / K.fy), 1.f);
      const Hit h = scene.intersectOne(ray);
      const int s = r.index(i, j);
      ++n;
      if (h.valid() != (r.id(s) >= 0) ||
          (h.valid() && std::abs(1.0 / r.inverseDepth(s) - h.t) > 1e-5 * h.t)) {
        ++differ;
        continue;
      }
      hits += h.valid();
    }
  *hitSamples = hits;
  return double(differ) / n;
}

}  // namespace

TEST(Raster, FirstTriangleAndDepthMatchRayCasting) {
  // A sphere of small triangles and a box of large ones, turned, 0.6 m in front of the camera.
  const Iso3 T = Iso3(Eigen::Translation3d(0.02, -0.01, 0.6)) *
                 Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized());
  const RasterWindow full{0, 639, 0, 479, 1};
  int hits = 0;
  for (const TriangleMesh& m : {makeSphere(0.1, 5), makeBox(Vec3(0.2, 0.1, 0.15))}) {
    EXPECT_LT(rasterDisagreement(m, T, full, false, &hits), 1e-3);
    EXPECT_GT(hits, 10000);
    // Closed and outward: culling back faces changes nothing.
    EXPECT_LT(rasterDisagreement(m, T, full, true, &hits), 1e-3);
    EXPECT_GT(hits, 10000);
  }
  // A window and a stride: samples at (i·3, j·3).
  const RasterWindow part{40, 150, 30, 120, 3};
  EXPECT_LT(rasterDisagreement(makeSphere(0.1, 5), T, part, false, &hits), 1e-3);
  EXPECT_GT(hits, 2000);
}

TEST(Raster, TrianglesCrossingTheNearPlaneAreClipped) {
  // A floor 10 cm below the camera reaching from behind it to 3 m ahead: its triangles cross
  // the near plane; only the part in front may be drawn, at the right depth.
  TriangleMesh floor;
  floor.vertices = {Vec3f(-2, 0.1f, -1), Vec3f(2, 0.1f, -1), Vec3f(2, 0.1f, 3.05f),
                    Vec3f(-2, 0.1f, 3.05f)};  // (3 m would put a row exactly on the far edge)
  floor.triangles = {Tri(0, 2, 1), Tri(0, 3, 2)};
  int hits = 0;
  EXPECT_LT(rasterDisagreement(floor, Iso3::Identity(), {0, 639, 0, 479, 1}, false, &hits), 1e-3);
  EXPECT_GT(hits, 100000);  // the lower half of the image, less the rows beyond 3 m
  // Entirely behind the camera: nothing drawn.
  DepthRaster r;
  r.reset({525, 525, 319.5, 239.5}, {0, 639, 0, 479, 1});
  r.draw(floor, Iso3(Eigen::Translation3d(0, 0, -4)));
  for (int s = 0; s < 640 * 480; s += 97) EXPECT_EQ(r.id(s), -1);
}

namespace {

// Projector shadows against Embree shadow rays on a scene of a sphere of small triangles in
// front of a box, and a strip 0.4 samples wide (an open mesh, narrower than a sample: a shadow
// map would miss it) slanted across the rows in front of both. Every sample's first surface is
// a point; the projector sits 7.5 cm to the right. Returns the fraction of points on which the
// two disagree; counts the points and the blocked ones.
double shadowDisagreement(const RasterWindow& w, int* points, int* blocked) {
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const Vec3 projector(0.075, 0, 0);
  const Iso3 T_sphere = Iso3(Eigen::Translation3d(0.03, 0.0, 0.55)) *
                        Eigen::AngleAxisd(0.4, Vec3(1, 1, 0).normalized());
  const Iso3 T_box = Iso3(Eigen::Translation3d(0, 0, 0.85));
  const TriangleMesh sphere = makeSphere(0.08, 5), box = makeBox(Vec3(0.6, 0.5, 0.05));
  TriangleMesh strip;
  const double z = 0.45, width = 0.4 * w.stride * z / K.fx;  // 0.4 samples at its depth
  strip.vertices = {Vec3f(-0.1f, -0.15f, float(z)), Vec3f(float(-0.1 + width), -0.15f, float(z)),
                    Vec3f(float(-0.08 + width), 0.15f, float(z)), Vec3f(-0.08f, 0.15f, float(z))};
  strip.triangles = {Tri(0, 2, 1), Tri(0, 3, 2)};
  DepthRaster first;
  first.reset(K, w);
  first.draw(sphere, T_sphere, 0, true);
  first.draw(box, T_box, 0, true);
  first.draw(strip, Iso3::Identity(), 0, false);
  RayScene scene;
  scene.addMesh(sphere, T_sphere);
  scene.addMesh(box, T_box);
  scene.addMesh(strip);
  scene.commit();
  ProjectorShadows shadows;
  shadows.reset(K, w, projector.x());
  std::vector<Ray> rays;
  constexpr double margin = 2e-4;
  for (int j = w.j0; j <= w.j1; ++j)
    for (int i = w.i0; i <= w.i1; ++i) {
      const int s = first.index(i, j);
      if (first.id(s) < 0) continue;
      const double iz = first.inverseDepth(s);
      const Vec3 p = Vec3((i * w.stride - K.cx) / K.fx, (j * w.stride - K.cy) / K.fy, 1) / iz;
      const double dist = (projector - p).norm();
      shadows.add(j, i, iz, iz / (1 - margin / dist));
      Ray r;
      r.origin = p.cast<float>();
      r.dir = ((projector - p) / dist).cast<float>();
      r.tnear = float(margin);
      r.tfar = float(dist - margin);
      rays.push_back(r);
    }
  shadows.index();
  shadows.draw(sphere, T_sphere, true);
  shadows.draw(box, T_box, true);
  shadows.draw(strip, Iso3::Identity(), false);
  std::vector<uint8_t> occluded(rays.size());
  scene.occluded(rays.data(), occluded.data(), rays.size(), false);
  int differ = 0;
  *blocked = 0;
  for (int k = 0; k < shadows.size(); ++k) {
    differ += shadows.blocked(k) != (occluded[size_t(k)] != 0);
    *blocked += shadows.blocked(k);
  }
  *points = shadows.size();
  return double(differ) / std::max(1, shadows.size());
}

}  // namespace

TEST(ProjectorShadows, MatchEmbreeShadowRaysIncludingBlockersThinnerThanASample) {
  int points = 0, blocked = 0;
  EXPECT_LT(shadowDisagreement({0, 639, 0, 479, 1}, &points, &blocked), 1e-3);
  EXPECT_GT(points, 100000);  // the box, 370 × 310 samples
  // The sphere's shadow on the box, and the strip's on both.
  EXPECT_GT(blocked, 3000);
  EXPECT_LT(shadowDisagreement({20, 300, 10, 230, 2}, &points, &blocked), 1e-3);
  EXPECT_GT(points, 25000);
  EXPECT_GT(blocked, 700);
}

TEST(ProjectorShadows, AStripThinnerThanASampleStillCastsItsShadow) {
  // The strip alone in front of a wall: in each row it spans, its shadow on the wall is 0.3
  // samples wide (a segment's W does not change along it), so most rows have no sample in it and
  // a shadow map at sample resolution would mostly miss it; the points it blocks are exactly
  // those Embree's rays find blocked.
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const RasterWindow w{0, 639, 0, 479, 1};
  TriangleMesh wall;
  wall.vertices = {Vec3f(-1, -1, 1), Vec3f(1, -1, 1), Vec3f(1, 1, 1), Vec3f(-1, 1, 1)};
  wall.triangles = {Tri(0, 1, 2), Tri(0, 2, 3)};  // facing the camera (−z)
  TriangleMesh strip;
  const float z = 0.5f, width = 0.3f * z / 525.f;
  strip.vertices = {Vec3f(0.0123f, -0.1f, z), Vec3f(0.0123f + width, -0.1f, z),
                    Vec3f(0.0537f + width, 0.1f, z), Vec3f(0.0537f, 0.1f, z)};
  strip.triangles = {Tri(0, 2, 1), Tri(0, 3, 2)};
  ProjectorShadows shadows;
  shadows.reset(K, w, 0.075);
  RayScene scene;
  scene.addMesh(strip);
  scene.commit();
  std::vector<Ray> rays;
  for (int j = w.j0; j <= w.j1; ++j)
    for (int i = w.i0; i <= w.i1; ++i) {
      const Vec3 p((i - K.cx) / K.fx, (j - K.cy) / K.fy, 1);  // on the wall
      const double dist = (Vec3(0.075, 0, 0) - p).norm();
      shadows.add(j, i, 1.0, 1.0 / (1 - 2e-4 / dist));
      Ray r;
      r.origin = p.cast<float>();
      r.dir = ((Vec3(0.075, 0, 0) - p) / dist).cast<float>();
      r.tnear = 2e-4f;
      r.tfar = float(dist - 2e-4);
      rays.push_back(r);
    }
  shadows.index();
  shadows.draw(wall, Iso3::Identity(), true);  // the wall blocks nothing of itself
  shadows.draw(strip, Iso3::Identity(), false);
  std::vector<uint8_t> occluded(rays.size());
  scene.occluded(rays.data(), occluded.data(), rays.size(), false);
  int blocked = 0, differ = 0;
  for (int k = 0; k < shadows.size(); ++k) {
    blocked += shadows.blocked(k);
    differ += shadows.blocked(k) != (occluded[size_t(k)] != 0);
  }
  // The shadow spans 210 rows at 0.3 samples wide: about 0.3 × 210 = 63 points (64 by exact
  // arithmetic in double, and by Embree).
  EXPECT_GT(blocked, 50);
  EXPECT_LT(blocked, 80);
  EXPECT_LE(differ, 1);
}

TEST(ProjectorShadows, LargeTrianglesBlockExactlyWhereTheyAreNearer) {
  // Points on a wavy surface (0.5 to 1.1 m) behind and in front of a large slanted quad (two
  // triangles, 0.5 m deep at one side, 1.2 m at the other): each point is blocked exactly when the
  // quad crosses its projector ray nearer than it (1/z at least its iz_block), as found here by
  // intersecting that ray with the quad's plane.
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const RasterWindow w{100, 540, 60, 420, 1};
  const double b = 0.075;
  TriangleMesh quad;
  quad.vertices = {Vec3f(-0.4f, -0.3f, 0.5f), Vec3f(0.4f, -0.3f, 1.2f), Vec3f(0.4f, 0.3f, 1.2f),
                   Vec3f(-0.4f, 0.3f, 0.5f)};
  quad.triangles = {Tri(0, 1, 2), Tri(0, 2, 3)};
  const Vec3 a = quad.vertices[0].cast<double>();
  const Vec3 n = (quad.vertices[1].cast<double>() - a).cross(quad.vertices[3].cast<double>() - a);
  ProjectorShadows shadows;
  shadows.reset(K, w, b);
  struct Expect {
    int k;
    bool blocked;
  };
  std::vector<Expect> expected;
  // The points in a shuffled order: rows need not come one after another.
  std::vector<std::pair<int, int>> samples;
  for (int j = w.j0; j <= w.j1; j += 2)
    for (int i = w.i0; i <= w.i1; i += 2) samples.push_back({i, j});
  std::mt19937 rng(7);
  std::shuffle(samples.begin(), samples.end(), rng);
  for (const auto& [i, j] : samples) {
    const double z = 0.8 + 0.3 * std::sin(i * 0.05) * std::cos(j * 0.07);
    const double iz = 1 / z, izBlock = iz / (1 - 2e-4);
    const int k = shadows.add(j, i, iz, izBlock);
    // The projector's ray through the point: X(z) = ((W − cx)/fx·z + b, (j − cy)/fy·z, z).
    const double W = i - K.fx * b * iz;
    const Vec3 dir((W - K.cx) / K.fx, (j - K.cy) / K.fy, 1);
    const double zHit = (n.dot(a) - n.x() * b) / n.dot(dir);
    const Vec3 X = Vec3(b, 0, 0) + zHit * dir;
    const double edge = std::min({0.3 - std::abs(X.y()), 0.4 - std::abs(X.x())});
    if (!(zHit > 0) || std::abs(edge) < 1e-6 || std::abs(1 / zHit - izBlock) < 1e-9)
      continue;  // on an edge or a tie: either answer is right
    expected.push_back({k, edge > 0 && 1 / zHit >= izBlock});
  }
  shadows.index();
  shadows.draw(quad, Iso3::Identity(), false);
  int blocked = 0;
  for (const Expect& e : expected) {
    EXPECT_EQ(shadows.blocked(e.k), e.blocked) << "point " << e.k;
    blocked += e.blocked;
  }
  EXPECT_GT(blocked, 2000);
  EXPECT_GT(int(expected.size()) - blocked, 2000);
}

namespace {

// Points of a wall 1 m away on every step-th sample of `w`, with the shadow ray's margin.
void addWallAtOneMetre(ProjectorShadows* p, const PinholeProjection& K, const RasterWindow& w,
                       int step) {
  p->reset(K, w, 0.075);
  for (int j = w.j0; j <= w.j1; j += step)
    for (int i = w.i0; i <= w.i1; i += step) p->add(j, i, 1.0, 1.0 / (1 - 2e-4));
  p->index();
}

// Both rasters hold the same ids and depths; returns how many samples hit.
int expectSameRaster(const DepthRaster& a, const DepthRaster& b) {
  int hits = 0;
  for (int s = 0; s < a.window().size(); ++s) {
    EXPECT_EQ(a.id(s), b.id(s));
    EXPECT_EQ(a.inverseDepth(s), b.inverseDepth(s));
    hits += a.id(s) >= 0;
  }
  return hits;
}

// Both passes blocked the same points; returns how many.
int expectSameBlocked(const ProjectorShadows& a, const ProjectorShadows& b) {
  int blocked = 0;
  for (int k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a.blocked(k), b.blocked(k));
    blocked += a.blocked(k);
  }
  return blocked;
}

}  // namespace

TEST(Raster, MeshesSkippedByTheirBoxesDrawNothingTheyWouldHaveDrawn) {
  // A sphere in view, one beside the window, one behind the camera and one beyond max_depth:
  // with their boxes given, the buffers are exactly those drawn without (the boxes only skip
  // meshes that would have drawn nothing), and the projector pass blocks the same points.
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const RasterWindow w{100, 400, 80, 300, 1};
  const TriangleMesh sphere = makeSphere(0.05, 4);
  const Aabb box = sphere.bounds();
  const std::vector<Vec3> places = {Vec3(0.02, 0, 0.5), Vec3(0.6, 0, 0.5), Vec3(0, 0, -0.5),
                                    Vec3(0, 0.01, 3.0), Vec3(-0.03, 0.02, 0.45)};
  DepthRaster plain, boxed;
  plain.reset(K, w);
  boxed.reset(K, w);
  for (const Vec3& at : places) {
    const Iso3 T = Iso3(Eigen::Translation3d(at));
    plain.draw(sphere, T, 0, true, 2.0);
    boxed.draw(sphere, T, 0, true, 2.0, &box);
  }
  EXPECT_GT(expectSameRaster(plain, boxed), 5000);
  ProjectorShadows a, b;
  addWallAtOneMetre(&a, K, w, 3);
  addWallAtOneMetre(&b, K, w, 3);
  for (const Vec3& at : places) {
    const Iso3 T = Iso3(Eigen::Translation3d(at));
    a.draw(sphere, T, true);
    b.draw(sphere, T, true, nullptr, &box);
  }
  EXPECT_GT(expectSameBlocked(a, b), 500);
}

TEST(Raster, FacingBitsHoldEveryTriangleThatFacesTheEyeAndSkipNothingDrawn) {
  // A turned sphere of small triangles and a box with a degenerate triangle added: from eyes
  // all around, the bit of every triangle that faces the eye (n·(e − a) > 0, in double) is set,
  // and the bits of those clearly facing away are clear.
  TriangleMesh m = transformed(makeSphere(0.08, 4), Iso3(Eigen::AngleAxisd(0.3, Vec3::UnitY())));
  m.append(transformed(makeBox(Vec3(0.05, 0.04, 0.03)), Iso3(Eigen::Translation3d(0.2, 0, 0))));
  m.triangles.push_back(Tri(0, 0, 1));  // no normal: always looked at
  const TriangleFacing facing(m);
  ASSERT_EQ(facing.size(), int(m.triangles.size()));
  std::vector<uint64_t> bits;
  int set = 0, clear = 0;
  for (const Vec3& eye :
       {Vec3(0.7, 0.1, 0), Vec3(-0.3, 0.5, 0.4), Vec3(0, 0, -0.9), Vec3(0.2, 0, 0.0251)}) {
    facing.mayFace(eye, &bits);
    ASSERT_EQ(bits.size(), (m.triangles.size() + 63) / 64);
    for (size_t k = 0; k < m.triangles.size(); ++k) {
      const Tri& f = m.triangles[k];
      const Vec3 a = m.vertices[size_t(f[0])].cast<double>();
      const Vec3 n = (m.vertices[size_t(f[1])].cast<double>() - a)
                         .cross(m.vertices[size_t(f[2])].cast<double>() - a);
      const bool bit = (bits[k / 64] >> (k % 64)) & 1;
      const double s = n.norm() > 0 ? n.normalized().dot(eye - a) : 0.0;
      if (s >= 0) {
        EXPECT_TRUE(bit) << "triangle " << k;
      } else if (s < -1e-3) {
        EXPECT_FALSE(bit) << "triangle " << k;
      }
      set += bit;
      clear += !bit;
    }
  }
  EXPECT_GT(clear, 1000);
  EXPECT_GT(set, 1000);
  // Drawn with the camera's bits, a culled raster is exactly the one drawn without them, and so
  // is the projector pass with the projector's.
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const RasterWindow w{150, 500, 100, 380, 1};
  const Iso3 T_C_M = Iso3(Eigen::Translation3d(-0.05, 0.01, 0.5)) *
                     Eigen::AngleAxisd(0.9, Vec3(1, 2, 0).normalized());
  const Iso3 T_M_C = T_C_M.inverse();
  facing.mayFace(T_M_C.translation(), &bits);
  DepthRaster plain, masked;
  plain.reset(K, w);
  masked.reset(K, w);
  plain.draw(m, T_C_M, 0, true);
  masked.draw(m, T_C_M, 0, true, 0, nullptr, &bits);
  EXPECT_GT(expectSameRaster(plain, masked), 5000);
  facing.mayFace(T_M_C * Vec3(0.075, 0, 0), &bits);
  ProjectorShadows a, b;
  addWallAtOneMetre(&a, K, w, 2);
  addWallAtOneMetre(&b, K, w, 2);
  a.draw(m, T_C_M, true);
  b.draw(m, T_C_M, true, nullptr, nullptr, &bits);
  EXPECT_GT(expectSameBlocked(a, b), 2000);
}

TEST(Raster, SamplesBeyondMaxDepthAreTheOnlyOnesLeftOut) {
  // A floor sloping away from 0.3 m to 3 m, in large triangles, turned so that its depth
  // changes along the rows too: with max_depth 1 m, every sample nearer than 0.99 m holds
  // exactly what it holds without a max_depth (the skipped samples lie beyond it, where an
  // occluder hides nothing nearer).
  TriangleMesh floor;
  floor.vertices = {Vec3f(-2, 0.1f, 0.3f), Vec3f(2, 0.1f, 0.3f), Vec3f(2, 0.1f, 3),
                    Vec3f(-2, 0.1f, 3)};
  floor.triangles = {Tri(0, 2, 1), Tri(0, 3, 2)};
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const RasterWindow w{0, 639, 0, 479, 1};
  DepthRaster plain, near;
  plain.reset(K, w);
  near.reset(K, w);
  const Iso3 T(Eigen::AngleAxisd(0.4, Vec3::UnitZ()));
  plain.draw(floor, T);
  near.draw(floor, T, 0, false, 1.0);
  int kept = 0, left = 0;
  for (int s = 0; s < w.size(); ++s) {
    if (plain.inverseDepth(s) > 1 / 0.99) {
      EXPECT_EQ(plain.id(s), near.id(s));
      EXPECT_EQ(plain.inverseDepth(s), near.inverseDepth(s));
      ++kept;
    }
    left += plain.id(s) >= 0 && near.id(s) < 0;
  }
  EXPECT_GT(kept, 10000);
  EXPECT_GT(left, 10000);  // and it did skip the far part
}

TEST(Raster, OccludersMarkExactlyTheSurfaceSamplesTheyAreNearerThan) {
  // Two spheres of small triangles side by side (the surface: rows with a gap), then as
  // occluders a large box crossing in front of both and the gap and reaching far beside them,
  // a finger-like thin box both in front of and behind a sphere, and a small ball: a sample is
  // kOccluded exactly where the occluders' own z-buffer (drawn alone) is nearer than the spheres',
  // keeps the spheres' id and depth where it is not, and stays empty where there is no sphere (the
  // gap included), however near an occluder is there.
  const PinholeProjection K{525, 525, 319.5, 239.5};
  const RasterWindow w{120, 520, 60, 420, 1};
  const TriangleMesh sphere = makeSphere(0.08, 5);
  const Iso3 T_sphere(Eigen::Translation3d(0.01, 0.0, 0.6));
  const TriangleMesh plate = makeBox(Vec3(0.3, 0.05, 0.02)), finger = makeBox(Vec3(0.01, 0.2, 0.3));
  const Iso3 T_plate =
      Iso3(Eigen::Translation3d(0.12, 0.03, 0.5)) * Eigen::AngleAxisd(0.3, Vec3::UnitZ());
  const Iso3 T_finger =
      Iso3(Eigen::Translation3d(-0.04, 0.0, 0.6)) * Eigen::AngleAxisd(0.2, Vec3::UnitX());
  const Aabb plateBox = plate.bounds(), fingerBox = finger.bounds();
  const TriangleMesh ball = makeSphere(0.03, 4);
  const Iso3 T_ball(Eigen::Translation3d(0.14, -0.06, 0.45));
  for (const double maxDepth : {0.0, 0.7}) {
    DepthRaster surface, alone, merged;
    for (DepthRaster* r : {&surface, &alone, &merged}) r->reset(K, w);
    for (DepthRaster* r : {&surface, &merged}) {
      r->draw(sphere, T_sphere, 0, true);
      r->draw(sphere, Iso3(Eigen::Translation3d(0.22, 0.02, 0.65)), 100000, true);
    }
    alone.draw(plate, T_plate, 0, true, maxDepth, &plateBox);
    alone.draw(finger, T_finger, 0, true, maxDepth, &fingerBox);
    merged.drawOccluder(plate, T_plate, true, maxDepth, &plateBox);
    merged.drawOccluder(finger, T_finger, true, maxDepth, &fingerBox);
    // Small triangles too (a ball over the right sphere's edge and the gap).
    alone.draw(ball, T_ball, 0, true, maxDepth);
    merged.drawOccluder(ball, T_ball, true, maxDepth);
    int occluded = 0, kept = 0, emptyUnderOccluder = 0;
    for (int s = 0; s < w.size(); ++s) {
      if (surface.id(s) < 0) {
        EXPECT_EQ(merged.id(s), -1);
        emptyUnderOccluder += alone.id(s) >= 0;
      } else if (alone.id(s) >= 0 && alone.inverseDepth(s) > surface.inverseDepth(s)) {
        EXPECT_EQ(merged.id(s), DepthRaster::kOccluded);
        EXPECT_EQ(merged.inverseDepth(s), alone.inverseDepth(s));
        ++occluded;
      } else {
        EXPECT_EQ(merged.id(s), surface.id(s));
        EXPECT_EQ(merged.inverseDepth(s), surface.inverseDepth(s));
        ++kept;
      }
    }
    EXPECT_GT(occluded, 3000);
    EXPECT_GT(kept, 3000);
    EXPECT_GT(emptyUnderOccluder, 3000);
  }
}

TEST(Raster, FourAtATimeIsBitForBitOneAtATime) {
  // The AVX2 set-up against the one-at-a-time path: spheres of small triangles cut by the
  // window's edges (the right edge, where fillSmall's four-wide rows do not fit, included), one
  // crossing the near plane, a box of large triangles, with and without culling, with the
  // facing bits, a max_depth, at strides 1 and 2, then occluders drawn over it: the same ids
  // and depths at every sample.
  if (!DepthRaster::avx2Available()) GTEST_SKIP() << "no AVX2 on this CPU";
  const PinholeProjection K{525, 525, 319.5, 239.5};
  TriangleMesh m = makeSphere(0.1, 5);
  m.append(transformed(makeSphere(0.03, 4), Iso3(Eigen::Translation3d(0.12, 0.05, -0.55))));
  m.append(transformed(makeBox(Vec3(0.05, 0.3, 0.02)), Iso3(Eigen::Translation3d(-0.1, 0, 0.1))));
  const TriangleFacing facing(m);
  std::vector<uint64_t> bits;
  TriangleMesh plate = makeBox(Vec3(0.12, 0.05, 0.004));
  plate.append(
      transformed(makeBox(Vec3(0.015, 0.09, 0.015)), Iso3(Eigen::Translation3d(0.02, 0, 0))));
  const Iso3 T_C_plate = Iso3(Eigen::Translation3d(-0.02, 0.03, 0.5)) *
                         Eigen::AngleAxisd(0.4, Vec3(0, 1, 0.3).normalized());
  int compared = 0;
  for (const RasterWindow& w :
       {RasterWindow{0, 639, 0, 479, 1}, RasterWindow{200, 401, 150, 330, 1},
        RasterWindow{100, 253, 60, 181, 2}}) {
    for (const double angle : {0.0, 0.7, 2.1}) {
      const Iso3 T_C_M = Iso3(Eigen::Translation3d(0.03, -0.02, 0.6)) *
                         Eigen::AngleAxisd(angle, Vec3(1, 2, 3).normalized());
      facing.mayFace(T_C_M.inverse().translation(), &bits);
      for (int mode = 0; mode < 4; ++mode) {
        DepthRaster one, four;
        EXPECT_FALSE(one.setVectorised(false));
        EXPECT_TRUE(four.setVectorised(true));
        for (DepthRaster* r : {&one, &four}) {
          r->reset(K, w);
          const bool cull = mode != 0;
          r->draw(m, T_C_M, 7, cull, mode == 3 ? 0.62 : 0.0, nullptr, mode >= 2 ? &bits : nullptr);
          // Occluders over it: a plate and a finger of large triangles (the wide fill).
          r->drawOccluder(plate, T_C_plate, cull, mode == 3 ? 0.62 : 0.0);
        }
        compared += expectSameRaster(one, four);
      }
    }
  }
  EXPECT_GT(compared, 100000);
}

TEST(ProjectorShadows, FourAtATimeBlocksTheSamePointsAsOneAtATime) {
  // The AVX2 set-up against the one-at-a-time path. Points: the first surface of every sample
  // of a bumpy scene (spheres of small triangles in front of a box), so that the spheres shadow
  // themselves and the box; then the same meshes and one crossing the near plane drawn, with and
  // without culling and the facing bits: the same points blocked.
  if (!DepthRaster::avx2Available()) GTEST_SKIP() << "no AVX2 on this CPU";
  const PinholeProjection K{525, 525, 319.5, 239.5};
  TriangleMesh m = makeSphere(0.06, 5);
  m.append(transformed(makeSphere(0.03, 4), Iso3(Eigen::Translation3d(0.05, 0.02, -0.07))));
  m.append(transformed(makeBox(Vec3(0.5, 0.4, 0.02)), Iso3(Eigen::Translation3d(0, 0, 0.2))));
  const TriangleMesh nearSphere = makeSphere(0.03, 4);
  const Iso3 T_near(Eigen::Translation3d(-0.05, 0.04, 0.0));  // crosses z = 0
  const TriangleFacing facing(m);
  std::vector<uint64_t> bits;
  int blocked = 0;
  for (const RasterWindow& w :
       {RasterWindow{0, 639, 0, 479, 1}, RasterWindow{100, 253, 60, 181, 2}}) {
    for (const double angle : {0.3, 1.9}) {
      const Iso3 T_C_M = Iso3(Eigen::Translation3d(0.0, -0.01, 0.55)) *
                         Eigen::AngleAxisd(angle, Vec3(1, 2, 3).normalized());
      DepthRaster first;
      first.reset(K, w);
      first.draw(m, T_C_M, 0, true);
      facing.mayFace(T_C_M.inverse() * Vec3(0.075, 0, 0), &bits);
      for (int mode = 0; mode < 3; ++mode) {
        ProjectorShadows one, four;
        EXPECT_FALSE(one.setVectorised(false));
        EXPECT_TRUE(four.setVectorised(true));
        for (ProjectorShadows* p : {&one, &four}) {
          p->reset(K, w, 0.075);
          for (int j = w.j0; j <= w.j1; ++j)
            for (int i = w.i0; i <= w.i1; ++i) {
              const int s = first.index(i, j);
              if (first.id(s) < 0) continue;
              const double iz = first.inverseDepth(s);
              p->add(j, i, iz, iz * (1 + 3e-4));
            }
          p->index();
          p->draw(m, T_C_M, mode != 0, mode == 2 ? &first.projected() : nullptr, nullptr,
                  mode == 2 ? &bits : nullptr);
          p->draw(nearSphere, T_near, true);
        }
        blocked += expectSameBlocked(one, four);
      }
    }
  }
  EXPECT_GT(blocked, 5000);
}

TEST(Raster, WatertightIsWeakerThanClosed) {
  TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  EXPECT_TRUE(box.isClosed());
  EXPECT_TRUE(box.isWatertight());
  // Two boxes sharing an edge: four triangles on that edge, still bounding a region.
  TriangleMesh two = box;
  two.append(transformed(box, Iso3(Eigen::Translation3d(0.1, 0.1, 0))));
  two = welded(two);
  EXPECT_FALSE(two.isClosed());
  EXPECT_TRUE(two.isWatertight());
  TriangleMesh open = box;
  open.triangles.pop_back();
  EXPECT_FALSE(open.isWatertight());
}

// ---- stable resting poses ---------------------------------------------------------------------

// The hull of a point set contains every point and has every hull vertex on it: a cube with
// interior points and points on its faces comes back as 8 vertices, 12 triangles.
TEST(StablePoses, ConvexHullOfACubeWithInteriorAndFacePoints) {
  std::vector<Vec3> pts;
  Rng rng = makeRng(5);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int i = 0; i < 2000; ++i) pts.push_back(Vec3(u(rng), u(rng), u(rng)));
  for (int i = 0; i < 200; ++i) pts.push_back(Vec3(0.5, u(rng), u(rng)));
  for (int sx : {-1, 1})
    for (int sy : {-1, 1})
      for (int sz : {-1, 1}) pts.push_back(0.5 * Vec3(sx, sy, sz));
  const ConvexHull h = convexHull(pts);
  // Face points may stay as hull vertices (coplanar); every one lies on the cube's surface.
  for (const Vec3& v : h.vertices) EXPECT_NEAR(v.cwiseAbs().maxCoeff(), 0.5, 1e-12);
  double area = 0;
  for (const auto& t : h.triangles)
    area += 0.5 *
            (h.vertices[t[1]] - h.vertices[t[0]]).cross(h.vertices[t[2]] - h.vertices[t[0]]).norm();
  EXPECT_NEAR(area, 6.0, 1e-9);
}

// A box a × b × c rests on each face pair with the solid angle the face subtends at the centre,
// Ω = 4 asin(ab / √((a² + 4d²)(b² + 4d²))) at distance d, over 4π.
// Many cocircular and coplanar points (a revolved mug of 10^5 vertices): the hull is closed
// (V − E + F = 2), every point lies inside every face's plane, and it comes out in bounded memory
// and time (an earlier incremental hull grew without bound on this input).
TEST(StablePoses, ConvexHullOfAMugIsClosedAndHoldsEveryPoint) {
  const TriangleMesh mug = loadObject("builtin:mug");
  std::vector<Vec3> pts;
  for (const Vec3f& v : mug.vertices) pts.push_back(v.cast<double>());
  const ConvexHull h = convexHull(pts);
  ASSERT_GE(h.vertices.size(), 4u);
  EXPECT_EQ(2 * long(h.vertices.size()) - 4, long(h.triangles.size()));
  double worst = 0;
  for (const auto& t : h.triangles) {
    const Vec3 a = h.vertices[size_t(t[0])], b = h.vertices[size_t(t[1])],
               c = h.vertices[size_t(t[2])];
    const Vec3 n = (b - a).cross(c - a);
    if (n.norm() < 1e-14) continue;
    for (size_t k = 0; k < pts.size(); k += 7)
      worst = std::max(worst, n.normalized().dot(pts[k] - a));
  }
  EXPECT_LT(worst, 1e-9);
  const Aabb box = mug.bounds();
  EXPECT_GT(hullVolume(h), 0.5 * box.size().prod());
  EXPECT_LT(hullVolume(h), box.size().prod());
}

TEST(StablePoses, BoxProbabilitiesAreTheFacesSolidAngles) {
  const Vec3 s(0.06, 0.158, 0.21);  // the cracker box
  auto face = [](double a, double b, double d) {
    return 4 * std::asin(a * b / std::sqrt((a * a + 4 * d * d) * (b * b + 4 * d * d))) / (4 * M_PI);
  };
  const Iso3 T = Iso3(Eigen::Translation3d(0.01, -0.02, 0.03)) *
                 Eigen::AngleAxisd(0.3, Vec3(1, 2, 3).normalized());
  const std::vector<StablePose> poses = stablePoses(transformed(makeBox(s), T));
  ASSERT_EQ(poses.size(), 6u);
  double total = 0;
  for (const StablePose& p : poses) {
    total += p.probability;
    const Vec3 n = T.linear().transpose() * p.down_O;  // in the box's own axes
    int axis;
    n.cwiseAbs().maxCoeff(&axis);
    EXPECT_NEAR(std::abs(n[axis]), 1.0, 1e-6);
    const double a = s[(axis + 1) % 3], b = s[(axis + 2) % 3], d = 0.5 * s[axis];
    EXPECT_NEAR(p.probability, face(a, b, d), 1e-6) << axis;  // float vertices
    EXPECT_NEAR(p.height_m, d, 1e-6);
    EXPECT_LT((p.R_B_O * p.down_O - Vec3(0, 0, -1)).norm(), 1e-12);
  }
  EXPECT_NEAR(total, 1.0, 1e-12);
  // Most probable: on the largest face (the 158 × 210 mm one).
  EXPECT_NEAR(std::abs((T.linear().transpose() * poses[0].down_O).x()), 1.0, 1e-6);
}

// A cylinder (radius r, height h) stands on a cap with probability (1 − cos θ)/2 each,
// cos θ = (h/2)/√((h/2)² + r²), and lies on its side (one pose: every side facet is at the same
// height) with the rest. The 128-gon is within 0.2 % of the circle.
TEST(StablePoses, CylinderCapsAndSideMatchTheAnalyticSolidAngles) {
  const double r = 0.051, h = 0.139;  // the coffee can
  const std::vector<StablePose> poses = stablePoses(makeCylinder(r, h, 128));
  ASSERT_EQ(poses.size(), 3u);
  const double cap = 0.5 * (1 - 0.5 * h / std::hypot(0.5 * h, r));
  EXPECT_NEAR(poses[0].probability, 1 - 2 * cap, 3e-3);  // on its side
  EXPECT_NEAR(std::abs(poses[0].down_O.z()), 0.0, 1e-9);
  EXPECT_NEAR(poses[0].height_m, r, 1e-3);
  for (int k : {1, 2}) {
    EXPECT_NEAR(poses[k].probability, cap, 3e-3);
    EXPECT_NEAR(std::abs(poses[k].down_O.z()), 1.0, 1e-9);
  }
  // A flat disc stands on a cap almost always.
  const std::vector<StablePose> disc = stablePoses(makeCylinder(0.05, 0.01, 64));
  EXPECT_GT(disc[0].probability + disc[1].probability, 0.85);
}

// A right-angled wedge (legs 0.1 m in x, 0.02 m in z, 0.05 m deep) rests on all five faces: its
// centre of mass projects inside each. Sheared so that its top overhangs far beyond the base
// (apex at x = 0.25 m), the base is unstable and passes its probability on; the probabilities
// still sum to 1.
TEST(StablePoses, UnstableFacesPassTheirProbabilityOn) {
  TriangleMesh w;
  const std::vector<Vec3> v = {{0, 0, 0},    {0.1, 0, 0},    {0, 0, 0.02},
                               {0, 0.05, 0}, {0.1, 0.05, 0}, {0, 0.05, 0.02}};
  for (const Vec3& p : v) w.vertices.push_back(p.cast<float>());
  w.triangles = {{0, 2, 1}, {3, 4, 5}, {0, 1, 4}, {0, 4, 3},
                 {0, 3, 5}, {0, 5, 2}, {1, 2, 5}, {1, 5, 4}};
  const std::vector<StablePose> poses = stablePoses(w);
  double total = 0;
  for (const StablePose& p : poses) {
    total += p.probability;
    EXPECT_GT(p.probability, 0);
  }
  EXPECT_NEAR(total, 1.0, 1e-12);
  EXPECT_EQ(poses.size(), 5u);
  TriangleMesh lean = w;
  for (Vec3f& p : lean.vertices)
    if (p.z() > 0.01f) p = Vec3f(0.25f, p.y(), 0.3f);  // the apex far beyond x = 0.1
  const std::vector<StablePose> leaning = stablePoses(lean);
  double sum = 0;
  for (const StablePose& p : leaning) {
    sum += p.probability;
    EXPECT_FALSE(p.down_O.z() < -0.99) << "the base is unstable: the COM overhangs it";
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
}

TEST(Geometry, ClusteringKeepsTheShapeWithinACellAndStlRoundTrips) {
  const TriangleMesh sphere = makeSphere(0.05, 5);
  const size_t limit = sphere.triangles.size() / 8;
  const TriangleMesh fewer = simplifiedTo(sphere, limit);
  EXPECT_LE(fewer.triangles.size(), limit);
  EXPECT_GT(fewer.triangles.size(), limit / 4);
  EXPECT_EQ(validateMesh(fewer), "");
  EXPECT_TRUE(fewer.isWatertight());
  // Every vertex within a few mm of the sphere; the enclosed volume within 3 %.
  for (const Vec3f& v : fewer.vertices) EXPECT_NEAR(v.cast<double>().norm(), 0.05, 0.003);
  EXPECT_NEAR(massProperties(fewer).volume_m3, massProperties(sphere).volume_m3,
              0.03 * massProperties(sphere).volume_m3);
  EXPECT_EQ(simplifiedTo(sphere, sphere.triangles.size()).triangles.size(),
            sphere.triangles.size());
  // Binary STL: written and read back, the same triangles (welded: the same vertices).
  test::TempDir dir;
  writeStl(dir.path() / "s.stl", fewer);
  const TriangleMesh back = importMesh(dir.path() / "s.stl");
  EXPECT_EQ(back.triangles.size(), fewer.triangles.size());
  EXPECT_EQ(back.vertices.size(), fewer.vertices.size());
  EXPECT_NEAR(massProperties(back).volume_m3, massProperties(fewer).volume_m3, 1e-12);
}

// Subdivision splits every long edge and leaves the surface as it was: the same enclosed volume
// and area (exact: midpoints lie on the edges), closed (every edge shared by two triangles, so
// the volume is still the box's), flags carried to the midpoints of flagged edges only.
TEST(Geometry, SubdividedSplitsEveryLongEdgeAndKeepsTheSurface) {
  const TriangleMesh box = makeBox(Vec3(0.06, 0.05, 0.10));
  std::vector<uint8_t> flags(box.vertices.size(), 1);
  flags[0] = 0;
  const TriangleMesh fine = subdivided(box, 0.01, &flags);
  ASSERT_EQ(flags.size(), fine.vertices.size());
  EXPECT_GT(fine.triangles.size(), 100 * box.triangles.size() / 10);
  std::map<std::pair<int, int>, int> edges;
  double area = 0;
  for (const Tri& t : fine.triangles) {
    for (int k = 0; k < 3; ++k) {
      const int a = t[k], b = t[(k + 1) % 3];
      EXPECT_LE((fine.vertices[size_t(a)] - fine.vertices[size_t(b)]).norm(), 0.01 + 1e-6);
      ++edges[std::minmax(a, b)];
    }
    const Vec3 p = fine.vertices[size_t(t[0])].cast<double>();
    area += 0.5 * (fine.vertices[size_t(t[1])].cast<double>() - p)
                      .cross(fine.vertices[size_t(t[2])].cast<double>() - p)
                      .norm();
  }
  for (const auto& [e, n] : edges) EXPECT_EQ(n, 2) << e.first << " " << e.second;
  EXPECT_NEAR(area, 2 * (0.06 * 0.05 + 0.06 * 0.10 + 0.05 * 0.10), 1e-6);
  EXPECT_NEAR(massProperties(fine).volume_m3, 0.06 * 0.05 * 0.10, 1e-9);
  // A vertex is unflagged only where it lies on an edge from the unflagged corner's side.
  int unflagged = 0;
  for (size_t k = 0; k < flags.size(); ++k)
    if (!flags[k]) {
      ++unflagged;
      const Vec3f d = fine.vertices[k] - box.vertices[0];
      int off = 0;  // coordinates away from the corner: on an edge or face through it
      for (int a = 0; a < 3; ++a) off += std::abs(d[a]) > 1e-6f;
      EXPECT_LE(off, 2);
    }
  EXPECT_GE(unflagged, 1);
  EXPECT_THROW(subdivided(box, 0), std::runtime_error);
}
