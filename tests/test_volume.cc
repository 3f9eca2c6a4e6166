#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "inhand/core/error.h"
#include "inhand/core/pose.h"
#include "inhand/eval/metrics.h"
#include "inhand/geometry/primitives.h"
#include "inhand/mesh/extract.h"
#include "test_util.h"

using namespace inhand;

namespace {
Aabb cube(double half) {
  Aabb b;
  b.extend(Vec3::Constant(-half));
  b.extend(Vec3::Constant(half));
  return b;
}
double boxDistance(const Vec3& p, const Vec3& half) {
  Vec3 q = p.cwiseAbs() - half;
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}
struct SurfaceError {
  double rms = 0;
  int observed = 0, holes = 0;
};
template <typename Dist>
SurfaceError surfaceError(const ObjectModel& m, Dist dist) {
  SurfaceError e;
  double s2 = 0;
  for (size_t i = 0; i < m.mesh.vertices.size(); ++i) {
    if (!m.observed[i]) {
      ++e.holes;
      continue;
    }
    double d = dist(m.mesh.vertices[i].cast<double>());
    s2 += d * d;
    ++e.observed;
  }
  e.rms = std::sqrt(s2 / std::max(1, e.observed));
  return e;
}
}  // namespace

TEST(Fusion, SphereFromAllRoundIsAccurateAndComplete) {
  const double r = 0.08;
  VolumeOptions vo;  // 2 mm voxels
  TsdfVolume vol(cube(0.1), vo);
  test::renderAndFuse(makeSphere(r, 6), test::viewsAround(40, 0.7), false, &vol);
  ObjectModel m = extractModel(vol);
  EXPECT_TRUE(m.mesh.isClosed());
  SurfaceError e = surfaceError(m, [&](const Vec3& p) { return p.norm() - r; });
  EXPECT_LT(e.rms, 0.5 * vo.voxel_size_m);
  EXPECT_EQ(e.holes, 0);
  EXPECT_GT(e.observed, 10000);
  EXPECT_NEAR(m.observedAreaFraction(), 1.0, 1e-12);
}

TEST(Fusion, BoxFromAllRoundIsAccurateAndComplete) {
  const Vec3 size(0.06, 0.10, 0.14);
  VolumeOptions vo;
  TsdfVolume vol(cube(0.1), vo);
  test::renderAndFuse(makeBox(size), test::viewsAround(40, 0.7), false, &vol);
  ObjectModel m = extractModel(vol);
  EXPECT_TRUE(m.mesh.isClosed());
  SurfaceError e = surfaceError(m, [&](const Vec3& p) { return boxDistance(p, 0.5 * size); });
  EXPECT_LT(e.rms, 0.5 * vo.voxel_size_m);
  EXPECT_EQ(e.holes, 0);
}

TEST(Fusion, NoisyFusionStaysWithinAVoxel) {
  const double r = 0.08;
  VolumeOptions vo;
  TsdfVolume vol(cube(0.1), vo);
  test::renderAndFuse(makeSphere(r, 6), test::viewsAround(40, 0.7), true, &vol);
  ObjectModel m = extractModel(vol);
  SurfaceError e = surfaceError(m, [&](const Vec3& p) { return p.norm() - r; });
  EXPECT_LT(e.rms, 1.0 * vo.voxel_size_m);
  EXPECT_GT(m.observedAreaFraction(), 0.99);
}

TEST(Fusion, SingleViewLeavesBackClosedByHoleSurface) {
  const double r = 0.08;
  VolumeOptions vo;
  TsdfVolume vol(cube(0.1), vo);
  const Vec3 camDir(1, 0, 0);  // camera on +x
  test::renderAndFuse(makeSphere(r, 6), {lookAt(0.7 * camDir, Vec3::Zero())}, false, &vol);
  MeshOptions mo;
  ObjectModel m = extractModel(vol, mo);
  EXPECT_TRUE(m.mesh.isClosed());
  int holes = 0, observedFront = 0, observed = 0;
  for (size_t i = 0; i < m.mesh.vertices.size(); ++i) {
    Vec3 p = m.mesh.vertices[i].cast<double>();
    if (m.observed[i]) {
      ++observed;
      observedFront += p.dot(camDir) > -0.01;  // measured surface faces the camera
    } else {
      ++holes;
      EXPECT_FLOAT_EQ(m.variance[i], float(mo.hole_sigma_m * mo.hole_sigma_m));
    }
  }
  EXPECT_GT(holes, 1000);
  EXPECT_GT(observed, 1000);
  EXPECT_EQ(observedFront, observed);
  EXPECT_LT(m.observedAreaFraction(), 0.6);
  // The σ = 5 cm surface makes the entropy higher than the fully observed model's.
  TsdfVolume all(cube(0.1), vo);
  test::renderAndFuse(makeSphere(r, 6), test::viewsAround(40, 0.7), false, &all);
  EXPECT_GT(m.meanEntropy(), extractModel(all).meanEntropy() + 1.0);
}

TEST(Fusion, EmptyInFrontObservedInBandUnknownBehind) {
  // Camera at the origin looking along +z at a cube whose front face is at z = 0.65.
  RayScene unused;
  VolumeOptions vo;
  Aabb box;
  box.extend(Vec3(-0.08, -0.08, 0.56));
  box.extend(Vec3(0.08, 0.08, 0.80));
  TsdfVolume vol(box, vo);
  TriangleMesh cubeMesh = makeBox(Vec3(0.1, 0.1, 0.1));
  // Render in the camera frame = object frame here (T_O_C = identity).
  Iso3 T_O_C = Iso3::Identity();
  TriangleMesh placed = transformed(cubeMesh, Iso3(Eigen::Translation3d(0, 0, 0.70)));
  test::renderAndFuse(placed, {T_O_C}, false, &vol);
  const double mu = vol.truncation();
  int checked = 0;
  for (int z = 0; z < vol.dims().z(); ++z) {
    size_t i = vol.index(40, 40, z);  // the sample on the optical axis (x = y = 0)
    double pz = vol.point(40, 40, z).z();
    ASSERT_NEAR(vol.point(40, 40, z).x(), 0.0, 1e-12);
    if (std::abs(pz - 0.65 - mu) < 1e-3 || std::abs(pz - 0.65 + mu) < 1e-3) continue;  // band edges
    ++checked;
    if (pz < 0.65 - mu) {
      EXPECT_EQ(vol.state(i), VoxelState::kEmpty) << pz;
    } else if (pz <= 0.65 + mu) {
      EXPECT_EQ(vol.state(i), VoxelState::kObserved) << pz;
      EXPECT_NEAR(vol.distance(i), 0.65 - pz, 1e-5);  // exact signed distance along the axis
      DepthCameraOptions cam;
      EXPECT_NEAR(vol.variance(i), std::pow(axialSigma(NoiseModelOptions{}, 0.65, 0.0), 2), 1e-9);
    } else {
      EXPECT_EQ(vol.state(i), VoxelState::kUnknown) << pz;
    }
  }
  EXPECT_GT(checked, 100);
}

