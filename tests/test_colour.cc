// Colour: images, textured meshes, colour in the volume, and a scan that gets an object's colours.
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <gtest/gtest.h>
#include <assimp/Importer.hpp>

#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>

#include "inhand/core/error.h"
#include "inhand/driver/simulated_scan.h"
#include "inhand/geometry/appearance.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/geometry/texture_atlas.h"
#include "inhand/sensor/frame_set.h"
#include "inhand/volume/colour_volume.h"
#include "test_util.h"

using namespace inhand;
namespace fs = std::filesystem;

namespace {
Vec3f rgb(int r, int g, int b) { return Vec3f(float(r), float(g), float(b)); }

// Expects `what` to throw an Error whose message contains `part`.
template <class F>
void expectErrorNaming(F&& what, const std::string& part) {
  try {
    what();
    ADD_FAILURE() << "no error; expected one naming " << part;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}
}  // namespace

TEST(Colour, LabAndDeltaE76OfKnownColours) {
  // CIELAB of sRGB white, black and primaries (D65): published reference values.
  EXPECT_NEAR((srgbToLab(rgb(255, 255, 255)) - Vec3(100, 0, 0)).norm(), 0, 0.02);
  EXPECT_NEAR(srgbToLab(rgb(0, 0, 0)).norm(), 0, 1e-9);
  EXPECT_NEAR((srgbToLab(rgb(255, 0, 0)) - Vec3(53.24, 80.09, 67.20)).norm(), 0, 0.05);
  EXPECT_NEAR((srgbToLab(rgb(0, 0, 255)) - Vec3(32.30, 79.19, -107.86)).norm(), 0, 0.05);
  EXPECT_NEAR(deltaE76(rgb(255, 255, 255), rgb(0, 0, 0)), 100, 0.02);
  EXPECT_EQ(deltaE76(rgb(10, 200, 30), rgb(10, 200, 30)), 0);
}

TEST(Colour, PngRoundTripsAndBadFilesAreNamed) {
  test::TempDir dir;
  RgbImage img(5, 3);
  for (size_t i = 0; i < img.rgb.size(); ++i) img.rgb[i] = uint8_t(i * 17);
  writeRgbPng(dir.path() / "a.png", img);
  const RgbImage back = readRgbPng(dir.path() / "a.png");
  EXPECT_EQ(back.width, 5);
  EXPECT_EQ(back.height, 3);
  EXPECT_EQ(back.rgb, img.rgb);
  expectErrorNaming([&] { readRgbPng(dir.path() / "none.png"); }, "none.png");
  std::ofstream(dir.path() / "bad.png") << "not a png";
  expectErrorNaming([&] { readRgbPng(dir.path() / "bad.png"); }, "bad.png");
}

TEST(Colour, TexturedObjReadsItsMaterialsAndTexture) {
  test::TempDir dir;
  // A unit quad in two triangles, its texture 2 × 2 texels: red, green (top row), blue, white.
  RgbImage tex(2, 2);
  const uint8_t texels[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
  std::copy(texels, texels + 12, tex.rgb.begin());
  writeRgbPng(dir.path() / "tex.png", tex);
  std::ofstream(dir.path() / "quad.mtl") << "newmtl painted\nKd 0.5 0.5 0.5\nmap_Kd tex.png\n"
                                         << "newmtl plain\nKd 1 0 1\n";
  std::ofstream(dir.path() / "quad.obj")
      << "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
      << "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl painted\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
      << "usemtl plain\nf 1 2 5\n";
  const TexturedMesh t = importTexturedMesh(dir.path() / "quad.obj");
  ASSERT_EQ(t.mesh.triangles.size(), 3u);
  // Texel centres: u, v = 0.25 or 0.75; v up, so v = 0.75 is the image's top row.
  auto sample = [&](int tri, double u, double v) {
    // Barycentrics of (u, v) in triangle tri of the quad (corners as in the OBJ).
    const Vec3f a = t.mesh.vertices[size_t(t.mesh.triangles[tri][0])];
    const Vec3f b = t.mesh.vertices[size_t(t.mesh.triangles[tri][1])];
    const Vec3f c = t.mesh.vertices[size_t(t.mesh.triangles[tri][2])];
    Eigen::Matrix2f M;
    M << b.x() - a.x(), c.x() - a.x(), b.y() - a.y(), c.y() - a.y();
    const Eigen::Vector2f bc = M.inverse() * Eigen::Vector2f(float(u) - a.x(), float(v) - a.y());
    return t.colours.at(t.mesh, tri, bc.x(), bc.y());
  };
  EXPECT_LT((sample(0, 0.75, 0.25) - rgb(255, 255, 255)).norm(), 1e-3);              // bottom right
  EXPECT_LT((sample(1, 0.25, 0.75) - rgb(255, 0, 0)).norm(), 1e-3);                  // top left
  EXPECT_LT((sample(1, 0.25, 0.25) - rgb(0, 0, 255)).norm(), 1e-3);                  // bottom left
  EXPECT_LT((t.colours.at(t.mesh, 2, 0.3f, 0.3f) - rgb(255, 0, 255)).norm(), 1e-3);  // Kd
  // A texture that is missing, or not a PNG, is named.
  std::ofstream(dir.path() / "quad.mtl") << "newmtl painted\nmap_Kd gone.png\nnewmtl plain\n";
  expectErrorNaming([&] { importTexturedMesh(dir.path() / "quad.obj"); }, "gone.png");
  std::ofstream(dir.path() / "quad.mtl") << "newmtl painted\nmap_Kd photo.bmp\nnewmtl plain\n";
  expectErrorNaming([&] { importTexturedMesh(dir.path() / "quad.obj"); }, "photo.bmp");
}

TEST(Colour, PlyColoursRoundTripWithAlpha) {
  test::TempDir dir;
  const TriangleMesh box = makeBox(Vec3(0.1, 0.2, 0.3));
  std::vector<std::array<uint8_t, 4>> rgba;
  for (size_t i = 0; i < box.vertices.size(); ++i)
    rgba.push_back(
        {uint8_t(10 * i), uint8_t(255 - 10 * i), uint8_t(7 * i), uint8_t(i % 2 ? 255 : 0)});
  std::vector<float> variance(box.vertices.size(), 1e-6f);
  writePly(dir.path() / "m.ply", box, &variance, &rgba);
  const PlyData ply = readPly(dir.path() / "m.ply");
  ASSERT_EQ(ply.mesh.vertices.size(), box.vertices.size());
  for (size_t i = 0; i < rgba.size(); ++i) {
    EXPECT_EQ(ply.vertexProperties.at("red")[i], rgba[i][0]);
    EXPECT_EQ(ply.vertexProperties.at("green")[i], rgba[i][1]);
    EXPECT_EQ(ply.vertexProperties.at("blue")[i], rgba[i][2]);
    EXPECT_EQ(ply.vertexProperties.at("alpha")[i], rgba[i][3]);
    EXPECT_FLOAT_EQ(ply.vertexProperties.at("variance")[i], 1e-6f);
  }
  const TexturedMesh t = importTexturedMesh(dir.path() / "m.ply");
  ASSERT_EQ(t.colours.vertex_rgb.size(), t.mesh.vertices.size());
}

TEST(Colour, CheckerIsExactAwayFromItsEdges) {
  const double s = 0.02;
  const TriangleMesh box = makeBox(Vec3(0.16, 0.06, 0.21));
  const SurfaceColours c = checkerColours(box, s);
  int tested = 0;
  for (size_t t = 0; t < box.triangles.size(); ++t)
    for (float b1 : {0.1f, 0.3f, 0.6f})
      for (float b2 : {0.1f, 0.25f}) {
        const Tri& f = box.triangles[t];
        const Vec3 p = ((1 - b1 - b2) * box.vertices[size_t(f[0])] +
                        b1 * box.vertices[size_t(f[1])] + b2 * box.vertices[size_t(f[2])])
                           .cast<double>();
        int axis = 0;
        box.faceNormal(int(t)).cwiseAbs().maxCoeff(&axis);
        const double x = p[(axis + 1) % 3] / s, y = p[(axis + 2) % 3] / s;
        // 1 mm or more from a square's edge.
        auto off = [&](double q) { return std::abs(q - std::round(q)) * s; };
        if (off(x) < 0.001 || off(y) < 0.001) continue;
        // Square (floor x, floor y) has the first colour where both are even or both odd.
        const long ix = long(std::floor(x)), iy = long(std::floor(y));
        const bool first = ((ix & 1) != 0) == ((iy & 1) != 0);
        const Vec3f want = first ? rgb(200, 40, 40) : rgb(235, 225, 190);
        EXPECT_LT((c.at(box, int(t), b1, b2) - want).norm(), 1e-3) << p.transpose();
        ++tested;
      }
  EXPECT_GT(tested, 40);
}

// A plane facing the camera 0.8 m away; the colour camera (2.5 cm to its side) sees red left of
// its image's column 320 and blue right of it. Each point of the plane gets the colour the colour
// camera sees it in (projected independently here), not the colour at its depth pixel.
TEST(ColourVolume, APlaneTakesTheColourTheColourCameraSeesItIn) {
  DepthCameraOptions cam;
  cam.colour.enabled = true;
  const CameraIntrinsics& K = cam.intrinsics;
  DepthImage depth(K.width, K.height);
  for (float& d : depth.depth_m) d = 0.8f;
  RgbImage colour(cam.colour.intrinsics.width, cam.colour.intrinsics.height);
  for (int v = 0; v < colour.height; ++v)
    for (int u = 0; u < colour.width; ++u) {
      uint8_t* px = colour.at(u, v);
      px[0] = u < 320 ? 220 : 20;
      px[1] = 30;
      px[2] = u < 320 ? 20 : 210;
    }
  VolumeOptions vo;
  vo.voxel_size_m = 0.004;
  Aabb box;
  box.extend(Vec3(-0.2, -0.15, 0.7));
  box.extend(Vec3(0.2, 0.15, 0.9));
  TsdfVolume volume(box, vo);
  ColourVolume cv(volume);
  const std::vector<float> sigma(depth.depth_m.size(), 0.002f);
  const ColourIntegrationStats st =
      integrateColour(depth, colour, Iso3::Identity(), cam, sigma, &cv, nullptr);
  EXPECT_GT(st.pixels, 100000);
  EXPECT_EQ(st.occluded, 0);
  int red = 0, blue = 0;
  for (double x = -0.15; x <= 0.15; x += 0.0037) {
    const Vec3 p(x, 0.01, 0.8);
    const Vec3 q = cam.colour.T_D_RGB.inverse() * p;
    const double u = cam.colour.intrinsics.project(q).x();
    if (std::abs(u - 319.5) < 8) continue;  // the edge, blurred over a voxel
    Vec3f c;
    ASSERT_TRUE(cv.at(p, &c)) << x;
    const Vec3f want = u < 319.5 ? rgb(220, 30, 20) : rgb(20, 30, 210);
    EXPECT_LT((c - want).norm(), 1.0) << "x " << x << " u " << u;
    (u < 319.5 ? red : blue)++;
  }
  // The offset moves the edge 16.6 px (2.5 cm at 0.8 m): columns the depth camera sees left of
  // 320 that the colour camera sees right of it are among those checked.
  EXPECT_GT(red, 20);
  EXPECT_GT(blue, 20);
  // Pixels with the robot's flag add nothing.
  ColourVolume none(volume);
  const std::vector<uint8_t> carve(depth.depth_m.size(), 1);
  EXPECT_EQ(integrateColour(depth, colour, Iso3::Identity(), cam, sigma, &none, &carve).pixels, 0);
  EXPECT_TRUE(none.empty());
}

// The colour sums, kept in blocks of voxels, against a plain map of the same adds: the same
// voxels with the same sums, and a volume rebuilt from them (as a checkpoint does) equal.
TEST(ColourVolume, TheBlockStoreKeepsEveryVoxelsSums) {
  VolumeOptions vo;
  vo.voxel_size_m = 0.002;
  TsdfVolume volume(Aabb{Vec3(-0.05, -0.04, 0.7), Vec3(0.05, 0.05, 0.75)}, vo);
  ColourVolume cv(volume);
  std::map<size_t, ColourVolume::Sum> want;
  const Vec3i dims = volume.dims();
  for (int k = 0; k < 5000; ++k) {
    const Vec3 p(-0.05 + 0.1 * std::fmod(0.6180339 * k, 1.0),
                 -0.04 + 0.09 * std::fmod(0.4142135 * k, 1.0),
                 0.7 + 0.05 * std::fmod(0.7320508 * k, 1.0));
    const Vec3f c(float(k % 256), float((3 * k) % 256), float((7 * k) % 256));
    const float w = 0.5f + float(k % 3);
    cv.add(p, c, w);
    // The nearest voxel of the cell p lies in (a cell wholly inside the grid).
    const Vec3 g = (p - volume.origin()) / volume.voxelSize();
    const Vec3 fl = g.array().floor().matrix();
    if ((fl.array() < 0).any() || (fl.array() + 1 >= dims.cast<double>().array()).any()) continue;
    const Vec3i i =
        (fl + (g - fl).unaryExpr([](double f) { return f >= 0.5 ? 1.0 : 0.0; })).cast<int>();
    ColourVolume::Sum& s =
        want[(size_t(i.z()) * size_t(dims.y()) + size_t(i.y())) * size_t(dims.x()) + size_t(i.x())];
    s.w += w, s.r += w * c[0], s.g += w * c[1], s.b += w * c[2];
  }
  const auto got = cv.entries();
  ASSERT_EQ(got.size(), want.size());
  EXPECT_EQ(cv.voxels(), want.size());
  size_t k = 0;
  for (const auto& [index, s] : want) {
    ASSERT_EQ(got[k].first, index);
    EXPECT_FLOAT_EQ(got[k].second.w, s.w);
    EXPECT_FLOAT_EQ(got[k].second.r, s.r);
    EXPECT_FLOAT_EQ(got[k].second.b, s.b);
    ASSERT_NE(cv.find(index), nullptr);
    ++k;
  }
  ColourVolume copy(volume);
  for (const auto& [index, s] : got) ASSERT_TRUE(copy.set(index, s));
  EXPECT_FALSE(copy.set(volume.voxelCount(), got[0].second));
  EXPECT_EQ(copy.voxels(), cv.voxels());
  for (double x = -0.04; x < 0.04; x += 0.0013) {
    Vec3f a, b;
    const Vec3 p(x, 0.3 * x, 0.72);
    ASSERT_EQ(cv.at(p, &a), copy.at(p, &b));
    EXPECT_EQ(a, b);
  }
}

// A whole scan with the colour camera: the checkerboard box's colours against the truth.
// The colour camera's pose in the depth camera's frame is honoured: a checkerboard plane (2 cm
// squares) 0.8 m away, tilted 30°, imaged by a colour camera 3.5 cm beside the depth camera; fused
// telling the volume that pose, the plane's colours are right; telling it the default 2.5 cm (the
// camera moved 1 cm without the volume knowing), they are smeared a centimetre across the squares.
TEST(ColourVolume, TheColourCamerasPoseIsHonoured) {
  DepthCameraOptions told;
  told.colour.enabled = true;
  DepthCameraOptions truth = told;
  truth.colour.T_D_RGB = Iso3(Eigen::Translation3d(0.035, 0.0, 0.0));
  // The plane through (0, 0, 0.8) with normal n (tilted about y); checker on its (x, y).
  const Vec3 n = Vec3(std::sin(M_PI / 6), 0, -std::cos(M_PI / 6));
  const Vec3 o(0, 0, 0.8);
  auto onPlane = [&](const Vec3& centre, const Vec3& ray) {
    return Vec3(centre + ray * ((o - centre).dot(n) / ray.dot(n)));
  };
  auto checker = [](const Vec3& p) {
    const bool a = (int(std::floor(p.x() / 0.02)) + int(std::floor(p.y() / 0.02))) % 2 == 0;
    return a ? rgb(200, 40, 40) : rgb(235, 225, 190);
  };
  const CameraIntrinsics& K = told.intrinsics;
  DepthImage depth(K.width, K.height);
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u)
      depth.at(u, v) =
          float(onPlane(Vec3::Zero(), Vec3((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1)).z());
  const CameraIntrinsics& Kc = truth.colour.intrinsics;
  RgbImage colour(Kc.width, Kc.height);
  const Vec3 c_D = truth.colour.T_D_RGB.translation();
  for (int v = 0; v < Kc.height; ++v)
    for (int u = 0; u < Kc.width; ++u) {
      const Vec3 ray =
          truth.colour.T_D_RGB.linear() * Vec3((u - Kc.cx) / Kc.fx, (v - Kc.cy) / Kc.fy, 1);
      const Vec3f c = checker(onPlane(c_D, ray));
      for (int ch = 0; ch < 3; ++ch) colour.at(u, v)[ch] = uint8_t(c[ch]);
    }
  VolumeOptions vo;
  vo.voxel_size_m = 0.002;
  Aabb box;
  box.extend(Vec3(-0.12, -0.1, 0.65));
  box.extend(Vec3(0.12, 0.1, 0.95));
  TsdfVolume volume(box, vo);
  const std::vector<float> sigma(depth.depth_m.size(), 0.002f);
  auto meanDeltaE = [&](const DepthCameraOptions& cam) {
    ColourVolume cv(volume);
    integrateColour(depth, colour, Iso3::Identity(), cam, sigma, &cv, nullptr);
    double sum = 0;
    int n = 0;
    for (double x = -0.08; x <= 0.08; x += 0.0013)
      for (double y = -0.06; y <= 0.06; y += 0.0017) {
        const Vec3 p = onPlane(Vec3::Zero(), Vec3(x, y, 0.8).normalized());
        Vec3f c;
        if (!cv.at(p, &c)) continue;
        sum += deltaE76(c, checker(p));
        ++n;
      }
    EXPECT_GT(n, 5000);
    return sum / std::max(n, 1);
  };
  const double right = meanDeltaE(truth), wrong = meanDeltaE(told);
  std::printf("mean dE76: pose told %.1f, 1 cm off %.1f\n", right, wrong);
  EXPECT_LT(right, 12.0);
  EXPECT_GT(wrong, 2.5 * right);
}

namespace {
// A plane through `o` with unit normal `n` (facing the cameras) seen by a depth camera at
// T_O_C (its pose in the plane's frame) and its colour camera (cam.colour): the depth image,
// and the colour image of albedo(p) (sRGB) lit as shading 1 − falloff · (1 − cos θ) in linear
// intensity, θ between the plane's normal and the colour camera's ray.
struct PlaneFrame {
  DepthImage depth;
  RgbImage colour;
};
PlaneFrame renderPlane(const DepthCameraOptions& cam, const Iso3& T_O_C, const Vec3& o,
                       const Vec3& n, const std::function<Vec3f(const Vec3&)>& albedo,
                       double falloff) {
  auto hit = [&](const Vec3& from, const Vec3& dir) {
    return Vec3(from + dir * ((o - from).dot(n) / dir.dot(n)));
  };
  const CameraIntrinsics& K = cam.intrinsics;
  PlaneFrame f{DepthImage(K.width, K.height), RgbImage()};
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      const Vec3 dir = T_O_C.linear() * K.rayZ1(u, v);
      const Vec3 p = hit(T_O_C.translation(), dir);
      f.depth.at(u, v) = float((T_O_C.inverse() * p).z());
    }
  const CameraIntrinsics& Kc = cam.colour.intrinsics;
  const Iso3 T_O_RGB = T_O_C * cam.colour.T_D_RGB;
  f.colour = RgbImage(Kc.width, Kc.height);
  for (int v = 0; v < Kc.height; ++v)
    for (int u = 0; u < Kc.width; ++u) {
      const Vec3 dir = T_O_RGB.linear() * Kc.rayZ1(u, v);
      const Vec3 p = hit(T_O_RGB.translation(), dir);
      const double shade = 1 - falloff * (1 - std::abs(n.dot(dir.normalized())));
      const Vec3f a = albedo(p);
      for (int ch = 0; ch < 3; ++ch)
        f.colour.at(u, v)[ch] = uint8_t(std::lround(linearToSrgb(srgbToLinear(a[ch]) * shade)));
    }
  return f;
}

// A square grid of the plane z = 0.8 (normal −z, towards cameras on the −z side), `side` m
// across, `step` m between vertices.
TriangleMesh planeGrid(double side, double step) {
  TriangleMesh m;
  const int n = int(std::lround(side / step)) + 1;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      m.vertices.emplace_back(float(-side / 2 + i * step), float(-side / 2 + j * step), 0.8f);
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      m.triangles.push_back({a, c, b});  // wound so that the normal is −z
      m.triangles.push_back({b, c, d});
    }
  return m;
}

// Depth cameras on the −z side looking at (0, 0, 0.8) from `degrees` off the plane's normal
// (turned about y), 0.8 m away.
Iso3 cameraAt(double degrees) {
  const double a = degrees * M_PI / 180;
  const Vec3 target(0, 0, 0.8), eye = target + 0.8 * Vec3(-std::sin(a), 0, -std::cos(a));
  Iso3 T = Iso3::Identity();
  const Vec3 z = (target - eye).normalized(), x = Vec3(0, 1, 0).cross(z).normalized();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}
}  // namespace

