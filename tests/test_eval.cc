// Ground-truth metrics and the baseline view metrics of `inhand eval`, against exact answers and
// hand computations.
#include <gtest/gtest.h>

#include "inhand/core/random.h"
#include "inhand/eval/metrics.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/planning/view_selection.h"
#include "inhand/planning/volumetric.h"
#include "test_util.h"

using namespace inhand;

namespace {

ObjectModel observedModel(const TriangleMesh& mesh) {
  ObjectModel m;
  m.mesh = mesh;
  m.variance.assign(mesh.vertices.size(), 1e-6f);
  m.observed.assign(mesh.vertices.size(), 1);
  return m;
}

}  // namespace

TEST(SurfaceDistance, ClosestPointOnTriangleCoversEveryRegion) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_LT((closestPointOnTriangle(Vec3(0.2, 0.2, 3), a, b, c) - Vec3(0.2, 0.2, 0)).norm(), 1e-12);
  EXPECT_LT((closestPointOnTriangle(Vec3(-1, -1, 0), a, b, c) - a).norm(), 1e-12);
  EXPECT_LT((closestPointOnTriangle(Vec3(2, -1, 0), a, b, c) - b).norm(), 1e-12);
  EXPECT_LT((closestPointOnTriangle(Vec3(-1, 2, 1), a, b, c) - c).norm(), 1e-12);
  EXPECT_LT((closestPointOnTriangle(Vec3(0.5, -2, 0), a, b, c) - Vec3(0.5, 0, 0)).norm(), 1e-12);
  EXPECT_LT((closestPointOnTriangle(Vec3(-2, 0.3, 0), a, b, c) - Vec3(0, 0.3, 0)).norm(), 1e-12);
  EXPECT_LT((closestPointOnTriangle(Vec3(1, 1, 0), a, b, c) - Vec3(0.5, 0.5, 0)).norm(), 1e-12);
}

TEST(SurfaceDistance, IndexMatchesBruteForceReference) {
  const TriangleMesh mesh = makeCylinder(0.04, 0.12, 48);
  const TriangleDistanceIndex index(mesh);
  Rng rng = makeRng(7);
  std::uniform_real_distribution<double> U(-0.15, 0.15);
  for (int i = 0; i < 2000; ++i) {
    const Vec3 p(U(rng), U(rng), U(rng) * (i % 3 == 0 ? 4 : 1));  // some far outside the grid
    EXPECT_NEAR(index.distance(p), index.distanceReference(p), 1e-12) << p.transpose();
  }
}

// within(p, r) against the reference distance, for radii about the index's cells and points
// near the surface (where the answer turns), some far outside the grid.
TEST(SurfaceDistance, WithinMatchesTheReferenceDistance) {
  const TriangleMesh mesh = makeSphere(0.05, 4);
  const TriangleDistanceIndex index(mesh);
  Rng rng = makeRng(11);
  std::uniform_real_distribution<double> U(-1, 1), R(0.0, 0.01);
  int in = 0, out = 0;
  for (int i = 0; i < 4000; ++i) {
    Vec3 d(U(rng), U(rng), U(rng));
    d.normalize();
    const double radius = i % 5 == 0 ? 0.3 : 0.05 + 0.01 * U(rng);
    const Vec3 p = radius * d;
    const double r = R(rng), ref = index.distanceReference(p);
    if (std::abs(ref - r) < 1e-9) continue;  // on the boundary: either answer
    EXPECT_EQ(index.within(p, r), ref <= r) << p.transpose() << " r " << r << " d " << ref;
    (ref <= r ? in : out) += 1;
  }
  EXPECT_GT(in, 1000);
  EXPECT_GT(out, 1000);
}