namespace {
// The volume settings the kernels are checked under: the fixed band and the reach behind the
// smoothed surface at 2σ, each with raw and smoothed depths.
std::vector<VolumeOptions> bandSettings() {
  std::vector<VolumeOptions> out;
  for (double k : {0.0, 2.0})
    for (bool smooth : {false, true}) {
      VolumeOptions vo;
      vo.band_sigmas = k;
      vo.smooth_depth = smooth;
      out.push_back(vo);
    }
  return out;
}
}  // namespace

// The fast kernel against the simple reference, with the fixed band and with the band behind
// each measurement at 2σ, raw and smoothed depths (the reference computes the plane fit's reach
// and the band on its own), the frames' silhouettes carving beyond the band and a stripe of rows
// carving up to the surface.
TEST(Fusion, OptimisedIntegrationMatchesReference) {
  TriangleMesh obj = makeBox(Vec3(0.06, 0.158, 0.21));
  RayScene scene;
  scene.addMesh(obj);
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  for (const VolumeOptions& vo : bandSettings()) {
    const std::string k = std::to_string(vo.band_sigmas) + (vo.smooth_depth ? " smoothed" : " raw");
    TsdfVolume fast(cube(0.15), vo), ref(cube(0.15), vo);
    int64_t fastUpdated = 0, refUpdated = 0;
    for (const Iso3& T : test::viewsAround(5, 0.7)) {
      RenderOptions ro;
      DepthImage d = renderDepth(scene, T, cam, nm, ro);
      // Silhouettes carve beyond the band, a stripe of rows up to the surface (both codes).
      std::vector<uint8_t> carve = depthDiscontinuities(d, nm.discontinuity_jump_m);
      for (uint8_t& c : carve) c = c ? kCarveBeyondBand : 0;
      for (size_t i = 200 * size_t(d.width); i < 215 * size_t(d.width); ++i)
        carve[i] = kCarveToSurface;
      auto sigma = measurementSigma(d, cam.intrinsics, nm, nullptr, &carve);
      fastUpdated += integrate(d, T, cam.intrinsics, sigma, &fast, &carve).updated;
      refUpdated += integrateReference(d, T, cam.intrinsics, sigma, &ref, &carve).updated;
    }
    // Float (incremental) vs double (per-voxel) projection may round a voxel centre that lies on
    // a pixel border to the neighbouring pixel: allow a tiny fraction of differing voxels.
    size_t differ = 0;
    for (size_t i = 0; i < fast.voxelCount(); ++i) {
      bool same =
          fast.state(i) == ref.state(i) &&
          std::abs(fast.sumW()[i] - ref.sumW()[i]) <= 1e-4f * std::max(1.f, ref.sumW()[i]) &&
          std::abs(fast.distance(i) - ref.distance(i)) <= 1e-6f;
      differ += !same;
    }
    EXPECT_LT(double(differ), 1e-4 * double(fast.voxelCount())) << "band_sigmas " << k;
    EXPECT_GT(refUpdated, 100000) << "band_sigmas " << k;
    EXPECT_NEAR(double(fastUpdated), double(refUpdated), 1e-4 * double(refUpdated)) << k;
  }
}

// Skipping the bricks a frame cannot change, and testing eight voxels at a time in AVX2 (where
// the CPU has it) then four in SSE2, leaves every voxel as visiting them all one at a time does,
// to the bit (fails with a wrong lane or a depth of 0 let through): a box and a thin plate seen
// from all round (so bricks go empty, lie in front, behind and in the band), the camera close
// enough that bricks straddle it, a carve-only stripe, both bands.
TEST(Fusion, SkippingUnchangedBricksChangesNoVoxel) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(0.06, 0.158, 0.21)));
  scene.addMesh(makeBox(Vec3(0.1, 0.0015, 0.08)), Iso3(Eigen::Translation3d(0, 0.11, 0)));
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  for (const VolumeOptions& vo : bandSettings()) {
    const std::string k = std::to_string(vo.band_sigmas) + (vo.smooth_depth ? " smoothed" : " raw");
    TsdfVolume culled(cube(0.34), vo), every(cube(0.34), vo);
    int64_t updatedCulled = 0, updatedEvery = 0, visitedCulled = 0, visitedEvery = 0;
    int frame = 0;
    std::vector<Iso3> views = test::viewsAround(12, 0.7);
    views.push_back(lookAt(Vec3(0.05, 0.2, 0.12), Vec3::Zero()));  // inside the volume
    for (const Iso3& T : views) {
      RenderOptions ro;
      ro.seed = uint64_t(++frame);
      DepthImage d = renderDepth(scene, T, cam, nm, ro);
      std::vector<uint8_t> carve(d.depth_m.size(), 0);
      for (int v = 200; v < 260; ++v)
        for (int u = 0; u < d.width; ++u) carve[size_t(v) * d.width + u] = frame % 3 == 0;
      const auto sigma = measurementSigma(d, cam.intrinsics, nm);
      const IntegrationStats a = integrate(d, T, cam.intrinsics, sigma, &culled, &carve, true);
      const IntegrationStats b = integrate(d, T, cam.intrinsics, sigma, &every, &carve, false);
      updatedCulled += a.updated;
      updatedEvery += b.updated;
      visitedCulled += a.visited;
      visitedEvery += b.visited;
    }
    const size_t n = culled.voxelCount();
    EXPECT_EQ(std::memcmp(culled.states(), every.states(), n), 0) << k;
    EXPECT_EQ(std::memcmp(culled.sumW(), every.sumW(), n * sizeof(float)), 0) << k;
    EXPECT_EQ(std::memcmp(culled.sumWD(), every.sumWD(), n * sizeof(float)), 0) << k;
    EXPECT_EQ(updatedCulled, updatedEvery) << k;
    EXPECT_GT(updatedEvery, 1000000) << k;
    EXPECT_LT(double(visitedCulled), 0.97 * double(visitedEvery)) << k;  // it does skip
  }
}