// A plane of one colour seen from 35°, 45° and 55° (never head-on) under a light at the camera
// that takes 60 % of the brightness away at grazing angles: the fall-off is found from the
// frames and divided out, the plane's colour comes back. Lit evenly, the fall-off found is 0.
TEST(ColourFrames, TheShadingFallOffIsFoundAndDividedOut) {
  DepthCameraOptions cam;
  cam.colour.enabled = true;
  const Vec3f albedo = rgb(180, 120, 60);
  const TriangleMesh grid = planeGrid(0.16, 0.004);
  for (double k : {0.6, 0.0}) {
    ColourFrames frames(size_t(64) << 20);
    for (double deg : {35.0, 45.0, 55.0}) {
      const Iso3 T = cameraAt(deg);
      const PlaneFrame f = renderPlane(
          cam, T, Vec3(0, 0, 0.8), Vec3(0, 0, -1), [&](const Vec3&) { return albedo; }, k);
      frames.add(f.depth, f.colour, T, cam, std::vector<float>(f.depth.depth_m.size(), 0.002f));
    }
    EXPECT_EQ(frames.frames(), 3u);
    Aabb box;
    box.extend(Vec3(-0.1, -0.1, 0.7));
    box.extend(Vec3(0.1, 0.1, 0.9));
    VolumeOptions vo;
    vo.voxel_size_m = 0.004;
    const ColourVolume none(TsdfVolume(box, vo));
    double falloff = -1;
    const auto rgba = vertexColours(frames, none, grid, true, &falloff);
    EXPECT_NEAR(falloff, k, 0.03);
    double worst = 0;
    for (const auto& c : rgba) {
      ASSERT_EQ(c[3], 255);
      worst = std::max(worst, deltaE76(rgb(c[0], c[1], c[2]), albedo));
    }
    EXPECT_LT(worst, 2.0) << "fall-off " << k;
    // Without a light at the camera, nothing is divided out: the colour is darker (the 35°
    // view's shading, 0.89, and less).
    if (k > 0) {
      const auto seen = vertexColours(frames, none, grid, false, &falloff);
      EXPECT_EQ(falloff, 0.0);
      const size_t mid = grid.vertices.size() / 2;
      const double divided = deltaE76(rgb(rgba[mid][0], rgba[mid][1], rgba[mid][2]), albedo);
      const double seenDe = deltaE76(rgb(seen[mid][0], seen[mid][1], seen[mid][2]), albedo);
      EXPECT_GT(seenDe, 2.5);  // 2.9 measured
      EXPECT_GT(seenDe, 3 * divided);
    }
  }
}

