#include "commands.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <unistd.h>

#include "inhand/config/scan_config.h"
#include "inhand/core/clock.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/driver/simulated_scan.h"
#include "inhand/eval/metrics.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/geometry/texture_atlas.h"
#include "inhand/mesh/extract.h"
#include "inhand/report/snapshot.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/reachability.h"
#include "inhand/scan/records.h"
#include "inhand/scan/session.h"
#include "inhand/sensor/frame_set.h"
#include "inhand/sensor/render.h"
#include "inhand/volume/colour_volume.h"
#include "inhand/volume/integrate.h"

namespace inhand::app {

namespace fs = std::filesystem;

namespace {

// Progress on the terminal: rewritten in place on a TTY, every 10th step otherwise.
void progress(const char* what, size_t done, size_t total) {
  static const bool tty = isatty(fileno(stderr));
  if (tty) {
    std::fprintf(stderr, "\r%s: %zu/%zu", what, done, total);
    if (done == total) std::fprintf(stderr, "\n");
  } else if (done == total || done % 10 == 0) {
    std::fprintf(stderr, "%s: %zu/%zu\n", what, done, total);
  }
}

}  // namespace

int runRender(const RenderArgs& args) {
  if (args.views < 1 || args.views > 100000) throw Error("--views must be in 1..100000");
  DepthCameraOptions camera;
  if (!(args.range_m >= camera.min_range_m && args.range_m <= camera.max_range_m))
    throw Error("--range must be within the sensor's range [" + std::to_string(camera.min_range_m) +
                ", " + std::to_string(camera.max_range_m) + "] m");
  auto t0 = Clock::now();
  // A solid, as every simulated object (runSimulatedScan): the camera does not look into holes.
  TriangleMesh object = withHolesClosed(loadObject(args.object));
  Aabb box = object.bounds();
  if (box.size().maxCoeff() > 1.0)
    throw Error(args.object + ": the object is " + std::to_string(box.size().maxCoeff()) +
                " m across; inhand expects metres and objects under 1 m (is the file in mm?)");
  StagedDirectory out(args.out);
  if (args.room_m != 0 && !(args.room_m > args.range_m + 0.05))
    throw Error("--room must be 0 (no background) or larger than --range");
  const Vec3 centre = box.center();
  RayScene scene;
  scene.addMesh(object);
  if (args.room_m > 0)  // background: the inside of a sphere around the object
    scene.addMesh(makeSphere(args.room_m, 4), Iso3(Eigen::Translation3d(centre)));
  scene.commit();
  NoiseModelOptions noise;
  FrameSet set;
  set.intrinsics = camera.intrinsics;
  set.bounds_O = Aabb{box.min - Vec3::Constant(0.02), box.max + Vec3::Constant(0.02)};
  std::vector<Vec3> dirs = fibonacciSphere(args.views);
  for (int i = 0; i < args.views; ++i) {
    Iso3 T_O_C = lookAt(centre + args.range_m * dirs[i], centre, Vec3::UnitZ());
    RenderOptions ro;
    ro.noise = args.noise;
    ro.seed = mixSeed(args.seed, uint64_t(i));
    DepthImage depth = renderDepth(scene, T_O_C, camera, noise, ro);
    char name[32];
    std::snprintf(name, sizeof(name), "depth_%04d.png", i);
    writeDepthPng(out.path() / name, depth, set.depth_scale_m);
    set.frames.push_back({name, T_O_C});
    progress("render: views", size_t(i + 1), size_t(args.views));
  }
  writeFrameSet(out.path(), set);
  writePly(out.path() / "object.ply", object);
  out.commit();
  std::printf(
      "render: %d depth images of %s (%zu triangles, %.3f x %.3f x %.3f m) at %.2f m in %s "
      "(%.2f s)\n",
      args.views, args.object.c_str(), object.triangles.size(), box.size().x(), box.size().y(),
      box.size().z(), args.range_m, args.out.c_str(), secondsSince(t0));
  return 0;
}

std::vector<fs::path> writeTexturedModel(const fs::path& ply, const ObjectModel& model) {
  if (model.rgba.empty() || model.mesh.empty()) return {};
  std::vector<float> edges;
  edges.reserve(model.mesh.triangles.size());
  for (const Tri& f : model.mesh.triangles)
    edges.push_back((model.mesh.vertices[size_t(f[0])] - model.mesh.vertices[size_t(f[1])]).norm());
  std::nth_element(edges.begin(), edges.begin() + long(edges.size() / 2), edges.end());
  const double texel = std::max(1e-5, 0.5 * double(edges[edges.size() / 2]));
  const TextureAtlas atlas = bakeVertexColours(model.mesh, model.rgba, texel);
  const fs::path base = ply.parent_path() / ply.stem();
  const fs::path glb = base.string() + ".glb", obj = base.string() + ".obj";
  writeGlb(glb, model.mesh, atlas);
  writeTexturedObj(obj, model.mesh, atlas);
  return {glb, obj, base.string() + ".mtl", base.string() + "_texture.png"};
}

namespace {

// Bounds of the measured points in the object frame (0.1 / 99.9 percentiles, so a few stray
// pixels do not blow the volume up), plus a margin.
Aabb autoBounds(const fs::path& dir, const FrameSet& set, double margin) {
  std::vector<double> xs, ys, zs;
  for (size_t i = 0; i < set.frames.size(); ++i) {
    DepthImage d = loadFrameDepth(dir, set, i);
    const Iso3& T = set.frames[i].T_O_C;
    for (int v = 0; v < d.height; v += 2)
      for (int u = 0; u < d.width; u += 2) {
        float z = d.at(u, v);
        if (!(z > 0)) continue;
        Vec3 p = T * (set.intrinsics.rayZ1(u, v) * double(z));
        xs.push_back(p.x());
        ys.push_back(p.y());
        zs.push_back(p.z());
      }
  }
  if (xs.empty()) throw Error((dir / "frames.json").string() + ": no frame has any depth return");
  auto pct = [](std::vector<double>& v, double q) {
    size_t k = std::min(v.size() - 1, size_t(q * double(v.size() - 1)));
    std::nth_element(v.begin(), v.begin() + long(k), v.end());
    return v[k];
  };
  Aabb box;
  box.min = Vec3(pct(xs, 0.001), pct(ys, 0.001), pct(zs, 0.001)) - Vec3::Constant(margin);
  box.max = Vec3(pct(xs, 0.999), pct(ys, 0.999), pct(zs, 0.999)) + Vec3::Constant(margin);
  return box;
}

// The fused model's figures in `fuse`'s summary.
void addModelFigures(const ObjectModel& model, const std::string& surface, Json* summary) {
  Json& s = *summary;
  s["vertices"] = model.mesh.vertices.size();
  s["triangles"] = model.mesh.triangles.size();
  s["surface"] = surface;
  s["closed"] = model.mesh.isClosed();
  s["mean_entropy"] = model.meanEntropy();
  s["observed_fraction"] = model.observedAreaFraction();
  s["surface_area_m2"] = model.mesh.area();
  s["hole_area_m2"] = model.holeArea();
}

// Writes the model (and its textured forms) and its summary; none stays when another cannot be
// written.
void writeFusedModel(const fs::path& outPath, const fs::path& summaryPath, const ObjectModel& model,
                     const Json& summary) {
  writePly(outPath, model.mesh, &model.variance, model.rgba.empty() ? nullptr : &model.rgba);
  try {
    writeTexturedModel(outPath, model);
    writeTextAtomically(summaryPath, summary.dump(2) + "\n");
  } catch (...) {
    // No half-finished result: the PLY and whichever textured files were written before.
    std::error_code ec;
    fs::remove(outPath, ec);
    const fs::path base = outPath.parent_path() / outPath.stem();
    for (const char* ext : {".glb", ".obj", ".mtl", "_texture.png"})
      fs::remove(fs::path(base.string() + ext), ec);
    throw;
  }
}

// The robot's joints of frame `where` as a JointVector: every variable of the model by name.
JointVector jointsOf(const RobotModel& model, const FrameRecord& rec, const std::string& where) {
  JointVector q = model.home();
  std::vector<bool> given(size_t(model.variableCount()), false);
  for (const auto& [name, value] : rec.q) {
    const int v = model.variableIndex(name);
    if (v < 0)
      throw Error(where + ".q." + name + ": the robot " + model.name() + " has no such joint");
    q[v] = value;
    given[size_t(v)] = true;
  }
  for (int v = 0; v < model.variableCount(); ++v)
    if (!given[size_t(v)]) throw Error(where + ".q: no value for joint " + model.variable(v).name);
  return q;
}

// The volume's bounds (frame O): --bounds, else frames.json's bounds_O, else (without a robot)
// around the measured points.
Aabb fuseBounds(const FuseArgs& args, const fs::path& dir, const FrameSet& set) {
  Aabb box;
  if (args.bounds) {
    const auto& b = *args.bounds;
    box.min = Vec3(b[0], b[1], b[2]);
    box.max = Vec3(b[3], b[4], b[5]);
    if (!(box.min.array() < box.max.array()).all())
      throw Error("--bounds: each min must be below its max (xmin ymin zmin xmax ymax zmax)");
  } else if (set.bounds_O) {
    box = *set.bounds_O;
  } else if (!args.robot.empty()) {
    throw Error((dir / "frames.json").string() +
                ": no bounds_O; give --bounds around the object (with the robot in view, the "
                "measured points would take in the arm)");
  } else {
    box = autoBounds(dir, set, args.margin_m);
  }
  return box;
}

// The volume's figures (fuse's summary "volume").
Json volumeJson(const TsdfVolume& volume, int64_t updated) {
  return {{"voxel_size_m", volume.voxelSize()},
          {"truncation_m", volume.truncation()},
          {"dims", {volume.dims().x(), volume.dims().y(), volume.dims().z()}},
          {"origin_m", {volume.origin().x(), volume.origin().y(), volume.origin().z()}},
          {"voxels_observed", volume.countState(VoxelState::kObserved)},
          {"voxels_empty", volume.countState(VoxelState::kEmpty)},
          {"voxels_unknown", volume.countState(VoxelState::kUnknown)},
          {"voxel_updates", updated}};
}

// The scan options of `inhand fuse --robot`: the config's, tracking from --tracking (default on),
// the volume a cube around the bounds' centre, as large as their largest side, of --voxel.
ScanOptions robotFuseOptions(const FuseArgs& args, const ScanOptions& given, const Aabb& box,
                             const MeshOptions& mo) {
  ScanOptions o = given;
  if (!args.tracking.empty()) {
    if (args.tracking != "on" && args.tracking != "off")
      throw Error("--tracking: must be on or off, not \"" + args.tracking + "\"");
    o.tracking.enabled = args.tracking == "on";
  } else {
    o.tracking.enabled = true;
  }
  o.voxel_m = args.voxel_m;
  o.volume_size_m = box.size().maxCoeff();
  o.fit_volume = false;
  o.volume_budget.memory_budget_mb = args.memory_mb;
  o.mesh.hole_sigma_m = mo.hole_sigma_m;
  if (args.truncation_m > 0) o.volume_budget.truncation_m = args.truncation_m;
  o.volume_budget.band_sigmas = args.band_sigmas;
  o.volume_budget.smooth_depth = args.smooth_depth;
  if (std::string p = o.validate(); !p.empty()) throw Error(p);
  return o;
}

// What fusing the frames took and did.
struct FuseFigures {
  double integrate_s = 0, colour_s = 0, load_and_integrate_s = 0;
  int64_t updated = 0, colour_pixels = 0;
};

// Every frame of the set (plain poses, T_O_C) fused into `volume`, and its colour image, where
// it has one, into `colour` and `frames` (the camera as frames.json gives it).
FuseFigures integrateFrames(const fs::path& dir, const FrameSet& set, TsdfVolume* volume,
                            ColourVolume* colour, ColourFrames* frames) {
  FuseFigures f;
  const NoiseModelOptions noise;
  const auto t0 = Clock::now();
  DepthCameraOptions camera;
  camera.intrinsics = set.intrinsics;
  camera.colour = set.colour;
  for (size_t i = 0; i < set.frames.size(); ++i) {
    DepthImage depth = loadFrameDepth(dir, set, i);
    const RgbImage rgb = loadFrameColour(dir, set, i);
    auto ti = Clock::now();
    // σ only where the volume's voxels can project (integrate reads no other pixel).
    const PixelRect rect = volumeImageRect(*volume, set.frames[i].T_O_C, set.intrinsics);
    std::vector<float> sigma = measurementSigma(depth, set.intrinsics, noise, &rect);
    f.updated += integrate(depth, set.frames[i].T_O_C, set.intrinsics, sigma, volume).updated;
    f.integrate_s += secondsSince(ti);
    if (!rgb.empty()) {
      auto tc = Clock::now();
      f.colour_pixels +=
          integrateColour(depth, rgb, set.frames[i].T_O_C, camera, sigma, colour).pixels;
      frames->add(depth, rgb, set.frames[i].T_O_C, camera, sigma);
      f.colour_s += secondsSince(tc);
    }
    progress("fuse: frames", i + 1, set.frames.size());
  }
  f.load_and_integrate_s = secondsSince(t0);
  return f;
}

// Colour fusion's figures (fuse's summary "colour").
Json fuseColourJson(const ObjectModel& model, const ColourVolume& colour,
                    const ColourFrames& frames, double falloff, int64_t pixels) {
  size_t coloured = 0;
  for (const auto& c : model.rgba) coloured += c[3] == 255;
  return {{"pixels_fused", pixels},
          {"voxels", colour.voxels()},
          {"memory_mb", double(colour.bytes()) / (1 << 20)},
          {"frames_kept", frames.frames()},
          {"frames_mb", double(frames.bytes()) / (1 << 20)},
          {"shading_falloff", falloff},
          {"vertices_with_colour", coloured}};
}

// The volume options fuse's arguments give (checked).
VolumeOptions fuseVolumeOptions(const FuseArgs& args) {
  VolumeOptions vo;
  vo.voxel_size_m = args.voxel_m;
  vo.truncation_m = args.truncation_m;
  vo.band_sigmas = args.band_sigmas;
  vo.smooth_depth = args.smooth_depth;
  vo.memory_budget_mb = args.memory_mb;
  if (std::string p = vo.validate(); !p.empty()) throw Error("volume options: " + p);
  return vo;
}

// Each frame's joints and grasp (T_O_palm: its own, else the set's), checked; `file` names
// frames.json in the errors.
void robotFrames(const RobotModel& model, const FrameSet& set, const std::string& file,
                 std::vector<JointVector>* qs, std::vector<Iso3>* palms) {
  for (size_t i = 0; i < set.frames.size(); ++i) {
    const FrameRecord& rec = set.frames[i];
    const std::string where = file + ": frames[" + std::to_string(i) + "]";
    if (rec.q.empty()) throw Error(where + ": no q (the joints; --robot needs them)");
    if (!rec.T_B_C) throw Error(where + ": no T_B_C (the camera in the base frame)");
    if (!rec.T_O_palm && !set.T_O_palm)
      throw Error(where + ": no T_O_palm, here or at the top (the palm in the object frame)");
    qs->push_back(jointsOf(model, rec, where));
    palms->push_back(rec.T_O_palm ? *rec.T_O_palm : *set.T_O_palm);
  }
}

// frames_tracked.json beside the model; when it cannot be written, the model and its summary
// are removed too (no half-written output).
void writeFramesTracked(const fs::path& outPath, const fs::path& summaryPath, const Json& tracked) {
  try {
    writeTextAtomically(fs::absolute(outPath).parent_path() / "frames_tracked.json",
                        Json({{"frames", tracked}}).dump(1) + "\n");
  } catch (...) {
    std::error_code ec;
    fs::remove(outPath, ec);
    fs::remove(summaryPath, ec);
    throw;
  }
}

// `inhand fuse --robot`: the frames as a robot holding the object gave them (joints, camera in the
// base frame, the grasp), fused by a ScanSession: the robot's own pixels carve only, the voxels
// inside it are emptied, tracking aligns each frame with the hand and the model so far.
int fuseWithRobot(const FuseArgs& args, const fs::path& dir, const FrameSet& set, const Aabb& box,
                  const fs::path& outPath, const fs::path& summaryPath, const MeshOptions& mo,
                  Clock::time_point t0) {
  // Everything the frames give is checked before any work.
  const RobotModel model = RobotModel::load(args.robot);
  ScanConfig config;
  if (!args.config.empty()) readScanConfigFile(args.config, &config);
  const ScanOptions o = robotFuseOptions(args, config.scan, box, mo);
  const std::string file = (dir / "frames.json").string();
  std::vector<JointVector> qs;
  std::vector<Iso3> palms;
  robotFrames(model, set, file, &qs, &palms);
  DepthCameraOptions camera;
  camera.intrinsics = set.intrinsics;
  camera.colour = set.colour;
  NoiseModelOptions noise;
  ScanSession session(model, camera, noise, o, config.multi, box.center());
  std::fprintf(stderr, "fuse: %zu frames with %s, tracking %s, voxels of %.1f mm\n",
               set.frames.size(), model.name().c_str(), o.tracking.enabled ? "on" : "off",
               1000 * o.voxel_m);
  Json tracked = Json::array();
  int fused = 0, grasps = 0;
  for (size_t i = 0; i < set.frames.size(); ++i) {
    if (!session.holding() || !palms[i].isApprox(session.graspPose(), 1e-9)) {
      if (session.holding()) session.endGrasp();
      session.beginGrasp(palms[i], qs[i]);
      ++grasps;
    }
    const DepthImage depth = loadFrameDepth(dir, set, i);
    session.setColourOfNextFrame(loadFrameColour(dir, set, i));
    const FrameReport r = session.addFrame(depth, qs[i], *set.frames[i].T_B_C);
    fused += r.fused;
    Json t = {{"file", set.frames[i].file}, {"fused", r.fused}};
    if (r.fused) {
      const Iso3 T_O_B = palms[i] * model.tipPose(qs[i]).inverse();
      t["T_B_C"] = isoJson(r.T_B_C);
      t["T_O_C"] = isoJson(T_O_B * r.T_B_C);
      const Vec3 moved = (r.T_B_C.translation() - set.frames[i].T_B_C->translation());
      t["camera_correction_mm"] = 1000 * moved.norm();
    } else {
      t["refusal"] = frameRefusalName(r.refusal);
      t["rejected"] = r.rejected;
    }
    tracked.push_back(t);
    progress("fuse: frames", i + 1, set.frames.size());
  }
  auto tMesh = Clock::now();
  ObjectModel result = session.model();
  if (args.surface == "observed") result = result.observedSurface();
  const double meshS = secondsSince(tMesh);
  if (result.mesh.empty())
    throw Error(dir.string() +
                ": the frames produced no surface inside the bounds; check T_O_palm (palm in the "
                "object frame), T_B_C (camera in the robot's base frame) and the bounds");
  const ScanSession::Summary& sum = session.summary();
  Json summary;
  summary["model"] = outPath.filename().string();
  summary["frames"] = set.frames.size();
  summary["frames_fused"] = fused;
  summary["grasps"] = grasps;
  summary["robot"] = args.robot;
  summary["tracking"] = o.tracking.enabled;
  summary["frames_not_fused"] = framesNotFusedJson(sum);
  summary["slips_found"] = slipsJson(sum.slips);
  summary["creeps_followed"] = sum.creeps_followed;
  summary["frames_tracked"] = "frames_tracked.json";
  addModelFigures(result, args.surface, &summary);
  summary["timing_s"] = {{"fusion", sum.fusion_s},
                         {"tracking", sum.tracking_s},
                         {"mesh", meshS},
                         {"total", secondsSince(t0)}};
  writeFusedModel(outPath, summaryPath, result, summary);
  writeFramesTracked(outPath, summaryPath, tracked);
  std::printf(
      "fuse: %zu frames (%d fused, %d grasps, tracking %s) -> %s: %zu vertices, observed %.1f%% "
      "of the surface (%.2f s; corrected poses in frames_tracked.json)\n",
      set.frames.size(), fused, grasps, o.tracking.enabled ? "on" : "off", outPath.c_str(),
      result.mesh.vertices.size(), 100 * result.observedAreaFraction(), secondsSince(t0));
  return 0;
}

}  // namespace

int runFuse(const FuseArgs& args) {
  auto t0 = Clock::now();
  if (args.out.empty()) throw Error("--out is required");
  fs::path outPath(args.out);
  if (outPath.extension() != ".ply") throw Error("--out " + args.out + ": must end in .ply");
  if (args.surface != "closed" && args.surface != "observed")
    throw Error("--surface: must be closed or observed, not \"" + args.surface + "\"");
  fs::path summaryPath =
      args.summary.empty() ? fs::path(outPath).replace_extension(".json") : fs::path(args.summary);
  if (!(args.margin_m >= 0)) throw Error("--margin must be >= 0");
  const VolumeOptions vo = fuseVolumeOptions(args);
  MeshOptions mo;
  mo.hole_sigma_m = args.hole_sigma_m;
  if (std::string p = mo.validate(); !p.empty()) throw Error("--hole-sigma: " + p);
  for (const fs::path& p : {outPath, summaryPath}) {
    fs::path parent = fs::absolute(p).parent_path();
    if (!fs::is_directory(parent))
      throw Error(p.string() + ": the directory " + parent.string() + " does not exist");
  }

  const fs::path dir(args.frames);
  FrameSet set = readFrameSet(dir);
  if (set.reorthonormalised > 0)
    std::fprintf(stderr,
                 "fuse: note: %d of %zu poses were not exactly orthonormal (max |R^T R - I| = "
                 "%.2g); the nearest rotations were used\n",
                 set.reorthonormalised, set.frames.size(), set.max_rotation_deviation);
  if (args.robot.empty()) {
    if (!args.config.empty() || !args.tracking.empty())
      throw Error(std::string(args.config.empty() ? "--tracking" : "--config") +
                  ": only with --robot");
    for (size_t i = 0; i < set.frames.size(); ++i)
      if (!set.frames[i].has_T_O_C)
        throw Error((dir / "frames.json").string() + ": frames[" + std::to_string(i) +
                    "] has no T_O_C, only the robot's q and T_B_C: fuse with --robot CONFIG");
  }
  const Aabb box = fuseBounds(args, dir, set);
  if (!args.robot.empty()) return fuseWithRobot(args, dir, set, box, outPath, summaryPath, mo, t0);
  TsdfVolume volume(box, vo);
  std::fprintf(stderr, "fuse: volume %d x %d x %d voxels of %.1f mm (%.0f MiB)\n",
               volume.dims().x(), volume.dims().y(), volume.dims().z(), vo.voxel_size_m * 1000,
               TsdfVolume::megabytesFor(volume.dims()));
  ColourVolume colour(volume);
  ColourFrames colourFrames(size_t(ScanOptions{}.colour_frames_mb * 1024 * 1024));
  const FuseFigures ff = integrateFrames(dir, set, &volume, &colour, &colourFrames);
  auto tMesh = Clock::now();
  ObjectModel model = extractModel(volume, mo);
  if (args.surface == "observed") model = model.observedSurface();
  double falloff = 0;
  if (set.colour.enabled)
    model.rgba =
        vertexColours(colourFrames, colour, model.mesh, set.colour.light_at_camera, &falloff);
  double meshS = secondsSince(tMesh);
  if (model.mesh.empty())
    throw Error(dir.string() +
                ": the frames produced no surface inside the bounds; check the "
                "poses (T_O_C is camera-to-object) and --bounds");

  Json summary;
  summary["model"] = fs::path(outPath).filename().string();
  summary["frames"] = set.frames.size();
  addModelFigures(model, args.surface, &summary);
  summary["volume"] = volumeJson(volume, ff.updated);
  if (set.colour.enabled)
    summary["colour"] = fuseColourJson(model, colour, colourFrames, falloff, ff.colour_pixels);
  summary["timing_s"] = {{"integrate", ff.integrate_s},
                         {"colour", ff.colour_s},
                         {"load_and_integrate", ff.load_and_integrate_s},
                         {"mesh", meshS},
                         {"total", secondsSince(t0)}};
  writeFusedModel(outPath, summaryPath, model, summary);
  std::printf(
      "fuse: %zu frames -> %s: %zu vertices, %zu triangles, observed %.1f%% of the "
      "surface, mean entropy %.3f nats (%.2f s; summary %s)\n",
      set.frames.size(), outPath.c_str(), model.mesh.vertices.size(), model.mesh.triangles.size(),
      100 * model.observedAreaFraction(), model.meanEntropy(), secondsSince(t0),
      summaryPath.c_str());
  return 0;
}

int runRobot(const RobotArgs& args) {
  auto t0 = Clock::now();
  RobotModel model = RobotModel::load(args.config, args.urdf);
  std::printf("robot %s: %d movable joints, arm chain %s -> %s with %d DOF\n", model.name().c_str(),
              model.variableCount(), model.links()[model.baseLink()].name.c_str(),
              model.links()[model.tipLink()].name.c_str(), model.armDof());
  std::printf("  %-14s %-10s %10s %10s %12s\n", "joint", "type", "lower", "upper", "speed");
  for (int v : model.armVariables()) {
    const JointInfo& j = model.variable(v);
    const char* type = j.type == JointInfo::Type::kPrismatic ? "prismatic" : "revolute";
    std::printf("  %-14s %-10s %10.3f %10.3f %12.3f\n", j.name.c_str(), type, j.lower, j.upper,
                j.velocity);
  }
  std::printf("hand: %zu links, %zu fingers", model.handLinks().size(), model.fingers().size());
  for (const FingerInfo& f : model.fingers())
    std::printf(" [%s %.3f..%.3f]", model.variable(f.variable).name.c_str(), f.open, f.closed);
  std::printf(
      "%s%s\n", model.spreadVariable() >= 0 ? ", spread " : "",
      model.spreadVariable() >= 0 ? model.variable(model.spreadVariable()).name.c_str() : "");
  if (!model.fingers().empty()) {
    // What the open hand can envelop: how deep slabs of a few widths get between its fingers.
    std::printf(
        "open hand: reaches %.0f mm beyond the palm; depth a slab gets between the open "
        "fingers (mm, from the fingertips):\n",
        1000 * openHandReach(model));
    for (int axis = 0; axis < 2; ++axis) {
      std::printf("  slab across palm %c:", axis == 0 ? 'x' : 'y');
      for (int w = 10; w <= 100; w += 10)
        std::printf(" %d mm wide %.0f%s", w, 1000 * openHandDepth(model, axis, 0.001 * w),
                    w < 100 ? "," : "\n");
    }
    if (model.spreadVariable() >= 0) {
      // The edge grasps' case (grasp.edge_spreads): spread 90°, a slab across palm y whose edge
      // is 5 mm beyond the palm axis along palm x.
      std::printf("  edge at spread 90 deg, slab across palm y ending 5 mm past the palm axis:");
      for (int w = 10; w <= 100; w += 10)
        std::printf(" %d mm wide %.0f%s", w,
                    1000 * openHandDepth(model, 1, 0.001 * w, M_PI / 2, 0.005),
                    w < 100 ? "," : "\n");
    }
  }
  ReachabilityOptions ro;
  ro.directions = args.directions;
  ro.rolls = args.rolls;
  ro.grid = args.grid;
  ro.range_m = args.range_m;
  if (std::string p = ro.validate(); !p.empty()) throw Error("reachability: " + p);
  std::printf(
      "reachability: object held %.2f m in front of the palm, camera at %.2f m, %d directions "
      "x %d rolls per position\n",
      model.graspOffset(), ro.range_m, ro.directions, ro.rolls);
  std::printf("  %8s %8s   %-26s %s\n", "pan deg", "tilt deg", "object position (base, m)",
              "reachable directions");
  int reachable = 0, total = 0;
  for (const ReachabilityCell& c : reachabilityMap(model, ro)) {
    std::printf("  %8.1f %8.1f   (%6.3f, %6.3f, %6.3f)      ", c.pan_deg, c.tilt_deg,
                c.object_B.x(), c.object_B.y(), c.object_B.z());
    if (!c.aimable) {
      std::printf("camera cannot aim there\n");
      continue;
    }
    std::printf("%5.1f%%\n", 100.0 * c.reachable / c.total);
    reachable += c.reachable;
    total += c.total;
  }
  std::printf("overall: %.1f%% of viewing directions reachable (%.2f s)\n",
              total ? 100.0 * reachable / total : 0.0, secondsSince(t0));
  return 0;
}

// `snapshot --view-from DIR:N`: frame N's colour image (black without one) and the model rendered
// unlit from that frame's colour camera, side by side.
RgbImage viewFromFrame(const TriangleMesh& mesh, const std::vector<std::array<uint8_t, 3>>& colors,
                       const std::string& spec) {
  const size_t colon = spec.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == spec.size())
    throw Error("--view-from: expected DIR:N, not " + spec);
  const fs::path dir = spec.substr(0, colon);
  char* end = nullptr;
  const long n = std::strtol(spec.c_str() + colon + 1, &end, 10);
  const FrameSet set = readFrameSet(dir);
  if (*end != '\0' || n < 0 || size_t(n) >= set.frames.size())
    throw Error("--view-from: frame " + spec.substr(colon + 1) + " is not one of the " +
                std::to_string(set.frames.size()) + " in " + (dir / "frames.json").string());
  const FrameRecord& f = set.frames[size_t(n)];
  if (!f.has_T_O_C) throw Error("--view-from: frame " + std::to_string(n) + " has no T_O_C");
  std::vector<std::array<uint8_t, 4>> rgba(mesh.vertices.size(), {128, 128, 128, 0});
  for (size_t i = 0; i < colors.size() && i < rgba.size(); ++i)
    rgba[i] = {colors[i][0], colors[i][1], colors[i][2], 255};
  const CameraIntrinsics& K = set.colour.intrinsics;
  const RgbImage model = renderVertexColours(mesh, rgba, f.T_O_C * set.colour.T_D_RGB, K);
  const RgbImage photo = loadFrameColour(dir, set, size_t(n));
  RgbImage out(2 * K.width, K.height);
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      if (!photo.empty()) std::copy(photo.at(u, v), photo.at(u, v) + 3, out.at(u, v));
      std::copy(model.at(u, v), model.at(u, v) + 3, out.at(K.width + u, v));
    }
  return out;
}