TEST(Fusion, SigmaRestrictedToTheVolumeAndUncarvedPixelsFusesTheSame) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(0.3, 0.3, 0.02)), Iso3(Eigen::Translation3d(0, 0, -0.06)));  // a table
  scene.addMesh(makeSphere(0.04, 4));
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  VolumeOptions vo;
  TsdfVolume full(cube(0.06), vo), part(cube(0.06), vo);
  int rectsSmaller = 0;
  for (const Iso3& T : test::viewsAround(6, 0.6)) {
    DepthImage d = renderDepth(scene, T, cam, nm, RenderOptions());
    std::vector<uint8_t> carve(d.depth_m.size(), 0);
    for (size_t i = 0; i < carve.size(); i += 7) carve[i] = kCarveBeyondBand;
    for (size_t i = 3; i < carve.size(); i += 11) carve[i] = kCarveToSurface;
    const PixelRect rect = volumeImageRect(full, T, cam.intrinsics);
    rectsSmaller += (rect.u1 - rect.u0) * (rect.v1 - rect.v0) < d.width * d.height / 2;
    const std::vector<float> all = measurementSigma(d, cam.intrinsics, nm);
    const std::vector<float> some = measurementSigma(d, cam.intrinsics, nm, &rect, &carve);
    for (int v = 0; v < d.height; ++v)
      for (int u = 0; u < d.width; ++u) {
        const size_t i = size_t(v) * d.width + u;
        const bool inside = u >= rect.u0 && u < rect.u1 && v >= rect.v0 && v < rect.v1;
        // A known surface's carve-only pixels keep their σ (the weight of their free space).
        const bool weighed = !carve[i] || carve[i] == kCarveToSurface;
        ASSERT_EQ(some[i], inside && weighed ? all[i] : 0.f) << u << " " << v;
      }
    integrate(d, T, cam.intrinsics, all, &full, &carve);
    integrate(d, T, cam.intrinsics, some, &part, &carve);
  }
  EXPECT_EQ(rectsSmaller, 6);  // the test restricts something
  EXPECT_GT(full.countState(VoxelState::kObserved), 1000u);
  for (size_t i = 0; i < full.voxelCount(); ++i) {
    ASSERT_EQ(full.state(i), part.state(i)) << i;
    ASSERT_EQ(full.sumW()[i], part.sumW()[i]) << i;
    ASSERT_EQ(full.sumWD()[i], part.sumWD()[i]) << i;
  }
}

TEST(Fusion, CarveOnlyPixelsAddNoSurface) {
  VolumeOptions vo;
  TsdfVolume vol(cube(0.1), vo);
  RayScene scene;
  scene.addMesh(makeSphere(0.08, 5));
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  Iso3 T = lookAt(Vec3(0.7, 0, 0), Vec3::Zero());
  RenderOptions ro;
  ro.noise = false;
  DepthImage d = renderDepth(scene, T, cam, nm, ro);
  std::vector<uint8_t> carve(d.depth_m.size(), 1);
  integrate(d, T, cam.intrinsics, measurementSigma(d, cam.intrinsics, nm), &vol, &carve);
  EXPECT_EQ(vol.countState(VoxelState::kObserved), 0u);
  EXPECT_GT(vol.countState(VoxelState::kEmpty), 50000u);
}

// A known surface's pixel (the robot's, kCarveToSurface) says the space more than μ in front of it
// is free, as any measurement does: an observed voxel there gets +μ with the pixel's weight (a band
// that a ray grazing an edge wrote beyond the object is pulled out where the hand hid the face
// from every later view). At a depth edge (kCarveUnknownToSurface) it changes unknown voxels only.
// Both empty the unknown voxels up to μ/4 in front of it.
TEST(Fusion, AKnownSurfacesPixelsPullObservedVoxelsInFrontOfThemOut) {
  VolumeOptions vo;
  Aabb box;
  box.extend(Vec3(-0.08, -0.08, 0.56));
  box.extend(Vec3(0.08, 0.08, 0.80));
  TriangleMesh cubeMesh = makeBox(Vec3(0.1, 0.1, 0.1));
  TriangleMesh placed = transformed(cubeMesh, Iso3(Eigen::Translation3d(0, 0, 0.70)));
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  const CameraIntrinsics& K = cam.intrinsics;
  for (uint8_t flag : {kCarveToSurface, kCarveUnknownToSurface}) {
    TsdfVolume vol(box, vo);
    test::renderAndFuse(placed, {Iso3::Identity()}, false, &vol);  // the face at z = 0.65
    const double mu = vol.truncation();
    // A flat surface 3μ behind the face, every pixel carve-only.
    const double D2 = 0.65 + 3 * mu;
    DepthImage far(K.width, K.height);
    std::fill(far.depth_m.begin(), far.depth_m.end(), float(D2));
    std::vector<uint8_t> carve(far.depth_m.size(), flag);
    const std::vector<float> sigma = measurementSigma(far, K, nm, nullptr, &carve);
    // The voxels on the optical axis read the pixel at (cx, cy) rounded: (320, 240).
    const float s2 = sigma[240 * size_t(K.width) + 320];
    if (flag == kCarveToSurface) {
      EXPECT_NEAR(s2, axialSigma(nm, D2, 0), 1e-6);
    } else {
      EXPECT_EQ(s2, 0.f);
    }
    std::vector<VoxelState> state0;
    std::vector<float> sumW0, sumWD0;
    for (int z = 0; z < vol.dims().z(); ++z) {
      const size_t i = vol.index(40, 40, z);
      state0.push_back(vol.state(i));
      sumW0.push_back(vol.sumW()[i]);
      sumWD0.push_back(vol.sumWD()[i]);
    }
    integrate(far, Iso3::Identity(), K, sigma, &vol, &carve);
    int pulled = 0, emptied = 0;
    for (int z = 0; z < vol.dims().z(); ++z) {
      const size_t i = vol.index(40, 40, z);
      const double pz = vol.point(40, 40, z).z(), d = D2 - pz;
      if (std::abs(d - mu) < 1e-4 || std::abs(d - mu / 4) < 1e-4) continue;  // rounding at limits
      const VoxelState st = state0[size_t(z)];
      if (st == VoxelState::kObserved && d > mu && flag == kCarveToSurface) {
        const double w2 = 1.0 / (double(s2) * s2);
        EXPECT_EQ(vol.state(i), VoxelState::kObserved);
        EXPECT_NEAR(vol.distance(i), (sumWD0[size_t(z)] + w2 * mu) / (sumW0[size_t(z)] + w2), 1e-5)
            << pz;
        pulled += vol.distance(i) > sumWD0[size_t(z)] / sumW0[size_t(z)] + 1e-4;
      } else if (st == VoxelState::kUnknown && d > mu / 4) {
        EXPECT_EQ(vol.state(i), VoxelState::kEmpty) << pz;
        ++emptied;
      } else {
        EXPECT_EQ(vol.state(i), st) << pz;
        EXPECT_EQ(vol.sumW()[i], sumW0[size_t(z)]) << pz;
        EXPECT_EQ(vol.sumWD()[i], sumWD0[size_t(z)]) << pz;
      }
    }
    EXPECT_EQ(pulled > 0, flag == kCarveToSurface);
    EXPECT_GT(emptied, 0);
  }
}