// The tilted checkerboard of TheColourCamerasPoseIsHonoured, imaged from three directions: the
// frames kept give the squares at the colour camera's resolution, the volume's voxels (2 mm)
// blur a band either side of every edge; a finger in front of the plane in one frame (pixels
// flagged as the robot's, 10 cm nearer) does not colour the plane behind it.
TEST(ColourFrames, ColoursComeAtTheCamerasResolutionAndNotFromTheRobot) {
  DepthCameraOptions cam;
  cam.colour.enabled = true;
  auto checker = [](const Vec3& p) {
    const bool a = (int(std::floor(p.x() / 0.02)) + int(std::floor(p.y() / 0.02))) % 2 == 0;
    return a ? rgb(200, 40, 40) : rgb(235, 225, 190);
  };
  const TriangleMesh grid = planeGrid(0.14, 0.0013);
  Aabb box;
  box.extend(Vec3(-0.1, -0.1, 0.7));
  box.extend(Vec3(0.1, 0.1, 0.9));
  VolumeOptions vo;
  vo.voxel_size_m = 0.002;
  const TsdfVolume volume(box, vo);
  ColourVolume cv(volume);
  ColourFrames frames(size_t(64) << 20);
  for (double deg : {-15.0, 0.0, 15.0}) {
    const Iso3 T = cameraAt(deg);
    PlaneFrame f = renderPlane(cam, T, Vec3(0, 0, 0.8), Vec3(0, 0, -1), checker, 0.0);
    std::vector<uint8_t> robot(f.depth.depth_m.size(), 0);
    if (deg == 0) {
      // A green finger 10 cm in front of the plane: columns 300-340 of the depth image, and
      // where the colour camera sees it.
      for (int v = 0; v < f.depth.height; ++v)
        for (int u = 300; u < 340; ++u) {
          f.depth.at(u, v) -= 0.1f;
          robot[size_t(v) * size_t(f.depth.width) + size_t(u)] = 1;
        }
      const Iso3 T_RGB_D = cam.colour.T_D_RGB.inverse();
      for (int v = 0; v < f.depth.height; ++v)
        for (int u = 300; u < 340; ++u) {
          const Vec3 q = T_RGB_D * (cam.intrinsics.rayZ1(u, v) * double(f.depth.at(u, v)));
          const Vec2 px = cam.colour.intrinsics.project(q);
          for (int du = -1; du <= 1; ++du) {
            const int cu = int(std::lround(px.x())) + du, cv_ = int(std::lround(px.y()));
            if (cu < 0 || cv_ < 0 || cu >= f.colour.width || cv_ >= f.colour.height) continue;
            uint8_t* c = f.colour.at(cu, cv_);
            c[0] = 20, c[1] = 220, c[2] = 20;
          }
        }
    }
    const std::vector<float> sigma(f.depth.depth_m.size(), 0.002f);
    integrateColour(f.depth, f.colour, T, cam, sigma, &cv, &robot);
    frames.add(f.depth, f.colour, T, cam, sigma, &robot);
  }
  double fromFrames = 0, fromVoxels = 0;
  int n = 0, green = 0;
  const auto rgba = vertexColours(frames, cv, grid, false);
  for (size_t i = 0; i < grid.vertices.size(); ++i) {
    const Vec3 p = grid.vertices[i].cast<double>();
    if (std::abs(p.x()) > 0.06 || std::abs(p.y()) > 0.06) continue;
    Vec3f c, v;
    ASSERT_TRUE(frames.at(p, Vec3(0, 0, -1), &c)) << p.transpose();
    ASSERT_TRUE(cv.at(p, &v));
    fromFrames += deltaE76(c, checker(p));
    fromVoxels += deltaE76(v, checker(p));
    const Vec3f got = rgb(rgba[i][0], rgba[i][1], rgba[i][2]);
    green += deltaE76(got, rgb(20, 220, 20)) < 40;
    ++n;
  }
  ASSERT_GT(n, 5000);
  fromFrames /= n;
  fromVoxels /= n;
  std::printf("checkerboard plane: mean dE76 from the frames %.2f, from the voxels %.2f\n",
              fromFrames, fromVoxels);
  // 1.5 mm pixels at 0.8 m: what is left is the band within a pixel of each edge (5.1 and 9.0
  // measured).
  EXPECT_LT(fromFrames, 0.7 * fromVoxels);
  EXPECT_LT(fromFrames, 6.5);
  EXPECT_EQ(green, 0);
}