TEST(SurfaceDistance, UniformSamplesLieOnTheSurfaceInProportionToArea) {
  // Box 0.2 × 0.1 × 0.05: the ±x faces hold 0.005 / 0.035 of the area each.
  const TriangleMesh box = makeBox(Vec3(0.2, 0.1, 0.05));
  const std::vector<Vec3> s = sampleSurfaceUniform(box, 40000, 3);
  ASSERT_EQ(s.size(), 40000u);
  const TriangleDistanceIndex index(box);
  int plusX = 0;
  for (const Vec3& p : s) {
    EXPECT_LT(index.distance(p), 1e-9);
    plusX += p.x() > 0.1 - 1e-9;
  }
  EXPECT_NEAR(plusX / 40000.0, 0.005 / 0.07, 0.005);  // 3.5σ of the binomial
  EXPECT_EQ(sampleSurfaceUniform(box, 10, 3), sampleSurfaceUniform(box, 10, 3));  // seeded
}

TEST(GroundTruth, TrueMeshAgainstItselfIsCompleteAndExact) {
  const TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  const GroundTruth truth(box);
  const SurfaceMetrics m = truth.evaluate(observedModel(box));
  EXPECT_DOUBLE_EQ(m.coverage, 1.0);
  EXPECT_LT(m.accuracy_mean_mm, 1e-6);
  EXPECT_LT(m.accuracy_p95_mm, 1e-6);
  for (double f : m.fscore) EXPECT_DOUBLE_EQ(f, 1.0);
  EXPECT_NEAR(m.observed_area_m2, 0.06, 1e-7);  // float vertices
}

TEST(GroundTruth, RemovingAFaceLosesItsShareOfCoverage) {
  // A 10 cm cube with its +z face not observed. Samples on that face within τ = 3 mm of its
  // four edges are within τ of the side faces; the rest, (0.1 − 2τ)², are lost:
  // coverage = 1 − 0.094² / 0.06 = 0.85273.
  const TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  ObjectModel m = observedModel(box);
  // Unweld the +z face's vertices: only triangles with all three vertices observed count.
  TriangleMesh split;
  std::vector<uint8_t> obs;
  for (int t = 0; t < int(box.triangles.size()); ++t) {
    const bool top = box.faceNormal(t).z() > 0.9;
    Tri f;
    for (int k = 0; k < 3; ++k) {
      f[k] = int(split.vertices.size());
      split.vertices.push_back(box.vertices[box.triangles[t][k]]);
      obs.push_back(top ? 0 : 1);
    }
    split.triangles.push_back(f);
  }
  m = observedModel(split);
  m.observed = obs;
  EvalOptions o;
  o.samples = 60000;
  const GroundTruth truth(box, o);
  const SurfaceMetrics r = truth.evaluate(m);
  EXPECT_NEAR(r.coverage, 1 - 0.094 * 0.094 / 0.06, 0.006);
  EXPECT_NEAR(truth.coverage(m), r.coverage, 1e-12);
  EXPECT_LT(r.accuracy_mean_mm, 1e-6);  // what is there is exact
  EXPECT_NEAR(r.observed_area_m2, 0.05, 1e-7);
  // Recall at 10 mm: the top face minus its 10 mm border strip is lost.
  EXPECT_NEAR(r.recall[2], 1 - 0.08 * 0.08 / 0.06, 0.006);
  EXPECT_DOUBLE_EQ(r.precision[2], 1.0);
}

TEST(GroundTruth, ShiftedModelHasThatAccuracy) {
  const TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  // The same box grown by 2 mm on every side: every model point is 2 mm from the truth, except
  // near edges and corners, where it is farther (up to 2√3 mm at corners).
  const ObjectModel grown = observedModel(makeBox(Vec3(0.104, 0.104, 0.104)));
  const SurfaceMetrics r = GroundTruth(box).evaluate(grown);
  EXPECT_NEAR(r.accuracy_mean_mm, 2.0, 0.05);
  EXPECT_GE(r.accuracy_p95_mm, 2.0 - 1e-6);
  EXPECT_DOUBLE_EQ(r.coverage, 1.0);  // τ = 3 mm > 2 mm
  EXPECT_LT(r.fscore[0], 0.05);       // at 2 mm almost nothing matches
}

