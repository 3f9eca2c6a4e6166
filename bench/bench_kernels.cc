// Kernel benchmarks of the foundation (issue: integration, rendering, mesh extraction).
// Scenario constants are fixed: the cracker box (60×158×210 mm) at 0.7 m, a 0.3 m cube volume at
// 2 mm voxels (151³ = 3.44 M voxels), one 640×480 frame. Run: ./build/bench/bench_kernels
#include <benchmark/benchmark.h>

#include "inhand/core/pose.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/mesh/extract.h"
#include "inhand/sensor/render.h"
#include "inhand/volume/integrate.h"

using namespace inhand;

namespace {

struct Scenario {
  RayScene scene;
  DepthCameraOptions camera;
  NoiseModelOptions noise;
  Iso3 T_O_C;
  DepthImage depth;
  std::vector<float> sigma;
  Aabb box;
  Scenario() {
    scene.addMesh(loadObject("builtin:cracker_box"));
    scene.commit();
    T_O_C = lookAt(Vec3(0.45, -0.4, 0.3).normalized() * 0.7, Vec3::Zero());
    depth = renderDepth(scene, T_O_C, camera, noise, RenderOptions{});
    sigma = measurementSigma(depth, camera.intrinsics, noise);
    box.extend(Vec3::Constant(-0.15));
    box.extend(Vec3::Constant(0.15));
  }
};

Scenario& scenario() {
  static Scenario s;
  return s;
}

void BM_IntegrateFrame(benchmark::State& state) {
  Scenario& s = scenario();
  TsdfVolume vol(s.box, VolumeOptions{});
  int64_t updated = 0;
  for (auto _ : state)
    updated += integrate(s.depth, s.T_O_C, s.camera.intrinsics, s.sigma, &vol).updated;
  state.counters["voxels_M"] = double(vol.voxelCount()) / 1e6;
  state.counters["volume_Mvox_per_s"] = benchmark::Counter(
      double(vol.voxelCount()) * double(state.iterations()) / 1e6, benchmark::Counter::kIsRate);
  state.counters["updated_Mvox_per_s"] =
      benchmark::Counter(double(updated) / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_IntegrateFrame)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_IntegrateFrameReference(benchmark::State& state) {
  Scenario& s = scenario();
  TsdfVolume vol(s.box, VolumeOptions{});
  for (auto _ : state) integrateReference(s.depth, s.T_O_C, s.camera.intrinsics, s.sigma, &vol);
  state.counters["volume_Mvox_per_s"] = benchmark::Counter(
      double(vol.voxelCount()) * double(state.iterations()) / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_IntegrateFrameReference)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

void BM_MeasurementSigma(benchmark::State& state) {
  Scenario& s = scenario();
  for (auto _ : state)
    benchmark::DoNotOptimize(measurementSigma(s.depth, s.camera.intrinsics, s.noise));
}
BENCHMARK(BM_MeasurementSigma)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RenderFrame(benchmark::State& state) {
  Scenario& s = scenario();
  RenderOptions ro;
  ro.noise = state.range(0) != 0;
  for (auto _ : state)
    benchmark::DoNotOptimize(renderDepth(s.scene, s.T_O_C, s.camera, s.noise, ro));
  state.SetLabel(ro.noise ? "noisy" : "noise-free");
}
BENCHMARK(BM_RenderFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RenderFrameReference(benchmark::State& state) {
  Scenario& s = scenario();
  for (auto _ : state) benchmark::DoNotOptimize(renderDepthReference(s.scene, s.T_O_C, s.camera));
}
BENCHMARK(BM_RenderFrameReference)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// Mesh extraction of the 0.3 m volume after fusing 20 views all round.
void BM_ExtractMesh(benchmark::State& state) {
  Scenario& s = scenario();
  TsdfVolume vol(s.box, VolumeOptions{});
  int i = 0;
  for (const Vec3& d : fibonacciSphere(20)) {
    Iso3 T = lookAt(0.7 * d, Vec3::Zero());
    RenderOptions ro;
    ro.seed = uint64_t(++i);
    DepthImage depth = renderDepth(s.scene, T, s.camera, s.noise, ro);
    integrate(depth, T, s.camera.intrinsics, measurementSigma(depth, s.camera.intrinsics, s.noise),
              &vol);
  }
  size_t tris = 0;
  for (auto _ : state) tris = extractModel(vol).mesh.triangles.size();
  state.counters["triangles"] = double(tris);
}
BENCHMARK(BM_ExtractMesh)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
