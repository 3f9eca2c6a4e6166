#include <gtest/gtest.h>

#include <cstring>

#include <fstream>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/primitives.h"
#include "inhand/sensor/frame_set.h"
#include "inhand/sensor/render.h"
#include "test_util.h"

using namespace inhand;

TEST(NoiseModel, AxialSigmaMatchesNguyen) {
  NoiseModelOptions o;
  EXPECT_NEAR(axialSigma(o, 0.6, 0.0), 0.0013, 0.0001);  // 1.3 mm at 0.6 m head-on
  EXPECT_NEAR(axialSigma(o, 1.0, 0.0), 0.0012 + 0.0019 * 0.36, 1e-12);
  EXPECT_EQ(axialSigma(o, 1.0, 50 * M_PI / 180), axialSigma(o, 1.0, 0.0));  // below 60°: flat
  double t = 70 * M_PI / 180;
  EXPECT_NEAR(axialSigma(o, 1.0, t),
              0.0012 + 0.0019 * 0.36 + 0.0001 * t * t / std::pow(M_PI / 2 - t, 2), 1e-12);
  EXPECT_NEAR(lateralSigmaPx(o, 0.0), 0.8, 1e-12);
  // Disparity step z²/(8 f b): 1.14 mm at 0.6 m for f = 525 px, b = 7.5 cm.
  double z = 0.6, step = z * z / (8 * 525 * 0.075);
  double q1 = quantizeDepth(z, 525, 0.075, 0.125), q2 = quantizeDepth(z + step, 525, 0.075, 0.125);
  EXPECT_NEAR(q2 - q1, step, 0.05 * step);
}

// Empirical σ of a rendered head-on plane at 0.6 m: the noise model plus quantisation.
TEST(Render, NoiseSigmaAtSixtyCentimetresHeadOn) {
  RayScene scene;
  TriangleMesh plane = makeBox(Vec3(2, 2, 0.01));
  scene.addMesh(plane, Iso3(Eigen::Translation3d(0, 0, 0.605)));  // front face at z = 0.6
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  RenderOptions ro;
  ro.seed = 5;
  DepthImage d = renderDepth(scene, Iso3::Identity(), cam, nm, ro);
  double s = 0, s2 = 0;
  int n = 0;
  for (int v = 100; v < 380; ++v)
    for (int u = 100; u < 540; ++u) {
      double e = d.at(u, v) - 0.6;
      s += e;
      s2 += e * e;
      ++n;
    }
  double mean = s / n, sigma = std::sqrt(s2 / n - mean * mean);
  EXPECT_NEAR(sigma, 0.0013, 0.0001);
  EXPECT_NEAR(mean, 0.0, 0.0003);
  // Same seed, same image; another seed, another image.
  DepthImage again = renderDepth(scene, Iso3::Identity(), cam, nm, ro);
  EXPECT_EQ(again.depth_m, d.depth_m);
  ro.seed = 6;
  EXPECT_NE(renderDepth(scene, Iso3::Identity(), cam, nm, ro).depth_m, d.depth_m);
}

TEST(Render, NoiseFreeDepthMatchesAnalyticSphere) {
  const double r = 0.1;
  RayScene scene;
  scene.addMesh(makeSphere(r, 6));
  scene.commit();
  DepthCameraOptions cam;
  cam.projector_C = Vec3(1e-6, 0, 0);  // no stereo shadow on a convex object anyway
  Iso3 T_O_C = lookAt(Vec3(0.3, -0.5, 0.4).normalized() * 0.8, Vec3::Zero());
  RenderOptions ro;
  ro.noise = false;
  DepthImage d = renderDepth(scene, T_O_C, cam, NoiseModelOptions{}, ro);
  const Vec3 o = T_O_C.translation();
  int compared = 0, disagree = 0;
  for (int v = 0; v < 480; ++v)
    for (int u = 0; u < 640; ++u) {
      Vec3 dir = T_O_C.linear() * cam.intrinsics.rayZ1(u, v);  // z = 1 in the camera
      double a = dir.squaredNorm(), b = o.dot(dir), c = o.squaredNorm() - r * r;
      double disc = b * b - a * c;
      bool hit = disc > 0;
      double z = hit ? (-b - std::sqrt(disc)) / a : 0;
      // Within 80° incidence the sensor returns; allow the silhouette band to disagree.
      Vec3 n = (o + z * dir).normalized();
      double cosInc = std::abs(n.dot(dir.normalized()));
      if (hit && cosInc < std::cos(78 * M_PI / 180)) continue;
      if (!hit && disc > -1e-4 * a * r * r) continue;
      if (hit != (d.at(u, v) > 0)) {
        ++disagree;
        continue;
      }
      if (!hit) continue;
      ++compared;
      EXPECT_NEAR(d.at(u, v), z, 3e-4);
    }
  EXPECT_GT(compared, 10000);
  EXPECT_LE(disagree, compared / 2000);  // facet normals vs the true normal at the 80° cut-off
}