// A 10 cm cube with two 1 cm cubes beside it: one 3 cm off its face (no vertex within 5 mm of the
// truth: detached, 6 cm²), one whose near face lies 2 mm beyond the cube's (attached). Pieces are
// counted by shared vertices.
TEST(GroundTruth, PiecesAwayFromTheTruthAreDetached) {
  const TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  TriangleMesh model = box;
  const TriangleMesh small = makeBox(Vec3(0.01, 0.01, 0.01));
  model.append(transformed(small, Iso3(Eigen::Translation3d(0.085, 0, 0))));
  model.append(transformed(small, Iso3(Eigen::Translation3d(0, 0.057, 0))));
  int pieces = 0;
  const std::vector<int> piece = meshPieces(model, &pieces);
  EXPECT_EQ(pieces, 3);
  EXPECT_EQ(piece.front(), 0);
  EXPECT_EQ(piece.back(), 2);
  const SurfaceMetrics r = GroundTruth(box).evaluate(observedModel(model));
  EXPECT_EQ(r.detached_pieces, 1);
  EXPECT_NEAR(r.detached_area_m2, 6e-4, 1e-8);
  EXPECT_EQ(GroundTruth(box).evaluate(observedModel(box)).detached_area_m2, 0.0);
  // Nearer than detached_m counts as attached: at 4 cm the far cube is attached too.
  EvalOptions o;
  o.detached_m = 0.04;
  EXPECT_EQ(GroundTruth(box, o).evaluate(observedModel(model)).detached_pieces, 0);
}

// ---- baselines -----------------------------------------------------------------------------

TEST(Baselines, UnknownAreaIsTheVisibleHoleFilledArea) {
  // A 10 cm cube whose −x face (seen head-on by a camera on the −x side) is hole-filled.
  TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  ObjectModel m = test::unweldedModel(box, [](const Vec3&) { return 1e-7f; });
  for (size_t t = 0; t < m.mesh.triangles.size(); ++t)
    if (m.mesh.faceNormal(int(t)).x() < -0.9)
      for (int k = 0; k < 3; ++k) m.observed[m.mesh.triangles[t][k]] = 0;
  ViewQualityOptions o;
  o.integrand = QualityIntegrand::kUnknownArea;
  ViewQualityScene vq(m, DepthCameraOptions{}, NoiseModelOptions{}, o);
  const double facing = vq.quality(cameraPoseInObject(Vec3::Zero(), Vec3(1, 0, 0), 0.7, 0));
  const double behind = vq.quality(cameraPoseInObject(Vec3::Zero(), Vec3(-1, 0, 0), 0.7, 0));
  EXPECT_NEAR(facing, 0.01, 0.0003);  // the face's 0.01 m²
  EXPECT_DOUBLE_EQ(behind, 0.0);
  // The optimised and reference integrators sum in float in different orders (and the AVX2 paths
  // may be off): they agree to float precision, not bit for bit.
  EXPECT_NEAR(vq.qualityReference(cameraPoseInObject(Vec3::Zero(), Vec3(1, 0, 0), 0.7, 0)), facing,
              1e-5 * facing);
}

