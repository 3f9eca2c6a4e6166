#pragma once
// The simulated scan as `inhand scan` runs it, for any front end (the CLI, Python): the
// simulator built from a ScanConfig, the object resting on the table (or held at the simulator's
// default grasp with start "held"), the scan driven to its end, the model scored against the
// true mesh.
#include "inhand/config/scan_config.h"

namespace inhand {

struct SimulatedScan {
  MultiGraspResult result;
  SurfaceMetrics metrics;              // the final model against the true mesh
  Iso3 T_B_O_rest = Iso3::Identity();  // where the object rested
  // The fused in-hand frames' palm error (the pose fused with against the simulator's true palm,
  // camera frame), m: median and 95th percentile.
  double palm_error_median_m = 0, palm_error_p95_m = 0;
  // The fused in-hand frames' object pose error: the object's centre as the fused pose puts it
  // against where it is (the scan's grasp, the reported joints and the tracked camera against the
  // simulator's truth), m.
  double object_error_median_m = 0, object_error_p95_m = 0;
  int frames_fused_in_hand = 0, frames_rejected = 0;  // rejected: not fused, for any reason
  // Each creep the scan followed (ScanResult::creeps_followed; not one in a grasp's last frame,
  // and after a resume only those since): how far the scan's grasp put the object's centre in the
  // palm frame from where it truly was, before and after the correction, m.
  std::vector<std::pair<double, double>> creep_grasp_error_m;
  int drops = 0;        // how often the simulated object fell
  SimFaultLog faults;   // what the simulator injected (SimOptions::faults)
  double render_s = 0;  // rendering the simulated sensor's images (what a robot does not pay)
  int renders = 0;      // … how many images
  // Physics (SimOptions::physics; zero when off): the object's mass, its convex pieces and their
  // hulls' volume against the mesh's, physics time simulated and computed, motions in which the
  // object moved in the hand by more than 2 mm and the largest such movement.
  bool physics = false;
  double true_mass_kg = 0;  // the simulated object's mass (physics', or the density's)
  Vec3 true_com_O = Vec3::Zero();
  double mass_kg = 0, pieces_volume_ratio = 0, physics_simulated_s = 0, physics_s = 0;
  int pieces = 0, slips = 0, unstable_steps = 0;
  double slip_max_m = 0;
  DepthCameraOptions camera;  // the simulated sensor
  ColourMetrics colour;       // the model's colour against the truth's (sim.colour.enabled)
};

// Checkpoints of a simulated scan (scan/checkpoint.h): the scan's state, the simulator's and
// `extra` (the caller's, e.g. its arguments) in one file, rewritten atomically at every point the
// scan can resume from.
struct SimulatedScanCheckpoints {
  std::filesystem::path file;  // empty: no checkpoints
  bool resume = false;         // go on from `file` (written by a scan with the same config)
  Json extra;
};

// The object a simulated scan takes ("builtin:NAME" or a mesh file): with `colour` (the colour
// camera on) its colours from its file (OBJ + MTL + texture, PLY colours; flat grey when it has
// none), or a built-in object's checkerboard (kBuiltinCheckerSquare_m). Throws Error naming the
// object or file.
TexturedMesh loadSimulatedObject(const std::string& spec, bool colour);

// `object`: the true mesh (frame O, the model's frame; an open mesh with its holes closed:
// withHolesClosed); the seed is config.sim.seed (noise) and
// config.scan.planner.seed (IK). `progress.coverage` is set to the truth's coverage when empty.
// With checkpoints.resume the scan goes on from the file and ends as the scan that wrote it
// would have. Throws Error for invalid options, an object larger than the volume when held, or
// a checkpoint that cannot be read.
// `colours`: the object's surface colours for the simulated colour camera (sim.colour.enabled;
// flat grey when empty), addressing `object`'s triangles.
SimulatedScan runSimulatedScan(const RobotModel& robot, const TriangleMesh& object,
                               const ScanConfig& config, ScanProgress progress = {},
                               const SimulatedScanCheckpoints& checkpoints = {},
                               const SurfaceColours& colours = {});

}  // namespace inhand