TEST(Render, OptimisedMatchesScalarReference) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(0.06, 0.158, 0.21)));
  scene.addMesh(makeSphere(0.04, 4), Iso3(Eigen::Translation3d(0.05, 0.05, 0.12)));
  scene.commit();
  DepthCameraOptions cam;
  Iso3 T_O_C = lookAt(Vec3(0.5, 0.3, 0.35), Vec3::Zero());
  RenderOptions ro;
  ro.noise = false;
  std::vector<int> geom;
  DepthImage fast = renderDepth(scene, T_O_C, cam, NoiseModelOptions{}, ro, &geom);
  DepthImage ref = renderDepthReference(scene, T_O_C, cam);
  int returns = 0;
  for (size_t i = 0; i < fast.depth_m.size(); ++i) {
    EXPECT_FLOAT_EQ(fast.depth_m[i], ref.depth_m[i]);
    returns += ref.depth_m[i] > 0;
    EXPECT_EQ(geom[i] >= 0, fast.depth_m[i] > 0);
  }
  EXPECT_GT(returns, 5000);
}

// The per-pixel steps four pixels at a time (AVX2) give the image of the one-at-a-time steps bit
// for bit: every failure mode in view (misses into the room, grazing silhouettes, returns nearer
// than the minimum range, projector shadows), with noise and without, quantised and not, over a
// region whose width leaves pixels after the last four.
TEST(Render, VectorisedStepsMatchTheScalarOnes) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(0.06, 0.158, 0.21)));
  scene.addMesh(makeSphere(0.04, 4), Iso3(Eigen::Translation3d(0.05, 0.05, 0.12)));
  scene.addMesh(makeBox(Vec3(0.3, 0.002, 0.3)), Iso3(Eigen::Translation3d(0.2, -0.1, -0.1)));
  scene.commit();
  DepthCameraOptions cam;
  const Iso3 T_O_C = lookAt(Vec3(0.45, 0.3, 0.35), Vec3::Zero());
  struct Case {
    bool noise, quantize, region;
    double room_m;
  };
  int compared = 0;
  for (const Case& c : {Case{true, true, false, 2.5}, Case{true, false, true, 2.5},
                        Case{false, true, false, 2.5}, Case{true, true, false, 0}}) {
    NoiseModelOptions noise;
    noise.quantize = c.quantize;
    RenderOptions ro;
    ro.noise = c.noise;
    ro.seed = 7;
    ro.background_radius_m = c.room_m;
    if (c.region) {
      ro.region_u0 = 101;
      ro.region_v0 = 57;
      ro.region_u1 = 498;
      ro.region_v1 = 402;
    }
    std::vector<int> geomFast, geomOne;
    ro.vectorised = true;
    const DepthImage fast = renderDepth(scene, T_O_C, cam, noise, ro, &geomFast);
    ro.vectorised = false;
    const DepthImage one = renderDepth(scene, T_O_C, cam, noise, ro, &geomOne);
    ASSERT_EQ(fast.depth_m.size(), one.depth_m.size());
    int same = 0, room = 0;
    for (size_t i = 0; i < one.depth_m.size(); ++i) {
      same += std::memcmp(&fast.depth_m[i], &one.depth_m[i], sizeof(float)) == 0 &&
              geomFast[i] == geomOne[i];
      room += geomOne[i] == scene.geometryCount();
    }
    EXPECT_EQ(same, int(one.depth_m.size()));
    if (c.room_m > 0) {
      EXPECT_GT(room, 10000);
    }
    compared +=
        std::count_if(one.depth_m.begin(), one.depth_m.end(), [](float z) { return z > 0; });
  }
  EXPECT_GT(compared, 300000);
}