namespace {

constexpr double kRange = 0.7;

// A 10 cm volume of 5 mm voxels, everything seen empty except a 4 × 4 cm block (8 × 8 voxels) of
// `front` surface voxels then `depth` unknown voxels along +z.
TsdfVolume blockVolume(int front, int depth) {
  Aabb box;
  box.extend(Vec3::Constant(-0.05));
  box.extend(Vec3::Constant(0.05));
  VolumeOptions vo;
  vo.voxel_size_m = 0.005;
  TsdfVolume v(box, vo);
  for (size_t i = 0; i < v.voxelCount(); ++i) v.states()[i] = uint8_t(VoxelState::kEmpty);
  const int c = v.dims().x() / 2;
  for (int z = 0; z < front + depth; ++z)
    for (int y = c - 4; y < c + 4; ++y)
      for (int x = c - 4; x < c + 4; ++x) {
        const size_t i = v.index(x, y, z + 6);
        if (z < front) {
          v.states()[i] = uint8_t(VoxelState::kObserved);
          v.sumW()[i] = 1;
          v.sumWD()[i] = -0.001f;  // just behind the surface: occupied
        } else {
          v.states()[i] = uint8_t(VoxelState::kUnknown);
        }
      }
  return v;
}

// A one-pixel camera whose single ray is the optical axis (exact per-ray hand computations).
DepthCameraOptions axisCamera() {
  DepthCameraOptions c;
  c.intrinsics.width = c.intrinsics.height = 1;
  c.intrinsics.cx = c.intrinsics.cy = 0;
  return c;
}

// Pixels the 4 cm block face covers, seen head-on from `range` to the volume centre: its front
// face lies at depth range + z_front.
double blockPixels(const TsdfVolume& v, int zIndex, double range) {
  const double zFront = v.origin().z() + (zIndex - 0.5) * v.voxelSize();
  const double d = range + zFront;
  const CameraIntrinsics K;
  return 0.04 * 0.04 * K.fx * K.fy / (d * d);
}

}  // namespace

TEST(Baselines, UnobservedVoxelsCountsVisibleUnknownVoxels) {
  const int depth = 3;
  TsdfVolume v = blockVolume(0, depth);
  VolumetricOptions o;
  o.ray_stride = 1;
  const VolumetricScorer scorer(v, DepthCameraOptions{}, o);
  const Iso3 T_O_C = cameraPoseInObject(Vec3::Zero(), Vec3(0, 0, 1), kRange, 0);
  // Each ray through the block: unknown voxels of p = 0.5 behind each other, visibility halving:
  // 1 + ½ + ¼ = 1.75 exactly on the axis.
  EXPECT_DOUBLE_EQ(
      VolumetricScorer(v, axisCamera(), o).score(T_O_C, VolumetricMetric::kUnobservedVoxels), 1.75);
  // Over the image: that times the block's pixels, less a few percent for rays near the block's
  // edges that leave through its sides.
  const double expected = blockPixels(v, 6, kRange) * (2 * (1 - std::pow(0.5, depth)));
  EXPECT_NEAR(scorer.score(T_O_C, VolumetricMetric::kUnobservedVoxels), expected, 0.08 * expected);
  // From the other side the same (the block is symmetric in traversal), and from the side the
  // block shows a 4 × 1.5 cm face.
  EXPECT_NEAR(scorer.score(cameraPoseInObject(Vec3::Zero(), Vec3(0, 0, -1), kRange, 0),
                           VolumetricMetric::kUnobservedVoxels),
              expected * blockPixels(v, 6 + depth, kRange) / blockPixels(v, 6, kRange),
              0.08 * expected);
  // A stride of 4 samples the same integral.
  o.ray_stride = 4;
  EXPECT_NEAR(VolumetricScorer(v, DepthCameraOptions{}, o)
                  .score(T_O_C, VolumetricMetric::kUnobservedVoxels),
              expected, 0.1 * expected);
  // No unknown voxel behind an observed surface here: no rear-side entropy.
  EXPECT_DOUBLE_EQ(scorer.score(T_O_C, VolumetricMetric::kRearSideEntropy), 0.0);
}