// A checkerboard plane (its squares' edges off the vertex grid) seen from five directions
// (−20° to 20°, 1.5 mm pixels); the head-on frame and the 10° one are added with their poses
// off by 0.8 mm and 0.6 mm along the plane (the colour images were taken at the true poses; the
// plane's depth does not show the error), and between them they carry 44 % of the weight. Their
// colours fall across the squares' edges up to 1.55 mm (their error and half a pixel) from
// them; the three right frames are outvoted nowhere beyond half a pixel (0.8 mm). Every vertex
// over 1 mm from an edge takes its square's colour: a weighted mean of the five would put a
// blend up to 44 % the other square's colour (ΔE 36) on those up to 1.55 mm from an edge.
TEST(ColourFrames, SightsThatFellAcrossAnEdgeAreOutvoted) {
  DepthCameraOptions cam;
  cam.colour.enabled = true;
  const double phase_x = 0.0037, phase_y = 0.0061, square = 0.02;
  auto checker = [&](const Vec3& p) {
    const bool a = (int(std::floor((p.x() + phase_x) / square)) +
                    int(std::floor((p.y() + phase_y) / square))) %
                       2 ==
                   0;
    return a ? rgb(200, 40, 40) : rgb(235, 225, 190);
  };
  auto toEdge = [&](const Vec3& p) {
    auto d = [&](double x) {
      const double f = std::fmod(x, square) + (x < 0 ? square : 0);
      return std::min(f, square - f);
    };
    return std::min(d(p.x() + phase_x), d(p.y() + phase_y));
  };
  const TriangleMesh grid = planeGrid(0.14, 0.0013);
  ColourFrames frames(size_t(64) << 20);
  const std::vector<double> degrees{-20, -10, 0, 10, 20};
  const std::vector<Vec3> off_O{Vec3::Zero(), Vec3::Zero(), Vec3(0.0008, 0, 0), Vec3(0, -0.0006, 0),
                                Vec3::Zero()};
  for (size_t k = 0; k < degrees.size(); ++k) {
    const Iso3 T = cameraAt(degrees[k]);
    const PlaneFrame f = renderPlane(cam, T, Vec3(0, 0, 0.8), Vec3(0, 0, -1), checker, 0.0);
    frames.add(f.depth, f.colour, Eigen::Translation3d(off_O[k]) * T, cam,
               std::vector<float>(f.depth.depth_m.size(), 0.002f));
  }
  ASSERT_EQ(frames.frames(), degrees.size());
  int far = 0, farRight = 0, near = 0;
  double farSum = 0, all = 0;
  for (const Vec3f& v : grid.vertices) {
    const Vec3 p = v.cast<double>();
    if (std::abs(p.x()) > 0.05 || std::abs(p.y()) > 0.05) continue;
    Vec3f c;
    ASSERT_TRUE(frames.at(p, Vec3(0, 0, -1), &c)) << p.transpose();
    const double de = deltaE76(c, checker(p));
    all += de;
    if (toEdge(p) > 0.001) {
      ++far;
      farSum += de;
      farRight += de < 3;
    } else {
      ++near;
    }
  }
  ASSERT_GT(far, 4000);
  std::printf(
      "%d vertices over 1 mm from an edge: mean dE76 %.2f, %d within 3; %d nearer: "
      "mean dE76 over all %.2f\n",
      far, farSum / far, farRight, near, all / (far + near));
  EXPECT_EQ(farRight, far);
  EXPECT_LT(farSum / far, 1.0);
  // 2.75 measured; the five frames' weighted mean: 3.51, and 15 of the far vertices off.
  EXPECT_LT(all / (far + near), 3.1);
}