// A region renders exactly the whole image's pixels there (noise is seeded per pixel) and
// nothing elsewhere; without projector shadows the shadowed pixels return the surface.
TEST(Render, RegionAndNoShadowOptions) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(0.1, 0.1, 0.1)), Iso3(Eigen::Translation3d(0, 0, 0.7)));
  scene.addMesh(makeBox(Vec3(3, 3, 0.02)), Iso3(Eigen::Translation3d(0, 0, 1.01)));
  scene.commit();
  DepthCameraOptions cam;
  RenderOptions ro;
  ro.seed = 7;
  const DepthImage whole = renderDepth(scene, Iso3::Identity(), cam, NoiseModelOptions{}, ro);
  ro.region_u0 = 101;
  ro.region_v0 = 50;
  ro.region_u1 = 383;
  ro.region_v1 = 301;
  const DepthImage part = renderDepth(scene, Iso3::Identity(), cam, NoiseModelOptions{}, ro);
  int inside = 0;
  for (int v = 0; v < whole.height; ++v)
    for (int u = 0; u < whole.width; ++u) {
      const bool in = u >= 101 && u < 383 && v >= 50 && v < 301;
      if (in) {
        ASSERT_EQ(part.at(u, v), whole.at(u, v)) << u << " " << v;
        inside += part.at(u, v) > 0;
      } else {
        ASSERT_EQ(part.at(u, v), 0.f) << u << " " << v;
      }
    }
  EXPECT_GT(inside, 50000);
  RenderOptions exact;
  exact.noise = false;
  const DepthImage shadowed = renderDepth(scene, Iso3::Identity(), cam, NoiseModelOptions{}, exact);
  exact.projector_shadows = false;
  const DepthImage lit = renderDepth(scene, Iso3::Identity(), cam, NoiseModelOptions{}, exact);
  int holes = 0;
  for (size_t i = 0; i < lit.depth_m.size(); ++i) {
    if (shadowed.depth_m[i] > 0) {
      EXPECT_EQ(lit.depth_m[i], shadowed.depth_m[i]);
    }
    holes += shadowed.depth_m[i] == 0 && lit.depth_m[i] > 0;
  }
  EXPECT_GT(holes, 1000);  // the box's projector shadow on the wall
}