TEST(Baselines, RearSideEntropyCountsUnknownBehindTheSurface) {
  const int front = 2, depth = 4;
  TsdfVolume v = blockVolume(front, depth);
  VolumetricOptions o;
  o.ray_stride = 1;
  const VolumetricScorer scorer(v, DepthCameraOptions{}, o);
  const Iso3 T_O_C = cameraPoseInObject(Vec3::Zero(), Vec3(0, 0, 1), kRange, 0);
  const double series = 2 * (1 - std::pow(0.5, depth));  // Σ ½ⁱ, H(0.5) = 1 bit each
  const double px = blockPixels(v, 6, kRange);
  // Rear side: the surface band passed unattenuated, then 1 + ½ + ¼ + ⅛ bits.
  const VolumetricScorer axis(v, axisCamera(), o);
  EXPECT_DOUBLE_EQ(axis.score(T_O_C, VolumetricMetric::kRearSideEntropy), series);
  EXPECT_NEAR(scorer.score(T_O_C, VolumetricMetric::kRearSideEntropy), px * series,
              0.08 * px * series);
  // Unobserved voxels: behind two occupied voxels (p = 0.9) only 0.1² of the visibility is left.
  EXPECT_NEAR(axis.score(T_O_C, VolumetricMetric::kUnobservedVoxels), 0.01 * series, 1e-12);
  // (Over the image, rays that cross the band obliquely pass three occupied voxels, not two.)
  EXPECT_LT(scorer.score(T_O_C, VolumetricMetric::kUnobservedVoxels), 0.01 * px * series);
  // A robot surface in front of the block hides it completely.
  RayScene wall;
  wall.addMesh(makeBox(Vec3(0.2, 0.2, 0.01)), Iso3(Eigen::Translation3d(0, 0, -0.2)));
  wall.commit();
  EXPECT_DOUBLE_EQ(
      scorer.score(T_O_C, VolumetricMetric::kRearSideEntropy, {{&wall, Iso3::Identity()}}), 0.0);
}

TEST(Baselines, PlannerNamesSetTheirMetric) {
  ViewPlannerOptions o;
  for (const std::string& n : plannerNames()) EXPECT_TRUE(applyPlannerName(n, &o)) << n;
  EXPECT_FALSE(applyPlannerName("best", &o));
  ASSERT_TRUE(applyPlannerName("ig-no-hand", &o));
  EXPECT_FALSE(o.hand_occlusion);
  EXPECT_TRUE(o.use_cost);
  ASSERT_TRUE(applyPlannerName("area", &o));
  EXPECT_EQ(o.quality.integrand, QualityIntegrand::kUnknownArea);
  EXPECT_FALSE(o.use_cost);
  ASSERT_TRUE(applyPlannerName("ig", &o));  // back to the paper's settings
  EXPECT_EQ(o.quality.integrand, QualityIntegrand::kInformationGain);
  EXPECT_TRUE(o.hand_occlusion && o.use_cost);
  EXPECT_DOUBLE_EQ(o.t_q, 0.005);
}

TEST(Baselines, RandomPlannerIsSeededAndPicksAReachableView) {
  const RobotModel& r = test::wam();
  const ObjectModel m = observedModel(makeBox(Vec3(0.06, 0.06, 0.12)));
  ViewPlannerOptions o;
  ASSERT_TRUE(applyPlannerName("random", &o));
  o.directions = 40;
  o.rolls = 4;
  o.fallback_ranges_m.clear();
  // The default side grasp of the sim holds a box like this one from +y.
  const Iso3 T_O_palm =
      Iso3(Eigen::Translation3d(0, 0.03 + 0.09, 0)) * Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX());
  GraspState g{T_O_palm, r.home()};
  auto pick = [&](uint64_t seed) {
    o.seed = seed;
    ViewPlanner p(r, DepthCameraOptions{}, NoiseModelOptions{}, o);
    return p.select(m, g, {}, nullptr);
  };
  const ViewSelection a = pick(1), b = pick(1), c = pick(2);
  ASSERT_TRUE(a.best && b.best && c.best);
  EXPECT_GT(a.reachable, 3);
  EXPECT_EQ(a.best->dir_O, b.best->dir_O);
  EXPECT_GE(a.best->quality, 0.0);
  EXPECT_LT(a.best->quality, 1.0);
  // Across seeds the choice changes (the draws are independent per seed).
  int differ = 0;
  for (uint64_t s = 2; s < 6; ++s) differ += pick(s).best->dir_O != a.best->dir_O;
  EXPECT_GE(differ, 3);
}