// Over the budget, every other frame goes and from then on every other one is kept: the frames
// stay spread over the whole sequence, and the memory within the budget.
TEST(ColourFrames, TheBudgetKeepsFramesSpreadOverTheSequence) {
  DepthCameraOptions cam;
  cam.colour.enabled = true;
  const PlaneFrame f = renderPlane(
      cam, cameraAt(0), Vec3(0, 0, 0.8), Vec3(0, 0, -1),
      [](const Vec3&) { return rgb(90, 90, 90); }, 0.0);
  const std::vector<float> sigma(f.depth.depth_m.size(), 0.002f);
  ColourFrames one(size_t(1) << 30);
  one.add(f.depth, f.colour, cameraAt(0), cam, sigma);
  const size_t frameBytes = one.bytes();
  ASSERT_GT(frameBytes, 0u);
  ColourFrames frames(5 * frameBytes);
  for (int i = 0; i < 21; ++i) frames.add(f.depth, f.colour, cameraAt(0), cam, sigma);
  // 21 frames into room for 5: stride 4 keeps frames 0, 4, 8, 12, 16, 20 — over; stride 8:
  // 0, 8, 16.
  EXPECT_LE(frames.bytes(), 5 * frameBytes);
  EXPECT_EQ(frames.stride(), 8);
  EXPECT_EQ(frames.frames(), 3u);
  // Written and read back, the same; data cut short is refused.
  std::stringstream out;
  frames.write(out);
  ColourFrames back(5 * frameBytes);
  EXPECT_EQ(back.read(out), "");
  EXPECT_EQ(back.frames(), 3u);
  EXPECT_EQ(back.bytes(), frames.bytes());
  EXPECT_EQ(back.stride(), 8);
  const std::string data = [&] {
    std::stringstream s;
    frames.write(s);
    return s.str();
  }();
  std::stringstream cut(data.substr(0, data.size() / 2));
  EXPECT_EQ(back.read(cut), "colour frames cut short");
  EXPECT_TRUE(back.empty());
}

