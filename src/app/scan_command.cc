// `inhand scan`: the autonomous (multi-grasp) scan of a simulated object.
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <set>

#include "commands.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/driver/simulated_scan.h"
#include "inhand/eval/metrics.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/report/html_report.h"
#include "inhand/robot/collision.h"
#include "inhand/scan/checkpoint.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/scan/records.h"
#include "inhand/scan/session.h"
#include "inhand/sensor/frame_set.h"
#include "inhand/sim/sim_world.h"

namespace inhand::app {

namespace fs = std::filesystem;

// Every first-grasp pose tried, compactly: approach (palm z in O), roll, spread, preshape,
// edge, ε, and what became of it.
namespace {

// The options of a scan: the named planner, the config file over it, the command line over both.
ScanConfig scanConfigFor(const ScanArgs& args) {
  ScanConfig o;
  o.robot = args.robot;
  // The named planner first: a config file can still override any of its fields.
  if (!applyPlannerName(args.planner, &o.scan.planner)) {
    std::string names;
    for (const std::string& n : plannerNames()) names += (names.empty() ? "" : ", ") + n;
    throw Error("--planner: unknown planner \"" + args.planner + "\" (known: " + names + ")");
  }
  const Json file = args.config.empty() ? Json() : readJsonFile(args.config);
  if (!args.config.empty()) readScanConfig(file, args.config, &o);
  if (!args.physics.empty()) {
    if (args.physics != "on" && args.physics != "off")
      throw Error("--physics: must be on or off, not \"" + args.physics + "\"");
    setPhysics(args.physics == "on", file, &o);
  }
  if (!args.robot.empty()) o.robot = args.robot;
  if (o.robot.empty()) o.robot = defaultRobotConfig();
  if (args.max_views >= 0) o.scan.max_views = args.max_views;
  if (args.max_grasps != -1) o.multi.max_grasps = args.max_grasps;
  if (!args.hand_mode.empty() && !parseHandMode(args.hand_mode, &o.scan.hand_mode))
    throw Error("--hand-mode: must be naive, carve or carve-empty");
  if (args.arm_error_m >= 0) o.sim.arm_error_m = args.arm_error_m;
  if (!args.tracking.empty()) {
    if (args.tracking != "on" && args.tracking != "off")
      throw Error("--tracking: must be on or off, not \"" + args.tracking + "\"");
    o.scan.tracking.enabled = args.tracking == "on";
  }
  o.scan.planner.seed = args.seed;
  o.sim.seed = args.seed;
  if (std::string p = o.validate(); !p.empty()) throw Error(p);
  return o;
}

// The rest pose: the mesh as given, or one of its stable poses (frame O stays the mesh's). Sets
// config->sim.R_B_O_rest; returns its summary.json record.
Json applyRestPose(const ScanArgs& args, const TriangleMesh& object, ScanConfig* config) {
  ScanConfig& o = *config;
  Json restJson = {{"pose", "as-is"}};
  if (args.rest_pose != "as-is") {
    char* end = nullptr;
    const long n = std::strtol(args.rest_pose.c_str(), &end, 10);
    if (args.rest_pose.empty() || *end != '\0' || n < 0)
      throw Error("--rest-pose: must be as-is or a stable pose's index (0, 1, ...), not \"" +
                  args.rest_pose + "\"");
    std::vector<StablePose> poses;
    try {
      poses = stablePoses(object);
    } catch (const Error& e) {
      throw Error("--rest-pose: " + args.object + ": " + e.what());
    }
    if (n >= long(poses.size()))
      throw Error("--rest-pose: " + args.object + " has " + std::to_string(poses.size()) +
                  " stable poses (0.." + std::to_string(poses.size() - 1) + "), not " +
                  args.rest_pose);
    const StablePose& p = poses[size_t(n)];
    o.sim.R_B_O_rest = p.R_B_O;
    restJson = {{"pose", n},
                {"probability", p.probability},
                {"down_O", {p.down_O.x(), p.down_O.y(), p.down_O.z()}},
                {"stable_poses", poses.size()}};
  }
  return restJson;
}

// model.ply, truth.ply and, per grasp, the model after its views, the hand as it held the
// object and the best candidates.
void writeModels(const fs::path& dir, const RobotModel& model, const TriangleMesh& object,
                 const MultiGraspResult& mr) {
  const ScanResult& r = mr.scan;
  writePly(dir / "model.ply", r.model.mesh, &r.model.variance,
           r.model.rgba.empty() ? nullptr : &r.model.rgba);
  writeTexturedModel(dir / "model.ply", r.model);  // with colour: model.glb, model.obj
  writePly(dir / "truth.ply", object);             // the simulated object, frame O
  // Per grasp: the model after its views, the hand as it held the object, the best candidates.
  fs::create_directories(dir / "grasps");
  for (size_t g = 0; g < mr.grasps.size(); ++g) {
    const GraspRecord& gr = mr.grasps[g];
    const std::string k = "grasp_" + std::to_string(g + 1);
    writePly(dir / "grasps" / (k + "_model.ply"), gr.model.mesh, &gr.model.variance);
    if (int(gr.q.size()) == model.variableCount())
      writePly(dir / "grasps" / (k + "_hand.ply"), HandGeometry(model, gr.q, gr.T_O_palm).mesh());
    for (size_t c = 0; c < gr.ranked.size(); ++c)
      writePly(dir / "grasps" / (k + "_candidate_" + std::to_string(c + 1) + ".ply"),
               HandGeometry(model, gr.ranked[c].q, gr.ranked[c].T_O_palm).mesh());
  }
}

// Each view's record, with the trajectory time so far and its (1-based) grasp.
Json viewsJson(const MultiGraspResult& mr) {
  const ScanResult& r = mr.scan;
  Json views = Json::array();
  double trajectory = 0;
  std::vector<int> viewGrasp;  // 1-based grasp of each view
  for (size_t g = 0; g < mr.grasps.size(); ++g)
    for (int k = 0; k < mr.grasps[g].views; ++k) viewGrasp.push_back(int(g) + 1);
  for (size_t vi = 0; vi < r.views.size(); ++vi) {
    const ViewRecord& v = r.views[vi];
    trajectory += v.cost_s;
    Json j = viewRecordJson(v);
    j["trajectory_s"] = trajectory;
    j["grasp"] = vi < viewGrasp.size() ? viewGrasp[vi] : int(mr.grasps.size());
    views.push_back(std::move(j));
  }
  return views;
}

Json graspsJson(const MultiGraspResult& mr) {
  Json grasps = Json::array();
  for (const GraspRecord& g : mr.grasps) grasps.push_back(graspRecordJson(g));
  return grasps;
}

// Exit status: 3 no view reachable, 4 no grasp, 6 no object to scan, 130 interrupted; 0 for a
// scan that made its first grasp and wrote its model, whatever ended it (object_lost,
// regrasp_failed: the termination says why) (docs/scanning.md).
int exitStatus(Termination t) {
  switch (t) {
    case Termination::kInterrupted:
      return 130;
    case Termination::kNoReachableView:
      return 3;
    case Termination::kNoReachableGrasp:
    case Termination::kPickUpFailed:
    case Termination::kObjectTooLargeForHand:
    case Termination::kNoStableGrasp:
      return 4;
    case Termination::kObjectNotFound:
    case Termination::kObjectOutOfView:
    case Termination::kObjectTooLargeForVolume:
      return 6;
    default:
      return 0;
  }
}

// SIGINT and SIGTERM while a scan runs: the scan stops at its next frame and writes the model
// so far and a checkpoint to resume from; a second signal ends the process at once (the default
// action: output files are written atomically, the checkpoint stays).
std::atomic<int> g_signal{0};
extern "C" void onStopSignal(int sig) { g_signal = sig; }

class StopSignals {
 public:
  StopSignals() {
    g_signal = 0;
    struct sigaction a {};
    a.sa_handler = onStopSignal;
    a.sa_flags = SA_RESETHAND;  // the second signal: default action
    sigemptyset(&a.sa_mask);
    sigaction(SIGINT, &a, &oldInt_);
    sigaction(SIGTERM, &a, &oldTerm_);
  }
  ~StopSignals() {
    sigaction(SIGINT, &oldInt_, nullptr);
    sigaction(SIGTERM, &oldTerm_, nullptr);
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;
  static bool raised() { return g_signal != 0; }

 private:
  struct sigaction oldInt_ {
  }, oldTerm_{};
};

constexpr const char* kCheckpointName = "checkpoint.inhand";

// What a checkpoint keeps of the command line, so that --resume runs the same scan: the object
// (as given and as a path to load), the options as resolved, the seed and the rest pose.
Json argsJson(const ScanArgs& args, const ScanConfig& o) {
  std::string load = args.object;
  if (load.rfind("builtin:", 0) != 0) load = fs::absolute(load).lexically_normal().string();
  return {{"object", args.object},       {"object_load", load},         {"planner", args.planner},
          {"seed", args.seed},           {"rest_pose", args.rest_pose}, {"scale", args.scale},
          {"options", scanConfigJson(o)}};
}

// `--save-frames`: each in-hand frame as the robot delivered it (depth PNG, reported joints,
// camera pose in the base frame, the grasp as the scan knows it), in the format `inhand fuse
// --robot` reads. T_O_C is what the reported joints give (no tracking); bounds_O is the scan's
// volume. Dropped frames (no image) are not recorded.
class FrameRecorder {
 public:
  FrameRecorder(const RobotModel& model, const fs::path& dir) : model_(&model), dir_(dir) {}
  void add(const ScanSession& s, const DepthImage& depth, const JointVector& q, const Iso3& T_B_C) {
    if (depth.width == 0 || depth.height == 0) return;
    if (set_.frames.empty()) {
      fs::create_directories(dir_);
      set_.intrinsics = s.camera().intrinsics;
    }
    char name[32];
    std::snprintf(name, sizeof name, "depth_%05zu.png", set_.frames.size());
    writeDepthPng(dir_ / name, depth, set_.depth_scale_m);
    FrameRecord r;
    r.file = name;
    r.T_O_palm = s.graspPose();
    r.T_B_C = T_B_C;
    r.T_O_C = s.graspPose() * model_->tipPose(q).inverse() * T_B_C;
    for (int v = 0; v < model_->variableCount(); ++v)
      r.q.emplace_back(model_->variable(v).name, q[v]);
    set_.frames.push_back(std::move(r));
    const double half = 0.5 * s.options().volume_size_m;
    set_.bounds_O = Aabb{s.centre() - Vec3::Constant(half), s.centre() + Vec3::Constant(half)};
  }
  // Writes frames.json; false when no frame was recorded.
  bool finish() {
    if (set_.frames.empty()) return false;
    writeFrameSet(dir_, set_);
    return true;
  }