// depthDiscontinuities marks the near side of silhouettes: the outer ring of a 5×5 block 10 cm in
// front of a wall, also where a gap of no return (a projector shadow) lies between it and the
// wall; not the wall beside the block (the nearer edge), not the neighbours of a hole in the wall
// (a shadow on its own surface), not a 5 mm step; a return followed by no return up to the image
// border is a silhouette.
// nearestAround: a flagged pixel takes the nearest depth within the radius (itself included);
// pixels not flagged, and flagged ones with nothing nearer around, keep theirs.
TEST(Fusion, NearestAroundPullsFlaggedPixelsToTheNearestDepthBesideThem) {
  DepthImage d(8, 6);
  for (int v = 0; v < 6; ++v)
    for (int u = 0; u < 8; ++u) d.at(u, v) = u < 3 ? 0.80f : 1.50f;  // an edge at u = 3
  d.at(3, 2) = 1.20f;                                                // a return between the two
  d.at(6, 5) = 0.0f;                                                 // no return
  std::vector<uint8_t> mask(48, 0);
  auto flag = [&](int u, int v) { mask[size_t(v) * 8 + size_t(u)] = 1; };
  flag(3, 2);  // beside the edge: 0.80 two pixels left
  flag(5, 2);  // three pixels from the edge: nothing nearer within 2
  flag(6, 5);  // no return of its own: the nearest around it
  flag(0, 0);  // on the near side already
  const DepthImage r = nearestAround(d, mask, 2);
  EXPECT_FLOAT_EQ(r.at(3, 2), 0.80f);
  EXPECT_FLOAT_EQ(r.at(5, 2), 1.20f);  // the mixed return two pixels left is nearer
  EXPECT_FLOAT_EQ(r.at(6, 5), 1.50f);
  EXPECT_FLOAT_EQ(r.at(0, 0), 0.80f);
  EXPECT_FLOAT_EQ(r.at(4, 2), 1.50f);  // not flagged
  EXPECT_FLOAT_EQ(r.at(6, 4), 1.50f);
  int changed = 0;
  for (size_t i = 0; i < 48; ++i) changed += r.depth_m[i] != d.depth_m[i];
  EXPECT_EQ(changed, 3);
  EXPECT_THROW(nearestAround(d, std::vector<uint8_t>(3, 0), 2), Error);
}

// The robot's pixels beside a nearer measurement (more than the jump) only carve unknown voxels:
// a hand-made case with its answer, then the separable filter against the direct 5 × 5 search
// on random images, masks and rectangles (edges of the image included).
TEST(Fusion, FarSideOfSilhouettesIsTheRobotsPixelsBesideANearerMeasurement) {
  DepthImage d(10, 8);
  for (float& z : d.depth_m) z = 1.0f;
  std::vector<uint8_t> c(80, kCarveToSurface);
  for (int v = 0; v < 8; ++v)
    for (int u = 0; u < 3; ++u) c[size_t(v) * 10 + u] = 0;  // the object: columns 0-2
  for (int v = 0; v < 8; ++v) d.at(1, v) = 0.9f;            // nearer by 10 cm in column 1 only
  d.at(2, 3) = 0.0f;
  farSideOfSilhouettesOnlyCarveUnknown(d, 0.05f, PixelRect{0, 0, 10, 8}, &c);
  for (int v = 0; v < 8; ++v)
    for (int u = 3; u < 10; ++u)  // within 2 pixels of column 1: column 3
      EXPECT_EQ(c[size_t(v) * 10 + u], u == 3 ? kCarveUnknownToSurface : kCarveToSurface) << u;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0, 1);
  int changed = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const int W = 5 + int(rng() % 60), H = 5 + int(rng() % 40);
    DepthImage img(W, H);
    std::vector<uint8_t> mask(size_t(W) * H);
    for (size_t i = 0; i < mask.size(); ++i) {
      const float r = U(rng);
      img.depth_m[i] = r < 0.1f ? 0.0f : 0.5f + U(rng);
      mask[i] = r < 0.5f ? uint8_t(0) : r < 0.9f ? kCarveToSurface : uint8_t(rng() % 4);
    }
    const int u0 = int(rng() % W), v0 = int(rng() % H);
    const PixelRect rect{u0, v0, u0 + 1 + int(rng() % (W - u0)), v0 + 1 + int(rng() % (H - v0))};
    std::vector<uint8_t> fast = mask, ref = mask;
    farSideOfSilhouettesOnlyCarveUnknown(img, 0.2f, rect, &fast);
    farSideOfSilhouettesReference(img, 0.2f, rect, &ref);
    ASSERT_EQ(fast, ref) << "trial " << trial;
    changed += fast != mask;
  }
  EXPECT_GE(changed, 30);  // the cases are not empty (a rectangle of a pixel or two may be)
}

TEST(Fusion, DepthDiscontinuitiesAreTheNearSideOfSilhouettes) {
  DepthImage d;
  d.width = 20;
  d.height = 20;
  d.depth_m.assign(400, 1.0f);
  auto set = [&](int u, int v, float z) { d.depth_m[size_t(v) * 20 + u] = z; };
  for (int v = 5; v < 10; ++v) {
    for (int u = 5; u < 10; ++u) set(u, v, 0.9f);
    set(10, v, 0.0f);  // a shadow right of the block, the wall beyond it
    set(11, v, 0.0f);
  }
  set(15, 15, 0.0f);
  set(2, 2, 1.005f);
  set(19, 18, 0.0f);
  const std::vector<uint8_t> e = depthDiscontinuities(d, 0.01);
  auto at = [&](int u, int v) { return int(e[size_t(v) * 20 + u]); };
  int marked = 0;
  for (uint8_t x : e) marked += x;
  EXPECT_EQ(marked, 16 + 1);
  EXPECT_EQ(at(5, 5), 1);    // the block's corner
  EXPECT_EQ(at(9, 7), 1);    // across the shadow: the wall, farther
  EXPECT_EQ(at(7, 7), 0);    // inside the block
  EXPECT_EQ(at(4, 7), 0);    // the wall beside it: the nearer side is the block's
  EXPECT_EQ(at(12, 7), 0);   // the wall across the shadow
  EXPECT_EQ(at(14, 15), 0);  // beside a hole in the wall
  EXPECT_EQ(at(15, 15), 0);  // no return: nothing to mark
  EXPECT_EQ(at(2, 2), 0);
  EXPECT_EQ(at(18, 18), 1);  // no return up to the border
  EXPECT_EQ(at(19, 17), 0);  // the wall on the other side of that hole
  // Only inside a region when given one.
  const PixelRect r{0, 0, 7, 20};
  const std::vector<uint8_t> part = depthDiscontinuities(d, 0.01, &r);
  for (int v = 0; v < 20; ++v)
    for (int u = 0; u < 20; ++u)
      EXPECT_EQ(int(part[size_t(v) * 20 + u]), u < 7 ? at(u, v) : 0) << u << "," << v;
}