TEST(Colour, AScanGetsTheCheckerBoxsColours) {
  ScanConfig config = test::quickScanConfig(2);
  config.sim.colour.enabled = true;
  config.sim.colour.ambient = 1.0;  // no shading: what is left is resolution and registration
  const TriangleMesh box = loadObject("builtin:cracker_box");
  const SurfaceColours colours = checkerColours(box, kBuiltinCheckerSquare_m);
  const SimulatedScan s = runSimulatedScan(test::wam(), box, config, {}, {}, colours);
  const ObjectModel& m = s.result.scan.model;
  ASSERT_EQ(m.rgba.size(), m.mesh.vertices.size());
  EXPECT_GT(s.result.scan.colour_pixels, 0);
  EXPECT_GT(s.colour.vertices, int(0.8 * double(m.mesh.vertices.size())));
  std::printf("checker box scan: mean dE76 %.2f, %.2f off edges, %.2f at edges\n",
              s.colour.delta_e_mean, s.colour.delta_e_mean_off_edges,
              s.colour.delta_e_mean_at_edges);
  // 2 cm squares: the colours come from the frames kept (ColourFrames), blurred within about a
  // pixel of each edge, not from the 4 mm voxels (11.4 from them).
  EXPECT_LT(s.colour.delta_e_mean, 5.0);  // 2.9 measured
  // The squares' edges lie where they should: more than 1 mm from any true edge (a quarter of
  // the 4 mm voxels) the colours are right, the error sits within that millimetre.
  EXPECT_LT(s.colour.delta_e_mean_off_edges, 3.0);  // 1.5 measured (9.9 at edges)
  EXPECT_GT(s.colour.delta_e_mean_at_edges, s.colour.delta_e_mean_off_edges);
  // The hand, blue in the colour camera, colours no observed vertex: none lies within ΔE 3 of
  // its blue, nor nearer to it than to both of the squares' colours (a half-and-half blend).
  // (12 did when the sights at depth edges counted a tenth: the fingers' rims.)
  const auto& robotRgb = config.sim.colour.robot;
  const Vec3f robot(robotRgb[0], robotRgb[1], robotRgb[2]);
  const Vec3f red(200, 40, 40), cream(235, 225, 190);  // checkerColours' defaults
  int blue = 0;
  for (size_t i = 0; i < m.rgba.size(); ++i) {
    if (m.rgba[i][3] != 255 || !m.observed[i]) continue;
    const Vec3f c(m.rgba[i][0], m.rgba[i][1], m.rgba[i][2]);
    const double toRobot = deltaE76(c, robot);
    if (toRobot < 3 || (toRobot < deltaE76(c, red) && toRobot < deltaE76(c, cream))) ++blue;
  }
  EXPECT_EQ(blue, 0);
  // Unlit: no fall-off with the viewing angle is found.
  EXPECT_LT(s.result.scan.colour_shading_falloff, 0.1);
  EXPECT_GT(s.result.scan.colour_frames_kept, 20);
  // The same scan against a truth in other colours is far off: the measure can fail.
  const SurfaceColours other =
      checkerColours(box, kBuiltinCheckerSquare_m, {20, 120, 20}, {30, 30, 30});
  EXPECT_GT(colourAccuracy(m, box, other).delta_e_mean, 40.0);
}

// The colour measure's split at the truth's colour edges, against geometry: points 0.5 mm apart on
// the top face of a box with the 2 cm checkerboard. With their true colours, the share at an edge
// is that of the points within 1 mm of a square's edge (±0.31 mm, the checker texture's own
// bilinear blur), and ΔE is 0; with each point coloured as the truth 0.8 mm beside it (a
// texture misregistered by less than a pixel), the error lies at the edges only.
TEST(Colour, TheColourMeasureSplitsItsErrorAtTheTruthsEdges) {
  const TriangleMesh box = makeBox(Vec3(0.2, 0.2, 0.02));
  const SurfaceColours checker = checkerColours(box, 0.02);
  const Aabb b = box.bounds();
  const TriangleDistanceIndex index(box);
  auto trueColour = [&](const Vec3& p) {
    int tri = -1;
    Vec3 q;
    index.nearest(p, &tri, &q);
    const Tri& f = box.triangles[size_t(tri)];
    const Vec3 a = box.vertices[size_t(f[0])].cast<double>();
    const Vec3 e1 = box.vertices[size_t(f[1])].cast<double>() - a;
    const Vec3 e2 = box.vertices[size_t(f[2])].cast<double>() - a;
    const Eigen::Matrix<double, 3, 2> E = (Eigen::Matrix<double, 3, 2>() << e1, e2).finished();
    const Vec2 bc = E.colPivHouseholderQr().solve(q - a);
    return checker.at(box, tri, float(bc.x()), float(bc.y()));
  };
  for (const double shift : {0.0, 0.0008}) {
    ObjectModel m;
    int near = 0;
    for (double x = b.min.x() + 0.01; x <= b.max.x() - 0.01; x += 0.0005)
      for (double y = b.min.y() + 0.01; y <= b.max.y() - 0.01; y += 0.0005) {
        const Vec3 p(x, y, b.max.z());
        m.mesh.vertices.push_back(p.cast<float>());
        const Vec3f c = trueColour(p + Vec3(shift, 0, 0));
        m.rgba.push_back({uint8_t(std::lround(c[0])), uint8_t(std::lround(c[1])),
                          uint8_t(std::lround(c[2])), 255});
        // Within 1 mm of a square's edge (x or y a multiple of 2 cm).
        auto toLine = [](double t) { return std::abs(t / 0.02 - std::round(t / 0.02)) * 0.02; };
        near += std::min(toLine(x), toLine(y)) < 0.001;
      }
    const ColourMetrics cm = colourAccuracy(m, box, checker);
    ASSERT_EQ(cm.vertices, int(m.mesh.vertices.size()));
    const double want = double(near) / double(cm.vertices);  // 0.19
    EXPECT_NEAR(cm.edge_share, want, 0.06) << "shift " << shift;
    EXPECT_LT(cm.delta_e_mean_off_edges, 0.5) << "shift " << shift;
    if (shift == 0) {
      EXPECT_LT(cm.delta_e_mean, 0.5);
    } else {
      // Wrong within 0.8 mm of the edges across x (ΔE up to 81), right along y's: 16 measured.
      EXPECT_GT(cm.delta_e_mean_at_edges, 10.0);
      EXPECT_GT(cm.delta_e_mean, 2.0);
      EXPECT_NEAR(cm.delta_e_mean,
                  cm.edge_share * cm.delta_e_mean_at_edges +
                      (1 - cm.edge_share) * cm.delta_e_mean_off_edges,
                  1e-9);
    }
  }
}

