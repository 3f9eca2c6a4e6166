// View planning benchmarks (issue: 1000 evaluations/s; Alg. 1 over 500 directions < 1 s).
// Scenario: the juice bottle (Ø 88 × 245 mm, about 20 cm class) held by the WAM's BarrettHand,
// model fused from 3 noisy views, camera at 0.7 m, 640×480, hand and arm as occluders.
// Run: ./build/bench/bench_planning
#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>

#include "inhand/core/pose.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/planning/view_selection.h"
#include "inhand/sensor/render.h"
#include "inhand/sim/sim_world.h"
#include "inhand/volume/integrate.h"

using namespace inhand;

namespace {

struct Scenario {
  RobotModel model =
      RobotModel::load(std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json");
  TriangleMesh object = loadObject("builtin:juice_bottle");
  Iso3 T_O_palm;
  JointVector q;
  ObjectModel S_obj;
  std::shared_ptr<NearHandGrid> nearHand;
  Scenario() {
    std::tie(T_O_palm, q) = defaultGrasp(model, object);
    Aabb b = object.bounds();
    TsdfVolume vol(Aabb{b.min - Vec3::Constant(0.04), b.max + Vec3::Constant(0.04)},
                   VolumeOptions{});
    RayScene scene;
    scene.addMesh(object);
    scene.commit();
    DepthCameraOptions cam;
    NoiseModelOptions nm;
    int i = 0;
    for (const Vec3& d : fibonacciSphere(3)) {
      Iso3 T = lookAt(0.7 * d, Vec3::Zero());
      RenderOptions ro;
      ro.seed = uint64_t(++i);
      DepthImage depth = renderDepth(scene, T, cam, nm, ro);
      integrate(depth, T, cam.intrinsics, measurementSigma(depth, cam.intrinsics, nm), &vol);
    }
    S_obj = extractModel(vol);
    nearHand = std::make_shared<NearHandGrid>(HandGeometry(model, q, T_O_palm), 0.01, 0.002);
  }
};
Scenario& scenario() {
  static Scenario s;
  return s;
}

// One eq. 9 evaluation per iteration, candidates spread over the sphere, both cores (one
// candidate per core at a time, as Alg. 1 runs them).
void BM_ViewQuality(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene vq(s.S_obj, DepthCameraOptions{}, NoiseModelOptions{}, ViewQualityOptions{});
  vq.setNearHand(s.nearHand);
  RobotOccluders occ(s.model);
  ViewPlanner planner(s.model, DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{});
  std::vector<Iso3> poses;
  std::vector<std::vector<Occluder>> occluders;
  for (const Vec3& d : fibonacciSphere(64)) {
    Iso3 T_O_C = cameraPoseInObject(s.S_obj.mesh.bounds().center(), d, 0.7, 0);
    poses.push_back(T_O_C);
    Iso3 T_B_O = planner.objectPoseFor(T_O_C, 0.7);
    occluders.push_back(occ.at(s.q, T_B_O.inverse()));
  }
  const int batch = 64;
  for (auto _ : state) {
    std::vector<double> q(batch);
    tbb::parallel_for(0, batch, [&](int i) { q[i] = vq.quality(poses[i], occluders[i]); });
    benchmark::DoNotOptimize(q);
  }
  state.counters["evaluations_per_s"] =
      benchmark::Counter(double(state.iterations()) * batch, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ViewQuality)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ViewQualityReference(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene vq(s.S_obj, DepthCameraOptions{}, NoiseModelOptions{}, ViewQualityOptions{});
  vq.setNearHand(s.nearHand);
  Iso3 T_O_C =
      cameraPoseInObject(s.S_obj.mesh.bounds().center(), Vec3(1, 0.2, 0.1).normalized(), 0.7, 0);
  for (auto _ : state) benchmark::DoNotOptimize(vq.qualityReference(T_O_C));
}
BENCHMARK(BM_ViewQualityReference)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// A full Alg. 1 pass: 500 directions, 8 rolls each, IK + collision + eq. 9.
void BM_SelectView(benchmark::State& state) {
  Scenario& s = scenario();
  ViewPlanner planner(s.model, DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{});
  ViewSelection sel;
  for (auto _ : state) sel = planner.select(s.S_obj, GraspState{s.T_O_palm, s.q}, {}, s.nearHand);
  state.counters["directions"] = sel.directions;
  state.counters["reachable"] = sel.reachable;
  state.counters["ik_s"] = sel.ik_s;
  state.counters["quality_s"] = sel.quality_s;
}
BENCHMARK(BM_SelectView)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

}  // namespace

BENCHMARK_MAIN();