// The analytic background (the simulator's room) against the same sphere as a fine mesh: the
// object's pixels are the same, the room's agree to within the mesh's chordal sag, and the object
// shadows the room where the projector cannot see it.
TEST(Render, AnalyticBackgroundMatchesATessellatedSphere) {
  const double radius = 2.5;
  const Vec3 centre(0.1, -0.05, 0.0);
  const TriangleMesh box = makeBox(Vec3(0.06, 0.158, 0.21));
  RayScene analytic;
  analytic.addMesh(box);
  analytic.commit();
  RayScene meshed;
  meshed.addMesh(box);
  const TriangleMesh room = makeSphere(radius, 6);
  meshed.addMesh(room, Iso3(Eigen::Translation3d(centre)));
  meshed.commit();
  DepthCameraOptions cam;
  const Iso3 T_O_C = lookAt(Vec3(0.5, 0.3, 0.35), Vec3::Zero());
  RenderOptions ro;
  ro.noise = false;
  std::vector<int> ga, gm;
  DepthImage a = renderDepth(meshed, T_O_C, cam, NoiseModelOptions{}, ro, &gm);
  ro.background_centre = centre;
  ro.background_radius_m = radius;
  DepthImage b = renderDepth(analytic, T_O_C, cam, NoiseModelOptions{}, ro, &ga);
  // The largest sag of the mesh: its longest edge's chord below the sphere.
  double longest = 0;
  for (const Tri& t : room.triangles)
    for (int k = 0; k < 3; ++k)
      longest = std::max(
          longest,
          double((room.vertices[size_t(t[k])] - room.vertices[size_t(t[(k + 1) % 3])]).norm()));
  const double sag = radius - std::sqrt(radius * radius - 0.25 * longest * longest);
  int object = 0, background = 0, shadowed = 0, differ = 0;
  for (size_t i = 0; i < a.depth_m.size(); ++i) {
    if (ga[i] == 0) {
      ++object;
      EXPECT_EQ(gm[i], 0);
      EXPECT_FLOAT_EQ(b.depth_m[i], a.depth_m[i]);
    } else if (ga[i] == 1) {
      ++background;
      if (gm[i] != 1) {
        ++differ;  // a shadow edge a sub-millimetre shift of the wall moves
        continue;
      }
      // depth is z in the camera; the ray's length differs from it by at most 1/cos of the FOV
      EXPECT_NEAR(b.depth_m[i], a.depth_m[i], 1.5 * sag);
      EXPECT_GE(b.depth_m[i], a.depth_m[i] - 1e-4);  // the mesh lies inside the sphere
    } else {
      shadowed += gm[i] < 0;
    }
  }
  EXPECT_GT(object, 5000);
  EXPECT_GT(background, 200000);
  EXPECT_GT(shadowed, 100);  // the box's projector shadow on the room
  EXPECT_LT(differ, background / 1000);
  EXPECT_EQ(analytic.geometryCount(), 1);
}

// A box in front of a wall casts a projector shadow on the wall: exactly the wall pixels whose
// point the projector cannot see return nothing.
TEST(Render, ProjectorShadowMatchesAnalyticOcclusion) {
  const Vec3 lo(-0.05, -0.05, 0.65), hi(0.05, 0.05, 0.75);
  RayScene scene;
  scene.addMesh(makeBox(hi - lo), Iso3(Eigen::Translation3d(0.5 * (lo + hi))));
  scene.addMesh(makeBox(Vec3(3, 3, 0.02)), Iso3(Eigen::Translation3d(0, 0, 1.01)));  // wall z = 1
  scene.commit();
  DepthCameraOptions cam;
  RenderOptions ro;
  ro.noise = false;
  DepthImage d = renderDepth(scene, Iso3::Identity(), cam, NoiseModelOptions{}, ro);
  const Vec3 projector = cam.projector_C;
  int shadowed = 0, checked = 0;
  for (int v = 0; v < 480; v += 2)
    for (int u = 0; u < 640; u += 2) {
      Vec3 ray = cam.intrinsics.rayZ1(u, v);
      if (test::segmentHitsBox(Vec3::Zero(), ray * 1.0, lo, hi)) continue;  // camera sees the box
      Vec3 wall = ray * 1.0;
      // Skip pixels within a pixel of the shadow edge (sub-pixel geometry decides).
      bool inShadow = test::segmentHitsBox(wall, projector, lo, hi);
      Vec3 wallR = cam.intrinsics.rayZ1(u + 1, v) * 1.0,
           wallL = cam.intrinsics.rayZ1(u - 1, v) * 1.0;
      if (test::segmentHitsBox(wallR, projector, lo, hi) != inShadow ||
          test::segmentHitsBox(wallL, projector, lo, hi) != inShadow)
        continue;
      ++checked;
      shadowed += inShadow;
      EXPECT_EQ(d.at(u, v) > 0, !inShadow) << "pixel " << u << "," << v;
    }
  EXPECT_GT(shadowed, 200);  // the shadow exists and was tested
  EXPECT_GT(checked, 50000);
}

