#include "test_util.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>

#include "inhand/core/file_util.h"
#include "inhand/core/pose.h"

namespace inhand::test {

TempDir::TempDir() {
  static std::atomic<int> counter{0};
  path_ = std::filesystem::temp_directory_path() /
          ("inhand_test_" + std::to_string(getpid()) + "_" + std::to_string(counter++));
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

void renderAndFuse(const TriangleMesh& mesh, const std::vector<Iso3>& poses, bool noise,
                   TsdfVolume* volume) {
  RayScene scene;
  scene.addMesh(mesh);
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions nm;
  for (size_t i = 0; i < poses.size(); ++i) {
    RenderOptions ro;
    ro.noise = noise;
    ro.seed = 7 + i;
    DepthImage d = renderDepth(scene, poses[i], cam, nm, ro);
    integrate(d, poses[i], cam.intrinsics, measurementSigma(d, cam.intrinsics, nm), volume);
  }
}

std::vector<Iso3> viewsAround(int count, double range_m) {
  std::vector<Iso3> poses;
  for (const Vec3& d : fibonacciSphere(count)) poses.push_back(lookAt(range_m * d, Vec3::Zero()));
  return poses;
}

bool segmentHitsBox(const Vec3& a, const Vec3& b, const Vec3& lo, const Vec3& hi) {
  double t0 = 0, t1 = 1;
  Vec3 d = b - a;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-15) {
      if (a[k] < lo[k] || a[k] > hi[k]) return false;
      continue;
    }
    double ta = (lo[k] - a[k]) / d[k], tb = (hi[k] - a[k]) / d[k];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

const RobotModel& wam() {
  static RobotModel m = RobotModel::load(std::filesystem::path(INHAND_SOURCE_DIR) /
                                         "data/robots/wam_barretthand.json");
  return m;
}

ObjectModel unweldedModel(const TriangleMesh& mesh,
                          const std::function<float(const Vec3&)>& varianceOfNormal) {
  ObjectModel m;
  for (int t = 0; t < int(mesh.triangles.size()); ++t) {
    Vec3 n = mesh.faceNormal(t);
    int base = int(m.mesh.vertices.size());
    for (int k = 0; k < 3; ++k) {
      m.mesh.vertices.push_back(mesh.vertices[mesh.triangles[t][k]]);
      m.variance.push_back(varianceOfNormal(n));
      m.observed.push_back(1);
    }
    m.mesh.triangles.emplace_back(base, base + 1, base + 2);
  }
  return m;
}

ScanConfig quickScanConfig(int max_views) {
  ScanConfig c;
  setPhysics(false, Json(), &c);  // the kinematic simulator: these scans test other things
  c.scan.voxel_m = 0.004;
  c.scan.planner.directions = 60;
  c.scan.planner.rolls = 4;
  c.scan.initial_views = 2;
  c.scan.max_views = max_views;
  c.multi.max_grasps = 2;
  c.sim.frame_subsample = 8;
  return c;
}

const char* quickConfigJson() {
  return R"({"voxel_m": 0.004, "initial_views": 2,
    "planner": {"directions": 40, "rolls": 4, "fallback_ranges_m": []},
    "grasp": {"approaches": 16, "rolls": 2, "max_candidates": 6,
              "ranking": {"directions": 24, "rolls": 2}},
    "sim": {"frame_subsample": 10, "physics": {"enabled": false}}, "eval": {"samples": 4000}})";
}

CommandResult runInhand(const std::string& args, const TempDir& dir) {
  const std::filesystem::path log = dir.path() / "log.txt";
  const std::string cmd = std::string(INHAND_BINARY) + " " + args + " > " + log.string() + " 2>&1";
  const int status = std::system(cmd.c_str());
  CommandResult r{WIFEXITED(status) ? WEXITSTATUS(status) : -1, readTextFile(log)};
  std::filesystem::remove(log);
  return r;
}

int spawnInhand(const std::vector<std::string>& args, const std::filesystem::path& log,
                bool own_group) {
  const pid_t pid = fork();
  if (pid == 0) {
    if (own_group) setpgid(0, 0);
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    dup2(fd, 2);
    std::vector<char*> argv{const_cast<char*>(INHAND_BINARY)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(INHAND_BINARY, argv.data());
    _exit(127);
  }
  if (own_group) setpgid(pid, pid);  // either side may run first
  return pid;
}

int waitExit(int pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace inhand::test
