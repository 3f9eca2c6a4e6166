// View planning benchmarks (issue: 1000 evaluations/s; Alg. 1 over 500 directions < 1 s).
// Scenario: the cracker box (210 mm) held by the WAM's BarrettHand, S_obj as Alg. 1 sees it after
// the scan's initial trajectory (planning stride 2), camera at 0.7 m, 640×480, hand and arm as
// occluders.
// Run: ./build/bench/bench_planning
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <thread>
#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#else
#define CALLGRIND_START_INSTRUMENTATION
#define CALLGRIND_STOP_INSTRUMENTATION
#endif

#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/grasp/grasp.h"
#include "inhand/planning/view_selection.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/scan/scan.h"
#include "inhand/scan/session.h"
#include "inhand/sensor/render.h"
#include "inhand/sim/sim_world.h"
#include "inhand/volume/integrate.h"

using namespace inhand;

namespace {

struct Scenario {
  RobotModel model =
      RobotModel::load(std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json");
  TriangleMesh object = loadObject("builtin:cracker_box");  // 60 × 158 × 210 mm
  Iso3 T_O_palm;
  JointVector q;
  ObjectModel S_obj;
  std::shared_ptr<NearHandGrid> nearHand;
  Scenario() {
    // S_obj as the scan's Alg. 1 sees it after the initial trajectory (planning stride 2): a
    // simulated scan of several seconds, or the file INHAND_BENCH_SCENARIO names when it holds
    // one from an earlier run (it is written there otherwise; for quick A/B runs).
    const char* cache = std::getenv("INHAND_BENCH_SCENARIO");
    if (!(cache && load(cache))) {
      simulate();
      if (cache) save(cache);
    }
    nearHand = std::make_shared<NearHandGrid>(HandGeometry(model, q, T_O_palm), 0.01, 0.002);
    // 64 candidate views over the sphere, with the robot where it would be for each.
    RobotOccluders occ(model);
    ViewPlanner planner(model, DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{});
    for (const Vec3& d : fibonacciSphere(64)) {
      Iso3 T_O_C = cameraPoseInObject(S_obj.mesh.bounds().center(), d, 0.7, 0);
      poses.push_back(T_O_C);
      occluders.push_back(occ.at(q, planner.objectPoseFor(T_O_C, 0.7).inverse()));
    }
    robot_ = std::make_unique<RobotOccluders>(std::move(occ));
  }
  void simulate() {
    std::tie(T_O_palm, q) = defaultGrasp(model, object);
    SimWorld world(model, object, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{},
                   SimOptions{});
    world.q = q;
    SimRobot robot(&world);
    SimSensor sensor(&world, DepthCameraOptions{});
    ScanOptions o;
    o.max_views = 0;
    ScanResult r =
        scanSingleGrasp(robot, sensor, T_O_palm, T_O_palm * Vec3(0, 0, model.graspOffset()), o,
                        NoiseModelOptions{});
    S_obj = r.planning_model;
    q = robot.joints();
  }
  // Raw arrays, each after its element count.
  template <typename T>
  static void put(std::ofstream& f, const T* p, size_t n) {
    f.write(reinterpret_cast<const char*>(&n), sizeof n);
    f.write(reinterpret_cast<const char*>(p), std::streamsize(n * sizeof(T)));
  }
  template <typename T>
  static bool get(std::ifstream& f, std::vector<T>* v) {
    size_t n = 0;
    if (!f.read(reinterpret_cast<char*>(&n), sizeof n) || n > (size_t(1) << 28)) return false;
    v->resize(n);
    return bool(f.read(reinterpret_cast<char*>(v->data()), std::streamsize(n * sizeof(T))));
  }
  void save(const std::string& path) const {
    std::ofstream f(path, std::ios::binary);
    put(f, T_O_palm.matrix().data(), 16);
    put(f, q.data(), size_t(q.size()));
    put(f, S_obj.mesh.vertices.data(), S_obj.mesh.vertices.size());
    put(f, S_obj.mesh.triangles.data(), S_obj.mesh.triangles.size());
    put(f, S_obj.variance.data(), S_obj.variance.size());
    put(f, S_obj.observed.data(), S_obj.observed.size());
  }
  bool load(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    std::vector<double> palm, joints;
    if (!f || !get(f, &palm) || palm.size() != 16 || !get(f, &joints) ||
        !get(f, &S_obj.mesh.vertices) || !get(f, &S_obj.mesh.triangles) ||
        !get(f, &S_obj.variance) || !get(f, &S_obj.observed))
      return false;
    T_O_palm.matrix() = Eigen::Map<const Eigen::Matrix4d>(palm.data());
    q = Eigen::Map<const JointVector>(joints.data(), Eigen::Index(joints.size()));
    return true;
  }
  std::vector<Iso3> poses;
  std::vector<std::vector<Occluder>> occluders;
  std::unique_ptr<RobotOccluders> robot_;  // owns the link scenes the occluders point to
  ViewQualityScene qualityScene(int stride = 1,
                                PrimaryVisibility v = PrimaryVisibility::kAuto) const {
    ViewQualityOptions o;
    o.pixel_stride = stride;
    o.visibility = v;
    ViewQualityScene vq(S_obj, DepthCameraOptions{}, NoiseModelOptions{}, o);
    vq.setNearHand(nearHand);
    return vq;
  }
};
Scenario& scenario() {
  static Scenario s;
  return s;
}

// One eq. 9 evaluation per iteration, candidates spread over the sphere, both cores (one
// candidate per core at a time, as Alg. 1 runs them).
// Args: pixel stride (1: every pixel of the 640×480 map); primary visibility (0 auto: the
// rasteriser at strides 1 and 2, else ray casting; 1 rasteriser; 2 Embree ray casting).
void BM_ViewQuality(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene vq = s.qualityScene(int(state.range(0)), PrimaryVisibility(state.range(1)));
  const auto& poses = s.poses;
  const auto& occluders = s.occluders;
  const int batch = 64;
  for (auto _ : state) {
    std::vector<double> q(batch);
    parallelForThreads(0, batch, [&](int i) { q[i] = vq.quality(poses[i], occluders[i]); });
    benchmark::DoNotOptimize(q);
  }
  state.counters["evaluations_per_s"] =
      benchmark::Counter(double(state.iterations()) * batch, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ViewQuality)
    ->Args({1, 0})
    ->Args({1, 2})
    ->Args({2, 0})
    ->Args({2, 1})
    ->Args({4, 0})
    ->Args({4, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The same evaluations on one core, with the per-pixel outcome counts.
void BM_ViewQualityOneCore(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene vq = s.qualityScene();
  const auto& poses = s.poses;
  const auto& occluders = s.occluders;
  size_t i = 0;
  double cast = 0, counted = 0;
  const bool withRobot = state.range(0) != 0;
  for (auto _ : state) {
    ViewQualityStats st;
    benchmark::DoNotOptimize(
        vq.quality(poses[i], withRobot ? occluders[i] : std::vector<Occluder>{}, &st));
    cast += st.cast;
    counted += st.counted;
    i = (i + 1) % poses.size();
  }
  state.counters["rays_cast"] = cast / double(state.iterations());
  state.counters["pixels_counted"] = counted / double(state.iterations());
  state.counters["triangles"] = double(s.S_obj.mesh.triangles.size());
}
BENCHMARK(BM_ViewQualityOneCore)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();

// The same, robust to a shared machine: each of the 64 views evaluated 7 times in a row, its
// fastest time kept. `best_ms` is the mean of those per-view minimums: the code's own speed,
// with the interference of other tenants (which only ever adds time) mostly filtered out.
// Under `valgrind --tool=callgrind --instr-atstart=no` only these evaluations are measured: an
// instruction count that no other tenant changes.
void BM_ViewQualityOneCoreBest(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene vq = s.qualityScene();
  double best = 0;
  CALLGRIND_START_INSTRUMENTATION;
  for (auto _ : state) {
    best = 0;
    for (size_t i = 0; i < s.poses.size(); ++i) {
      double fastest = 1e9;
      for (int k = 0; k < 7; ++k) {
        const auto t0 = std::chrono::steady_clock::now();
        benchmark::DoNotOptimize(vq.quality(s.poses[i], s.occluders[i]));
        fastest = std::min(fastest, std::chrono::duration<double, std::milli>(
                                        std::chrono::steady_clock::now() - t0)
                                        .count());
      }
      best += fastest / double(s.poses.size());
    }
  }
  CALLGRIND_STOP_INSTRUMENTATION;
  state.counters["best_ms"] = best;
  // Every digit of the 64 views' summed quality: two builds that should agree bit for bit can be
  // compared by it.
  double sum = 0;
  for (size_t i = 0; i < s.poses.size(); ++i) sum += vq.quality(s.poses[i], s.occluders[i]);
  char label[64];
  std::snprintf(label, sizeof label, "sum_q=%.17g", sum);
  state.SetLabel(label);
}
BENCHMARK(BM_ViewQualityOneCoreBest)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

// The rasteriser alone: S_obj into a full 640×480 z-buffer, one core. Arg 1: back faces culled.
void BM_RasteriseModel(benchmark::State& state) {
  Scenario& s = scenario();
  const CameraIntrinsics K = DepthCameraOptions{}.intrinsics;
  DepthRaster r;
  size_t i = 0;
  for (auto _ : state) {
    r.reset({K.fx, K.fy, K.cx, K.cy}, {0, K.width - 1, 0, K.height - 1, 1});
    r.draw(s.S_obj.mesh, s.poses[i].inverse(), 0, state.range(0) != 0);
    benchmark::DoNotOptimize(r.id(0));
    i = (i + 1) % s.poses.size();
  }
}
BENCHMARK(BM_RasteriseModel)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// How far the rasterised path is from Embree ray casting on the scenario's 64 views: mean and
// largest relative difference of eq. 9.
void BM_ViewQualityAgreement(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene fast = s.qualityScene(1, PrimaryVisibility::kRaster);
  ViewQualityScene cast = s.qualityScene(1, PrimaryVisibility::kRayCast);
  double sum = 0, worst = 0;
  int n = 0;
  for (auto _ : state) {
    for (size_t i = 0; i < s.poses.size(); ++i) {
      const double a = fast.quality(s.poses[i], s.occluders[i]);
      const double b = cast.quality(s.poses[i], s.occluders[i]);
      if (b <= 0) continue;
      const double rel = std::abs(a - b) / b;
      sum += rel;
      worst = std::max(worst, rel);
      ++n;
    }
  }
  state.counters["mean_rel_diff"] = sum / std::max(1, n);
  state.counters["max_rel_diff"] = worst;
}
BENCHMARK(BM_ViewQualityAgreement)->Unit(benchmark::kMillisecond)->Iterations(1);

void BM_ViewQualityReference(benchmark::State& state) {
  Scenario& s = scenario();
  ViewQualityScene vq(s.S_obj, DepthCameraOptions{}, NoiseModelOptions{}, ViewQualityOptions{});
  vq.setNearHand(s.nearHand);
  Iso3 T_O_C =
      cameraPoseInObject(s.S_obj.mesh.bounds().center(), Vec3(1, 0.2, 0.1).normalized(), 0.7, 0);
  for (auto _ : state) benchmark::DoNotOptimize(vq.qualityReference(T_O_C));
}
BENCHMARK(BM_ViewQualityReference)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

// A full Alg. 1 pass: 500 directions, 8 rolls each, IK + collision + eq. 9. Arg 0: every
// reachable candidate at full resolution (exhaustive); arg 1: the default coarse to fine (all at
// stride 4, the best 32 again at full resolution). `same_view` (arg 1): 1 when it chose the
// exhaustive pass's view.
void BM_SelectView(benchmark::State& state) {
  Scenario& s = scenario();
  ViewPlannerOptions o;
  if (state.range(0) == 0) o.refine = 0;
  ViewPlanner planner(s.model, DepthCameraOptions{}, NoiseModelOptions{}, o);
  ViewSelection sel;
  for (auto _ : state) sel = planner.select(s.S_obj, GraspState{s.T_O_palm, s.q}, {}, s.nearHand);
  state.counters["directions"] = sel.directions;
  state.counters["reachable"] = sel.reachable;
  state.counters["refined"] = sel.refined;
  state.counters["ik_s"] = sel.ik_s;
  state.counters["quality_s"] = sel.quality_s;
  if (state.range(0) != 0) {
    ViewPlannerOptions ex;
    ex.refine = 0;
    const ViewSelection all = ViewPlanner(s.model, DepthCameraOptions{}, NoiseModelOptions{}, ex)
                                  .select(s.S_obj, GraspState{s.T_O_palm, s.q}, {}, s.nearHand);
    state.counters["same_view"] =
        sel.best && all.best && sel.best->dir_O.isApprox(all.best->dir_O) ? 1 : 0;
  }
}
BENCHMARK(BM_SelectView)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

// One frame of the simulated sensor as a scan renders it: the cracker box in the WAM's hand at
// 0.7 m, the arm and hand, and (Arg 1) the room around the camera that gives every pixel a depth.
void BM_SimulatedFrame(benchmark::State& state) {
  Scenario& s = scenario();
  SimOptions so;
  if (state.range(0) == 0) so.room_radius_m = 0;
  SimWorld world(s.model, s.object, s.T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, so);
  world.q = s.q;
  world.T_B_C =
      ViewPlanner(s.model, DepthCameraOptions{}, NoiseModelOptions{}, ViewPlannerOptions{})
          .cameraPose(0.7);
  size_t valid = 0;
  for (auto _ : state) {
    const DepthImage d = world.render();
    valid =
        size_t(std::count_if(d.depth_m.begin(), d.depth_m.end(), [](float z) { return z > 0; }));
  }
  state.counters["valid_px"] = double(valid);
  state.SetLabel(so.room_radius_m > 0 ? "room" : "no room");
}
BENCHMARK(BM_SimulatedFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// Re-grasping: candidates on S_obj with the box resting on the table, then ranking the 50 most
// stable by a coarse Alg. 1 pass each (the scan's defaults).
void BM_GenerateGrasps(benchmark::State& state) {
  Scenario& s = scenario();
  SimWorld world(s.model, s.object, s.T_O_palm, DepthCameraOptions{}, NoiseModelOptions{},
                 SimOptions{});
  GraspGeneration g;
  for (auto _ : state)
    g = generateGrasps(s.model, s.S_obj.mesh, world.restPose(), s.q, GraspOptions{});
  state.counters["tried"] = g.tried;
  state.counters["candidates"] = double(g.candidates.size());
}
BENCHMARK(BM_GenerateGrasps)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

void BM_RankGrasps(benchmark::State& state) {
  Scenario& s = scenario();
  SimWorld world(s.model, s.object, s.T_O_palm, DepthCameraOptions{}, NoiseModelOptions{},
                 SimOptions{});
  // Palm-first candidates: the target is for 50 of them, and first-contact generation
  // finds fewer stable ones on this object (ranking does not depend on how they were made).
  GraspOptions palmFirst;
  palmFirst.approach = GraspApproach::kPalm;
  GraspGeneration g = generateGrasps(s.model, s.S_obj.mesh, world.restPose(), s.q, palmFirst);
  ViewPlanner ranker(s.model, DepthCameraOptions{}, NoiseModelOptions{},
                     MultiGraspOptions::defaultRankingPlanner());
  for (auto _ : state) {
    std::vector<GraspCandidate> c = g.candidates;
    rankGrasps(ranker, s.S_obj, GraspOptions{}, &c);
    benchmark::DoNotOptimize(c);
  }
  state.counters["candidates"] = double(g.candidates.size());
}
BENCHMARK(BM_RankGrasps)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(2);

}  // namespace

// Tracking one in-hand frame (ScanSession::trackedCameraPose: hand, model and arm points,
// two starts, ICP): the cracker box held with 2 cm of arm error, the model from eight frames.
void BM_TrackFrame(benchmark::State& state) {
  const RobotModel model =
      RobotModel::load(std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json");
  const TriangleMesh box = loadObject("builtin:cracker_box");
  auto [T_O_palm, q] = defaultGrasp(model, box);
  SimOptions so;
  so.arm_error_m = 0.02;
  SimWorld world(model, box, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, so);
  world.q = q;
  ScanOptions o;
  o.tracking.enabled = true;
  const MultiGraspOptions multi;
  ScanSession session(model, DepthCameraOptions{}, NoiseModelOptions{}, o, multi,
                      T_O_palm * Vec3(0, 0, model.graspOffset()));
  ViewPlanner planner(model, DepthCameraOptions{}, NoiseModelOptions{}, o.planner);
  world.T_B_C = session.cameraPose();
  session.beginGrasp(T_O_palm, world.q);
  const Vec3 centre = T_O_palm * Vec3(0, 0, model.graspOffset());
  Aabb b;
  b.extend(centre - Vec3::Constant(0.12));
  b.extend(centre + Vec3::Constant(0.12));
  for (const Vec3& d : fibonacciSphere(8)) {
    const auto c = planner.reach({d}, centre, b, {T_O_palm, world.q})[0];
    if (!c) continue;
    world.q = model.withArm(world.q, c->arm);
    session.addFrame(world.render(), world.q, world.T_B_C);
  }
  session.beginGrasp(T_O_palm, world.q);  // the model's points for tracking
  const DepthImage frame = world.render();
  TrackResult r;
  for (auto _ : state) {
    benchmark::DoNotOptimize(session.trackedCameraPose(frame, world.q, world.T_B_C, T_O_palm, &r));
  }
  state.counters["points"] = r.inliers;
  state.counters["ok"] = r.ok;
}
BENCHMARK(BM_TrackFrame)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