 private:
  const RobotModel* model_;
  fs::path dir_;
  FrameSet set_;
};

}  // namespace

namespace {

// The physics the simulator ran (summary.json "physics").
Json physicsJson(const SimulatedScan& sim) {
  return {{"enabled", sim.physics},
          {"mass_kg", sim.mass_kg},
          {"convex_pieces", sim.pieces},
          {"pieces_volume_ratio", sim.pieces_volume_ratio},
          {"simulated_s", sim.physics_simulated_s},
          {"computation_s", sim.physics_s},
          {"slips", sim.slips},
          {"slip_max_mm", 1000 * sim.slip_max_m},
          {"unstable_steps_undone", sim.unstable_steps}};
}

// The faults the simulator injected (summary.json "faults_injected").
Json faultsJson(const SimFaultLog& f) {
  return {{"dropped_frames", f.dropped_frames},
          {"corrupted_frames", f.corrupted_frames},
          {"pose_jumps", f.pose_jumps},
          {"stopped_short", f.stopped_short},
          {"slips", f.slips},
          {"object_drops", f.object_drops},
          {"refused_motions", f.refused_motions},
          {"failed_pickups", f.failed_pickups}};
}

// Where the time went (summary.json "timing_s"): every grasp planning, the one that ended the
// scan included.
Json timingJson(const SimulatedScan& sim, std::chrono::steady_clock::time_point t0) {
  const MultiGraspResult& mr = sim.result;
  const ScanResult& r = mr.scan;
  return {{"total", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()},
          {"planning", r.planning_s},
          {"fusion", r.fusion_s},
          {"tracking", r.tracking_s},
          {"simulation", sim.render_s},
          {"fusion_ms_per_frame", r.frames > 0 ? 1000 * r.fusion_s / r.frames : 0.0},
          // Every grasp planning, the one that ended the scan included.
          {"grasp_generation",
           [&] {
             double t = mr.unused_generation_s;
             for (const GraspRecord& g : mr.grasps) t += g.generation_s;
             return t;
           }()},
          {"grasp_ranking", [&] {
             double t = mr.unused_ranking_s;
             for (const GraspRecord& g : mr.grasps) t += g.ranking_s;
             return t;
           }()}};
}

// In-hand tracking (summary.json "tracking").
Json trackingJson(const ScanConfig& o, const SimulatedScan& sim) {
  const ScanResult& r = sim.result.scan;
  return {
      {"enabled", o.scan.tracking.enabled},
      {"palm_error_mm",
       {{"median", 1000 * sim.palm_error_median_m}, {"p95", 1000 * sim.palm_error_p95_m}}},
      {"object_pose_error_mm",
       {{"median", 1000 * sim.object_error_median_m}, {"p95", 1000 * sim.object_error_p95_m}}},
      {"frames_rejected", r.frames_rejected},
      // Each creep the grasp followed: how far the grasp put the object's centre from where the
      // simulator holds it, in mm, in the frame before and after it (the scan never sees these).
      {"creep_grasp_error_mm",
       [&] {
         Json list = Json::array();
         for (const auto& [before, after] : sim.creep_grasp_error_m)
           list.push_back({{"before", 1000 * before}, {"after", 1000 * after}});
         return list;
       }()},
      {"ms_per_frame", sim.frames_fused_in_hand + r.frames_rejected > 0
                           ? 1000 * r.tracking_s / (sim.frames_fused_in_hand + r.frames_rejected)
                           : 0.0}};
}

// How the model's colours compare with the true ones, and what colour fusion cost
// (summary.json "colour").
Json colourJson(const SimulatedScan& sim) {
  const ScanResult& r = sim.result.scan;
  Json j = colourMetricsJson(sim.colour);
  j["pixels_fused"] = r.colour_pixels;
  j["fusion_s"] = r.colour_s;
  j["fusion_ms_per_frame"] = r.frames > 0 ? 1000 * r.colour_s / r.frames : 0.0;
  j["frames_kept"] = r.colour_frames_kept;
  j["frames_mb"] = r.colour_frames_mb;
  j["shading_falloff"] = r.colour_shading_falloff;
  return j;
}

// summary.json of a simulated scan (docs/commands.md), less the options and the resume line.
Json scanSummary(const ScanArgs& args, const ScanConfig& o, const SimulatedScan& sim,
                 const Json& restJson, std::chrono::steady_clock::time_point t0) {
  const MultiGraspResult& mr = sim.result;
  const ScanResult& r = mr.scan;
  const SurfaceMetrics& sm = sim.metrics;
  const Json views = viewsJson(mr);
  Json summary;
  summary["object"] = args.object;
  summary["object_scale"] = args.scale;
  summary["robot"] = o.robot;
  summary["seed"] = args.seed;
  summary["planner"] = args.planner;
  summary["termination"] = terminationName(r.termination);
  summary["coverage"] = sm.coverage;
  summary["accuracy_mm"] = {
      {"mean", sm.accuracy_mean_mm}, {"rms", sm.accuracy_rms_mm}, {"p95", sm.accuracy_p95_mm}};
  Json fs = Json::object();
  for (size_t k = 0; k < sm.fscore.size(); ++k) {
    char key[32];
    std::snprintf(key, sizeof key, "%gmm", 1000 * o.eval.fscore_m[k]);
    fs[key] = {{"f", sm.fscore[k]}, {"precision", sm.precision[k]}, {"recall", sm.recall[k]}};
  }
  summary["fscore"] = fs;
  summary["detached_area_m2"] = sm.detached_area_m2;
  summary["detached_pieces"] = sm.detached_pieces;
  if (sim.camera.colour.enabled) summary["colour"] = colourJson(sim);
  summary["trajectory_s"] = views.empty() ? 0.0 : views.back()["trajectory_s"].get<double>();
  summary["views"] = views;
  summary["grasps"] = graspsJson(mr);
  summary["failed_regrasp_attempts"] = attemptsJson(mr.failed_regrasp_attempts);
  summary["start"] = o.start;
  summary["rest_pose"] = restJson;
  if (mr.table_top) summary["table_top"] = tableTopRecordJson(*mr.table_top);
  const CameraIntrinsics& K = sim.camera.intrinsics;
  summary["camera"] = {{"width", K.width}, {"height", K.height}, {"fx", K.fx},
                       {"fy", K.fy},       {"cx", K.cx},         {"cy", K.cy}};
  summary["view_evaluations"] = r.view_evaluations;
  summary["view_evaluations_full_resolution"] = r.view_refinements;
  summary["view_evaluations_per_s"] = r.planning_s > 0 ? r.view_evaluations / r.planning_s : 0.0;
  summary["frames"] = r.frames;
  summary["simulated_frames"] = sim.renders;  // depth images the simulated sensor rendered
  // In-hand frames fused and not (for any reason: frames_not_fused says which).
  summary["in_hand_frames"] = {{"fused", sim.frames_fused_in_hand},
                               {"not_fused", sim.frames_rejected}};
  summary["tracking"] = trackingJson(o, sim);
  summary["frames_not_fused"] = framesNotFusedJson(r);
  summary["frames_repaired"] = r.frames_repaired;
  summary["slips_found"] = slipsJson(r.slips);
  summary["creeps_followed"] = r.creeps_followed;
  summary["object_drops"] = sim.drops;
  {
    std::vector<double> mm;  // the model registered where the object rests, per put-down
    for (double r : mr.refind_residuals_m) mm.push_back(1000 * r);
    summary["refound_on_table_residual_mm"] = mm;
  }
  if (const std::optional<PayloadEstimate>& p = r.payload) {
    summary["payload"] = {{"mass_kg", p->mass_kg},
                          {"sigma_kg", p->sigma_kg},
                          {"com_O", p->com_observed ? vecJson(p->com) : Json()},
                          {"readings", p->readings},
                          {"residual_nm", p->residual_nm},
                          {"true_mass_kg", sim.true_mass_kg},
                          {"true_com_O", vecJson(sim.true_com_O)}};
  }
  summary["physics"] = physicsJson(sim);
  summary["faults_injected"] = faultsJson(sim.faults);
  summary["mean_entropy"] = r.model.meanEntropy();
  summary["observed_fraction"] = r.model.observedAreaFraction();
  summary["vertices"] = r.model.mesh.vertices.size();
  summary["triangles"] = r.model.mesh.triangles.size();
  summary["timing_s"] = timingJson(sim, t0);
  return summary;
}

}  // namespace

namespace {

// The scan's arguments and options: those a checkpoint was started with (--resume: args->out
// becomes the resumed directory, *checkpoint its checkpoint) or those given; *objectToLoad: the
// mesh to load (a resumed scan's as it was loaded).
ScanConfig scanArguments(ScanArgs* args, std::string* objectToLoad, fs::path* checkpoint) {
  ScanConfig o;
  const bool resuming = !args->resume.empty();
  if (resuming) {
    // The scan goes on with the arguments and options it was started with.
    *checkpoint = fs::path(args->resume) / kCheckpointName;
    if (!fs::exists(*checkpoint))
      throw Error(args->resume + ": no " + kCheckpointName +
                  " (not the output of an interrupted scan, or the scan stopped before its first "
                  "grasp began: run it again)");
    const Json caller = readScanCheckpointExtra(*checkpoint).value("caller", Json());
    try {
      args->object = caller.at("object").get<std::string>();
      *objectToLoad = caller.at("object_load").get<std::string>();
      args->planner = caller.at("planner").get<std::string>();
      args->seed = caller.at("seed").get<uint64_t>();
      args->rest_pose = caller.at("rest_pose").get<std::string>();
      args->scale = caller.value("scale", 1.0);
      // What the planner's name sets that is not an option (the baselines' metric), then the
      // options as they were.
      if (!applyPlannerName(args->planner, &o.scan.planner))
        throw Error(checkpoint->string() + ": unknown planner \"" + args->planner + "\"");
      readScanConfig(caller.at("options"), checkpoint->string() + ": options", &o);
    } catch (const Json::exception& e) {
      throw Error(checkpoint->string() + ": not a checkpoint of `inhand scan` (" + e.what() + ")");
    }
    if (std::string p = o.validate(); !p.empty()) throw Error(checkpoint->string() + ": " + p);
    args->out = args->resume;
  } else {
    if (args->object.empty()) throw Error("--object is required (or --resume DIR)");
    if (args->out.empty()) throw Error("--out is required (or --resume DIR)");
    o = scanConfigFor(*args);
    *objectToLoad = args->object;
  }
  return o;
}

// The object as the simulator takes it (runSimulatedScan; truth.ply is what was scanned): a
// solid (holes closed), scaled by --scale; with the colour camera, its colours from its file (OBJ
// + MTL + PNG, PLY colours), a built-in object's checkerboard, or flat grey.
TriangleMesh simulatedObject(const ScanArgs& args, const std::string& file, bool colour,
                             SurfaceColours* colours) {
  int holes = 0;
  TexturedMesh loaded = loadSimulatedObject(file, colour);
  *colours = loaded.colours;
  TriangleMesh object = withHolesClosed(loaded.mesh, &holes);
  if (holes > 0)
    std::fprintf(stderr, "scan: %s: the mesh is open: %d holes closed (a solid is simulated)\n",
                 args.object.c_str(), holes);
  if (args.scale != 1.0)
    for (auto& v : object.vertices) v *= float(args.scale);
  return object;
}

// The report and, with --export, the asset, in `dir` (the staged output): a missing front-end
// install costs the report only, a failed export the asset only, never the scan.
void writeReportAndAsset(const fs::path& dir, const ScanArgs& args, const ScanConfig& o,
                         const RobotModel& model) {
  try {
    writeScanReport(dir, webDirectory());
  } catch (const Error& e) {
    std::fprintf(stderr, "scan: warning: no report.html: %s\n", e.what());
  }
  if (args.export_formats.empty() || !fs::exists(dir / "model.ply")) return;
  AssetOptions asset;
  asset.density_kg_m3 = o.sim.physics.density_kg_m3;  // when the arm did not weigh it
  try {
    exportAsset(dir, dir / "asset", parseAssetFormats(args.export_formats), asset, &model, 10,
                (fs::path(args.out) / "asset").string());
  } catch (const Error& e) {
    std::fprintf(stderr, "scan: warning: no asset: %s\n", e.what());
  }
}

// A scan that fails (an error) removes the checkpoint it started (and the output directory it
// created, when empty) unless disarmed.
struct CheckpointCleanup {
  fs::path dir, file;
  bool created, armed = true;
  ~CheckpointCleanup() {
    if (!armed || file.empty()) return;
    std::error_code ec;
    fs::remove(file, ec);
    if (created) fs::remove(dir, ec);  // only when empty
  }
};

}  // namespace

int runScan(const ScanArgs& given) {
  const auto t0 = std::chrono::steady_clock::now();
  ScanArgs args = given;
  std::string objectToLoad;
  const bool resuming = !args.resume.empty();
  if (!args.export_formats.empty()) parseAssetFormats(args.export_formats);  // before the scan
  fs::path checkpoint;
  ScanConfig o = scanArguments(&args, &objectToLoad, &checkpoint);
  RobotModel model = RobotModel::load(o.robot);
  if (!(std::isfinite(args.scale) && args.scale > 0))
    throw Error("--scale: must be a positive number, not " + std::to_string(args.scale));
  SurfaceColours colours;
  TriangleMesh object = simulatedObject(args, objectToLoad, o.sim.colour.enabled, &colours);
  const Json restJson = applyRestPose(args, object, &o);
  // An object too large for the volume is refused before the output directory exists.
  if (o.start == "held" && object.bounds().size().maxCoeff() > o.scan.volume_size_m - 0.02)
    throw Error(args.object + ": the object (" + std::to_string(object.bounds().size().maxCoeff()) +
                " m across) does not fit the scan volume (volume_size_m = " +
                std::to_string(o.scan.volume_size_m) + " m)");
  StagedDirectory out(args.out, /*replace=*/resuming);
  // The checkpoint lives in the output directory while the scan runs (a crash or a power cut
  // leaves it there for --resume); a scan that ends removes it, one that is interrupted keeps
  // it beside its outputs. A scan that fails (an error) leaves nothing it created.
  bool createdOut = false;
  if (!resuming) {
    std::error_code ec;
    createdOut = fs::create_directory(args.out, ec);
    checkpoint = fs::path(args.out) / kCheckpointName;
  }
  CheckpointCleanup cleanup{args.out, resuming ? fs::path() : checkpoint, createdOut};
  SimulatedScanCheckpoints checkpoints;
  checkpoints.file = checkpoint;
  checkpoints.resume = resuming;
  checkpoints.extra = argsJson(args, o);
  if (resuming) checkpoints.extra["object_load"] = objectToLoad;
  StopSignals signals;
  ScanProgress progress;
  progress.log = [](const std::string& s) { std::fprintf(stderr, "scan: %s\n", s.c_str()); };
  progress.interrupted = [] { return StopSignals::raised(); };
  std::optional<FrameRecorder> recorder;
  if (args.save_frames) {
    recorder.emplace(model, out.path() / "frames");
    progress.frame_input = [&](const ScanSession& s, const DepthImage& d, const JointVector& q,
                               const Iso3& T_B_C) { recorder->add(s, d, q, T_B_C); };
  }
  const SimulatedScan sim = runSimulatedScan(model, object, o, progress, checkpoints, colours);
  if (recorder && !recorder->finish())
    std::fprintf(stderr, "scan: --save-frames: no in-hand frame to save\n");
  const bool interrupted = sim.result.scan.termination == Termination::kInterrupted;
  const MultiGraspResult& mr = sim.result;
  const ScanResult& r = mr.scan;
  writeModels(out.path(), model, object, mr);
  Json summary = scanSummary(args, o, sim, restJson, t0);
  const SurfaceMetrics& sm = sim.metrics;
  summary["options"] = scanConfigJson(o);
  if (interrupted && fs::exists(checkpoint)) {
    summary["resume"] = "inhand scan --resume " + args.out;
    fs::copy_file(checkpoint, out.path() / kCheckpointName);
  }
  writeTextAtomically(out.path() / "summary.json", summary.dump(2) + "\n");
  writeReportAndAsset(out.path(), args, o, model);
  out.commit();  // replaces the directory that held the checkpoint
  cleanup.armed = false;
  if (interrupted)
    std::fprintf(stderr,
                 "scan: interrupted; the model so far is in %s, go on with: inhand scan "
                 "--resume %s\n",
                 args.out.c_str(), args.out.c_str());
  std::printf(
      "scan: %s: %zu grasps, %zu views, %d frames, %s; observed %.1f%% of the surface, "
      "coverage %.1f%% (%.0f mm), accuracy %.2f mm mean, mean entropy %.3f (%.1f s) -> %s\n",
      args.object.c_str(), mr.grasps.size(), r.views.size(), r.frames,
      terminationName(r.termination).c_str(), 100 * r.model.observedAreaFraction(),
      100 * sm.coverage, 1000 * o.eval.tau_m, sm.accuracy_mean_mm, r.model.meanEntropy(), r.total_s,
      args.out.c_str());
  return exitStatus(r.termination);
}

int runConfig(const std::string& file, bool reference) {
  if (reference) {
    std::fputs(scanConfigReference().c_str(), stdout);
    return 0;
  }
  ScanConfig config;
  if (!file.empty()) readScanConfigFile(file, &config);
  if (std::string p = config.validate(); !p.empty())
    throw Error((file.empty() ? std::string() : file + ": ") + p);
  std::printf("%s\n", scanConfigJson(config).dump(2).c_str());
  return 0;
}

}  // namespace inhand::app