// writeData / readData: a volume of runs and scattered sums (-0 and NaN bits among them) back bit
// for bit, far smaller than the arrays; a stream cut short, a bad state or runs that do not cover
// the volume refused with a reason.
TEST(Volume, CompactDataComesBackBitForBit) {
  VolumeOptions vo;
  vo.voxel_size_m = 0.004;
  TsdfVolume v(cube(0.1), vo);  // 51³ voxels
  const size_t n = v.voxelCount();
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> stateOf(0, 2);
  std::uniform_real_distribution<float> value(-1.f, 1.f);
  // Runs of 1 to 3,000 voxels of one state; sums on observed voxels and a few others.
  for (size_t i = 0; i < n;) {
    const size_t len = std::min(n - i, size_t(1 + rng() % 3000));
    std::fill_n(v.states() + i, len, uint8_t(stateOf(rng)));
    i += len;
  }
  for (size_t i = 0; i < n; ++i)
    if (v.states()[i] == uint8_t(VoxelState::kObserved) || rng() % 1000 == 0) {
      v.sumWD()[i] = value(rng);
      v.sumW()[i] = rng() % 7 == 0 ? 0.f : value(rng);
    }
  v.sumWD()[0] = -0.f;
  v.sumW()[n - 1] = std::numeric_limits<float>::quiet_NaN();
  v.states()[n - 1] = uint8_t(VoxelState::kEmpty);
  std::stringstream out;
  v.writeData(out);
  const std::string bytes = out.str();
  TsdfVolume back(cube(0.1), vo);
  std::istringstream in(bytes);
  ASSERT_EQ(back.readData(in), "");
  EXPECT_EQ(in.peek(), std::char_traits<char>::eof());  // every byte read
  EXPECT_EQ(std::memcmp(back.states(), v.states(), n), 0);
  EXPECT_EQ(std::memcmp(back.sumWD(), v.sumWD(), n * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(back.sumW(), v.sumW(), n * sizeof(float)), 0);

  // A scan-like volume (empty with a thin shell observed) is far smaller than the arrays.
  TsdfVolume shell(cube(0.1), vo);
  for (int z = 0; z < shell.dims().z(); ++z)
    for (int y = 0; y < shell.dims().y(); ++y)
      for (int x = 0; x < shell.dims().x(); ++x) {
        const size_t i = shell.index(x, y, z);
        const double r = (shell.point(x, y, z) - Vec3::Constant(0.0)).norm();
        shell.states()[i] = uint8_t(r < 0.05 ? VoxelState::kUnknown : VoxelState::kEmpty);
        if (std::abs(r - 0.05) < 0.006) {
          shell.states()[i] = uint8_t(VoxelState::kObserved);
          shell.sumWD()[i] = float(r - 0.05);
          shell.sumW()[i] = 1.f;
        }
      }
  std::stringstream compact;
  shell.writeData(compact);
  EXPECT_LT(compact.str().size(), n * TsdfVolume::kBytesPerVoxel / 4);
  TsdfVolume shellBack(cube(0.1), vo);
  std::istringstream shellIn(compact.str());
  ASSERT_EQ(shellBack.readData(shellIn), "");
  EXPECT_EQ(std::memcmp(shellBack.sumWD(), shell.sumWD(), n * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(shellBack.states(), shell.states(), n), 0);

  // Refusals.
  auto readOf = [&](const std::string& b) {
    TsdfVolume t(cube(0.1), vo);
    std::istringstream s(b);
    return t.readData(s);
  };
  EXPECT_NE(readOf(bytes.substr(0, bytes.size() - 1)).find("cut short"), std::string::npos);
  EXPECT_NE(readOf(bytes.substr(0, 4)).find("cut short"), std::string::npos);
  uint64_t runs;
  std::memcpy(&runs, bytes.data(), sizeof runs);
  std::string badState = bytes;
  badState[8 + 8 * runs] = 3;  // the first run's value
  EXPECT_NE(readOf(badState).find("invalid voxel state"), std::string::npos);
  std::string shortRun = bytes;
  const uint64_t one = 1;
  std::memcpy(shortRun.data() + 8, &one, sizeof one);  // the first run's length
  EXPECT_NE(readOf(shortRun).find("do not cover"), std::string::npos);
  // Data that end soon after a large run count: cut short.
  const uint64_t claimed = n;
  std::string manyRuns(reinterpret_cast<const char*>(&claimed), sizeof claimed);
  EXPECT_NE(readOf(manyRuns + std::string(100, '\0')).find("cut short"), std::string::npos);
  TsdfVolume other(cube(0.12), vo);  // more voxels: the runs fall short
  std::istringstream otherIn(bytes);
  EXPECT_NE(other.readData(otherIn).find("do not cover"), std::string::npos);
}

TEST(Volume, MemoryBudgetRefusalGivesSize) {
  VolumeOptions vo;
  vo.voxel_size_m = 0.001;
  vo.memory_budget_mb = 100;
  try {
    TsdfVolume v(cube(0.5), vo);  // 1001³ voxels ≈ 8.4 GiB
    FAIL();
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find("would need"), std::string::npos) << m;
    EXPECT_NE(m.find("MiB"), std::string::npos) << m;
  }
  vo.voxel_size_m = -1;
  EXPECT_THROW(TsdfVolume(cube(0.1), vo), Error);
}

TEST(Mesh, EntropyOfGaussian) {
  EXPECT_NEAR(gaussianEntropy(1.0), 0.5 * std::log(2 * M_PI * M_E), 1e-12);
  EXPECT_NEAR(gaussianEntropy(0.05 * 0.05), 0.5 * std::log(2 * M_PI * M_E) + std::log(0.05), 1e-12);
}

TEST(Mesh, UnknownAttachedByRunsIsTheVoxelFlood) {
  // Random volumes of every state: scattered voxels, boxes of each state (so long runs, pockets
  // closed off by empty walls and pockets touching the volume's faces), shapes of 1 voxel wide.
  std::mt19937 rng(7);
  int kept = 0, dropped = 0;
  for (int trial = 0; trial < 40; ++trial) {
    VolumeOptions vo;
    vo.voxel_size_m = 0.01;
    const Vec3 size(0.01 * (1 + rng() % 30), 0.01 * (1 + rng() % 20), 0.01 * (1 + rng() % 15));
    TsdfVolume vol(Aabb{Vec3::Zero(), size - Vec3::Constant(1e-4)}, vo);
    const Vec3i d = vol.dims();
    uint8_t* st = vol.states();
    // Mostly empty space with unknown boxes in it, some touching an observed box.
    const uint8_t background = uint8_t(trial % 4 == 0 ? rng() % 3 : 1);
    std::fill(st, st + vol.voxelCount(), background);
    for (int b = 0; b < 10; ++b) {
      const Vec3i lo(int(rng() % d.x()), int(rng() % d.y()), int(rng() % d.z()));
      const Vec3i hi = lo + Vec3i(int(rng() % (d.x() / 2 + 1)), int(rng() % (d.y() / 2 + 1)),
                                  int(rng() % (d.z() / 2 + 1)));
      const uint8_t value = uint8_t(std::array<int, 4>{0, 0, 1, 2}[rng() % 4]);
      for (int z = lo.z(); z <= std::min(hi.z(), d.z() - 1); ++z)
        for (int y = lo.y(); y <= std::min(hi.y(), d.y() - 1); ++y)
          for (int x = lo.x(); x <= std::min(hi.x(), d.x() - 1); ++x)
            st[vol.index(x, y, z)] = value;
    }
    const int scatter = int(rng() % 200);
    for (int k = 0; k < scatter; ++k) st[rng() % vol.voxelCount()] = uint8_t(rng() % 3);
    const std::vector<uint8_t> runs = unknownAttachedToObserved(vol),
                               voxels = unknownAttachedToObservedReference(vol);
    ASSERT_EQ(runs.size(), voxels.size());
    EXPECT_TRUE(runs == voxels) << "trial " << trial << " dims " << d.transpose();
    for (size_t i = 0; i < runs.size(); ++i) {
      if (vol.state(i) != VoxelState::kUnknown) continue;
      kept += voxels[i];
      dropped += !voxels[i];
    }
  }
  // Both outcomes occur often.
  EXPECT_GT(kept, 5000) << dropped;
  EXPECT_GT(dropped, 500) << kept;
}

namespace {
// Mean and p95 distance (mm) of the fused model's observed surface to the true one, with
// coverage, for `mesh` seen from 40 views all around at 0.6 m and fused with `band_sigmas`.
SurfaceMetrics thinWallFusion(const TriangleMesh& mesh, double band_sigmas) {
  VolumeOptions vo;
  vo.band_sigmas = band_sigmas;
  vo.smooth_depth = band_sigmas > 0;  // the scans' setting against the paper's
  const Aabb b = mesh.bounds();
  TsdfVolume vol(Aabb{b.min - Vec3::Constant(0.02), b.max + Vec3::Constant(0.02)}, vo);
  std::vector<Iso3> poses;
  for (const Vec3& d : fibonacciSphere(40))
    poses.push_back(lookAt(b.center() + 0.6 * d, b.center(), Vec3::UnitZ()));
  test::renderAndFuse(mesh, poses, /*noise=*/true, &vol);
  return GroundTruth(mesh).evaluate(extractModel(vol));
}
}  // namespace

// Thin walls (a 1.5 mm plate, a cup with 2 mm walls, both thinner than the 8 mm band and the
// plate thinner than a 2 mm voxel) seen from both sides: with the band behind each measurement
// at 2σ, the error stays below the sensor's σ at 0.6 m (1.28 mm); with the full band the two
// sides cancel and the plate's error is above it.
TEST(Fusion, ThinWallsSeenFromBothSidesKeepBothSides) {
  NoiseModelOptions nm;
  const double sigma_mm = 1000 * axialSigma(nm, 0.6, 0.0);
  const TriangleMesh plate = makeBox(Vec3(0.1, 0.1, 0.0015));
  const TriangleMesh cup = makeRevolution(
      {{0, 0}, {0.04, 0}, {0.04, 0.08}, {0.038, 0.08}, {0.038, 0.002}, {0, 0.002}}, 96);
  const SurfaceMetrics p = thinWallFusion(plate, 2.0), p0 = thinWallFusion(plate, 0.0);
  const SurfaceMetrics c = thinWallFusion(cup, 2.0), c0 = thinWallFusion(cup, 0.0);
  std::printf(
      "plate: %.2f mm mean, %.2f p95 (full band %.2f, %.2f); cup: %.2f, %.2f (%.2f, %.2f)"
      "; sigma %.2f mm\n",
      p.accuracy_mean_mm, p.accuracy_p95_mm, p0.accuracy_mean_mm, p0.accuracy_p95_mm,
      c.accuracy_mean_mm, c.accuracy_p95_mm, c0.accuracy_mean_mm, c0.accuracy_p95_mm, sigma_mm);
  EXPECT_LT(p.accuracy_mean_mm, sigma_mm);
  EXPECT_LT(c.accuracy_mean_mm, sigma_mm);
  EXPECT_GT(p.coverage, 0.98);
  EXPECT_GT(c.coverage, 0.95);
  EXPECT_GT(p0.accuracy_mean_mm, sigma_mm);  // the failure the band fixes
  EXPECT_LT(c.accuracy_mean_mm, c0.accuracy_mean_mm);
}

// A tilted plane without noise: the smoothed surface is the pixel's own depth and the cosine of
// the plane's incidence (independently: the ray against the plane's normal); next to a depth
// jump it stays on the pixel's side.
TEST(Fusion, SmoothedSurfaceIsThePlaneThroughTheNeighbourhood) {
  const Vec3 normal = Vec3(0.3, -0.4, -1.0).normalized();  // facing the camera (looking along +z)
  const double offset = 0.9;                               // plane: normal · p = −offset
  RayScene scene;
  TriangleMesh plane = makeBox(Vec3(1.0, 1.0, 0.001));
  const Iso3 T_C_P = Iso3(Eigen::Translation3d(-offset * normal)) *
                     Iso3(Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), normal));
  scene.addMesh(plane, T_C_P);
  scene.addMesh(makeBox(Vec3(0.05, 0.05, 0.05)), Iso3(Eigen::Translation3d(0.1, 0.0, 0.6)));
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  RenderOptions ro;
  ro.noise = false;
  const DepthImage d = renderDepth(scene, Iso3::Identity(), cam, nm, ro);
  const CameraIntrinsics& K = cam.intrinsics;
  int checked = 0;
  for (int v = 40; v < K.height - 40; v += 37)
    for (int u = 40; u < K.width - 40; u += 41) {
      const float D = d.at(u, v);
      if (!(D > 0.f)) continue;
      const SmoothedSurface s = smoothedSurface(d, K, u, v, 0.008f);
      const Vec3 ray = K.rayZ1(u, v).normalized();
      const Vec3 p = K.rayZ1(u, v) * double(D);
      if (std::abs(p.z() - 0.575) < 1e-3) {  // the box's face in front
        EXPECT_NEAR(s.depth, D, 1e-4);
        EXPECT_NEAR(s.cos_incidence, ray.z(), 1e-3);  // the face's normal is the optical axis
      } else if (std::abs(normal.dot(p) + offset) < 2e-3) {  // the plane (1 mm thick box)
        EXPECT_NEAR(s.depth, D, 2e-4) << u << " " << v;
        EXPECT_NEAR(s.cos_incidence, std::abs(normal.dot(ray)), 2e-3) << u << " " << v;
        ++checked;
      }
    }
  EXPECT_GT(checked, 50);
  // Pixels on the box next to its outline, the plane 10+ cm behind them: the plane is left out.
  const Vec2 edge = K.project(Vec3(0.075, 0.0, 0.575));
  int u = int(std::ceil(edge.x()));
  const int v = int(edge.y());
  while (u < K.width && !(d.at(u, v) > 0.f))
    ++u;  // the first pixel on the box (the sensor
          // drops some at the outline)
  ASSERT_NEAR(d.at(u, v), 0.575, 1e-3);
  EXPECT_FALSE(d.at(u - 3, v) > 0.f && std::abs(d.at(u - 3, v) - 0.575f) < 0.05f);
  EXPECT_NEAR(smoothedSurface(d, K, u, v, 0.008f).depth, 0.575, 1e-4);
  EXPECT_NEAR(smoothedSurface(d, K, u, v, 0.008f).cos_incidence, K.rayZ1(u, v).normalized().z(),
              1e-3);
}

