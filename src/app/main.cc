// The `inhand` command line. CLI11 is included in this translation unit only (it is slow to
// compile); the commands live in commands.cc. One function per subcommand declares its options.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <new>

#include "commands.h"
#include "inhand/core/error.h"

namespace {

using namespace inhand::app;

CLI::App* addRender(CLI::App& app, RenderArgs& render) {
  auto* r = app.add_subcommand("render", "render noisy depth images of an object from all around");
  r->add_option("--object", render.object, "builtin:NAME or a mesh file (OBJ, PLY, STL, ...)")
      ->required();
  r->add_option("--views", render.views, "number of views, spread evenly over the sphere")
      ->capture_default_str();
  r->add_option("--out", render.out, "output directory (new or empty)")->required();
  r->add_option("--range", render.range_m, "camera distance from the object centre, m")
      ->capture_default_str();
  r->add_option("--seed", render.seed, "noise seed")->capture_default_str();
  r->add_option("--room", render.room_m,
                "radius of a spherical room around the object that gives background returns, m "
                "(0: none)")
      ->capture_default_str();
  r->add_flag("!--no-noise", render.noise, "render exact depths (no sensor noise)");
  return r;
}

CLI::App* addFuse(CLI::App& app, FuseArgs& fuse, std::vector<double>& bounds) {
  auto* f = app.add_subcommand("fuse", "fuse a directory of depth frames into a model");
  f->add_option("--frames", fuse.frames, "directory with frames.json and depth PNGs")->required();
  f->add_option("--out", fuse.out, "output model, .ply")->required();
  f->add_option("--summary", fuse.summary, "summary JSON (default: MODEL.json)");
  f->add_option("--voxel", fuse.voxel_m, "voxel size, m")->capture_default_str();
  f->add_option("--truncation", fuse.truncation_m,
                "signed-distance band half-width, m (0: 4 voxels)")
      ->capture_default_str();
  f->add_option("--band-sigmas", fuse.band_sigmas,
                "how far each measurement reaches behind its smoothed surface, in its sigmas (at "
                "least a voxel across the surface, at most --truncation); 0: the truncation "
                "behind its depth")
      ->capture_default_str();
  f->add_option("--smooth-depth", fuse.smooth_depth,
                "true | false: update the voxels from each pixel's surface smoothed over its 5x5 "
                "neighbourhood (a fitted plane) rather than its raw depth")
      ->capture_default_str();
  f->add_option("--bounds", bounds,
                "volume bounds in the object frame: xmin ymin zmin xmax ymax zmax (m); default: "
                "frames.json bounds_O, else the measured points")
      ->expected(6);
  f->add_option("--margin", fuse.margin_m,
                "margin around the measured points for automatic bounds, m")
      ->capture_default_str();
  f->add_option("--memory-budget", fuse.memory_mb, "refuse volumes larger than this, MiB")
      ->capture_default_str();
  f->add_option("--hole-sigma", fuse.hole_sigma_m, "sigma of never-observed surface, m")
      ->capture_default_str();
  f->add_option("--robot", fuse.robot,
                "robot config JSON: fuse each frame with the joints (q) and camera pose (T_B_C) "
                "it gives, the robot's own pixels carving only, tracking the hand (writes "
                "frames_tracked.json beside the model)");
  f->add_option("--config", fuse.config,
                "with --robot: scan options JSON (tracking, hand_mode, "
                "checks; see docs/config.md)");
  f->add_option("--tracking", fuse.tracking, "with --robot: on | off (default: on)");
  f->add_option("--surface", fuse.surface,
                "closed: the model closed over what was never seen (hole-filled, red); observed: "
                "the measured surface alone (an open mesh)")
      ->capture_default_str();
  return f;
}

CLI::App* addSnapshot(CLI::App& app, SnapshotArgs& snap) {
  auto* s =
      app.add_subcommand("snapshot", "render a model (PLY with colours or variance) to a PNG");
  s->add_option("model", snap.model, "model .ply, mesh file or builtin:NAME")->required();
  s->add_option("--out", snap.out, "output PNG")->required();
  s->add_option("--size", snap.size_px, "pixels per view")->capture_default_str();
  s->add_option("--colour", snap.colour,
                "auto: the PLY's colours; scan: the scanned colours (grey where none was seen); "
                "confidence: grey to red by the variance")
      ->capture_default_str();
  s->add_option("--view-from", snap.view_from,
                "DIR:N: the model from frame N's colour camera (DIR/frames.json), beside that "
                "frame's colour image");
  return s;
}

struct CompareArgs {
  std::string model, truth;
  double variance = 1e-4;
  bool json = false;
};

CLI::App* addCompare(CLI::App& app, CompareArgs& a) {
  auto* cmp = app.add_subcommand(
      "compare", "score a model against the true surface: coverage, accuracy, F-scores");
  cmp->add_option("model", a.model, "the model: PLY (with per-vertex variance) or a mesh")
      ->required();
  cmp->add_option("--truth", a.truth, "the true surface: builtin:NAME or a mesh file")->required();
  cmp->add_option("--observed-variance", a.variance,
                  "vertices with a variance at or above this (m²) are hole-filled, not observed")
      ->capture_default_str();
  cmp->add_flag("--json", a.json, "print JSON");
  return cmp;
}

CLI::App* addRobot(CLI::App& app, RobotArgs& robot) {
  auto* rb = app.add_subcommand("robot", "check a robot: chain, limits, speeds, reachability map");
  rb->add_option("--config", robot.config, "robot config JSON (names the URDF)")->required();
  rb->add_option("--urdf", robot.urdf, "URDF file (default: the one the config names)");
  rb->add_option("--directions", robot.directions, "viewing directions per position")
      ->capture_default_str();
  rb->add_option("--rolls", robot.rolls, "rolls tried per direction")->capture_default_str();
  rb->add_option("--grid", robot.grid, "grid x grid object positions")->capture_default_str();
  rb->add_option("--range", robot.range_m, "camera-to-object distance, m")->capture_default_str();
  return rb;
}

CLI::App* addScan(CLI::App& app, ScanArgs& scan) {
  auto* sc = app.add_subcommand("scan", "simulated autonomous scan of an object held by the robot");
  std::vector<CLI::Option*> scanOptions;
  scanOptions.push_back(sc->add_option("--object", scan.object, "builtin:NAME or a mesh file"));
  scanOptions.push_back(sc->add_option("--out", scan.out, "output directory (new or empty)"));
  scanOptions.push_back(sc->add_option(
      "--robot", scan.robot, "robot config JSON (default: data/robots/wam_barretthand.json)"));
  scanOptions.push_back(
      sc->add_option("--config", scan.config, "JSON file of scan options (see README)"));
  scanOptions.push_back(
      sc->add_option("--max-grasps", scan.max_grasps,
                     "grasps at most (default: the config's max_grasps, 3; 1: no re-grasping)"));
  scanOptions.push_back(
      sc->add_option("--max-views", scan.max_views, "next-best views per grasp at most"));
  scanOptions.push_back(sc->add_option("--hand-mode", scan.hand_mode,
                                       "naive | carve | carve-empty (paper Fig. 3 a, b, c)"));
  scanOptions.push_back(
      sc->add_option("--planner", scan.planner,
                     "view planner: ig (inhand), ig-no-hand, ig-no-cost, random, area, "
                     "unobserved-voxels, rear-side-entropy")
          ->capture_default_str());
  scanOptions.push_back(
      sc->add_option("--seed", scan.seed, "noise and IK seed")->capture_default_str());
  scanOptions.push_back(
      sc->add_option(
            "--rest-pose", scan.rest_pose,
            "as-is (the mesh's frame, dropped onto the table) or N: the N-th most probable "
            "stable pose (0: the most probable)")
          ->capture_default_str());
  scanOptions.push_back(sc->add_option("--scale", scan.scale,
                                       "the object mesh's coordinates times this, about its "
                                       "frame's origin (0.001: a mesh in millimetres)")
                            ->capture_default_str());
  scanOptions.push_back(sc->add_option(
      "--arm-error", scan.arm_error_m,
      "simulated arm error: the palm's median distance (m) from where the reported joints put "
      "it (overrides the config's sim.arm_error_m)"));
  scanOptions.push_back(
      sc->add_option("--tracking", scan.tracking,
                     "on | off: align each in-hand frame with the hand and the model before fusing "
                     "(default on; overrides the config's tracking.enabled)"));
  scanOptions.push_back(sc->add_option(
      "--physics", scan.physics,
      "on | off: MuJoCo for every pick-up, hold and put-down, or the kinematic simulator (the "
      "object moves rigidly with the hand; faster) (default on; overrides the config's "
      "sim.physics.enabled, with what it implies where the config is silent)"));
  scanOptions.push_back(sc->add_flag(
      "--save-frames", scan.save_frames,
      "write the in-hand depth frames with the joints and camera poses the robot reported to "
      "OUT/frames (frames.json: the input of `inhand fuse --robot`)"));
  scanOptions.push_back(
      sc->add_option("--export", scan.export_formats,
                     "FORMATS (mjcf,urdf,sdf): write the model as a simulator's asset to "
                     "OUT/asset, as `inhand export OUT --out OUT/asset` does"));
  auto* resume =
      sc->add_option("--resume", scan.resume,
                     "DIR: go on with the interrupted scan in DIR (its checkpoint.inhand), "
                     "with the options it was started with");
  for (CLI::Option* o : scanOptions) resume->excludes(o);
  return sc;
}

CLI::App* addEval(CLI::App& app, EvalArgs& eval, CLI::Option** backendOpt) {
  auto* ev = app.add_subcommand(
      "eval", "scan objects with several view planners and seeds; tabulate against ground truth");
  std::vector<CLI::Option*> evalPlan;
  evalPlan.push_back(ev->add_option("--objects", eval.objects,
                                    "comma-separated objects: builtin:NAME or mesh files"));
  evalPlan.push_back(ev->add_option("--planners", eval.planners, "comma-separated planners")
                         ->capture_default_str());
  evalPlan.push_back(ev->add_option("--seeds", eval.seeds, "seeds 1..N per object and planner")
                         ->capture_default_str());
  evalPlan.push_back(ev->add_option("--out", eval.out, "output directory (new or empty)"));
  evalPlan.push_back(ev->add_option("--config", eval.config, "scan options JSON for every run"));
  evalPlan.push_back(
      ev->add_option("--max-grasps", eval.max_grasps, "grasps per run at most (default: scan's)"));
  evalPlan.push_back(
      ev->add_option("--max-views", eval.max_views, "next-best views per grasp at most"));
  evalPlan.push_back(ev->add_option("--rest-poses", eval.rest_poses,
                                    "comma-separated: as-is and/or stable pose indices (0: the "
                                    "most probable); each object is scanned in each")
                         ->capture_default_str());
  ev->add_option("--jobs", eval.jobs,
                 "runs at a time (local: 0 = one per core; slurm: array tasks at once, 0 = no "
                 "limit)")
      ->capture_default_str();
  *backendOpt = ev->add_option("--backend", eval.backend,
                               "local: runs on this machine; slurm: one Slurm job array "
                               "(the output directory must be on a file system the nodes "
                               "share)")
                    ->capture_default_str();
  ev->add_option("--slurm-args", eval.slurm_args,
                 "extra sbatch options, e.g. \"--partition=cpu --time=01:00:00 --mem=4G "
                 "--cpus-per-task=2\"");
  ev->add_flag("--no-wait", eval.no_wait,
               "slurm: submit and return (then: inhand report DIR, or --resume DIR)");
  auto* evalResume = ev->add_option("--resume", eval.resume,
                                    "DIR: run again what did not finish in the eval DIR "
                                    "(interrupted scans go on from their checkpoints)");
  for (CLI::Option* o : evalPlan) evalResume->excludes(o);
  return ev;
}

CLI::App* addExport(CLI::App& app, ExportArgs& exp) {
  auto* ex = app.add_subcommand(
      "export",
      "a scanned model as an asset: MJCF, URDF, SDF with mass, inertia, convex pieces, "
      "grasps");
  ex->add_option("input", exp.input, "a scan's output directory (or a closed mesh file)")
      ->required();
  ex->add_option("--out", exp.out, "output directory (new or empty)")->required();
  ex->add_option("--format", exp.formats, "comma-separated: mjcf, urdf, sdf")
      ->capture_default_str();
  ex->add_option("--name", exp.name, "the body's name")->capture_default_str();
  ex->add_option("--density", exp.density_kg_m3, "kg/m³ of the enclosed solid")
      ->capture_default_str();
  ex->add_option("--mass", exp.mass_kg, "kg: the object's mass (overrides --density)");
  ex->add_option("--ranked", exp.ranked,
                 "candidates on the model that hold it in the hold test (physics) added to the "
                 "grasp set, at most (0: none)")
      ->capture_default_str();
  ex->add_option("--robot", exp.robot,
                 "robot config JSON for --ranked (default: data/robots/wam_barretthand.json)");
  return ex;
}

CLI::App* addRegraspTest(CLI::App& app, RegraspArgs& rg) {
  auto* rt = app.add_subcommand(
      "regrasp-test",
      "a simulated robot finds the true object on the table with the asset alone, picks a grasp "
      "from its grasp set and lifts it with physics");
  rt->add_option("asset", rg.asset, "an asset directory (inhand export)")->required();
  rt->add_option("--object", rg.object, "the true object: builtin:NAME or a mesh file")->required();
  rt->add_option("--rest-pose", rg.rest_pose,
                 "the true object's stable pose on the table (0: the most probable)")
      ->capture_default_str();
  rt->add_option("--heading", rg.heading_deg, "… turned this many degrees about the vertical")
      ->capture_default_str();
  rt->add_option("--scale", rg.scale, "the mesh's coordinates times this")->capture_default_str();
  rt->add_option("--seed", rg.seed, "sensor noise and the arm's error")->capture_default_str();
  rt->add_option("--robot", rg.robot,
                 "robot config JSON (default: data/robots/wam_barretthand.json)");
  rt->add_option("--config", rg.config, "scan options JSON (sim, table_top, grasp)");
  rt->add_option("--out", rg.out, "write the report (JSON) here");
  return rt;
}

CLI::App* addEvalTask(CLI::App& app, std::string& taskDir, std::string& taskList) {
  auto* et = app.add_subcommand("eval-task", "one run of an eval, as a Slurm array task");
  et->group("");  // not listed: `inhand eval --backend slurm` submits it
  et->add_option("dir", taskDir, "the eval directory")->required();
  et->add_option("list", taskList, "the file of run indices, one per array task")->required();
  return et;
}

CLI::App* addConfig(CLI::App& app, std::string& configFile, bool& configReference) {
  auto* cf = app.add_subcommand(
      "config", "print every scan option with its value (JSON): the defaults, or FILE's over them");
  cf->add_option("file", configFile, "a scan options JSON to check and complete");
  cf->add_flag("--reference", configReference,
               "print the options reference (Markdown, as in docs/config.md) instead");
  return cf;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"inhand: autonomous in-hand 3D modelling of unknown objects (Krainin et al. 2011)"};
  app.require_subcommand(1);
  RenderArgs render;
  FuseArgs fuse;
  std::vector<double> bounds;
  SnapshotArgs snap;
  CompareArgs compare;
  RobotArgs robot;
  ScanArgs scan;
  EvalArgs eval;
  CLI::Option* backendOpt = nullptr;
  auto* r = addRender(app, render);
  auto* f = addFuse(app, fuse, bounds);
  auto* s = addSnapshot(app, snap);
  auto* cmp = addCompare(app, compare);
  auto* rb = addRobot(app, robot);
  auto* sc = addScan(app, scan);
  auto* ev = addEval(app, eval, &backendOpt);