int runSnapshot(const SnapshotArgs& args) {
  if (args.size_px < 16 || args.size_px > 4096) throw Error("--size must be in 16..4096");
  if (args.colour != "auto" && args.colour != "scan" && args.colour != "confidence")
    throw Error("--colour must be auto, scan or confidence, not " + args.colour);
  fs::path in(args.model);
  TriangleMesh mesh;
  std::vector<std::array<uint8_t, 3>> colors;
  if (in.extension() == ".ply") {
    PlyData ply = readPly(in);
    mesh = std::move(ply.mesh);
    auto& p = ply.vertexProperties;
    if (args.colour == "scan" && !p.count("alpha"))
      throw Error(args.model + ": no scanned colours (no alpha property: scanned without colour)");
    if (args.colour == "confidence" && !p.count("variance"))
      throw Error(args.model + ": no variance property for the confidence colours");
    if (args.colour == "confidence") {
      for (float v : p["variance"]) colors.push_back(confidenceColor(v));
    } else if (p.count("red") && p.count("green") && p.count("blue")) {
      for (size_t i = 0; i < mesh.vertices.size(); ++i)
        colors.push_back({uint8_t(p["red"][i]), uint8_t(p["green"][i]), uint8_t(p["blue"][i])});
    } else if (p.count("variance")) {
      for (float v : p["variance"]) colors.push_back(confidenceColor(v));
    }
  } else {
    mesh = loadObject(args.model);
  }
  if (!args.view_from.empty()) {
    writeRgbPng(args.out, viewFromFrame(mesh, colors, args.view_from));
    std::printf("snapshot: %s from %s -> %s\n", args.model.c_str(), args.view_from.c_str(),
                args.out.c_str());
    return 0;
  }
  SnapshotOptions so;
  so.tile_px = args.size_px;
  writeRgbPng(args.out, renderSnapshot(mesh, colors, so));
  std::printf("snapshot: %s -> %s\n", args.model.c_str(), args.out.c_str());
  return 0;
}

