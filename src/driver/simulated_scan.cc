#include "inhand/driver/simulated_scan.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/scan/checkpoint.h"

namespace inhand {

TexturedMesh loadSimulatedObject(const std::string& spec, bool colour) {
  if (colour && !isBuiltinSpec(spec)) return importTexturedMesh(spec);
  TexturedMesh out;
  out.mesh = loadObject(spec);
  if (colour) out.colours = checkerColours(out.mesh, kBuiltinCheckerSquare_m);
  return out;
}

namespace {
// The simulated object is a solid: a mesh open where its scanner did not see is closed, so that
// the camera cannot look into it (nor the scan fuse its inside as surface). Held, it must fit
// the scan volume (from the table the scan finds out itself: object_too_large_for_volume).
TriangleMesh simulatedSolid(const TriangleMesh& mesh, const ScanConfig& o,
                            const ScanProgress& progress) {
  if (std::string p = o.validate(); !p.empty()) throw Error(p);
  int holes = 0;
  TriangleMesh object = withHolesClosed(mesh, &holes);
  if (holes > 0 && progress.log)
    progress.log("the object's mesh is open: " + std::to_string(holes) +
                 " holes closed for the simulation");
  if (o.start != "table" && o.start != "held") throw Error("start: must be table or held");
  if (o.start == "held" && object.bounds().size().maxCoeff() > o.scan.volume_size_m - 0.02)
    throw Error("the object (" + std::to_string(object.bounds().size().maxCoeff()) +
                " m across) does not fit the scan volume (volume_size_m = " +
                std::to_string(o.scan.volume_size_m) + " m)");
  return object;
}

// What the simulated world knows after the scan: drops, the true mass, faults, physics.
void recordWorld(const SimWorld& world, const TriangleMesh& object, SimulatedScan* out) {
  out->drops = world.drops;
  out->true_mass_kg = world.objectMass_kg();
  out->true_com_O = centreOfMass(object);
  out->faults = world.faults;
  out->render_s = world.render_s;
  if (const PhysicsWorld* ph = world.physics()) {
    out->physics = true;
    out->mass_kg = ph->mass_kg();
    out->pieces = ph->pieces();
    // The enclosed volume whichever way the triangles face (inwards: negative, the same solid).
    out->pieces_volume_ratio = ph->piecesVolume_m3() / std::abs(massProperties(object).volume_m3);
    out->physics_simulated_s = ph->simulated_s();
    out->physics_s = ph->wall_s();
    out->unstable_steps = ph->unstableSteps();
    out->slips = world.slips;
    out->slip_max_m = world.slipMax_m;
  }
  out->renders = world.renders;
}

// Each fused in-hand frame's palm error against the true arm (SimOptions::arm_error_m), and
// the object's pose error: how far the pose the frame was fused with (the scan's grasp, the
// reported joints, the tracked camera) puts the object's centre from where it truly is; the
// frames not fused. watch() hooks them into the scan's progress callbacks (the caller's kept).
struct FrameErrors {
  const SimWorld* world;
  Vec3 centre_O;
  std::vector<double> palm, object;
  int rejected = 0;
  int creeps = -1;  // creeps followed by the last frame seen (-1: none seen yet)
  std::vector<std::pair<double, double>> creepErrors;  // SimulatedScan::creep_grasp_error_m
  Iso3 scanGrasp;  // the grasp as the scan knows it (ScanSession::graspPose)