TEST(Render, RangeLimits) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(3, 3, 0.02)), Iso3(Eigen::Translation3d(0, 0, 0.41)));  // z = 0.4
  scene.commit();
  RenderOptions ro;
  ro.noise = false;
  DepthImage d =
      renderDepth(scene, Iso3::Identity(), DepthCameraOptions{}, NoiseModelOptions{}, ro);
  EXPECT_EQ(d.validCount(), 0);  // nearer than 0.5 m
}

TEST(DepthImage, PngRoundTripInMillimetres) {
  test::TempDir dir;
  DepthImage img(640, 480);
  for (size_t i = 0; i < img.depth_m.size(); ++i)
    img.depth_m[i] = (i % 7 == 0) ? 0.f : 0.5f + 0.001f * float(i % 3000);
  writeDepthPng(dir.path() / "d.png", img);
  DepthImage back = readDepthPng(dir.path() / "d.png", 0.001, 640, 480);
  for (size_t i = 0; i < img.depth_m.size(); ++i)
    EXPECT_NEAR(back.depth_m[i], img.depth_m[i], 0.0005);
  // 65535, the other "no depth" sentinel real sensors write, reads as no depth.
  img.depth_m[5] = 65.535f;
  writeDepthPng(dir.path() / "s.png", img);
  EXPECT_EQ(readDepthPng(dir.path() / "s.png", 0.001, 640, 480).depth_m[5], 0.f);
}

TEST(DepthImage, BadFilesAreNamed) {
  test::TempDir dir;
  DepthImage small(320, 240);
  writeDepthPng(dir.path() / "small.png", small);
  try {
    readDepthPng(dir.path() / "small.png", 0.001, 640, 480);
    FAIL();
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find("small.png"), std::string::npos);
    EXPECT_NE(m.find("320x240"), std::string::npos);
  }
  std::ofstream(dir.path() / "text.png") << "hello";
  EXPECT_THROW(readDepthPng(dir.path() / "text.png"), Error);
  // An 8-bit PNG (written by hand through the RGB writer's format is not needed: truncate one).
  std::string bytes = readTextFile(dir.path() / "small.png");
  writeTextAtomically(dir.path() / "truncated.png", bytes.substr(0, bytes.size() / 2));
  EXPECT_THROW(readDepthPng(dir.path() / "truncated.png"), Error);
  EXPECT_THROW(readDepthPng(dir.path() / "absent.png"), Error);
}

TEST(FrameSet, WriteReadAndValidation) {
  test::TempDir dir;
  FrameSet set;
  DepthImage img(640, 480);
  writeDepthPng(dir.path() / "a.png", img);
  set.frames.push_back({"a.png", lookAt(Vec3(0.7, 0, 0), Vec3::Zero())});
  writeFrameSet(dir.path(), set);
  FrameSet back = readFrameSet(dir.path());
  ASSERT_EQ(back.frames.size(), 1u);
  EXPECT_TRUE(back.frames[0].T_O_C.isApprox(set.frames[0].T_O_C, 1e-12));
  auto expectError = [&](const std::string& json, const std::string& needle) {
    writeTextAtomically(dir.path() / "frames.json", json);
    try {
      readFrameSet(dir.path());
      ADD_FAILURE() << "no error for " << json;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  const std::string K =
      R"("intrinsics": {"width": 640, "height": 480, "fx": 525, "fy": 525, "cx": 319.5, "cy": 239.5})";
  expectError("{", "malformed JSON");
  expectError("{" + K + "}", "missing field \"frames\"");
  expectError(
      "{" + K +
          R"(, "frames": [{"file": "a.png", "T_O_C": [0,0,0,0, 0,0,0,0, 0,0,0,0, 0,0,0,1]}]})",
      "frames[0].T_O_C: not a rigid transform");
  expectError(
      "{" + K +
          R"(, "frames": [{"file": "missing.png", "T_O_C": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}]})",
      "frames[0].file");
  expectError("{" + K + R"(, "frames": [{"file": "a.png", "T_O_C": [1,0,0]}]})", "16 numbers");
  expectError(
      R"({"intrinsics": {"width": 640, "height": 480, "fx": -1, "fy": 525, "cx": 319.5, "cy": 239.5}, "frames": []})",
      "intrinsics.fx");
}