namespace {
// A noisy image of oblique faces (so that many neighbourhoods are partial) with what a loader
// may pass on: missing returns, NaN, +inf, depths below 2·max_jump, tiny and huge values.
DepthImage awkwardDepthImage(const DepthCameraOptions& cam) {
  RayScene scene;
  scene.addMesh(makeBox(Vec3(0.06, 0.158, 0.21)),
                Iso3(Eigen::AngleAxisd(0.7, Vec3(0.3, 1, 0.2).normalized())));
  scene.addMesh(makeBox(Vec3(0.4, 0.4, 0.002)), Iso3(Eigen::Translation3d(0, 0, -0.12)) *
                                                    Iso3(Eigen::AngleAxisd(1.1, Vec3::UnitX())));
  scene.commit();
  NoiseModelOptions nm;
  DepthImage d = renderDepth(scene, lookAt(Vec3(0.5, -0.3, 0.35).normalized() * 0.6, Vec3::Zero()),
                             cam, nm, RenderOptions{});
  std::mt19937 rng(7);
  std::uniform_int_distribution<size_t> any(0, d.depth_m.size() - 1);
  const float odd[] = {0.f,
                       std::numeric_limits<float>::quiet_NaN(),
                       std::numeric_limits<float>::infinity(),
                       0.004f,
                       1e-7f,
                       3e30f,
                       -0.5f};
  for (int k = 0; k < 3000; ++k) d.depth_m[any(rng)] = odd[k % 7];
  for (int v = 100; v < 140; ++v)  // a patch nearer than 2·max_jump, with a slope and noise
    for (int u = 300; u < 340; ++u)
      d.at(u, v) = 0.003f + 0.0004f * float(u - 300) + 1e-4f * float((u * 7 + v * 13) % 5);
  return d;
}
}  // namespace