// Real Kinect frames (../shared/data/sevenscenes: 50 frames of a 7-Scenes sequence, colour not
// registered to depth): 40 fused with their colours by `inhand fuse`; the model's colours
// checked against the 10 frames held out, where each of those sees a model vertex (its depth
// there within 2 cm of the vertex's). The same check against each held-out frame's colours at
// pixels shifted half an image away is far off: the check can fail.
TEST(Colour, RealKinectFramesFuseWithTheirColours) {
  const fs::path data = fs::path(INHAND_SOURCE_DIR) / ".." / "shared" / "data" / "sevenscenes";
  if (!fs::is_directory(data)) GTEST_SKIP() << data << " not found";
  test::TempDir dir;
  FrameSet all;
  all.intrinsics = CameraIntrinsics{640, 480, 585, 585, 320, 240};
  all.colour.enabled = true;
  all.colour.intrinsics = all.intrinsics;
  all.colour.T_D_RGB = Iso3::Identity();
  std::vector<FrameRecord> held;
  for (int f = 0; f < 1000; f += 20) {
    char stem[32];
    std::snprintf(stem, sizeof stem, "frame-%06d", f);
    std::ifstream in(data / (std::string(stem) + ".pose.txt"));
    Eigen::Matrix4d M;
    for (int k = 0; k < 16; ++k) in >> M(k / 4, k % 4);
    ASSERT_TRUE(in) << stem;
    Iso3 T = Iso3::Identity();
    // Rotations orthonormal to ~1e-4 only: the nearest rotation (as readFrameSet would use).
    Eigen::JacobiSVD<Mat3> svd(M.topLeftCorner<3, 3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
    T.linear() = svd.matrixU() * svd.matrixV().transpose();
    T.translation() = M.topRightCorner<3, 1>();
    FrameRecord r((data / (std::string(stem) + ".depth.png")).string(), T);
    r.colour_file = (data / (std::string(stem) + ".color.jpg")).string();
    ((f / 20) % 5 == 4 ? held : all.frames).push_back(r);
  }
  writeFrameSet(dir.path(), all);
  const fs::path model = dir.path() / "scene.ply";
  const test::CommandResult r =
      test::runInhand("fuse --frames " + dir.path().string() + " --out " + model.string() +
                          " --voxel 0.02 --surface observed",
                      dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const PlyData ply = readPly(model);
  const auto& P = ply.vertexProperties;
  ASSERT_TRUE(P.count("red") && P.count("alpha"));
  size_t coloured = 0;
  for (float a : P.at("alpha")) coloured += a == 255;
  EXPECT_GT(double(coloured), 0.9 * double(ply.mesh.vertices.size()));  // 96.2 % measured
  // Beside the PLY, the textured forms: the glb as assimp reads it has the PLY's surface area
  // (its node turns it y-up; the area does not change).
  for (const char* f : {"scene.glb", "scene.obj", "scene.mtl", "scene_texture.png"})
    EXPECT_TRUE(fs::exists(dir.path() / f)) << f;
  EXPECT_NEAR(importMesh(dir.path() / "scene.glb").area(), ply.mesh.area(), 1e-3 * ply.mesh.area());
  std::vector<double> de, shifted;
  for (const FrameRecord& h : held) {
    const DepthImage depth = readDepthPng(h.file, 0.001, 640, 480);
    const RgbImage img = readRgbImage(h.colour_file);
    const Iso3 T_C_O = h.T_O_C.inverse();
    for (size_t i = 0; i < ply.mesh.vertices.size(); i += 7) {
      if (P.at("alpha")[i] != 255) continue;
      const Vec3 p = T_C_O * ply.mesh.vertices[i].cast<double>();
      if (p.z() < 0.3) continue;
      const Vec2 uv = all.intrinsics.project(p);
      const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
      if (u < 0 || v < 0 || u >= 640 || v >= 480) continue;
      if (!(std::abs(depth.at(u, v) - p.z()) < 0.02)) continue;
      const Vec3f c(P.at("red")[i], P.at("green")[i], P.at("blue")[i]);
      de.push_back(deltaE76(c, img.bilinear(uv.x(), uv.y())));
      shifted.push_back(deltaE76(c, img.bilinear((u + 320) % 640, (v + 240) % 480)));
    }
  }
  ASSERT_GT(de.size(), 1000u);
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  std::printf("held-out frames: %zu vertex views, median dE76 %.1f (shifted %.1f)\n", de.size(),
              median(de), median(shifted));
  EXPECT_LT(median(de), 13.0);  // 11.6 measured
  EXPECT_GT(median(shifted), 2 * median(de));
}

namespace {
// A sphere whose vertices carry a colour linear in their position, alpha 0 on its top cap.
std::vector<std::array<uint8_t, 4>> linearColours(const TriangleMesh& mesh) {
  std::vector<std::array<uint8_t, 4>> rgba;
  for (const Vec3f& v : mesh.vertices)
    rgba.push_back({uint8_t(std::lround(128 + 1200 * v.x())),
                    uint8_t(std::lround(128 + 1200 * v.y())),
                    uint8_t(std::lround(128 + 1200 * v.z())), uint8_t(v.z() > 0.04f ? 0 : 255)});
  return rgba;
}
Vec4 interpolated(const std::vector<std::array<uint8_t, 4>>& rgba, const Tri& f, double b1,
                  double b2) {
  Vec4 c = Vec4::Zero();
  const double w[3] = {1 - b1 - b2, b1, b2};
  for (int k = 0; k < 3; ++k)
    for (int ch = 0; ch < 4; ++ch) c[ch] += w[k] * rgba[size_t(f[k])][size_t(ch)];
  return c;
}
// Bilinear sample of an RGBA atlas at (u, v) (v down, texel centres at (i + ½) / width).
Vec4 sampleAtlas(const TextureAtlas& a, double u, double v) {
  const double x = u * a.width - 0.5, y = v * a.height - 0.5;
  const int i = int(std::floor(x)), j = int(std::floor(y));
  const double fx = x - i, fy = y - j;
  Vec4 c = Vec4::Zero();
  for (int dj = 0; dj < 2; ++dj)
    for (int di = 0; di < 2; ++di) {
      const int ii = std::clamp(i + di, 0, a.width - 1), jj = std::clamp(j + dj, 0, a.height - 1);
      const double w = (di ? fx : 1 - fx) * (dj ? fy : 1 - fy);
      for (int ch = 0; ch < 4; ++ch)
        c[ch] += w * a.rgba[(size_t(jj) * size_t(a.width) + size_t(ii)) * 4 + size_t(ch)];
    }
  return c;
}
}  // namespace

// Per-vertex colours baked into an atlas come back from it anywhere on each triangle (bilinear,
// as a renderer samples it), from the written OBJ through inhand's own OBJ reader, and from the
// written glb through assimp's glTF 2.0 importer (an independent reader), whose node turns the
// z-up model y-up.
TEST(TextureAtlas, VertexColoursComeBackFromTheAtlasTheObjAndAssimpsGlb) {
  const TriangleMesh sphere = makeSphere(0.05, 3);
  const auto rgba = linearColours(sphere);
  const TextureAtlas atlas = bakeVertexColours(sphere, rgba, 0.001);
  ASSERT_EQ(atlas.uv.size(), sphere.triangles.size() * 3);
  EXPECT_DOUBLE_EQ(atlas.texel_m, 0.001);
  const double points[4][2] = {{1 / 3., 1 / 3.}, {0.1, 0.1}, {0.75, 0.15}, {0.15, 0.75}};
  double worst = 0;
  for (size_t t = 0; t < sphere.triangles.size(); ++t)
    for (const auto& b : points) {
      const Vec2f uv = (1 - b[0] - b[1]) * atlas.uv[3 * t] + float(b[0]) * atlas.uv[3 * t + 1] +
                       float(b[1]) * atlas.uv[3 * t + 2];
      const Vec4 want = interpolated(rgba, sphere.triangles[t], b[0], b[1]);
      const Vec4 got = sampleAtlas(atlas, uv.x(), uv.y());
      worst = std::max(worst, (want.head<3>() - got.head<3>()).cwiseAbs().maxCoeff());
      if (want[3] == 255 || want[3] == 0) {
        EXPECT_NEAR(got[3], want[3], 1.0) << t;
      }
    }
  EXPECT_LT(worst, 2.5);
  // A texel size the atlas cannot hold in 256 × 256 texels is doubled until it fits.
  const TextureAtlas coarse = bakeVertexColours(sphere, rgba, 0.0001, 256);
  EXPECT_LE(std::max(coarse.width, coarse.height), 256);
  EXPECT_GE(coarse.texel_m, 0.0001 * 8);
  EXPECT_THROW(bakeVertexColours(sphere, rgba, 0.0), Error);
  EXPECT_THROW(bakeVertexColours(sphere, {}, 0.001), Error);

  test::TempDir dir;
  writeTexturedObj(dir.path() / "m.obj", sphere, atlas);
  writeGlb(dir.path() / "m.glb", sphere, atlas);
  for (const char* f : {"m.obj", "m.mtl", "m_texture.png", "m.glb"})
    EXPECT_TRUE(fs::exists(dir.path() / f)) << f;
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 4);

  // inhand's OBJ reader: the same triangles, the same colours at their centres.
  const TexturedMesh obj = importTexturedMesh(dir.path() / "m.obj");
  ASSERT_EQ(obj.mesh.triangles.size(), sphere.triangles.size());
  double objWorst = 0;
  for (size_t t = 0; t < sphere.triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k)
      ASSERT_LT((obj.mesh.vertices[size_t(obj.mesh.triangles[t][k])] -
                 sphere.vertices[size_t(sphere.triangles[t][k])])
                    .norm(),
                1e-6f);
    const Vec3f got = obj.colours.at(obj.mesh, int(t), 1 / 3.f, 1 / 3.f);
    const Vec4 want = interpolated(rgba, sphere.triangles[t], 1 / 3., 1 / 3.);
    objWorst = std::max(objWorst, (want.head<3>() - got.cast<double>()).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(objWorst, 2.5);

  // assimp's glTF 2.0 importer: one mesh of the same triangles under a node that turns z up to
  // y up, one material whose base colour is the embedded PNG, the same colours at their centres.
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile((dir.path() / "m.glb").string(), 0);
  ASSERT_TRUE(scene) << importer.GetErrorString();
  ASSERT_EQ(scene->mNumMeshes, 1u);
  const aiMesh* mesh = scene->mMeshes[0];
  ASSERT_EQ(mesh->mNumFaces, sphere.triangles.size());
  ASSERT_TRUE(mesh->HasTextureCoords(0));
  ASSERT_TRUE(mesh->HasNormals());
  aiMatrix4x4 world;
  const aiNode* node = scene->mRootNode;
  while (node && node->mNumMeshes == 0 && node->mNumChildren > 0) {
    world = world * node->mTransformation;
    node = node->mChildren[0];
  }
  ASSERT_TRUE(node && node->mNumMeshes == 1);
  world = world * node->mTransformation;
  aiString texPath;
  const aiMaterial* mat = scene->mMaterials[mesh->mMaterialIndex];
  ASSERT_EQ(mat->GetTexture(aiTextureType_DIFFUSE, 0, &texPath), aiReturn_SUCCESS);
  const aiTexture* tex = scene->GetEmbeddedTexture(texPath.C_Str());
  ASSERT_TRUE(tex);
  ASSERT_EQ(tex->mHeight, 0u);  // compressed: the PNG's bytes
  {
    std::ofstream out(dir.path() / "embedded.png", std::ios::binary);
    out.write(reinterpret_cast<const char*>(tex->pcData), std::streamsize(tex->mWidth));
  }
  const RgbImage image = readRgbPng(dir.path() / "embedded.png");
  ASSERT_EQ(image.width, atlas.width);
  ASSERT_EQ(image.height, atlas.height);
  double glbWorst = 0, placed = 0;
  for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
    ASSERT_EQ(mesh->mFaces[f].mNumIndices, 3u);
    aiVector3D uv(0, 0, 0);
    for (int k = 0; k < 3; ++k) {
      const unsigned i = mesh->mFaces[f].mIndices[k];
      uv += mesh->mTextureCoords[0][i] / 3.f;
      const aiVector3D p = world * mesh->mVertices[i];
      const Vec3f& q = sphere.vertices[size_t(sphere.triangles[f][k])];
      placed =
          std::max(placed, double((Vec3f(p.x, p.y, p.z) - Vec3f(q.x(), q.z(), -q.y())).norm()));
    }
    // assimp gives texture coordinates with v up (it flips glTF's).
    const Vec3f got = image.bilinear(uv.x * image.width - 0.5, (1 - uv.y) * image.height - 0.5);
    const Vec4 want = interpolated(rgba, sphere.triangles[f], 1 / 3., 1 / 3.);
    glbWorst = std::max(glbWorst, (want.head<3>() - got.cast<double>()).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(placed, 1e-6);
  EXPECT_LT(glbWorst, 2.5);
}

// PSNR: a model with the truth's own colours renders as the truth does; a grey one does not.
TEST(Colour, PsnrOfTheTruthsOwnColoursIsPerfectAndOfGreyIsLow) {
  const TriangleMesh sphere = makeSphere(0.05, 3);
  SurfaceColours truth;
  ObjectModel m;
  m.mesh = sphere;
  for (const Vec3f& v : sphere.vertices) {
    const auto c = std::array<uint8_t, 3>{uint8_t(128 + 1200 * v.x()), uint8_t(128 + 1200 * v.y()),
                                          uint8_t(128 + 1200 * v.z())};
    truth.vertex_rgb.push_back(c);
    m.rgba.push_back({c[0], c[1], c[2], 255});
  }
  std::vector<RgbImage> images;
  EXPECT_GT(colourPsnr(m, sphere, truth, 8, &images), 60.0);
  EXPECT_EQ(images.size(), 16u);
  for (auto& c : m.rgba) c = {128, 128, 128, 255};
  const double grey = colourPsnr(m, sphere, truth, 8);
  EXPECT_GT(grey, 5.0);
  EXPECT_LT(grey, 30.0);
}

// A colour scan stopped midway and resumed from its checkpoint ends with the colours of the scan
// that was not stopped, vertex for vertex (same machine).
TEST(Colour, AResumedScanKeepsItsColours) {
  test::TempDir dir;
  ScanConfig config = test::quickScanConfig(2);
  config.sim.colour.enabled = true;
  const TexturedMesh can = loadSimulatedObject("builtin:coffee_can", true);
  const SimulatedScan whole = runSimulatedScan(test::wam(), can.mesh, config, {}, {}, can.colours);
  bool stop = false;
  int frames = 0;
  ScanProgress p;
  p.frame = [&](const FrameReport&, const JointVector&, const Iso3&) { stop = ++frames >= 12; };
  p.interrupted = [&] { return stop; };
  SimulatedScanCheckpoints cp;
  cp.file = dir.path() / "scan.inhand";
  runSimulatedScan(test::wam(), can.mesh, config, p, cp, can.colours);
  ASSERT_TRUE(fs::exists(cp.file));
  cp.resume = true;
  const SimulatedScan resumed =
      runSimulatedScan(test::wam(), can.mesh, config, {}, cp, can.colours);
  const ObjectModel &a = whole.result.scan.model, &b = resumed.result.scan.model;
  ASSERT_EQ(a.mesh.vertices.size(), b.mesh.vertices.size());
  ASSERT_EQ(a.rgba.size(), a.mesh.vertices.size());
  ASSERT_EQ(b.rgba.size(), b.mesh.vertices.size());
  for (size_t i = 0; i < a.rgba.size(); ++i) ASSERT_EQ(a.rgba[i], b.rgba[i]) << i;
  EXPECT_EQ(whole.result.scan.colour_pixels, resumed.result.scan.colour_pixels);
}
