#pragma once
#include <functional>
// Shared helpers for the tests: temp directories and fusing rendered views.
#include <filesystem>
#include <string>
#include <vector>

#include "inhand/config/scan_config.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/mesh/extract.h"
#include "inhand/robot/robot_model.h"
#include "inhand/sensor/render.h"
#include "inhand/volume/integrate.h"

namespace inhand::test {

// A fresh temporary directory, removed with its contents on destruction.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// The `inhand` executable run with `args` (a shell command line), its output captured.
struct CommandResult {
  int code;            // exit status (-1 when it did not exit)
  std::string output;  // stdout and stderr
};
CommandResult runInhand(const std::string& args, const TempDir& dir);

// `inhand ARGS...` started in the background, stdout and stderr into `log`; with
// `own_group`, in a process group of its own (kill(-pid, SIGINT) reaches it and its children,
// as Ctrl-C in a terminal does).
int spawnInhand(const std::vector<std::string>& args, const std::filesystem::path& log,
                bool own_group = false);
// The exit status of a spawned process (-1 when it did not exit).
int waitExit(int pid);

// Renders `mesh` from each camera pose (T_O_C) and fuses the images into `volume`.
void renderAndFuse(const TriangleMesh& mesh, const std::vector<Iso3>& poses, bool noise,
                   TsdfVolume* volume);

// Cameras on a sphere of `range` around the origin, looking at it.
std::vector<Iso3> viewsAround(int count, double range_m);

// Segment–box overlap by the slab method (independent of Embree).
bool segmentHitsBox(const Vec3& a, const Vec3& b, const Vec3& lo, const Vec3& hi);

// Each triangle with its own three vertices, so variance can differ per face.
ObjectModel unweldedModel(const TriangleMesh& mesh,
                          const std::function<float(const Vec3&)>& varianceOfNormal);

// The paper's robot from data/robots (loaded once).
const RobotModel& wam();

// A quick scan config for command-line tests (`inhand scan --config`): 4 mm voxels, 40
// directions × 4 rolls, two initial views, few grasp candidates, every 10th frame, the kinematic
// simulator (physics off).
const char* quickConfigJson();

// A short whole scan from the table for tests: 4 mm voxels, 60 directions × 4 rolls, two
// initial views, `max_views` Alg. 1 views per grasp, two grasps, every 8th frame fused, the
// kinematic simulator (physics off).
ScanConfig quickScanConfig(int max_views = 2);

}  // namespace inhand::test