// smoothedSurfaces (sliding sums where the whole neighbourhood is on the surface, SSE2 rows
// elsewhere inside the image) gives what smoothedSurface gives pixel by pixel, bit for bit, once
// per flagged pixel: noisy oblique faces, odd values, image borders, several jumps and rects.
TEST(Fusion, SmoothedSurfacesEqualThePixelByPixelFit) {
  DepthCameraOptions cam;
  const CameraIntrinsics& K = cam.intrinsics;
  const DepthImage d = awkwardDepthImage(cam);
  std::mt19937 rng(3);
  std::vector<uint8_t> fit(d.depth_m.size());
  for (size_t i = 0; i < fit.size(); ++i) fit[i] = (rng() % 10) < 8;
  int full = 0, partial = 0;
  for (const PixelRect rect :
       {PixelRect{0, 0, K.width, K.height}, PixelRect{-5, 3, 200, 477}, PixelRect{600, 0, 700, 30}})
    for (float jump : {0.008f, 0.002f, 0.f}) {
      std::vector<SmoothedSurface> got(d.depth_m.size());
      std::vector<std::atomic<int>> seen(d.depth_m.size());
      smoothedSurfaces(d, K, rect, fit.data(), jump, [&](size_t i, const SmoothedSurface& s) {
        got[i] = s;
        ++seen[i];
      });
      int wrong = 0, count = 0;
      for (int v = 0; v < K.height; ++v)
        for (int u = 0; u < K.width; ++u) {
          const size_t i = size_t(v) * K.width + u;
          const bool in = u >= rect.u0 && u < rect.u1 && v >= rect.v0 && v < rect.v1;
          ASSERT_EQ(seen[i].load(), in && fit[i] ? 1 : 0) << u << " " << v;
          if (!(in && fit[i])) continue;
          ++count;
          const SmoothedSurface want = smoothedSurface(d, K, u, v, jump);
          wrong += std::memcmp(&want, &got[i], sizeof want) != 0;
          if (jump == 0.008f && u >= 2 && v >= 2 && u + 2 < K.width && v + 2 < K.height &&
              d.at(u, v) > 0.1f && d.at(u, v) < 2.f) {
            bool all = true;
            for (int dv = -2; dv <= 2; ++dv)
              for (int du = -2; du <= 2; ++du) {
                const float Dn = d.at(u + du, v + dv);
                all = all && Dn > 0.f && std::abs(Dn - d.at(u, v)) <= jump;
              }
            ++(all ? full : partial);
          }
        }
      EXPECT_EQ(wrong, 0) << "jump " << jump << " rect " << rect.u0 << "," << rect.v0;
      EXPECT_GT(count, 500);
    }
  EXPECT_GT(full, 5000);  // both fast paths were taken
  EXPECT_GT(partial, 5000);
}

