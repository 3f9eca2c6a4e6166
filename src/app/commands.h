#pragma once
// The `inhand` subcommands, apart from the CLI parsing (kept in main.cc: CLI11 is slow to compile).
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "inhand/asset/asset.h"
#include "inhand/core/json_util.h"
#include "inhand/eval/metrics.h"
#include "inhand/mesh/extract.h"
#include "inhand/robot/robot_model.h"

namespace inhand::app {

// A model's colours against the truth's as summary.json and `compare --json` write them.
Json colourMetricsJson(const ColourMetrics& c);

// A model scanned with colour (model.rgba) as a textured mesh beside `ply`: <stem>.glb and
// <stem>.obj with <stem>.mtl and <stem>_texture.png, the per-vertex colours baked into an atlas
// whose texel is half the mesh's median edge. Nothing without colour. Returns the files written.
std::vector<std::filesystem::path> writeTexturedModel(const std::filesystem::path& ply,
                                                      const ObjectModel& model);

struct RenderArgs {
  std::string object;    // builtin:NAME or a mesh file
  int views = 40;        // number of depth images, directions spread over the sphere
  std::string out;       // output directory (must not exist, or be empty)
  double range_m = 0.7;  // camera distance from the object's centre
  uint64_t seed = 1;     // noise seed
  bool noise = true;     // false: exact depths
  double room_m = 1.5;   // radius of a spherical room around the object (background
                         // returns, as a real lab gives); 0: no background
};

struct FuseArgs {
  std::string frames;                           // directory with frames.json
  std::string out;                              // MODEL.ply
  std::string summary;                          // summary JSON; empty: MODEL.json beside MODEL.ply
  double voxel_m = 0.002;                       // voxel size
  double truncation_m = 0.0;                    // band half-width; 0: 4 voxels
  double band_sigmas = 2.0;                     // behind-surface band: this many σ (0: μ)
  bool smooth_depth = true;                     // voxels updated from the smoothed surface
  std::optional<std::array<double, 6>> bounds;  // xmin ymin zmin xmax ymax zmax in O; else auto
  double margin_m = 0.02;                       // auto bounds: margin around the measured points
  double memory_mb = 2048;                      // volume memory budget
  double hole_sigma_m = 0.05;                   // σ of never-observed surface
  std::string surface = "closed";  // closed (hole-filled, the paper's) or observed (measured only)
  std::string robot;               // robot config: fuse the frames' q and T_B_C in a ScanSession
  std::string config;              // with robot: scan options JSON (tracking, hand mode, checks)
  std::string tracking;            // with robot: on | off (default on)
};

struct SnapshotArgs {
  std::string model;  // PLY (colours per vertex used when present) or any mesh file
  std::string out;    // PNG
  int size_px = 400;  // per view
  // auto: the PLY's red, green, blue; scan: the scanned colours (a PLY with alpha: inhand's
  // colour models); confidence: from the per-vertex variance.
  std::string colour = "auto";
  // DIR:N: instead of six views, the model from frame N's colour camera (DIR/frames.json) beside
  // that frame's colour image.
  std::string view_from;
};

struct RobotArgs {
  std::string config;    // robot config JSON
  std::string urdf;      // overrides the config's "urdf" when given
  int directions = 100;  // reachability: viewing directions per position
  int rolls = 8;         // reachability: rolls per direction
  int grid = 3;          // reachability: grid × grid positions
  double range_m = 0.7;  // reachability: camera-to-object distance
};

int runRobot(const RobotArgs& args);

struct ScanArgs {
  std::string object;               // builtin:NAME or a mesh file
  std::string out;                  // output directory (new or empty)
  std::string robot;                // robot config (default: the WAM + BarrettHand in data/robots)
  std::string config;               // JSON of scan options (optional)
  int max_grasps = -1;              // grasps at most; -1: the config's (default 3)
  int max_views = -1;               // overrides the config when >= 0
  std::string hand_mode;            // overrides the config when set: naive | carve | carve-empty
  std::string planner = "ig";       // view planner (see plannerNames())
  uint64_t seed = 1;                // sensor noise and IK restarts
  std::string rest_pose = "as-is";  // as-is (the mesh's own frame, dropped onto the table) or N
  double scale = 1.0;               // the mesh's coordinates times this (e.g. 0.001 for mm)
  double arm_error_m = -1;          // overrides sim.arm_error_m when >= 0
  std::string tracking;             // on | off: overrides tracking.enabled when set
  std::string physics;              // on | off: overrides sim.physics.enabled when set
  std::string resume;               // a scan's output directory with checkpoint.inhand: go on
  bool save_frames = false;         // OUT/frames: the in-hand frames as the robot gave them
  std::string export_formats;       // non-empty: OUT/asset in these formats (inhand export)
};

int runScan(const ScanArgs& args);

struct ExportArgs {
  std::string input;                      // a scan's output directory, or a closed mesh file
  std::string out;                        // output directory (new or empty)
  std::string formats = "mjcf,urdf,sdf";  // comma-separated
  std::string name = "object";            // body, link and model name
  double density_kg_m3 = 300;             // of the enclosed solid
  double mass_kg = 0;                     // > 0: this mass instead
  int ranked = 10;    // candidates on the model that held the hold test, at most
  std::string robot;  // robot config for them (default: the WAM + BarrettHand)
};

// The robot config used when none is given: the WAM + BarrettHand in data/robots.
std::string defaultRobotConfig();

struct RegraspArgs {
  std::string asset;        // an asset directory (inhand export)
  std::string object;       // the true object: builtin:NAME or a mesh file
  std::string robot;        // robot config (default: the WAM + BarrettHand in data/robots)
  std::string config;       // JSON of scan options (the simulator's, the table top's, the grasps')
  int rest_pose = 1;        // the true object's stable pose (0: the most probable)
  double heading_deg = 30;  // … turned this far about the vertical
  uint64_t seed = 1;
  double scale = 1.0;
  std::string out;  // the report (JSON), optional
};
// `inhand regrasp-test`: exit 0 when the object was lifted, 4 when not (docs/asset.md).
int runRegraspTest(const RegraspArgs& args);

// `inhand export`: the model as a simulator's asset (docs/asset.md).
int runExport(const ExportArgs& args);
// "mjcf,urdf": the formats; throws Error naming one that is not mjcf, urdf or sdf.
std::vector<AssetFormat> parseAssetFormats(const std::string& list);
// The asset of `in` (a scan's directory: its model.ply, and from its summary.json the grasps
// and the mass the arm weighed; or a closed mesh file) written to `out`; prints one line. The
// mass: options.mass_kg when > 0, else the weighed one, else options.density_kg_m3's. With a
// robot, up to `ranked` candidates on the model that hold it in the hold test join the grasps.
void exportAsset(const std::filesystem::path& in, const std::filesystem::path& out,
                 const std::vector<AssetFormat>& formats, AssetOptions options,
                 const RobotModel* robot = nullptr, int ranked = 0,
                 const std::string& shown_out = "");

struct EvalArgs {
  std::string objects;  // comma-separated: builtin:NAME or mesh files
  std::string planners = "ig,ig-no-hand,ig-no-cost,random,area,unobserved-voxels,rear-side-entropy";
  int seeds = 3;                     // seeds 1..seeds per (object, planner)
  std::string out;                   // output directory (new or empty)
  std::string config;                // scan options JSON passed to every run
  int max_grasps = -1;               // passed to every run when >= 0
  int max_views = -1;                // passed to every run when >= 0
  int jobs = 0;                      // runs at a time; 0: one per core
  std::string rest_poses = "as-is";  // comma-separated: as-is and/or stable pose indices
  std::string backend = "local";     // local | slurm
  bool backend_given = false;  // --backend was on the command line (--resume keeps eval.json's)
  std::string slurm_args;      // extra sbatch options
  bool no_wait = false;        // slurm: submit and return
  std::string resume;          // an eval directory: run again what did not finish
};
int runEval(const EvalArgs& args);
// `inhand eval-task DIR LIST` (hidden): one run of an eval as a Slurm array task.
int runEvalTask(const std::string& dir, const std::string& list);
// `inhand report DIR`: rebuilds DIR/report.html (a scan) or DIR/index.html (an eval).
int runReport(const std::string& dir);
int runSnapshot(const SnapshotArgs& args);
// `inhand config [FILE] [--reference]`: every scan option (FILE's over the defaults) as JSON, or
// the Markdown reference of docs/config.md.
int runConfig(const std::string& file, bool reference);
int runRender(const RenderArgs& args);
int runFuse(const FuseArgs& args);
// `inhand compare MODEL --truth MESH`: coverage, accuracy and F-scores of a model against the true
// surface (as `inhand scan` and `eval` score theirs); vertices with a variance property at or
// above `observed_variance` (m²) count as hole-filled.
int runCompare(const std::string& model, const std::string& truth, double observed_variance,
               bool json);

}  // namespace inhand::app
