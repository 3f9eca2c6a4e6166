// Kernel benchmarks of the foundation (issue: integration, rendering, mesh extraction).
// Scenario constants are fixed: the cracker box (60×158×210 mm) at 0.7 m, a 0.3 m cube volume at
// 2 mm voxels (151³ = 3.44 M voxels), one 640×480 frame. Run: ./build/bench/bench_kernels
#include <benchmark/benchmark.h>

#include <algorithm>

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

// What `inhand fuse` does per frame with the defaults (σ over the volume's image rect, the band
// behind each pixel's smoothed surface, smoothed depths) in a tight cube around the box (0.23 m),
// the same frame again and again.
void BM_FuseFrameTight(benchmark::State& state) {
  Scenario& s = scenario();
  const CameraIntrinsics& K = s.camera.intrinsics;
  VolumeOptions vo;
  vo.band_sigmas = 2.0;
  vo.smooth_depth = true;
  TsdfVolume vol(Aabb{Vec3::Constant(-0.115), Vec3::Constant(0.115)}, vo);
  for (auto _ : state) {
    const PixelRect rect = volumeImageRect(vol, s.T_O_C, K);
    benchmark::DoNotOptimize(
        integrate(s.depth, s.T_O_C, K, measurementSigma(s.depth, K, s.noise, &rect), &vol));
  }
}
BENCHMARK(BM_FuseFrameTight)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_MeasurementSigma(benchmark::State& state) {
  Scenario& s = scenario();
  for (auto _ : state)
    benchmark::DoNotOptimize(measurementSigma(s.depth, s.camera.intrinsics, s.noise));
}
BENCHMARK(BM_MeasurementSigma)->Unit(benchmark::kMillisecond)->UseRealTime();

// The smoothed surface (5×5 plane fit) of every pixel with a depth: smoothedSurfaces() (/1) and
// smoothedSurface() pixel by pixel on one core (/0, the reference).
void BM_SmoothedSurfaces(benchmark::State& state) {
  Scenario& s = scenario();
  const CameraIntrinsics& K = s.camera.intrinsics;
  std::vector<uint8_t> fit(s.depth.depth_m.size());
  for (size_t i = 0; i < fit.size(); ++i) fit[i] = s.depth.depth_m[i] > 0.f;
  std::vector<SmoothedSurface> out(fit.size());
  const PixelRect all{0, 0, K.width, K.height};
  for (auto _ : state) {
    if (state.range(0)) {
      smoothedSurfaces(s.depth, K, all, fit.data(), 0.008f,
                       [&](size_t i, const SmoothedSurface& sm) { out[i] = sm; });
    } else {
      for (int v = 0; v < K.height; ++v)
        for (int u = 0; u < K.width; ++u)
          if (fit[size_t(v) * K.width + u])
            out[size_t(v) * K.width + u] = smoothedSurface(s.depth, K, u, v, 0.008f);
    }
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["pixels"] = double(std::count(fit.begin(), fit.end(), 1));
}
BENCHMARK(BM_SmoothedSurfaces)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

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