Json colourMetricsJson(const ColourMetrics& c) {
  return {{"vertices_compared", c.vertices},
          {"delta_e76_mean", c.delta_e_mean},
          {"delta_e76_p95", c.delta_e_p95},
          {"colour_edge_share", c.edge_share},
          {"delta_e76_mean_at_edges", c.delta_e_mean_at_edges},
          {"delta_e76_mean_off_edges", c.delta_e_mean_off_edges},
          {"psnr_db_8_views", c.psnr_db}};
}

// compare's colour score: the colours, where the model has them (red, green, blue, alpha) and the
// truth has its own (a built-in object's checkerboard, a mesh's materials, textures or vertex
// colours); the model's vertices take them (model->rgba). None where either lacks them.
std::optional<ColourMetrics> compareColours(PlyData& ply, const std::string& truthSpec,
                                            ObjectModel* model) {
  std::optional<ColourMetrics> colour;
  const char* rgbaKeys[4] = {"red", "green", "blue", "alpha"};
  if (std::all_of(rgbaKeys, rgbaKeys + 4,
                  [&](const char* k) { return ply.vertexProperties.count(k) > 0; })) {
    // The truth's colours are read apart from its shape: colours it cannot give (an OBJ whose
    // mtllib is missing) cost the colour score only, not the shape's.
    TexturedMesh t;
    try {
      t = loadSimulatedObject(truthSpec, true);
    } catch (const Error& e) {
      std::fprintf(stderr, "compare: warning: no colour score: %s\n", e.what());
    }
    if (!t.colours.empty()) {
      for (size_t i = 0; i < model->mesh.vertices.size(); ++i) {
        std::array<uint8_t, 4> c{};
        for (size_t k = 0; k < 4; ++k)
          c[k] = uint8_t(std::clamp(ply.vertexProperties[rgbaKeys[k]][i], 0.f, 255.f));
        model->rgba.push_back(c);
      }
      colour = colourAccuracy(*model, t.mesh, t.colours);
      colour->psnr_db = colourPsnr(*model, t.mesh, t.colours);
    }
  }
  return colour;
}