  std::string taskDir, taskList;
  auto* et = addEvalTask(app, taskDir, taskList);

  ExportArgs exp;
  auto* ex = addExport(app, exp);
  RegraspArgs rg;
  auto* rt = addRegraspTest(app, rg);

  std::string reportDir;
  auto* rp = app.add_subcommand("report", "rebuild the HTML report of a scan or an eval directory");
  rp->add_option("dir", reportDir, "a scan's or an eval's output directory")->required();

  std::string configFile;
  bool configReference = false;
  auto* cf = addConfig(app, configFile, configReference);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11 prints the message (or the help); a usage error is bad input: status 1, as the
    // README's exit statuses say (CLI11's own codes are 100 and up).
    return app.exit(e) == 0 ? 0 : 1;
  }
  try {
    if (*sc) return inhand::app::runScan(scan);
    if (*ev) {
      eval.backend_given = backendOpt->count() > 0;
      return inhand::app::runEval(eval);
    }
    if (*et) return inhand::app::runEvalTask(taskDir, taskList);
    if (*rp) return inhand::app::runReport(reportDir);
    if (*ex) return inhand::app::runExport(exp);
    if (*rt) return inhand::app::runRegraspTest(rg);
    if (*cf) return inhand::app::runConfig(configFile, configReference);
    if (*rb) return inhand::app::runRobot(robot);
    if (*cmp)
      return inhand::app::runCompare(compare.model, compare.truth, compare.variance, compare.json);
    if (*s) return inhand::app::runSnapshot(snap);
    if (*r) return inhand::app::runRender(render);
    if (*f) {
      if (!bounds.empty()) {
        std::array<double, 6> b{};
        std::copy(bounds.begin(), bounds.end(), b.begin());
        fuse.bounds = b;
      }
      return inhand::app::runFuse(fuse);
    }
  } catch (const inhand::Error& e) {
    std::fprintf(stderr, "inhand: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "inhand: error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "inhand: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