  FrameErrors(const SimWorld& w, const Vec3& centre) : world(&w), centre_O(centre) {
    scanGrasp = w.T_O_palm;
  }
  void watch(ScanProgress& progress) {
    const auto userInput = progress.frame_input;
    progress.frame_input = [this, userInput](const ScanSession& s, const DepthImage& d,
                                             const JointVector& q, const Iso3& T_B_C) {
      // The frame before followed a creep: the grasp's error before and after it (counted from
      // the first frame this run sees: a resumed scan's earlier creeps are not its own).
      const int n = s.summary().creeps_followed;
      if (creeps >= 0 && n > creeps)
        creepErrors.push_back({graspError(scanGrasp), graspError(s.graspPose())});
      creeps = n;
      scanGrasp = s.graspPose();
      if (userInput) userInput(s, d, q, T_B_C);
    };
    const auto userFrame = progress.frame;
    progress.frame = [this, userFrame](const FrameReport& r, const JointVector& q,
                                       const Iso3& T_B_C) {
      if (userFrame) userFrame(r, q, T_B_C);
      if (r.fused)
        add(r, q, T_B_C);
      else
        ++rejected;
    };
  }
  // How far grasp T_O_palm puts the object's centre in the palm frame from where it is.
  double graspError(const Iso3& T_O_palm) const {
    const Iso3 trueT_palm_O =
        world->model().tipPose(world->trueJoints()).inverse() * world->objectPose();
    return (T_O_palm.inverse() * centre_O - trueT_palm_O * centre_O).norm();
  }
  void add(const FrameReport& r, const JointVector& q, const Iso3& T_B_C) {
    const RobotModel& model = world->model();
    const Vec3 truePalm = (T_B_C.inverse() * model.tipPose(world->trueJoints())).translation();
    palm.push_back(((r.T_B_C.inverse() * model.tipPose(q)).translation() - truePalm).norm());
    const Iso3 fused_T_O_C = scanGrasp * model.tipPose(q).inverse() * r.T_B_C;
    const Iso3 true_T_O_C = world->objectPose().inverse() * world->T_B_C;
    object.push_back((fused_T_O_C * (true_T_O_C.inverse() * centre_O) - centre_O).norm());
  }
};

// Median and 95th percentile (0 without values).
void medianP95(std::vector<double> v, double* median, double* p95) {
  if (v.empty()) return;
  std::sort(v.begin(), v.end());
  *median = v[v.size() / 2];
  *p95 = v[std::min(v.size() - 1, v.size() * 95 / 100)];
}
}  // namespace

SimulatedScan runSimulatedScan(const RobotModel& model, const TriangleMesh& mesh,
                               const ScanConfig& o, ScanProgress progress,
                               const SimulatedScanCheckpoints& checkpoints,
                               const SurfaceColours& colours) {
  const TriangleMesh object = simulatedSolid(mesh, o, progress);
  SimulatedScan out;
  out.camera.colour = model.camera().colour;  // the robot's colour camera, on when the scan asks
  out.camera.colour.enabled = o.sim.colour.enabled;
  const DepthCameraOptions& camera = out.camera;
  NoiseModelOptions noise;
  // start "table": the object rests on the table, the arm at home (the whole scan, §V);
  // "held": the robot already holds it at the simulator's default side grasp. With physics the
  // squeeze moves the object in the hand (millimetres): the scan is told the grasp where it left
  // it, as it is told the exact grasp without physics.
  auto [T_O_palm, qGrasp] = defaultGrasp(model, object);
  SimWorld world(model, object, T_O_palm, camera, noise, o.sim);
  world.setObjectColours(colours);  // its triangles first, then those closing its holes
  world.held = false;
  world.q = model.home();
  if (o.start == "held") world.holdAt(qGrasp);
  T_O_palm = world.T_O_palm;
  SimRobot robot(&world);
  SimSensor sensor(&world, camera);
  // The simulated object is known: score the model against it after every view (its frame O
  // is the mesh's own input frame).
  const GroundTruth truth(object, o.eval);
  if (!progress.coverage)
    progress.coverage = [&](const ObjectModel& m) { return truth.coverage(m); };
  FrameErrors errors(world, object.bounds().center());
  errors.watch(progress);
  std::vector<double>& palmError = errors.palm;
  std::vector<double>& objectError = errors.object;
  int& rejected = errors.rejected;
  // Held: the volume is centred where the robot expects a held object, grasp_offset_m in front of
  // the palm. Table: on the points the camera sees there. The scan is never told the object's
  // shape or size; frame O is the object's frame where it rests (the mesh's own input frame).
  out.T_B_O_rest = world.restPose();
  if (!checkpoints.file.empty())
    progress.checkpoint = [&](const ScanCheckpoint& c) {
      saveScanCheckpoint(checkpoints.file, c,
                         {{"sim", world.state()},
                          {"palm_error_m", palmError},
                          {"object_error_m", objectError},
                          {"frames_rejected", rejected},
                          {"caller", checkpoints.extra}});
    };
  if (checkpoints.resume) {
    LoadedCheckpoint c =
        loadScanCheckpoint(checkpoints.file, model, camera, noise, o.scan, o.multi);
    try {
      world.setState(c.extra.at("sim"));
      palmError = c.extra.at("palm_error_m").get<std::vector<double>>();
      objectError = c.extra.value("object_error_m", std::vector<double>());
      rejected = c.extra.at("frames_rejected").get<int>();
    } catch (const std::exception& e) {
      throw Error(checkpoints.file.string() + ": not a simulated scan's checkpoint (" + e.what() +
                  ")");
    }
    out.result = resumeScan(robot, sensor, std::move(c), progress);
  } else {
    const Vec3 expected = T_O_palm * Vec3(0, 0, model.graspOffset());
    out.result =
        o.start == "held"
            ? scanMultiGrasp(robot, sensor, T_O_palm, expected, out.T_B_O_rest, o.scan, o.multi,
                             noise, progress)
            : scanFromTable(robot, sensor, out.T_B_O_rest, o.scan, o.multi, noise, progress);
  }
  out.metrics = truth.evaluate(out.result.scan.model);
  if (camera.colour.enabled) {
    out.colour = colourAccuracy(out.result.scan.model, object, colours);
    out.colour.psnr_db = colourPsnr(out.result.scan.model, object, colours);
  }
  recordWorld(world, object, &out);
  out.frames_rejected = rejected;
  out.creep_grasp_error_m = errors.creepErrors;
  out.frames_fused_in_hand = int(palmError.size());
  medianP95(palmError, &out.palm_error_median_m, &out.palm_error_p95_m);
  medianP95(objectError, &out.object_error_median_m, &out.object_error_p95_m);
  return out;
}

}  // namespace inhand
