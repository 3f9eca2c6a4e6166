// Robot kernel benchmarks: IK solves per second (7-DOF WAM, seeded near the answer and from a
// fixed far seed with random restarts), collision checks per second, finger closing.
// Run: ./build/bench/bench_robot
#include <benchmark/benchmark.h>

#include "inhand/geometry/builtin_objects.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/ik.h"

using namespace inhand;

namespace {

const RobotModel& wam() {
  static RobotModel m =
      RobotModel::load(std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json");
  return m;
}

struct Problems {
  std::vector<Eigen::VectorXd> truth, nearSeed;
  std::vector<Iso3> targets;
  Problems() {
    const RobotModel& m = wam();
    Rng rng = makeRng(17);
    std::uniform_real_distribution<double> U(0, 1);
    std::normal_distribution<double> N(0, 0.2);
    IkSolver fk(m);
    Eigen::VectorXd lo = m.armLower(), hi = m.armUpper();
    for (int i = 0; i < 1000; ++i) {
      Eigen::VectorXd q(m.armDof()), s(m.armDof());
      for (int k = 0; k < q.size(); ++k) {
        q[k] = lo[k] + U(rng) * (hi[k] - lo[k]);
        s[k] = std::clamp(q[k] + N(rng), lo[k], hi[k]);
      }
      truth.push_back(q);
      nearSeed.push_back(s);
      targets.push_back(fk.fk(q));
    }
  }
};
const Problems& problems() {
  static Problems p;
  return p;
}

// Arg: 0 our damped least squares (default), 1 KDL's LMA (the reference).
IkOptions ikOptions(const benchmark::State& state) {
  IkOptions o;
  o.method = state.range(0) ? IkMethod::kKdlLma : IkMethod::kDampedLeastSquares;
  return o;
}

void BM_IkNearSeed(benchmark::State& state) {
  const Problems& p = problems();
  IkSolver ik(wam(), ikOptions(state));
  Rng rng = makeRng(1);
  size_t i = 0, ok = 0, n = 0;
  for (auto _ : state) {
    ok += ik.solve(p.targets[i], p.nearSeed[i], &rng).has_value();
    ++n;
    i = (i + 1) % p.targets.size();
  }
  state.counters["solves_per_s"] = benchmark::Counter(double(n), benchmark::Counter::kIsRate);
  state.counters["success"] = double(ok) / double(n);
}
BENCHMARK(BM_IkNearSeed)->Arg(0)->Arg(1)->UseRealTime();

// From the home configuration, whatever the target: LMA from home, then random restarts.
void BM_IkFarSeed(benchmark::State& state) {
  const Problems& p = problems();
  IkSolver ik(wam(), ikOptions(state));
  Rng rng = makeRng(1);
  const Eigen::VectorXd home = wam().arm(wam().home());
  size_t i = 0, ok = 0, n = 0;
  for (auto _ : state) {
    ok += ik.solve(p.targets[i], home, &rng).has_value();
    ++n;
    i = (i + 1) % p.targets.size();
  }
  state.counters["solves_per_s"] = benchmark::Counter(double(n), benchmark::Counter::kIsRate);
  state.counters["success"] = double(ok) / double(n);
}
BENCHMARK(BM_IkFarSeed)->Arg(0)->Arg(1)->UseRealTime();

// The batch form on both cores (as used for roll sweeps): 1000 targets from home.
void BM_IkBatchBothCores(benchmark::State& state) {
  const Problems& p = problems();
  const Eigen::VectorXd home = wam().arm(wam().home());
  size_t n = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(solveIkBatch(wam(), p.targets, home, 7, ikOptions(state)));
    n += p.targets.size();
  }
  state.counters["solves_per_s"] = benchmark::Counter(double(n), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_IkBatchBothCores)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// Whole-robot collision check (arm + hand vs table and base, plus a held cracker box).
void BM_CollisionCheck(benchmark::State& state) {
  const RobotModel& m = wam();
  CollisionChecker checker(m);
  if (state.range(0))
    checker.setHeldObject(loadObject("builtin:cracker_box"),
                          Iso3(Eigen::Translation3d(0, 0, 0.15)));
  const Problems& p = problems();
  const JointVector home = m.home();
  size_t i = 0, n = 0, hits = 0;
  for (auto _ : state) {
    hits += checker.inCollision(m.withArm(home, p.truth[i]));
    ++n;
    i = (i + 1) % p.truth.size();
  }
  state.counters["checks_per_s"] = benchmark::Counter(double(n), benchmark::Counter::kIsRate);
  state.counters["colliding"] = double(hits) / double(n);
  state.SetLabel(state.range(0) ? "with held object" : "robot only");
}
BENCHMARK(BM_CollisionCheck)->Arg(0)->Arg(1)->UseRealTime();

void BM_CloseFingersOnCan(benchmark::State& state) {
  const RobotModel& m = wam();
  TriangleMesh can =
      transformed(loadObject("builtin:coffee_can"), Iso3(Eigen::Translation3d(0, 0, 0.16)) *
                                                        Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX()));
  for (auto _ : state) benchmark::DoNotOptimize(closeFingers(m, m.home(), Iso3::Identity(), can));
}
BENCHMARK(BM_CloseFingersOnCan)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