int runCompare(const std::string& modelPath, const std::string& truthSpec, double observedVariance,
               bool json) {
  if (!(observedVariance > 0)) throw Error("--observed-variance: must be > 0 (m²)");
  const TriangleMesh truth = loadObject(truthSpec);
  PlyData ply;
  ObjectModel model;
  if (fs::path(modelPath).extension() == ".ply") {
    ply = readPly(modelPath);
    model.mesh = std::move(ply.mesh);
  } else {
    model.mesh = loadObject(modelPath);
  }
  if (model.mesh.triangles.empty()) throw Error(modelPath + ": no triangles");
  const auto it = ply.vertexProperties.find("variance");
  if (it != ply.vertexProperties.end()) model.variance = it->second;
  for (size_t i = 0; i < model.mesh.vertices.size(); ++i)
    model.observed.push_back(model.variance.empty() || model.variance[i] < observedVariance);
  if (model.variance.empty()) model.variance.assign(model.mesh.vertices.size(), 0.f);
  const EvalOptions eo;
  const SurfaceMetrics m = GroundTruth(truth, eo).evaluate(model);
  const std::optional<ColourMetrics> colour = compareColours(ply, truthSpec, &model);
  if (json) {
    Json fsj = Json::object();
    for (size_t k = 0; k < m.fscore.size(); ++k) {
      char key[32];
      std::snprintf(key, sizeof key, "%gmm", 1000 * eo.fscore_m[k]);
      fsj[key] = {{"f", m.fscore[k]}, {"precision", m.precision[k]}, {"recall", m.recall[k]}};
    }
    std::printf("%s\n", Json({{"model", modelPath},
                              {"truth", truthSpec},
                              {"coverage", m.coverage},
                              {"accuracy_mm",
                               {{"mean", m.accuracy_mean_mm},
                                {"rms", m.accuracy_rms_mm},
                                {"p95", m.accuracy_p95_mm}}},
                              {"fscore", fsj},
                              {"observed_area_m2", m.observed_area_m2},
                              {"detached_area_m2", m.detached_area_m2},
                              {"detached_pieces", m.detached_pieces},
                              {"colour", colour ? colourMetricsJson(*colour) : Json()}})
                            .dump(2)
                            .c_str());
  } else {
    std::printf(
        "compare: %s against %s: coverage %.1f%% (%.0f mm), accuracy %.2f mm mean, %.2f "
        "mm p95, F-score %.3f at %.0f mm, %d detached pieces (%.1f cm²)\n",
        modelPath.c_str(), truthSpec.c_str(), 100 * m.coverage, 1000 * eo.tau_m, m.accuracy_mean_mm,
        m.accuracy_p95_mm, m.fscore.empty() ? 0.0 : m.fscore[0], 1000 * eo.fscore_m[0],
        m.detached_pieces, 1e4 * m.detached_area_m2);
    if (colour)
      std::printf(
          "compare: colour of %d vertices: mean ΔE76 %.2f (p95 %.1f); %.0f%% of them within "
          "%.0f mm of a colour edge of the truth: %.1f there, %.2f away from edges\n",
          colour->vertices, colour->delta_e_mean, colour->delta_e_p95, 100 * colour->edge_share,
          1000 * kColourEdgeRadius_m, colour->delta_e_mean_at_edges,
          colour->delta_e_mean_off_edges);
  }
  return 0;
}

std::string defaultRobotConfig() {
  return (resourceDirectory("data", INHAND_DATA_DIR) / "robots/wam_barretthand.json").string();
}

}  // namespace inhand::app