// The plane smoothedSurface fits to a partial neighbourhood is the least-squares plane through
// the neighbours within max_jump (independently: a QR solve of the design matrix), and its
// cosine that of the plane's normal (the cross product of its tangents) with the pixel's ray.
TEST(Fusion, SmoothedSurfaceIsTheLeastSquaresPlane) {
  DepthCameraOptions cam;
  const CameraIntrinsics& K = cam.intrinsics;
  const DepthImage d = awkwardDepthImage(cam);
  const float jump = 0.008f;
  int checked = 0;
  for (int v = 2; v < K.height - 2; v += 3)
    for (int u = 2; u < K.width - 2; u += 3) {
      const float D = d.at(u, v);
      if (!(D > 0.1f && D < 2.f)) continue;
      std::vector<Eigen::Vector3d> rows;
      std::vector<double> zs;
      for (int dv = -2; dv <= 2; ++dv)
        for (int du = -2; du <= 2; ++du) {
          const float Dn = d.at(u + du, v + dv);
          if (!(Dn > 0.f) || std::abs(Dn - D) > jump) continue;
          rows.emplace_back(1.0, du, dv);
          zs.push_back(double(Dn) - double(D));
        }
      if (rows.size() < 8 || rows.size() == 25) continue;
      Eigen::MatrixXd A(rows.size(), 3);
      Eigen::VectorXd z(rows.size());
      for (size_t k = 0; k < rows.size(); ++k) {
        A.row(Eigen::Index(k)) = rows[k].transpose();
        z(Eigen::Index(k)) = zs[k];
      }
      const Eigen::Vector3d abc = A.colPivHouseholderQr().solve(z);
      const double Z = double(D) + abc(0);
      const Vec3 ray = K.rayZ1(u, v);
      const Vec3 tu = abc(1) * ray + Vec3(Z / K.fx, 0, 0), tv = abc(2) * ray + Vec3(0, Z / K.fy, 0);
      const double cosine = std::abs(tu.cross(tv).normalized().dot(ray.normalized()));
      const SmoothedSurface s = smoothedSurface(d, K, u, v, jump);
      EXPECT_NEAR(s.depth, Z, 2e-6 * Z) << u << " " << v;
      EXPECT_NEAR(s.cos_incidence, cosine, 1e-5) << u << " " << v;
      ++checked;
    }
  EXPECT_GT(checked, 1000);
}

// measurementSigma against the noise model written out pixel by pixel here: the incidence from
// the cross product of the tangents along u and v (central differences over the neighbours on
// the same surface), axialSigma at that angle, × discontinuity_factor next to a jump or a
// missing return; on noisy oblique faces with odd values, whole image and a region.
TEST(Fusion, MeasurementSigmaFollowsTheNoiseModelAtEveryPixel) {
  DepthCameraOptions cam;
  const CameraIntrinsics& K = cam.intrinsics;
  const DepthImage d = awkwardDepthImage(cam);
  NoiseModelOptions nm;
  auto point = [&](int u, int v) { return Vec3(K.rayZ1(u, v) * double(d.at(u, v))); };
  const PixelRect region{100, 50, 420, 300};
  const std::vector<float> all = measurementSigma(d, K, nm),
                           some = measurementSigma(d, K, nm, &region);
  int checked = 0, grazing = 0, edges = 0;
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      const size_t i = size_t(v) * K.width + u;
      const double D = d.at(u, v);
      const bool inRegion = u >= region.u0 && u < region.u1 && v >= region.v0 && v < region.v1;
      ASSERT_EQ(some[i], inRegion ? all[i] : 0.f) << u << " " << v;
      if (!(D > 0)) {
        ASSERT_EQ(all[i], 0.f);
        continue;
      }
      bool edge = false;
      Vec3 t[2] = {Vec3::Zero(), Vec3::Zero()};
      for (int axis = 0; axis < 2; ++axis)
        for (int s : {-1, 1}) {
          const int uu = u + (axis == 0 ? s : 0), vv = v + (axis == 1 ? s : 0);
          if (uu < 0 || vv < 0 || uu >= K.width || vv >= K.height) continue;
          const double Dn = d.at(uu, vv);
          if (!(Dn > 0) || std::abs(Dn - D) > nm.discontinuity_jump_m) {
            edge = true;
            continue;
          }
          t[axis] += s * (point(uu, vv) - point(u, v));
        }
      const Vec3 n = t[0].cross(t[1]);
      double theta = 0;
      if (n.norm() > 0)
        theta = std::acos(std::min(1.0, std::abs(n.normalized().dot(point(u, v).normalized()))));
      if (theta < nm.grazing_start_deg * M_PI / 180.0 - 1e-6) theta = 0;  // no grazing term
      const double want = axialSigma(nm, D, theta) * (edge ? nm.discontinuity_factor : 1.0);
      if (std::isfinite(float(want)))
        ASSERT_NEAR(all[i], want, 1e-6 * want) << u << " " << v;
      else
        ASSERT_EQ(all[i], float(want)) << u << " " << v;  // a depth of 3e30 m or +inf
      ++checked;
      grazing += theta > 0;
      edges += edge;
    }

  EXPECT_GT(checked, 50000);
  EXPECT_GT(grazing, 100);
  EXPECT_GT(edges, 1000);
}

// The reach behind each measurement is taken from the smoothed surface, so which voxels a
// measurement updates hardly depends on its own noise: a solid box fused with the reach at 2σ
// has its surface where it is (the box's own signed distance at the observed vertices, mean
// within 0.05 mm), raw and smoothed depths alike. (A reach taken from each pixel's noisy depth
// drops the measurements that fell behind more often than those in front.)
TEST(Fusion, TheReachBehindTheSmoothedSurfaceLeavesSolidsUnbiased) {
  const Vec3 half(0.03, 0.079, 0.105);
  const TriangleMesh box = makeBox(2 * half);
  auto meanSignedMm = [&](const VolumeOptions& vo) {
    TsdfVolume vol(cube(0.3), vo);
    std::vector<Iso3> poses;
    for (const Vec3& dir : fibonacciSphere(20)) poses.push_back(lookAt(0.7 * dir, Vec3::Zero()));
    test::renderAndFuse(box, poses, /*noise=*/true, &vol);
    const ObjectModel m = extractModel(vol);
    double sum = 0;
    int n = 0;
    for (size_t i = 0; i < m.mesh.vertices.size(); ++i) {
      if (!m.observed[i]) continue;
      const Vec3 p = m.mesh.vertices[i].cast<double>();
      const Vec3 q = p.cwiseAbs() - half;  // box signed distance (outside: > 0)
      const double sd = q.maxCoeff() > 0 ? q.cwiseMax(0.0).norm() : q.maxCoeff();
      sum += sd;
      ++n;
    }
    return 1000 * sum / std::max(1, n);
  };
  const std::vector<VolumeOptions> settings = bandSettings();
  const double full = meanSignedMm(settings[0]);
  for (size_t i = 1; i < settings.size(); ++i) {
    const double m = meanSignedMm(settings[i]);
    std::printf("band %.0f %s: mean signed %.3f mm (full band, raw: %.3f)\n",
                settings[i].band_sigmas, settings[i].smooth_depth ? "smoothed" : "raw", m, full);
    if (settings[i].band_sigmas > 0) {
      EXPECT_LT(std::abs(m), 0.05) << i;
    }
  }
}
