#include "inhand/scan/session.h"

#include "inhand/volume/colour_volume.h"
#include "inhand/volume/integrate.h"

#include <Eigen/Geometry>
#include "inhand/sensor/depth_image.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>

#include "inhand/core/clock.h"
#include "inhand/core/enum_names.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/robot/collision.h"
#include "inhand/scan/records.h"
#include "inhand/scan/registration.h"
#include "inhand/sensor/render.h"

namespace inhand {

namespace {
// How far a surface moves under `T` as a depth frame can tell: the RMS of its points' motion
// along their normals (a cylinder turned about its axis, or a plane slid in itself, does not
// move).
double surfaceMotion(const std::vector<SurfacePoint>& points, const Iso3& T) {
  double sum = 0;
  for (const SurfacePoint& p : points) sum += std::pow(p.n.dot(T * p.p - p.p), 2);
  return points.empty() ? 0.0 : std::sqrt(sum / double(points.size()));
}
// How far the centroid of `points` moves under `T`.
double centroidMotion(const std::vector<SurfacePoint>& points, const Iso3& T) {
  Vec3 c = Vec3::Zero();
  for (const SurfacePoint& p : points) c += p.p;
  c /= double(std::max<size_t>(1, points.size()));
  return (T * c - c).norm();
}
// What measureSlip found.
struct SlipMeasure {
  TrackResult r;                  // the model aligned with the frame
  Iso3 moved = Iso3::Identity();  // its correction in the palm frame
  double surface_m = 0;           // surfaceMotion of the correction
  bool significant = false;       // beyond the alignment's own uncertainty
  bool moving = false;            // a slip: farther than slip_m, significant, better borne out
  TrackResult held;               // the frame against the model where the grasp holds it
  double sigma_m = 0;             // the sensor's axial σ at the palm's depth
};

// Creep (TrackingOptions::creep_m), not a slip: a significant correction moving the surface
// (`points`) more than creep_m and at most twice slip_m, while no slip goes on, that the frame
// bears out better than the held pose (a residual 15 % smaller, of residuals above half the
// sensor's σ: below it they tell nothing apart) and does not see through clearly
// more (the converse of SlipMeasure::moving's test). An alignment with a model that is coarse or
// seen from few sides slides by as much, but where it slides depends on where the camera looks
// from; an object that crept sits alike from every side. So the grasp follows a creep when the
// frames since the first that showed it all showed it alike (within slip_m) and the camera has
// since turned about the object by creep_turn_deg (its optical axis in the palm frame).
// `*pending` keeps the first frame's correction and axis.
struct CreepPending {
  Iso3 moved = Iso3::Identity();
  Vec3 dir = Vec3::Zero();
};
bool creepConfirmed(const SlipMeasure& slip, bool slipping, const TrackingOptions& o,
                    const std::vector<SurfacePoint>& points, const Iso3& T_C_palm,
                    std::optional<CreepPending>* pending) {
  const Vec3 dir = T_C_palm.linear().transpose() * Vec3::UnitZ();  // the camera's, palm frame
  const bool creep = !slip.moving && !slipping && o.creep_m > 0 && slip.significant &&
                     slip.surface_m > o.creep_m && slip.surface_m <= 2 * o.slip_m &&
                     slip.held.rms_m > 1.15 * std::max(slip.r.rms_m, 0.5 * slip.sigma_m) &&
                     slip.r.see_through <= 2 * slip.held.see_through + slip.r.inliers / 20;
  if (!creep) {
    pending->reset();
    return false;
  }
  const bool alike =
      *pending && surfaceMotion(points, slip.moved * (*pending)->moved.inverse()) < o.slip_m;
  if (!alike) {
    *pending = CreepPending{slip.moved, dir};
    return false;
  }
  if (dir.dot((*pending)->dir) > std::cos(o.creep_turn_deg * M_PI / 180)) return false;
  pending->reset();
  return true;
}
}  // namespace

// A reading of the arm's joint torques at rest, with the grasp it was taken in.
struct TorqueReading {
  JointVector q, tau;  // tau: the mean of `samples` readings at q
  Iso3 T_O_palm;
  int samples = 1;
  double scatter_nm2 = 0;  // TorqueSamples::scatter_nm2
};

struct ScanSession::State {
  Clock::time_point born = Clock::now();
  State(const RobotModel& robot, const DepthCameraOptions& camera, const NoiseModelOptions& noise,
        const ScanOptions& options, const MultiGraspOptions& multi, const Vec3& centre_O)
      : model(&robot),
        camera(camera),
        noise(noise),
        options(options),
        multi(multi),
        centre(centre_O),
        volume(makeScanVolume(centre_O, options)),
        planner(robot, camera, noise, options.planner),
        ranker(robot, camera, noise, multi.ranking),
        scenes(robot),
        payload(robot) {}

  const RobotModel* model;
  DepthCameraOptions camera;
  NoiseModelOptions noise;
  ScanOptions options;
  MultiGraspOptions multi;
  Vec3 centre;
  TsdfVolume volume;
  // The frames of the object not held fused with their silhouettes, where `volume` only carves
  // them (ScanOptions::discontinuities_carve_only_on_table): the first grasp's model
  // (tableTopVolume). Not in checkpoints.
  std::optional<TsdfVolume> tableVolume;
  // Colour (camera.colour): the grid's colours once a frame had them; the next frame's image.
  std::unique_ptr<ColourVolume> colour;
  // … and the colour frames kept for model()'s colours (options.colour_frames_mb; not in
  // checkpoints: after a resume, what they did not see takes the volume's colour).
  std::unique_ptr<ColourFrames> colourFrames;
  RgbImage nextColour;
  // A frame of the object not held, its silhouettes fused, into tableVolume (made at the first).
  void fuseIntoTableVolume(const DepthImage& depth, const Iso3& T_O_C, const PixelRect& rect,
                           const std::vector<uint8_t>& carve) {
    if (!tableVolume) tableVolume.emplace(makeScanVolume(centre, options));
    const std::vector<uint8_t>* c = carve.empty() ? nullptr : &carve;
    const std::vector<float> sigma = measurementSigma(depth, camera.intrinsics, noise, &rect, c);
    integrate(depth, T_O_C, camera.intrinsics, sigma, &*tableVolume, c);
  }
  // A fused frame's colours into `colour` and `colourFrames` (made at the first).
  void fuseColour(const DepthImage& depth, const RgbImage& image, const Iso3& T_O_C,
                  const std::vector<float>& sigma, const std::vector<uint8_t>* carve,
                  const JointVector& q, const Iso3& T_B_C) {
    const auto tc = Clock::now();
    if (!colour) colour = std::make_unique<ColourVolume>(volume);
    summary.colour_pixels +=
        integrateColour(depth, image, T_O_C, camera, sigma, colour.get(), carve).pixels;
    if (options.colour_frames_mb > 0) {
      if (!colourFrames)
        colourFrames =
            std::make_unique<ColourFrames>(size_t(options.colour_frames_mb * 1024 * 1024));
      // The robot as the colour camera sees it, over the volume's pixels there.
      const Iso3 T_B_RGB = T_B_C * camera.colour.T_D_RGB;
      DepthCameraOptions inColour = camera;
      inColour.intrinsics = camera.colour.intrinsics;
      const PixelRect rect =
          volumeImageRect(volume, T_O_C * camera.colour.T_D_RGB, inColour.intrinsics);
      const DepthImage robotThere =
          colourFrames->keepsNext()
              ? robotDepthImage(scenes, q, T_B_RGB, inColour, /*with_table=*/false, rect)
              : DepthImage();
      colourFrames->add(depth, image, T_O_C, camera, sigma, carve, &robotThere);
    }
    summary.colour_s += secondsSince(tc);
  }
  ViewPlanner planner, ranker;
  RobotOccluders scenes;
  std::vector<Aabb> linkBox;  // each link's collision primitives' box, link frame
  ScanProgress progress;

  // The grasp.
  bool holding = false;
  std::vector<TorqueReading> torqueReadings;  // addJointTorques (kept for checkpoints)
  PayloadEstimator payload;                   // … fitted as they come (O frame)
  void addTorques(TorqueReading r) {
    payload.add(r.q, r.tau, r.T_O_palm.inverse(), r.samples, r.scatter_nm2);
    torqueReadings.push_back(std::move(r));
  }
  int grasp = -1;
  Iso3 T_O_palm = Iso3::Identity();
  JointVector qGrasp;  // the robot's joints when the grasp began (the hand as it holds)
  Aabb objectBox;
  std::shared_ptr<NearHandGrid> nearHand;
  // Within ScanOptions::t_hand_m of the hand as it holds (fusion's §IV rule; nearHand itself when
  // the planner's t_hand is the same).
  std::shared_ptr<NearHandGrid> fuseNearHand;
  // Tracking: the hand's surface at the grasp's finger joints, the model's observed surface (both
  // palm frame), the last frame's correction.
  std::vector<SurfacePoint> handPoints, objectPoints;
  std::vector<Vec3> objectOccluders;  // the whole model (observed or not), palm frame
  std::vector<Vec3> supportPoints;    // measured model surface, palm frame (FrameChecks)
  std::vector<JointVector> viewPath;  // the open view's waypoints (FrameChecks)
  int unsupportedStreak = 0;          // frames in a row not showing the object in the hand
  int confirmFrames = 0;              // confirmGraspOnNextFrames: frames left to try
  // TrackingOptions::slip_check: the object is moving in the hand (since the grasp was at
  // slipFrom), the event's record so far.
  bool slipping = false;
  Iso3 slipFrom = Iso3::Identity();
  std::optional<Iso3> slipPending;           // the last frame's unconfirmed slip (palm frame)
  std::optional<CreepPending> creepPending;  // an unconfirmed creep (palm frame)
  std::vector<SurfacePoint> slipPoints;      // the model's observed surface for it (palm frame)
  int slipRefinements = 0;                   // frames that refined the grasp after it moved
  SlipRecord slip;
  std::vector<std::vector<Vec3>> linkSamples;  // the arm's links' surfaces (link frames)
  JointVector handPointsQ;
  // The last aligned frame's error in the palm frame: true palm = reported palm · correction.
  Iso3 correction = Iso3::Identity();
  // The joints of the frame that set it in this grasp (none yet: no jump check), and the last
  // frame's correction refused as a jump (TrackingOptions::max_jump_m).
  std::optional<JointVector> correctionQ;
  // The joints of this grasp's last in-hand frame that showed the object where the hand holds
  // it (lastSeenHeld).
  std::optional<JointVector> lastHeldQ;
  std::optional<Iso3> jumpPending;
  // TrackingOptions::filter: the correction's estimate (palm frame: rotation vector, translation),
  // its covariance and the joints of the last tracked frame; started at the grasp's first frame.
  bool filterStarted = false;
  Eigen::Matrix<double, 6, 1> filterX = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 6> filterP = Eigen::Matrix<double, 6, 6>::Identity();
  JointVector filterQ;
  bool trackingFromFull = false;  // tracking's object points are from model(), not planningModel()
  // The model's occluders in the palm frame of a grasp other than the current one (the lift's),
  // and that grasp: rebuilt when it changes.
  std::vector<Vec3> liftOccluders;
  Iso3 liftOccludersFor = Iso3::Identity();
  std::vector<Vec3> used;         // directions of this grasp's views
  std::vector<Vec3> initialDirs;  // the initial trajectory's directions not yet tried
  int alg1Views = 0;              // Alg. 1 views of this grasp

  // The views.
  std::vector<ViewRecord> views;
  std::vector<int> viewGrasp;
  bool viewOpen = false;

  Summary summary;

  // Every change to the volume (fusion, emptying inside the robot, the non-const volume()
  // accessor) moves `revision` on; a model extracted at one revision is kept until the next.
  // Between two frames the scan asks for the same model several times (a view's end and its
  // grasp's, grasp planning, each pick-up attempt's tracking), at 0.05-0.3 s an extraction.
  uint64_t revision = 0;
  struct CachedModel {
    uint64_t revision = std::numeric_limits<uint64_t>::max();
    ObjectModel model;
  };
  CachedModel full, planning;
  const ObjectModel& extracted(CachedModel& cache, const MeshOptions& mesh) {
    if (cache.revision != revision) {
      cache.model = extractModel(volume, mesh);
      if (colour && &cache == &full) cache.model.rgba = vertexColours(*colour, cache.model.mesh);
      cache.revision = revision;
    }
    return cache.model;
  }
  // The grasp's near-hand grids: the planner's (eq. 9 skips hits within its t_hand) and fusion's
  // (measurements within ScanOptions::t_hand_m only carve), one grid when the two agree.
  // The initial trajectory's next view that the arm reaches from the grasp's joints (the
  // directions it does not are skipped, and logged); nullopt when none is left.
  std::optional<PlannedView> initialView(const GraspState& g,
                                         const std::function<void(const std::string&)>& log) {
    const RobotModel& m = *model;
    const JointVector& q_now = g.q;
    while (!initialDirs.empty()) {
      const Vec3 dir = initialDirs.front();
      initialDirs.erase(initialDirs.begin());
      const std::optional<ViewCandidate> c = planner.reach({dir}, centre, objectBox, g, true)[0];
      if (!c) {
        log("initial view skipped: no collision-free move there");
        continue;
      }
      PlannedView v;
      v.initial = true;
      v.dir_O = c->dir_O;
      v.T_O_C = c->T_O_C;
      v.waypoints = {q_now, m.withArm(q_now, c->arm)};
      v.cost_s = trajectoryTime(m, m.arm(q_now), c->arm);
      ViewRecord rec;
      rec.initial = true;
      rec.dir_O = v.dir_O;
      rec.T_O_C = v.T_O_C;
      rec.cost_s = v.cost_s;
      openView(rec, v.waypoints);
      return v;
    }
    return std::nullopt;
  }
  // A view begins: its record, its direction used, the path the arm is sent along.
  void openView(const ViewRecord& rec, const std::vector<JointVector>& path) {
    views.push_back(rec);
    viewGrasp.push_back(grasp);
    used.push_back(rec.dir_O);
    viewOpen = true;
    viewPath = path;
  }
  // addFrame's checks: why the reported joints lie off the open view's path (the largest
  // joint's distance from it over FrameChecks::max_path_deviation_rad), or ""; the held
  // object's measured surface points (supportPoints) the frame bears out and those it sees past
  // (the palm at T_C_palm).
  std::string offPath(const JointVector& q) const;
  std::pair<int, int> supportIn(const DepthImage& depth, const Iso3& T_C_palm,
                                const std::vector<uint8_t>* robot = nullptr) const;
  // Why the frame does not show the object where the hand holds it (FrameChecks::min_support;
  // too few of those points borne out), or "" (the streak of such frames then ends).
  std::string notHeldIn(const DepthImage& depth, const Iso3& T_C_palm, const JointVector& q,
                        const Iso3& T_B_C);
  // The same for a frame tracking could not align, with the object where the last aligned frame
  // held it (T_C_held): one that bears it out leaves the streak as it was.
  std::string notHeldUnaligned(const DepthImage& depth, const Iso3& T_C_held, const JointVector& q,
                               const Iso3& T_B_C) {
    const int streak = unsupportedStreak;
    std::string why = notHeldIn(depth, T_C_held, q, T_B_C);
    if (why.empty()) unsupportedStreak = streak;
    return why.empty() ? why : why + ", where the last aligned frame held it";
  }
  // The arm's torque readings from a checkpoint's header (load).
  void readTorques(const Json& h);
  // The tracking state a checkpoint holds: the last correction, the jump check's, the filter's.
  void readTrackingFilter(const Json& h, const std::function<Error(const std::string&)>& bad);
  // The object moved in the hand by `moved` (palm frame): the model's points in the palm frame
  // move with it, T_O_palm the other way.
  void moveHeldModel(const RobotModel& robot, const Iso3& moved) {
    T_O_palm = T_O_palm * moved.inverse();
    for (std::vector<SurfacePoint>* set : {&objectPoints, &slipPoints})
      for (SurfacePoint& p : *set) {
        p.p = moved * p.p;
        p.n = moved.linear() * p.n;
      }
    for (Vec3& p : objectOccluders) p = moved * p;
    for (Vec3& p : supportPoints) p = moved * p;
    buildNearHand(robot, qGrasp, T_O_palm);
  }
  void buildNearHand(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm_) {
    const HandGeometry hand(robot, q, T_O_palm_);
    const ViewQualityOptions& vq = options.planner.quality;
    nearHand = std::make_shared<NearHandGrid>(hand, vq.t_hand_m, vq.near_hand_cell_m);
    fuseNearHand =
        options.t_hand_m == vq.t_hand_m
            ? nearHand
            : std::make_shared<NearHandGrid>(hand, options.t_hand_m, vq.near_hand_cell_m);
  }
  // Why a frame's correction (palm frame, at joints q) is taken for a wrong alignment, or "":
  // it lies farther from the last tracked frame's than TrackingOptions::max_jump_m allows and
  // the frame before was not refused for a jump to within as much of it. A refused one is
  // remembered for the next frame.
  std::string correctionJump(const Iso3& c, const JointVector& q) {
    const TrackingOptions& o = options.tracking;
    if (!(o.max_jump_m > 0) || !correctionQ) return {};
    auto apart = [](const Iso3& a, const Iso3& b) {
      const Iso3 D = a.inverse() * b;
      return D.translation().norm() + 0.1 * Eigen::AngleAxisd(D.linear()).angle();
    };
    const double bound = o.max_jump_m * (1 + (model->arm(q) - model->arm(*correctionQ)).norm());
    const double jump = apart(correction, c);
    const bool confirmed = jumpPending && apart(*jumpPending, c) <= bound;
    jumpPending.reset();
    if (jump <= bound || confirmed) return {};
    jumpPending = c;
    char why[160];
    std::snprintf(why, sizeof why,
                  "the alignment puts the palm %.1f mm from the last frame's (at most %.1f)",
                  1000 * jump, 1000 * bound);
    return why;
  }
  // The model alone aligned with an in-hand frame from where the grasp holds it (the palm at
  // T_C_palm; TrackingOptions::slip_check). A slip moves the model farther than slip_m,
  // significantly for the alignment's own uncertainty, and the frame bears the moved model out
  // clearly better than the held one (a residual a half larger there, a quarter fewer points
  // aligned, or more seen through): an alignment that slid along what the frame leaves free
  // fits no better than where it began. Residuals are compared above half the sensor's σ (its
  // information's floor): below it, with a frame less noisy than the sensor model says, the
  // ratio of two small residuals found slips where nothing moved.
  SlipMeasure measureSlip(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C,
                          const Iso3& T_C_palm, double gate_m) const {
    const TrackingOptions& o = options.tracking;
    const CameraIntrinsics& K = camera.intrinsics;
    // The robot as the frame shows it (as fusion masks it) hides the model where it is in front.
    const JointVector qSeen = q + armOffsetsFromPalmError(*model, q, correction);
    const Iso3 T_O_C = T_O_palm * model->tipPose(qSeen).inverse() * T_B_C;
    const PixelRect rect = volumeImageRect(volume, T_O_C, K);
    const std::vector<uint8_t> hidden =
        robotPixelMask(depth, T_B_C, qSeen, scenes, camera, options.t_hand_m,
                       options.carve_radius_px, /*with_table=*/true, &rect);
    // The model in the palm frame is a body at the palm's pose: its correction is the slip,
    // looked for within gate_m.
    TrackingOptions near = o;
    near.gate_m = std::max(o.final_gate_m, gate_m);
    const double sigma = axialSigma(noise, T_C_palm.translation().z(), 0);
    SlipMeasure out;
    out.sigma_m = sigma;
    out.r = alignBodyToDepth(depth, hidden, K, slipPoints, objectOccluders, T_C_palm, sigma, near,
                             UncoveredPull::kFromStart);
    if (!out.r.ok) return out;
    out.moved = T_C_palm.inverse() * out.r.correction * T_C_palm;  // palm frame
    out.surface_m = surfaceMotion(slipPoints, out.moved);
    out.significant =
        correctionSignificance(out.r, T_C_palm, o.pair_information) > o.in_hand_significance;
    const double least = o.creep_m > 0 ? std::min(o.creep_m, o.slip_m) : o.slip_m;
    if (!(out.surface_m > least && out.significant)) return out;
    TrackingOptions at = near;
    at.iterations = 0;  // the frame against the model where the hand holds it
    out.held = alignBodyToDepth(depth, hidden, K, slipPoints, objectOccluders, T_C_palm, sigma, at);
    const TrackResult& held = out.held;
    const TrackResult& r = out.r;
    if (!(out.surface_m > o.slip_m)) return out;
    // Residuals below half the sensor's σ (its information's floor) tell nothing apart.
    out.moving = held.rms_m > 1.5 * std::max(r.rms_m, 0.5 * sigma) ||
                 held.inliers < 0.75 * r.inliers ||
                 held.see_through > 2 * r.see_through + r.inliers / 20;
    return out;
  }
  // A slip event begins (unless one goes on): from the grasp as it is, in the current view.
  void startSlip() {
    if (slipping) return;
    slipping = true;
    slipFrom = T_O_palm;
    slip = SlipRecord{};
    slip.grasp = grasp;
    slip.view = std::max(0, int(views.size()) - 1);
  }

  // Why an in-hand frame (taken from T_O_C) lands where the model knows space is empty, or ""
  // when it does not: more than checks.max_free_space_fraction of its sampled points not in
  // `carve` (every second pixel of every second row, in the volume) lie in empty voxel cells.
  std::string inKnownFreeSpace(const DepthImage& depth, const std::vector<uint8_t>& carve,
                               const Iso3& T_O_C) const {
    const CameraIntrinsics& K = camera.intrinsics;
    const TsdfVolume& vol = volume;
    const Vec3i& dims = vol.dims();
    // Counted per row (on both cores) then summed.
    const int rows = (depth.height + 1) / 2;
    std::vector<int> rowInside(size_t(rows), 0), rowEmpty(size_t(rows), 0);
    parallelFor(0, rows, [&](int row) {
      const int v = 2 * row;
      int& inside = rowInside[size_t(row)];
      int& inEmpty = rowEmpty[size_t(row)];
      for (int u = 0; u < depth.width; u += 2) {
        const size_t i = size_t(v) * depth.width + u;
        const float z = depth.depth_m[i];
        if (!(z > 0) || (!carve.empty() && carve[i])) continue;
        const Vec3 g = (T_O_C * (double(z) * K.rayZ1(u, v)) - vol.origin()) / vol.voxelSize();
        const int x = int(std::floor(g.x())), y = int(std::floor(g.y())),
                  w = int(std::floor(g.z()));
        if (x < 0 || y < 0 || w < 0 || x + 1 >= dims.x() || y + 1 >= dims.y() || w + 1 >= dims.z())
          continue;
        ++inside;
        // In known-empty space only when the whole voxel cell around the point is: a surface
        // point's cell always has a corner in the surface's band or behind it, while rays that
        // grazed the surface may have emptied the voxel nearest to it.
        bool allEmpty = true;
        for (int c = 0; c < 8 && allEmpty; ++c)
          allEmpty = vol.state(vol.index(x + (c & 1), y + ((c >> 1) & 1), w + ((c >> 2) & 1))) ==
                     VoxelState::kEmpty;
        inEmpty += allEmpty;
      }
    });
    int inside = 0, inEmpty = 0;
    for (int row = 0; row < rows; ++row) {
      inside += rowInside[size_t(row)];
      inEmpty += rowEmpty[size_t(row)];
    }
    if (std::getenv("INHAND_DEBUG_FREE_SPACE"))
      std::fprintf(stderr, "free space: %d of %d\n", inEmpty, inside);
    if (inside < options.checks.min_points ||
        inEmpty <= options.checks.max_free_space_fraction * inside)
      return {};
    return "depth where the model knows space is empty (" + std::to_string(inEmpty) + " of " +
           std::to_string(inside) + " sampled pixels in the volume)";
  }
  // The pixels of an in-hand frame (taken from T_O_C) that fusion does not use at all, among
  // those robotPixelMask left to fuse (`carve` 0):
  //  - §IV in the object frame: the measurement lies within t_hand of the hand. The rendered
  //    robot depth that robotPixelMask compares with holds the nearest robot surface per pixel,
  //    so a return from the palm seen past a finger's edge (lateral noise moves returns across
  //    silhouettes) escaped it and was fused as surface. Not carving either: the object's own
  //    surface within t_hand stays unknown (the planner counts it unobservable in this grasp),
  //    and carving a pixel's noisy depth would erode it.
  //  - A silhouette: a pixel next to one farther by more than edge_jump_m, or beside a gap of no
  //    return whose first return across it (within 8 pixels along a row or column) is farther
  //    by as much, or missing (the background out of range: the usual case in the hand). Its
  //    return may come from across the edge (the sensor's lateral noise; seen at a grazing
  //    angle a fraction of a pixel is millimetres of depth), and fused it grows flakes of
  //    surface beyond the object's edges that no later view carves away (the cracker box's
  //    bottom edge: a skirt 5-12 mm below it). A gap whose far side is nearer does not count:
  //    a projector shadow beside a finger lies on the object's face, and dropping the face's
  //    pixels along it left slits at the contacts (depthDiscontinuities).
  std::vector<uint8_t> unusedInHand(const DepthImage& depth, const std::vector<uint8_t>& carve,
                                    const Iso3& T_O_C, const PixelRect& rect) const {
    const CameraIntrinsics& K = camera.intrinsics;
    const int W = depth.width, H = depth.height;
    const float jump = float(options.edge_jump_m);
    const std::vector<uint8_t> acrossGap =
        jump > 0 ? depthDiscontinuities(depth, jump, &rect) : std::vector<uint8_t>();
    std::vector<uint8_t> unused(depth.depth_m.size(), 0);
    parallelFor(rect.v0, rect.v1, [&](int v) {
      for (int u = rect.u0; u < rect.u1; ++u) {
        const size_t i = size_t(v) * W + u;
        const float z = depth.depth_m[i];
        if (!(z > 0) || (!carve.empty() && carve[i])) continue;
        bool edge = !acrossGap.empty() && acrossGap[i];           // the row and column neighbours
        for (int dv = -1; dv <= 1 && jump > 0 && !edge; dv += 2)  // … and the diagonal ones
          for (int du = -1; du <= 1 && !edge; du += 2) {
            const int uu = u + du, vv = v + dv;
            if (uu < 0 || vv < 0 || uu >= W || vv >= H) continue;
            const float zn = depth.depth_m[size_t(vv) * W + uu];
            edge = zn - z > jump;
          }
        unused[i] = edge || fuseNearHand->near(T_O_C * (double(z) * K.rayZ1(u, v)));
      }
    });
    return unused;
  }
};

ScanSession::ScanSession(const RobotModel& robot, const DepthCameraOptions& camera,
                         const NoiseModelOptions& noise, const ScanOptions& options,
                         const MultiGraspOptions& multi, const Vec3& centre_O) {
  std::string problem = options.validate();
  if (problem.empty()) problem = multi.validate();
  if (!problem.empty()) throw Error("scan options: " + problem);
  s_ = std::make_unique<State>(robot, camera, noise, options, multi, centre_O);
  const RobotModel& m = robot;
  s_->linkBox.resize(m.links().size());
  for (size_t li = 0; li < m.links().size(); ++li)
    for (const Primitive& p : m.links()[li].collision) {
      const Aabb b = p.toMesh().bounds();
      s_->linkBox[li].extend(b.min);
      s_->linkBox[li].extend(b.max);
    }
}

ScanSession::~ScanSession() = default;
ScanSession::ScanSession(ScanSession&&) noexcept = default;

const ScanOptions& ScanSession::options() const { return s_->options; }
const MultiGraspOptions& ScanSession::multiOptions() const { return s_->multi; }
const RobotModel& ScanSession::robot() const { return *s_->model; }
const Vec3& ScanSession::centre() const { return s_->centre; }
const DepthCameraOptions& ScanSession::camera() const { return s_->camera; }
const NoiseModelOptions& ScanSession::noise() const { return s_->noise; }
Iso3 ScanSession::cameraPose() const { return s_->planner.cameraPose(s_->options.planner.range_m); }
void ScanSession::setProgress(const ScanProgress& progress) { s_->progress = progress; }
const ScanProgress& ScanSession::progress() const { return s_->progress; }
double ScanSession::elapsedSeconds() const { return secondsSince(s_->born); }
bool ScanSession::holding() const { return s_->holding; }
int ScanSession::graspIndex() const { return s_->grasp; }
const Iso3& ScanSession::graspPose() const { return s_->T_O_palm; }
const std::optional<JointVector>& ScanSession::lastSeenHeld() const { return s_->lastHeldQ; }
const std::vector<ViewRecord>& ScanSession::views() const { return s_->views; }
const std::vector<int>& ScanSession::viewGrasps() const { return s_->viewGrasp; }
const TsdfVolume& ScanSession::volume() const { return s_->volume; }
const TsdfVolume& ScanSession::tableTopVolume() const {
  return s_->tableVolume ? *s_->tableVolume : s_->volume;
}
TsdfVolume& ScanSession::volume() {
  ++s_->revision;  // the caller may change it
  return s_->volume;
}

namespace {

// A depth frame must have the camera's size, one depth per pixel.
void checkFrameSize(const DepthImage& d, const CameraIntrinsics& K) {
  if (d.width != K.width || d.height != K.height)
    throw Error("depth frame: " + std::to_string(d.width) + "x" + std::to_string(d.height) +
                " pixels, the camera's are " + std::to_string(K.width) + "x" +
                std::to_string(K.height));
  if (d.depth_m.size() != size_t(K.width) * size_t(K.height))
    throw Error("depth frame: " + std::to_string(d.depth_m.size()) + " depths for " +
                std::to_string(K.width) + "x" + std::to_string(K.height) + " pixels");
}

void checkJoints(const RobotModel& m, const JointVector& q, const char* where) {
  if (q.size() != m.variableCount())
    throw Error(std::string(where) + ": joint state of " + std::to_string(q.size()) +
                " values, the robot has " + std::to_string(m.variableCount()));
}
}  // namespace

void ScanSession::log(const std::string& line) const {
  if (s_->progress.log) s_->progress.log(line);
}

void ScanSession::beginGrasp(const Iso3& T_O_palm, const JointVector& q, const Aabb& object_box_O) {
  checkJoints(*s_->model, q, "beginGrasp");
  if (s_->viewOpen) finishView();
  State& s = *s_;
  s.holding = true;
  ++s.grasp;
  s.summary.grasps = s.grasp + 1;
  s.summary.termination = Termination::kRunning;
  s.summary.message.clear();
  closeSlip();
  s.creepPending.reset();
  s.lastHeldQ.reset();
  s.T_O_palm = T_O_palm;
  s.qGrasp = q;
  s.objectBox = object_box_O;
  if (s.objectBox.empty()) {
    s.objectBox.extend(s.centre - Vec3::Constant(0.05));
    s.objectBox.extend(s.centre + Vec3::Constant(0.05));
  }
  s.buildNearHand(*s.model, q, T_O_palm);
  s.tableVolume.reset();  // a grasp began: re-grasps are planned on the whole model
  s.used.clear();
  s.alg1Views = 0;
  s.correction = Iso3::Identity();
  s.correctionQ.reset();
  s.jumpPending.reset();
  s.filterStarted = false;
  if (modelPointsNeeded(s.options)) refreshTrackingModel();
  s.trackingFromFull = false;
  s.unsupportedStreak = 0;
  s.initialDirs.clear();
  // The model exists after the first grasp: Alg. 1 from the start.
  if (s.grasp == 0 && s.options.initial_views > 0)
    s.initialDirs = fibonacciSphere(s.options.initial_views);
}

void ScanSession::confirmGraspOnNextFrames(int frames) {
  if (frames < 0) throw Error("confirmGraspOnNextFrames: frames must be >= 0");
  s_->confirmFrames = frames;
}

void ScanSession::confirmGrasp(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C) {
  State& s = *s_;
  const RobotModel& m = *s.model;
  --s.confirmFrames;
  // The camera relative to the palm as tracking has it (reported where it refuses the frame).
  TrackResult handOnly;
  const std::optional<Iso3> T_B_C_hand = trackedCameraPose(depth, q, T_B_C, s.T_O_palm, &handOnly);
  const Iso3 T_B_C_used = T_B_C_hand ? *T_B_C_hand : T_B_C;
  const std::vector<uint8_t> mask =
      robotPixelMask(depth, T_B_C_used, q, s.scenes, s.camera, s.options.t_hand_m,
                     s.options.carve_radius_px, /*with_table=*/false);
  TrackResult r;
  const std::optional<Iso3> grasp = registerHeldObject(depth, mask, q, T_B_C_used, s.T_O_palm, &r);
  if (!grasp) return;
  const Iso3 moved = grasp->inverse() * s.T_O_palm;  // in the palm frame
  char line[160];
  std::snprintf(line, sizeof line,
                "the grasp confirmed by registration: the object's centre %.1f mm and the object "
                "%.1f° from where the grasp had them",
                1000 * centroidMotion(s.slipPoints, moved),
                180 / M_PI * Eigen::AngleAxisd(moved.linear()).angle());
  log(line);
  s.confirmFrames = 0;
  s.moveHeldModel(m, moved);
}

void ScanSession::endGrasp() {
  if (s_->viewOpen) finishView();
  s_->holding = false;
  s_->confirmFrames = 0;
  closeSlip();
}

void ScanSession::closeSlip(bool settled) {
  State& s = *s_;
  s.slipPending.reset();
  if (!s.slipping) return;
  s.slipping = false;
  // An event no second frame bore out (an alignment gone wrong, not a slip) leaves no record.
  if (s.slipFrom.isApprox(s.T_O_palm, 1e-12)) return;
  s.slip.settled = settled;
  s.slip.moved_m = centroidMotion(s.slipPoints, s.T_O_palm.inverse() * s.slipFrom);
  s.slip.turned_rad = rotationBetween(s.slipFrom, s.T_O_palm);
  s.summary.slips.push_back(s.slip);
}

void ScanSession::emptyInsideRobot(const JointVector& q, const Iso3& T_O_B) {
  // Fig. 3 (c): voxels inside the robot are empty. The paper marks the hand; every link is marked
  // (the wrist and forearm too), at each frame's joint state: nothing of the object can be there.
  const RobotModel& m = *s_->model;
  TsdfVolume& volume = s_->volume;
  ++s_->revision;
  const std::vector<Iso3> T = m.linkPoses(q);
  for (size_t li = 0; li < m.links().size(); ++li) {
    if (m.links()[li].collision.empty()) continue;
    const Iso3 T_O_link = T_O_B * T[li];
    Aabb b;  // the link's box in O
    for (int c = 0; c < 8; ++c) b.extend(T_O_link * s_->linkBox[li].corner(c));
    Vec3 lo = ((b.min - volume.origin()) / volume.voxelSize()).array().ceil();
    Vec3 hi = ((b.max - volume.origin()) / volume.voxelSize()).array().floor();
    lo = lo.cwiseMax(Vec3::Zero());
    hi = hi.cwiseMin((volume.dims().cast<double>().array() - 1).matrix());
    if ((lo.array() > hi.array()).any()) continue;
    const Iso3 T_link_O = T_O_link.inverse();
    parallelFor(int(lo.z()), int(hi.z()) + 1, [&](int z) {
      for (int y = int(lo.y()); y <= int(hi.y()); ++y)
        for (int x = int(lo.x()); x <= int(hi.x()); ++x) {
          const size_t i = volume.index(x, y, z);
          // An empty voxel has no sums: emptying it again changes nothing.
          if (volume.state(i) == VoxelState::kEmpty) continue;
          const Vec3 p = T_link_O * volume.point(x, y, z);
          for (const Primitive& prim : m.links()[li].collision)
            if (prim.contains(p)) {
              // Measurements win over the hand model: a voxel the sensor saw behind the
              // object's surface stays (a finger closed on the model can overlap the object).
              if (volume.state(i) == VoxelState::kObserved && volume.distance(i) < 0) break;
              volume.states()[i] = uint8_t(VoxelState::kEmpty);
              volume.sumW()[i] = 0;
              volume.sumWD()[i] = 0;
              break;
            }
        }
    });
  }
}

namespace {
// The frame's pixels with a return, and of those the ones that only carve, into r.
void countPixels(const DepthImage& depth, const std::vector<uint8_t>& carve, FrameReport* r) {
  std::vector<int> rowPixels(size_t(depth.height), 0), rowCarve(size_t(depth.height), 0);
  parallelFor(0, depth.height, [&](int v) {
    for (size_t i = size_t(v) * depth.width; i < size_t(v + 1) * depth.width; ++i)
      if (depth.depth_m[i] > 0) {
        ++rowPixels[size_t(v)];
        if (!carve.empty() && carve[i]) ++rowCarve[size_t(v)];
      }
  });
  for (int v = 0; v < depth.height; ++v) {
    r->pixels += rowPixels[size_t(v)];
    r->carve_pixels += rowCarve[size_t(v)];
  }
}

// The silhouette pixels of `depth` (depthDiscontinuities) that are not the robot's get
// kCarveBeyondBand in `carve`: they only carve. A silhouette pixel's return may come from beside
// its ray, behind the object's edge: the depths to fuse (returned) carve in front of the nearest
// depth within 2 pixels of it (5 × 5), not into the edge of a thin object. The robot's silhouette
// pixels carve as they did, unknown voxels only (kCarveUnknownToSurface): their depth may be of
// what lies across the edge.
DepthImage silhouettesOnlyCarve(const DepthImage& depth, double jump_m, const PixelRect& rect,
                                std::vector<uint8_t>* carve) {
  std::vector<uint8_t> edges = depthDiscontinuities(depth, jump_m, &rect);
  if (carve->empty()) carve->assign(depth.depth_m.size(), 0);
  for (size_t i = 0; i < carve->size(); ++i) {
    if (edges[i] && (*carve)[i]) {
      if ((*carve)[i] == kCarveToSurface) (*carve)[i] = kCarveUnknownToSurface;
      edges[i] = 0;
    }
    if (edges[i]) (*carve)[i] = kCarveBeyondBand;
  }
  return nearestAround(depth, edges, 2);
}

// `depth` with the flagged pixels' depths set to 0 (no return); an empty image when none is.
DepthImage withPixelsDropped(const DepthImage& depth, const std::vector<uint8_t>& drop) {
  if (std::find(drop.begin(), drop.end(), 1) == drop.end()) return DepthImage();
  DepthImage out = depth;
  for (size_t i = 0; i < drop.size(); ++i)
    if (drop[i]) out.depth_m[i] = 0;
  return out;
}
}  // namespace

FrameReport ScanSession::fuse(const DepthImage& input, const JointVector& q, const Iso3& T_B_C,
                              const Iso3& T_O_B, const std::vector<uint8_t>* extraCarve,
                              bool inHand, bool maskRobot, const RgbImage& colour) {
  const auto t0 = Clock::now();
  State& s = *s_;
  const CameraIntrinsics& K = s.camera.intrinsics;
  checkFrameSize(input, K);
  if (extraCarve && extraCarve->size() != input.depth_m.size())
    throw Error("carve mask: " + std::to_string(extraCarve->size()) + " values for " +
                std::to_string(input.depth_m.size()) + " pixels");
  const Iso3 T_O_C = T_O_B * T_B_C;
  std::vector<uint8_t> carve;
  // The pixels the volume's voxels project to: the only ones fusion reads.
  const PixelRect rect = volumeImageRect(s.volume, T_O_C, K);
  // The robot's own surfaces only carve (§IV); in the hand the table counts as the robot's (in
  // the air it can only be background), on the table the caller's mask says where the table is.
  if (maskRobot)
    carve = robotPixelMask(input, T_B_C, q, s.scenes, s.camera, s.options.t_hand_m,
                           s.options.carve_radius_px, /*with_table=*/inHand, &rect);
  // In the hand, pixels that are not used at all (neither fused nor carving): see unusedInHand.
  DepthImage trimmed;
  if (inHand && maskRobot && s.fuseNearHand)
    trimmed = withPixelsDropped(input, s.unusedInHand(input, carve, T_O_C, rect));
  const DepthImage& depth = trimmed.width > 0 ? trimmed : input;
  if (extraCarve) {
    if (carve.empty()) carve.assign(depth.depth_m.size(), 0);
    for (size_t i = 0; i < carve.size(); ++i)  // the caller's: a known surface (the table's)
      if ((*extraCarve)[i] && !carve[i]) carve[i] = kCarveToSurface;
  }
  // The robot's and the table's pixels on the far side of the object's silhouette only carve
  // unknown voxels (beside a measurement more than μ/2 nearer: a voxel of the object's rim can lie
  // more than μ in front of them).
  if (!carve.empty())
    farSideOfSilhouettesOnlyCarveUnknown(depth, float(s.volume.truncation() / 2), rect, &carve);
  // Silhouette pixels only carve beyond the band (ScanOptions::discontinuities_carve_only, and
  // ..._on_table for an object not held), found after the in-hand trim: the pixels beside those
  // it dropped are silhouettes too. On the table the frame also goes whole into tableVolume.
  const bool onTable = !inHand && s.options.discontinuities_carve_only_on_table &&
                       !s.options.discontinuities_carve_only;
  const std::vector<uint8_t> carveWhole = onTable ? carve : std::vector<uint8_t>();
  const DepthImage pulled =
      s.options.discontinuities_carve_only || onTable
          ? silhouettesOnlyCarve(depth, s.noise.discontinuity_jump_m, rect, &carve)
          : DepthImage();
  const DepthImage& fused = pulled.width > 0 ? pulled : depth;
  // In the hand: measurements that land where the model knows space is empty (seen through
  // before) are not the object (a stripe of wrong depth, a reflection): a frame with many of
  // them is not fused.
  if (inHand && s.options.checks.max_free_space_fraction < 1) {
    if (std::string why = s.inKnownFreeSpace(depth, carve, T_O_C); !why.empty()) {
      FrameReport r;
      r.fused = false;
      r.refusal = FrameRefusal::kInKnownFreeSpace;
      r.rejected = why;
      return r;
    }
  }
  // σ only where voxels can project, and not for pixels that only carve (integrate reads neither).
  const std::vector<float> sigma =
      measurementSigma(depth, K, s.noise, &rect, carve.empty() ? nullptr : &carve);
  integrate(fused, T_O_C, K, sigma, &s.volume, carve.empty() ? nullptr : &carve);
  if (onTable) s.fuseIntoTableVolume(depth, T_O_C, rect, carveWhole);
  if (s.camera.colour.enabled && !colour.empty())
    s.fuseColour(depth, colour, T_O_C, sigma, carve.empty() ? nullptr : &carve, q, T_B_C);
  ++s.revision;
  if (inHand && s.options.hand_mode == HandMode::kCarveAndEmpty) emptyInsideRobot(q, T_O_B);
  FrameReport r;
  r.T_B_C = T_B_C;
  countPixels(depth, carve, &r);
  ++s.summary.frames;
  if (s.viewOpen) ++s.views.back().frames;
  r.seconds = secondsSince(t0);
  s.summary.fusion_s += r.seconds;
  return r;
}

namespace {
// The image with its non-finite and negative depths set to 0 (no return); nullopt when it has
// none.
std::optional<DepthImage> withoutInvalidDepths(const DepthImage& input) {
  auto valid = [](float z) { return std::isfinite(z) && z >= 0; };
  if (std::all_of(input.depth_m.begin(), input.depth_m.end(), valid)) return std::nullopt;
  DepthImage repaired = input;
  for (float& z : repaired.depth_m)
    if (!valid(z)) z = 0;
  return repaired;
}
}  // namespace

std::string ScanSession::State::offPath(const JointVector& q) const {
  const double most = options.checks.max_path_deviation_rad;
  if (!(most > 0) || !viewOpen || viewPath.size() < 2) return "";
  const RobotModel& m = *model;
  const Eigen::VectorXd a = m.arm(q);
  double best = std::numeric_limits<double>::infinity();
  for (size_t k = 1; k < viewPath.size(); ++k) {
    const Eigen::VectorXd p = m.arm(viewPath[k - 1]), e = m.arm(viewPath[k]);
    const Eigen::VectorXd d = e - p;
    const double t =
        d.squaredNorm() > 0 ? std::clamp((a - p).dot(d) / d.squaredNorm(), 0.0, 1.0) : 0.0;
    best = std::min(best, (a - (p + t * d)).cwiseAbs().maxCoeff());
  }
  if (best <= most) return "";
  char why[160];
  std::snprintf(why, sizeof why, "joints %.3f rad off the planned path (a jump)", best);
  return why;
}

std::string ScanSession::State::notHeldIn(const DepthImage& depth, const Iso3& T_C_palm,
                                          const JointVector& q, const Iso3& T_B_C) {
  const FrameChecks& fc = options.checks;
  if (!(fc.min_support > 0) || supportPoints.empty()) return "";
  int support = 0, against = 0;
  std::tie(support, against) = supportIn(depth, T_C_palm);
  auto unsupported = [&] {
    const int counted = support + against;
    return counted >= fc.min_points && support < fc.min_support * counted;
  };
  if (unsupported()) {
    // Counted again with a point against only where nothing but the robot lies within 1 cm of it
    // (a face seen edge-on projects past its own silhouette when the pose is a pixel or two off;
    // the fingers stay where the object was when it falls).
    const std::vector<uint8_t> robot =
        robotPixelMask(depth, T_B_C, q, scenes, camera, options.t_hand_m, options.carve_radius_px);
    std::tie(support, against) = supportIn(depth, T_C_palm, &robot);
  }
  const int counted = support + against;
  if (unsupported()) {
    char why[200];
    std::snprintf(why, sizeof why,
                  "the object is not where the hand holds it (%d of %d known surface points "
                  "borne out)",
                  support, counted);
    return why;
  }
  unsupportedStreak = 0;
  return "";
}

namespace {
// Whether a pixel within 1 cm (at depth z) of (u, v), not the robot's, sees something no more
// than 2 cm behind z: a point of a face seen at a grazing angle projects beside the face's
// silhouette when the pose is a pixel or two off, and is not evidence that the object is gone.
bool surfaceBeside(const DepthImage& depth, const std::vector<uint8_t>& robot, int u, int v,
                   double z, const CameraIntrinsics& K) {
  const int r = int(std::ceil(0.01 * std::max(K.fx, K.fy) / z));
  const int u0 = std::max(0, u - r), u1 = std::min(depth.width - 1, u + r);
  const int v0 = std::max(0, v - r), v1 = std::min(depth.height - 1, v + r);
  for (int vv = v0; vv <= v1; ++vv)
    for (int uu = u0; uu <= u1; ++uu) {
      const float zz = depth.at(uu, vv);
      if (zz > 0 && zz < z + 0.02 && !robot[size_t(vv) * size_t(depth.width) + size_t(uu)])
        return true;
    }
  return false;
}
}  // namespace

std::pair<int, int> ScanSession::State::supportIn(const DepthImage& depth, const Iso3& T_C_palm,
                                                  const std::vector<uint8_t>* robot) const {
  const CameraIntrinsics& K = camera.intrinsics;
  int support = 0, against = 0;
  for (const Vec3& p_palm : supportPoints) {
    const Vec3 p = T_C_palm * p_palm;
    // Only points the sensor could measure count (nearer than its minimum range, the object
    // gives no return, and the pixel may see past its edge).
    if (p.z() < camera.min_range_m || p.z() > camera.max_range_m) continue;
    const Vec2 uv = K.project(p);
    const int u = int(std::lround(uv.x())), v = int(std::lround(uv.y()));
    if (u < 0 || v < 0 || u >= depth.width || v >= depth.height) continue;
    const float z = depth.at(u, v);
    if (!(z > 0)) continue;
    if (std::abs(z - p.z()) < 0.02)
      ++support;
    else if (z > p.z() + 0.03 && !(robot && surfaceBeside(depth, *robot, u, v, p.z(), K)))
      ++against;
  }
  return {support, against};
}

namespace {
const EnumNames<FrameRefusal, 7> kFrameRefusals = {
    {FrameRefusal::kNone, ""},
    {FrameRefusal::kDroppedOrEmpty, "dropped_or_empty"},
    {FrameRefusal::kOffPath, "off_path"},
    {FrameRefusal::kObjectMovingInHand, "object_moving_in_hand"},
    {FrameRefusal::kTracking, "tracking"},
    {FrameRefusal::kObjectNotInHand, "object_not_in_hand"},
    {FrameRefusal::kInKnownFreeSpace, "in_known_free_space"}};

// The report of a frame not fused (with the alignment's figures when tracking refused it).
FrameReport refusedFrame(FrameRefusal refusal, const std::string& why, const TrackResult* track) {
  FrameReport r;
  r.fused = false;
  r.refusal = refusal;
  r.rejected = why;
  if (track) {
    r.tracking_refusal = track->refusal;
    r.tracking_inliers = track->inliers;
    r.tracking_rms_m = track->rms_m;
  }
  return r;
}
}  // namespace

const char* frameRefusalName(FrameRefusal r) { return enumName(kFrameRefusals, r); }

FrameReport ScanSession::addFrame(const DepthImage& input, const JointVector& q,
                                  const Iso3& T_B_C) {
  if (!s_->holding) throw Error("addFrame: no grasp (beginGrasp first)");
  checkJoints(*s_->model, q, "addFrame");
  State& s = *s_;
  const RgbImage colour = std::exchange(s.nextColour, RgbImage());
  if (s.progress.frame_input) s.progress.frame_input(*this, input, q, T_B_C);
  const FrameChecks& fc = s.options.checks;
  auto refuse = [&](FrameRefusal refusal, const std::string& why,
                    const TrackResult* track = nullptr) {
    if (refusal == FrameRefusal::kObjectNotInHand && ++s.unsupportedStreak >= fc.lost_after)
      finish(Termination::kObjectLost, "in-hand frames stopped showing the object");
    ++refusedFrames(s.summary, refusal);
    log("frame not fused: " + why);
    const FrameReport r = refusedFrame(refusal, why, track);
    if (s.progress.frame) s.progress.frame(r, q, T_B_C);
    return r;
  };
  // What the sensor delivered: nothing, non-finite depths, too few returns.
  if (input.width == 0 && input.height == 0)
    return refuse(FrameRefusal::kDroppedOrEmpty, "no image (a dropped frame)");
  checkFrameSize(input, s.camera.intrinsics);
  const std::optional<DepthImage> repaired = withoutInvalidDepths(input);
  if (repaired) ++s.summary.frames_repaired;
  const DepthImage& depth = repaired ? *repaired : input;
  if (depth.validCount() < fc.min_valid_fraction * double(depth.depth_m.size()))
    return refuse(FrameRefusal::kDroppedOrEmpty,
                  "an empty frame (" + std::to_string(depth.validCount()) + " depth pixels)");
  // The reported joints must lie on the path the arm was sent along.
  if (std::string why = s.offPath(q); !why.empty()) return refuse(FrameRefusal::kOffPath, why);
  Iso3 T_B_C_used = T_B_C;
  TrackResult track;
  if (s.options.tracking.enabled) {
    if (s.confirmFrames > 0) confirmGrasp(depth, q, T_B_C);
    const std::optional<Iso3> tracked = trackedCameraPose(depth, q, T_B_C, s.T_O_palm, &track);
    const Iso3 T_C_palm = T_B_C.inverse() * s.model->tipPose(q);
    const Iso3 correction = T_C_palm.inverse() * track.correction * T_C_palm;
    const std::string jump = tracked ? s.correctionJump(correction, q) : "";
    // The object may have moved in the hand (the palm as tracked, or as the last frame had it).
    const Iso3 T_C_held = tracked && jump.empty() ? Iso3(tracked->inverse() * s.model->tipPose(q))
                                                  : Iso3(T_C_palm * s.correction);
    if (std::string why = followSlip(depth, q, T_B_C, T_C_held); !why.empty())
      return refuse(FrameRefusal::kObjectMovingInHand, why);
    if (!tracked || !jump.empty()) {
      // A frame tracking cannot align may still show that the object left the hand.
      if (std::string why = s.notHeldUnaligned(depth, T_C_held, q, T_B_C); !why.empty())
        return refuse(FrameRefusal::kObjectNotInHand, why);
      return refuse(FrameRefusal::kTracking, tracked ? jump : track.reason, &track);
    }
    T_B_C_used = *tracked;
    s.correction = correction;
    s.correctionQ = q;
  }
  // The object must be where the hand holds it.
  if (std::string why =
          s.notHeldIn(depth, T_B_C_used.inverse() * s.model->tipPose(q), q, T_B_C_used);
      !why.empty())
    return refuse(FrameRefusal::kObjectNotInHand, why);
  s.lastHeldQ = q;
  // With tracking, the robot as the frame shows it: the joint offsets that put the palm where the
  // frame says (armOffsetsFromPalmError) place the other links too (robot pixels, the space inside
  // it: Fig. 3 c); the camera where it reported itself, the palm as tracked. Without, as reported.
  const bool tracking = s.options.tracking.enabled;
  const JointVector qSeen =
      tracking ? JointVector(q + armOffsetsFromPalmError(*s.model, q, s.correction)) : q;
  const Iso3& T_B_C_seen = tracking ? T_B_C : T_B_C_used;
  const Iso3 T_O_B = s.T_O_palm * s.model->tipPose(qSeen).inverse();
  FrameReport r = fuse(depth, qSeen, T_B_C_seen, T_O_B, nullptr, true,
                       s.options.hand_mode != HandMode::kNaive, colour);
  if (!r.fused) return refuse(r.refusal, r.rejected);
  r.T_B_C = T_B_C_used;  // the camera relative to the palm at the reported joints
  r.tracking_inliers = track.inliers;
  r.tracking_hand_inliers = track.hand_inliers;
  r.tracking_hand_see_through = track.hand_see_through;
  r.tracking_rms_m = track.rms_m;
  if (s.progress.frame) s.progress.frame(r, q, T_B_C);
  return r;
}

void ScanSession::moveGrasp(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C,
                            const Iso3& T_C_palm, const TrackResult& r, Iso3 moved) {
  State& s = *s_;
  const RobotModel& m = *s.model;
  // The palm as tracked leaned towards the moved object (its model is part of the alignment):
  // the palm again from the hand alone (the model where it now lies hides the hand's points),
  // and the object's pose relative to that.
  TrackResult handOnly;
  if (const std::optional<Iso3> T_B_C_hand =
          trackedCameraPose(depth, q, T_B_C, s.T_O_palm * moved.inverse(), &handOnly)) {
    const Iso3 T_C_palm_hand = T_B_C_hand->inverse() * m.tipPose(q);
    moved = T_C_palm_hand.inverse() * r.correction * T_C_palm;
    s.correction = (T_B_C.inverse() * m.tipPose(q)).inverse() * T_C_palm_hand;
    s.correctionQ = q;
    s.jumpPending.reset();
  }
  s.moveHeldModel(m, moved);
}

std::string ScanSession::followSlip(const DepthImage& depth, const JointVector& q,
                                    const Iso3& T_B_C, const Iso3& T_C_palm) {
  State& s = *s_;
  const TrackingOptions& o = s.options.tracking;
  if (!o.enabled || !o.slip_check || s.slipPoints.size() < size_t(o.min_inliers)) return {};
  const auto t0 = Clock::now();
  // A slip is looked for within slip_gate_m (farther, the object has fallen or the alignment
  // gone wrong); while one goes on, within the tracking's own gate: an object sliding on in
  // the hand may have gone farther since the last frame that showed it.
  const double gate = std::min(o.gate_m, o.slip_gate_m);
  SlipMeasure slip = s.measureSlip(depth, q, T_B_C, T_C_palm, gate);
  if (!slip.r.ok && s.slipping && o.gate_m > gate)
    slip = s.measureSlip(depth, q, T_B_C, T_C_palm, o.gate_m);
  s.summary.tracking_s += secondsSince(t0);
  const bool graspMoved = s.slipping && !s.slipFrom.isApprox(s.T_O_palm, 1e-12);
  if (!slip.r.ok) {
    // Not aligned: while a slip that moved the grasp goes on, the frame cannot show where the
    // object is. While one is suspected (a frame before showed the object moving), a frame whose
    // points contradict every pose tried (seen through, a residual too large) does not show it
    // back where the hand holds it; one with too few points to align shows nothing either way.
    // Not fused; otherwise the frame checks decide.
    if (graspMoved || (s.slipping && slip.r.inliers >= o.min_inliers))
      return "the object moving in the hand (" + slip.r.reason + ")";
    closeSlip();
    return {};
  }
  char why[160];
  // Once a slip has moved the grasp, the frames after it refine where the object came to rest
  // (the first correction came from a model aligned with one frame): a significant correction
  // is followed, its frame not fused, for a few frames.
  if (!slip.moving && graspMoved && slip.significant && slip.surface_m > 0.25 * o.slip_m &&
      s.slipRefinements < 4) {
    ++s.slipRefinements;
    ++s.slip.frames;
    moveGrasp(depth, q, T_B_C, T_C_palm, slip.r, slip.moved);
    std::snprintf(why, sizeof why, "the object settling in the hand (its surface %.1f mm)",
                  1000 * slip.surface_m);
    return why;
  }
  if (creepConfirmed(slip, s.slipping, o, s.slipPoints, T_C_palm, &s.creepPending)) {
    moveGrasp(depth, q, T_B_C, T_C_palm, slip.r, slip.moved);  // the frame fused there
    ++s.summary.creeps_followed;
    std::snprintf(why, sizeof why, "the object crept in the hand %.1f mm; the grasp follows it",
                  1000 * slip.surface_m);
    log(why);
  }
  if (!slip.moving) {
    // At rest where the hand holds it: the event (if any) ends; this frame is fused.
    closeSlip(/*settled=*/true);
    if (graspMoved) {
      const SlipRecord& e = s.summary.slips.back();
      std::snprintf(why, sizeof why,
                    "the object at rest in the hand again: it moved %.1f mm and %.1f deg (%d "
                    "frames not fused)",
                    1000 * e.moved_m, e.turned_rad * 180 / M_PI, e.frames);
      log(why);
    }
    return {};
  }
  s.startSlip();
  // One frame alone may be a wrong alignment: the grasp moves when the next frame bears the same
  // correction out (the object now rests there in the hand, or goes on moving).
  const bool confirmed =
      s.slipPending &&
      surfaceMotion(s.slipPoints, slip.moved * s.slipPending->inverse()) < o.slip_m;
  s.slipPending = slip.moved;
  ++s.slip.frames;
  if (!confirmed) {
    std::snprintf(why, sizeof why, "the object may have moved in the hand (its surface %.1f mm)",
                  1000 * slip.surface_m);
    return why;
  }
  s.slipPending.reset();
  s.slipRefinements = 0;
  moveGrasp(depth, q, T_B_C, T_C_palm, slip.r, slip.moved);
  std::snprintf(why, sizeof why,
                "the object moved in the hand (its surface %.1f mm; the grasp corrected)",
                1000 * slip.surface_m);
  return why;
}

bool ScanSession::modelPointsNeeded(const ScanOptions& o) {
  return o.tracking.enabled || o.checks.min_support > 0;
}

void ScanSession::refreshTrackingModel(const ObjectModel* current) {
  State& s = *s_;
  const TrackingOptions& o = s.options.tracking;
  s.objectPoints.clear();
  const ObjectModel fresh = current ? ObjectModel() : planningModel();
  const ObjectModel& m = current ? *current : fresh;
  const Iso3 T_palm_O = s.T_O_palm.inverse();
  s.objectOccluders = modelOccluders(m, T_palm_O);
  s.liftOccluders.clear();  // the model changed
  // The frame checks' points: measured vertices, at most about 2000.
  s.supportPoints.clear();
  size_t measured = 0;
  for (uint8_t f : m.observed) measured += f != 0;
  const size_t every2 = std::max<size_t>(1, measured / 2000 + 1);
  for (size_t k = 0, seen = 0; k < m.mesh.vertices.size(); ++k)
    if (m.observed[k] && seen++ % every2 == 0)
      s.supportPoints.push_back(T_palm_O * m.mesh.vertices[k].cast<double>());
  if (s.options.tracking.enabled)
    s.objectPoints = observedSurface(m, o.max_object_points, T_palm_O);
  s.slipPoints.clear();
  if (o.enabled && o.slip_check)
    s.slipPoints = observedSurface(m, std::max(o.slip_points, o.max_object_points), T_palm_O);
}

std::optional<Iso3> ScanSession::trackedCameraPose(const DepthImage& depth, const JointVector& q,
                                                   const Iso3& T_B_C, const Iso3& T_O_palm,
                                                   TrackResult* result) {
  State& s = *s_;
  if (!s.options.tracking.enabled) return T_B_C;
  const auto t0 = Clock::now();
  const RobotModel& m = *s.model;
  // The hand's surface in the palm frame at the fingers' joints, rebuilt when they change: built
  // with the arm at home, so that it does not depend on the arm's joints (not even in rounding).
  const JointVector atHome = m.withArm(q, m.arm(m.home()));
  if (s.handPointsQ.size() != q.size() || (s.handPointsQ - atHome).cwiseAbs().maxCoeff() > 1e-6) {
    s.handPoints = evenSurfaceSamples(HandGeometry(m, atHome, Iso3::Identity()).mesh(),
                                      s.options.tracking.hand_spacing_m);
    s.handPointsQ = atHome;
  }
  std::vector<SurfacePoint> objectPoints;
  std::vector<Vec3> occluders;
  // The rest of the robot hides the hand as the hand hides itself (at the reported joints: near
  // the hand the arm's error relative to it is small).
  if (s.linkSamples.empty()) {
    s.linkSamples.resize(m.links().size());
    for (size_t li = 0; li < m.links().size(); ++li) {
      if (std::find(m.handLinks().begin(), m.handLinks().end(), int(li)) != m.handLinks().end())
        continue;
      for (const Primitive& p : m.links()[li].collision)
        for (const SurfacePoint& sp : evenSurfaceSamples(p.toMesh(), 0.01))
          s.linkSamples[li].push_back(sp.p);
    }
  }
  {
    const std::vector<Iso3> T_B_link = m.linkPoses(q);
    const Iso3 T_palm_B = m.tipPose(q).inverse();
    for (size_t li = 0; li < s.linkSamples.size(); ++li)
      for (const Vec3& p : s.linkSamples[li]) occluders.push_back(T_palm_B * (T_B_link[li] * p));
  }
  // The model's points are in the palm frame of the grasp they were made for.
  if ((T_O_palm.matrix() - s.T_O_palm.matrix()).cwiseAbs().maxCoeff() < 1e-9) {
    objectPoints = s.objectPoints;
    occluders.insert(occluders.end(), s.objectOccluders.begin(), s.objectOccluders.end());
  } else {
    // Another grasp (a pick-up's check): the model is not aligned with the hand there (the
    // object may sit elsewhere in it), but it still hides the hand's points behind it, which
    // would otherwise pair with the object's depths.
    if (s.liftOccluders.empty() || !s.liftOccludersFor.isApprox(T_O_palm, 1e-12)) {
      s.liftOccluders = modelOccluders(planningModel(), T_O_palm.inverse());
      s.liftOccludersFor = T_O_palm;
    }
    occluders.insert(occluders.end(), s.liftOccluders.begin(), s.liftOccluders.end());
  }
  const Iso3 T_C_palm = T_B_C.inverse() * m.tipPose(q);
  // Start from the last frame's error (it changes slowly along a trajectory), carried in the
  // palm frame.
  std::vector<Iso3> starts = {Iso3::Identity()};
  if (!s.correction.isApprox(Iso3::Identity(), 1e-9))
    starts.push_back(T_C_palm * s.correction * T_C_palm.inverse());
  TrackResult r =
      alignToDepth(depth, s.camera.intrinsics, s.handPoints, objectPoints, occluders, T_C_palm,
                   starts, axialSigma(s.noise, T_C_palm.translation().z(), 0), s.options.tracking);
  if (s.options.tracking.filter) filterCorrection(q, T_C_palm, &r);
  s.summary.tracking_s += secondsSince(t0);
  if (result) *result = r;
  if (!r.ok) return std::nullopt;
  return T_B_C * r.correction.inverse();
}

std::optional<Iso3> ScanSession::registerHeldObject(const DepthImage& depth,
                                                    const std::vector<uint8_t>& robot_mask,
                                                    const JointVector& q, const Iso3& T_B_C,
                                                    const Iso3& T_O_palm, TrackResult* result) {
  State& s = *s_;
  checkJoints(*s.model, q, "registerHeldObject");
  if (robot_mask.size() != depth.depth_m.size())
    throw Error("registerHeldObject: the robot mask does not match the image");
  const auto t0 = Clock::now();
  const RegistrationModel reg = registrationModel(planningModel(), s.options.tracking);
  const Iso3 T_C_palm = T_B_C.inverse() * s.model->tipPose(q);
  const Iso3 T_C_O = T_C_palm * T_O_palm.inverse();
  const TrackResult r =
      alignBodyToDepth(depth, robot_mask, s.camera.intrinsics, reg.points, reg.occluders, T_C_O,
                       axialSigma(s.noise, T_C_O.translation().z(), 0), s.options.tracking,
                       UncoveredPull::kAfterConverging, NoDepthPixels::kUnknown);
  s.summary.tracking_s += secondsSince(t0);
  if (result) *result = r;
  if (!r.ok) return std::nullopt;
  return (r.correction * T_C_O).inverse() * T_C_palm;
}

std::vector<std::pair<std::optional<Iso3>, TrackResult>> ScanSession::registerObjectAt(
    const DepthImage& depth, const std::vector<uint8_t>& hidden, const Iso3& T_B_C,
    const std::vector<Iso3>& starts, bool in_hand) {
  State& s = *s_;
  if (hidden.size() != depth.depth_m.size())
    throw Error("registerObjectAt: the hidden mask does not match the image");
  const auto t0 = Clock::now();
  auto out =
      registerModelAt(registrationModel(planningModel(), s.options.tracking), depth, hidden, T_B_C,
                      s.camera.intrinsics, s.noise, s.options.tracking, starts, in_hand);
  s.summary.tracking_s += secondsSince(t0);
  return out;
}

void ScanSession::filterCorrection(const JointVector& q, const Iso3& T_C_palm, TrackResult* r) {
  State& s = *s_;
  const TrackingOptions& o = s.options.tracking;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  // Predict: a random walk, wider the more the joints moved (the arm's error depends on its
  // configuration) and a little every frame.
  if (!s.filterStarted) {
    s.filterX.setZero();  // the reported pose, give or take 0.1 rad and 5 cm
    s.filterP.setZero();
    s.filterP.diagonal() << Vec6(0.01, 0.01, 0.01, 0.0025, 0.0025, 0.0025);
    s.filterStarted = true;
  } else {
    const double moved = (s.model->arm(q) - s.model->arm(s.filterQ)).norm();
    const double rot = o.frame_drift_rad + o.drift_rad * moved;
    const double trans = o.frame_drift_m + o.drift_m * moved;
    s.filterP.diagonal().head<3>().array() += rot * rot;
    s.filterP.diagonal().tail<3>().array() += trans * trans;
  }
  s.filterQ = q;
  if (!r->ok) return;
  // The frame's alignment as a measurement of the palm-frame correction: camera-frame parameters
  // about the palm are blockdiag(R, R) times the palm-frame ones (R: the palm's rotation).
  const Iso3 C = T_C_palm.inverse() * r->correction * T_C_palm;
  const Eigen::AngleAxisd aa(C.linear());
  Vec6 z;
  z.head<3>() = aa.angle() * aa.axis();
  z.tail<3>() = C.translation();
  Mat6 G = Mat6::Zero();
  G.topLeftCorner<3, 3>() = T_C_palm.linear();
  G.bottomRightCorner<3, 3>() = T_C_palm.linear();
  const Mat6 info = o.pair_information * (G.transpose() * r->information * G);
  const Mat6 priorInfo = s.filterP.inverse();
  const Mat6 posterior = priorInfo + info;
  const Eigen::LDLT<Mat6> solve(posterior);
  s.filterX = solve.solve(priorInfo * s.filterX + info * z);
  s.filterP = solve.solve(Mat6::Identity());
  // Fused with the filtered correction.
  Iso3 F = Iso3::Identity();
  const Vec3 w = s.filterX.head<3>();
  if (w.norm() > 1e-12) F.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  F.translation() = s.filterX.tail<3>();
  r->correction = T_C_palm * F * T_C_palm.inverse();
}

FrameReport ScanSession::addFrameOfObjectAt(const DepthImage& depth, const JointVector& q,
                                            const Iso3& T_B_C, const Iso3& T_B_O,
                                            const std::vector<uint8_t>* carve,
                                            bool carve_includes_robot) {
  checkJoints(*s_->model, q, "addFrameOfObjectAt");
  const RgbImage colour = std::exchange(s_->nextColour, RgbImage());
  return fuse(depth, q, T_B_C, T_B_O.inverse(), carve, false, !(carve && carve_includes_robot),
              colour);
}

void ScanSession::setColourOfNextFrame(RgbImage colour) {
  const CameraIntrinsics& K = s_->camera.colour.intrinsics;
  if (!colour.empty() && (colour.width != K.width || colour.height != K.height))
    throw Error("colour image is " + std::to_string(colour.width) + "x" +
                std::to_string(colour.height) + ", the colour camera's intrinsics say " +
                std::to_string(K.width) + "x" + std::to_string(K.height));
  s_->nextColour = std::move(colour);
}

std::optional<PlannedView> ScanSession::nextView(const JointVector& q_now) {
  State& s = *s_;
  if (!s.holding) throw Error("nextView: no grasp (beginGrasp first)");
  checkJoints(*s.model, q_now, "nextView");
  if (s.viewOpen) finishView();
  const RobotModel& m = *s.model;
  const GraspState g{s.T_O_palm, q_now};
  // The initial trajectory: directions spread over the sphere, each move from where the arm is
  // kept clear of the object in the hand (a forearm swinging through it would also empty its
  // inside in the model).
  if (std::optional<PlannedView> v =
          s.initialView(g, [this](const std::string& line) { log(line); }))
    return v;
  if (s.alg1Views >= s.options.max_views) {
    finish(Termination::kMaxViews,
           "the grasp's view limit (" + std::to_string(s.options.max_views) + ") is reached");
    return std::nullopt;
  }
  const ObjectModel model = planningModel();
  const auto tp = Clock::now();
  const ViewSelection sel = s.planner.select(model, g, s.used, s.nearHand, &s.volume);
  s.summary.planning_s += secondsSince(tp);
  s.summary.view_evaluations += sel.evaluated;
  s.summary.view_refinements += sel.refined;
  if (!sel.best) {
    const std::string none =
        "no view reaches t_q (" + std::to_string(sel.evaluated) + " candidates)";
    if (sel.reachable == 0)
      finish(Termination::kNoReachableView, "the arm reaches no view with this grasp");
    else
      finish(Termination::kNoViewAboveThreshold, none);
    log(none + ": done");
    return std::nullopt;
  }
  const ViewCandidate& c = *sel.best;
  ++s.alg1Views;
  PlannedView v;
  v.dir_O = c.dir_O;
  v.T_O_C = c.T_O_C;
  v.waypoints = {q_now, m.withArm(q_now, c.arm)};
  v.quality = c.quality;
  v.cost_s = c.cost_s;
  v.score = c.score;
  v.candidates = sel.evaluated;
  v.planning_s = sel.total_s;
  ViewRecord rec;
  rec.dir_O = c.dir_O;
  rec.T_O_C = c.T_O_C;
  rec.quality = c.quality;
  rec.gain = c.gain;
  rec.t_q = sel.t_q;
  rec.cost_s = c.cost_s;
  rec.score = c.score;
  rec.candidates = sel.evaluated;
  rec.planning_s = sel.total_s;
  s.openView(rec, v.waypoints);
  char line[240];
  std::snprintf(line, sizeof(line),
                "view %d: quality %.4f, cost %.2f s, %d candidates, %d at full resolution (%.2f "
                "s: IK %.2f, quality %.2f)",
                s.alg1Views, rec.quality, rec.cost_s, rec.candidates, sel.refined, rec.planning_s,
                sel.ik_s, sel.quality_s);
  log(line);
  return v;
}

const ViewRecord& ScanSession::finishView() {
  State& s = *s_;
  if (s.views.empty()) throw Error("finishView: no view");
  ViewRecord& rec = s.views.back();
  if (!s.viewOpen) return rec;
  s.viewOpen = false;
  // The volume's colours: the frames' (model()) are for the model handed out, not for these
  // figures.
  const ObjectModel after = s.extracted(s.full, s.options.mesh);
  if (modelPointsNeeded(s.options)) refreshTrackingModel(&after);
  s.trackingFromFull = true;
  rec.mean_entropy = after.meanEntropy();
  rec.unresolved = after.unresolvedInformation(axialSigma(s.noise, s.options.planner.range_m, 0.0));
  rec.observed_fraction = after.observedAreaFraction();
  if (s.progress.coverage) rec.coverage = s.progress.coverage(after);
  char line[160];
  std::snprintf(line, sizeof(line), "%s %zu: %d frames, mean entropy %.3f",
                rec.initial ? "initial view" : "view", s.views.size(), rec.frames,
                rec.mean_entropy);
  log(line);
  ++s.summary.views;
  return rec;
}

GraspPlan ScanSession::planGrasps(const Iso3& T_B_O_rest, const JointVector& q_now) {
  checkJoints(*s_->model, q_now, "planGrasps");
  State& s = *s_;
  if (s.viewOpen) finishView();
  GraspPlan plan;
  const ObjectModel S_obj = planningModel();
  // Candidates are ranked by eq. 9 (the ranking planner) whatever the view planner is, so its
  // own t_q decides; a baseline view planner's threshold is in other units.
  plan.model_area_m2 = S_obj.mesh.area();
  plan.t_q = viewThreshold(s.multi.ranking, plan.model_area_m2);
  char line[240];
  std::vector<double> viewBounds;  // each view's eq. 9 with no hand, for the ranking too
  {
    // No grasp can promise more than the best view with no hand at all: below t_q, neither
    // generating nor ranking candidates can change the decision.
    ViewQualityScene scene = s.ranker.qualityScene(S_obj);
    const double bound = s.ranker.graspQualityBound(scene, &viewBounds);
    if (bound < plan.t_q) {
      std::snprintf(line, sizeof(line),
                    "no grasp candidate promises a view above t_q: no view of the model does, "
                    "even without the hand (best %.5f < t_q %.5f)",
                    bound, plan.t_q);
      log(line);
      finish(Termination::kNoGraspAboveThreshold, line);
      return plan;
    }
  }
  // The pinch poses' footprint: the model's measured surface (its hole-filled parts left out).
  std::vector<Vec3> measured;
  for (size_t i = 0; i < S_obj.mesh.vertices.size(); ++i)
    if (i < S_obj.observed.size() && S_obj.observed[i])
      measured.push_back(S_obj.mesh.vertices[i].cast<double>());
  plan.generation =
      generateGrasps(*s.model, S_obj.mesh, T_B_O_rest, q_now, s.multi.grasp, &measured);
  const GraspGeneration& gen = plan.generation;
  std::snprintf(line, sizeof(line),
                "grasp candidates: %d poses, %d touching, %d stable, %d clear of the table, %zu "
                "reachable (%.2f s)",
                gen.tried, gen.touching, gen.stable, gen.table_free, gen.candidates.size(),
                gen.seconds);
  log(line);
  plan.candidates = std::move(plan.generation.candidates);
  plan.generation.candidates.clear();
  if (plan.candidates.empty()) {
    finish(Termination::kNoReachableGrasp,
           "no grasp candidate is stable, clear of the table and reachable");
    return plan;
  }
  plan.ranking_s = rankGrasps(s.ranker, S_obj, s.multi.grasp, &plan.candidates,
                              /*reference=*/false, &viewBounds);
  const GraspCandidate& best = plan.candidates.front();
  std::snprintf(line, sizeof(line), "ranked %zu grasps in %.2f s: best quality %.4f, ε %.4f",
                plan.candidates.size(), plan.ranking_s, best.quality, best.epsilon);
  log(line);
  const double t_q = plan.t_q;
  while (plan.above_threshold < int(plan.candidates.size()) &&
         plan.candidates[plan.above_threshold].quality >= t_q)
    ++plan.above_threshold;
  if (plan.above_threshold == 0) {
    std::snprintf(line, sizeof(line),
                  "no grasp candidate promises a view above t_q (best %.5f < t_q %.5f)",
                  best.quality, t_q);
    finish(Termination::kNoGraspAboveThreshold, line);
    return plan;
  }
  // Among those above t_q, the ones that hold the model in physics first (grasp/hold_test.h).
  std::vector<GraspCandidate> usable(plan.candidates.begin(),
                                     plan.candidates.begin() + plan.above_threshold);
  plan.hold_s = rankByHold(*s.model, S_obj.mesh, T_B_O_rest, nullptr, s.multi.grasp.friction,
                           s.multi.grasp.hold, &usable);
  std::move(usable.begin(), usable.end(), plan.candidates.begin());
  log(holdLine(plan.candidates, plan.hold_s));
  return plan;
}

std::optional<GraspCandidate> ScanSession::nextGrasp(const Iso3& T_B_O_rest,
                                                     const JointVector& q_now) {
  GraspPlan plan = planGrasps(T_B_O_rest, q_now);
  if (plan.above_threshold == 0) return std::nullopt;
  return plan.candidates.front();
}

ObjectModel ScanSession::model() const {
  ObjectModel m = s_->extracted(s_->full, s_->options.mesh);
  // The volume's colours serve the scan between views; the model handed out takes its colours
  // from the frames kept, where they saw it.
  if (s_->colour && s_->colourFrames && !s_->colourFrames->empty()) {
    Summary& sum = s_->summary;
    m.rgba = vertexColours(*s_->colourFrames, *s_->colour, m.mesh,
                           s_->camera.colour.light_at_camera, &sum.colour_shading_falloff);
    sum.colour_frames_kept = int(s_->colourFrames->frames());
    sum.colour_frames_mb = double(s_->colourFrames->bytes()) / (1 << 20);
  }
  return m;
}

ObjectModel ScanSession::planningModel() const {
  MeshOptions planningMesh = s_->options.mesh;
  planningMesh.stride = s_->options.planning_stride;
  planningMesh.method = s_->options.planning_method;
  return s_->extracted(s_->planning, planningMesh);
}

void ScanSession::finish(Termination termination, const std::string& message) {
  s_->summary.termination = termination;
  s_->summary.message = message.empty() ? terminationName(termination) : message;
}

ScanSession::Summary ScanSession::summary() const {
  Summary out = s_->summary;
  out.payload = s_->payload.estimate();  // nullopt before any reading
  return out;
}

void ScanSession::addJointTorques(const JointVector& q, const JointVector& tau) {
  if (!s_->holding) return;
  s_->addTorques({q, tau, s_->T_O_palm});
}

void ScanSession::addJointTorques(const JointVector& q, const TorqueSamples& rest) {
  if (!s_->holding || rest.count() < 1) return;
  s_->addTorques({q, rest.mean(), s_->T_O_palm, rest.count(), rest.scatter_nm2()});
}

void ScanSession::Summary::copyTo(ScanResult* r) const {
  r->view_evaluations = view_evaluations;
  r->view_refinements = view_refinements;
  r->planning_s = planning_s;
  r->fusion_s = fusion_s;
  r->tracking_s = tracking_s;
  r->colour_pixels = colour_pixels;
  r->colour_s = colour_s;
  r->colour_frames_kept = colour_frames_kept;
  r->colour_frames_mb = colour_frames_mb;
  r->colour_shading_falloff = colour_shading_falloff;
  r->frames = frames;
  r->frames_rejected = frames_rejected;
  r->frames_dropped = frames_dropped;
  r->frames_off_path = frames_off_path;
  r->frames_unsupported = frames_unsupported;
  r->frames_repaired = frames_repaired;
  r->frames_in_free_space = frames_in_free_space;
  r->frames_moving = frames_moving;
  r->creeps_followed = creeps_followed;
  r->slips = slips;
  r->payload = payload;
}

std::string ScanSession::Summary::brief() const {
  char line[240];
  std::snprintf(line, sizeof(line),
                "%s: %d grasps, %d views, %d frames (planning %.2f s, fusion %.2f s)",
                terminationName(termination).c_str(), grasps, views, frames, planning_s, fusion_s);
  return line;
}

// The checkpoint: "INHAND-SESSION 1\n", the JSON header's byte count and newline, the header,
// then the volume's data: with "encoding": "runs" in the header's volume, TsdfVolume::writeData's
// (the states as runs, the non-zero sums as spans); without it (older checkpoints), the three
// arrays whole (sumWD, sumW as float32, states as uint8), little-endian.
namespace {
constexpr char kMagic[] = "INHAND-SESSION 1\n";

}  // namespace

namespace {
// A checkpoint's records (read back by load: State::readTorques, viewRecordFrom,
// readSummaryCounts).
Json torqueJson(const TorqueReading& r) {
  return {{"q", vectorJson(r.q)},
          {"tau", vectorJson(r.tau)},
          {"T_O_palm", isoJson(r.T_O_palm)},
          {"samples", r.samples},
          {"scatter_nm2", r.scatter_nm2}};
}
Json checkpointSummaryJson(const ScanSession::Summary& m) {
  return {{"termination", terminationName(m.termination)},
          {"message", m.message},
          {"grasps", m.grasps},
          {"views", m.views},
          {"frames", m.frames},
          {"frames_rejected", m.frames_rejected},
          {"frames_dropped", m.frames_dropped},
          {"frames_off_path", m.frames_off_path},
          {"frames_unsupported", m.frames_unsupported},
          {"frames_in_free_space", m.frames_in_free_space},
          {"frames_moving", m.frames_moving},
          {"creeps_followed", m.creeps_followed},
          {"slips", slipsJson(m.slips)},
          {"frames_repaired", m.frames_repaired},
          {"tracking_s", m.tracking_s},
          {"view_evaluations", m.view_evaluations},
          {"view_refinements", m.view_refinements},
          {"planning_s", m.planning_s},
          {"fusion_s", m.fusion_s},
          {"colour_pixels", m.colour_pixels},
          {"colour_s", m.colour_s},
          {"colour_frames_kept", m.colour_frames_kept},
          {"colour_frames_mb", m.colour_frames_mb},
          {"colour_shading_falloff", m.colour_shading_falloff}};
}
}  // namespace

void ScanSession::save(const std::filesystem::path& path, const Json& extra) const {
  const State& s = *s_;
  if (s.viewOpen) throw Error("save: finish the current view first (finishView)");
  Json h;
  const TsdfVolume& v = s.volume;
  h["volume"] = {{"dims", {v.dims().x(), v.dims().y(), v.dims().z()}},
                 {"origin", vecJson(v.origin())},
                 {"voxel_m", v.voxelSize()},
                 {"truncation_m", v.truncation()},
                 {"encoding", "runs"}};
  h["centre"] = vecJson(s.centre);
  h["holding"] = s.holding;
  h["grasp"] = s.grasp;
  h["T_O_palm"] = isoJson(s.T_O_palm);
  h["q_grasp"] = Json::array();
  for (int i = 0; i < s.qGrasp.size(); ++i) h["q_grasp"].push_back(s.qGrasp[i]);
  h["object_box"] = {vecJson(s.objectBox.min), vecJson(s.objectBox.max)};
  for (const Vec3& d : s.used) h["used"].push_back(vecJson(d));
  for (const Vec3& d : s.initialDirs) h["initial_dirs"].push_back(vecJson(d));
  h["alg1_views"] = s.alg1Views;
  h["tracking_correction"] = isoJson(s.correction);  // the last frame's arm error (palm frame)
  if (s.correctionQ) h["tracking_correction_q"] = vectorJson(*s.correctionQ);
  if (s.jumpPending) h["tracking_jump_pending"] = isoJson(*s.jumpPending);
  if (s.filterStarted) {
    h["tracking_filter"]["x"] = std::vector<double>(s.filterX.data(), s.filterX.data() + 6);
    h["tracking_filter"]["P"] = std::vector<double>(s.filterP.data(), s.filterP.data() + 36);
    h["tracking_filter"]["q"] = vectorJson(s.filterQ);
  }
  h["tracking_from_full_model"] = s.trackingFromFull;
  h["unsupported_streak"] = s.unsupportedStreak;
  for (const TorqueReading& r : s.torqueReadings) h["torque_readings"].push_back(torqueJson(r));
  for (size_t i = 0; i < s.views.size(); ++i) {
    Json v = viewRecordJson(s.views[i]);
    v["grasp"] = s.viewGrasp[i];
    h["views"].push_back(std::move(v));
  }
  h["summary"] = checkpointSummaryJson(s.summary);
  if (!extra.is_null()) h["extra"] = extra;
  // The colours (camera.colour): after the voxels, one record per coloured voxel in index order
  // (its index, then Σw, Σw·r, Σw·g, Σw·b as floats).
  std::vector<std::pair<size_t, ColourVolume::Sum>> colours;
  if (s.colour) colours = s.colour->entries();
  if (s.colour) h["colour_voxels"] = colours.size();
  if (s.colourFrames) h["colour_frames"] = s.colourFrames->frames();
  const std::string header = h.dump();
  writeFileAtomically(path, [&](const fs::path& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    f << kMagic << header.size() << "\n" << header;
    v.writeData(f);
    for (const auto& [i, c] : colours) {
      const uint64_t index = i;
      const float sums[4] = {c.w, c.r, c.g, c.b};
      f.write(reinterpret_cast<const char*>(&index), sizeof index);
      f.write(reinterpret_cast<const char*>(sums), sizeof sums);
    }
    if (s.colourFrames) s.colourFrames->write(f);
    if (!f) throw Error(path.string() + ": cannot write the checkpoint");
  });
}

namespace {

// The checkpoint's volume (its header's "volume", `dims` voxels) is the options' `v`; else an
// error naming both.
void checkVolumeMatches(const std::filesystem::path& path, const Json& vj, const Vec3i& dims,
                        const TsdfVolume& v) {
  if (v.dims() != dims || std::abs(v.voxelSize() - vj.at("voxel_m").get<double>()) > 1e-12 ||
      (v.origin() - vecFrom(vj.at("origin"))).norm() > 1e-9)
    throw Error(path.string() + ": the checkpoint's volume (" + std::to_string(dims.x()) + "x" +
                std::to_string(dims.y()) + "x" + std::to_string(dims.z()) + " voxels of " +
                std::to_string(vj.at("voxel_m").get<double>()) + " m) differs from the options' (" +
                std::to_string(v.dims().x()) + "x" + std::to_string(v.dims().y()) + "x" +
                std::to_string(v.dims().z()) + " voxels of " + std::to_string(v.voxelSize()) +
                " m)");
}

// A checkpoint's colour frames (after the colour sums), kept within the options' budget.
std::unique_ptr<ColourFrames> readColourFrames(
    std::istream& f, const ScanOptions& o, const std::function<Error(const std::string&)>& bad) {
  auto frames = std::make_unique<ColourFrames>(size_t(o.colour_frames_mb * 1024 * 1024));
  if (std::string problem = frames->read(f); !problem.empty()) throw bad(problem);
  return frames;
}

// A checkpoint's voxel data after its header `h` (save's layout): the volume's, then the colour
// sums of the voxels that have them.
void readVolumeData(std::istream& f, const Json& h, TsdfVolume& v,
                    std::unique_ptr<ColourVolume>* colour,
                    const std::function<Error(const std::string&)>& bad) {
  const std::string encoding = h.at("volume").value("encoding", std::string("raw"));
  if (encoding == "runs") {
    if (std::string problem = v.readData(f); !problem.empty()) throw bad(problem);
  } else if (encoding == "raw") {
    const size_t n = v.voxelCount();
    if (!f.read(reinterpret_cast<char*>(v.sumWD()), std::streamsize(n * sizeof(float))) ||
        !f.read(reinterpret_cast<char*>(v.sumW()), std::streamsize(n * sizeof(float))) ||
        !f.read(reinterpret_cast<char*>(v.states()), std::streamsize(n)))
      throw bad("voxel data cut short");
    for (size_t i = 0; i < n; ++i)
      if (v.states()[i] > uint8_t(VoxelState::kObserved)) throw bad("invalid voxel state");
  } else {
    throw bad("unknown volume encoding \"" + encoding + "\"");
  }
  if (h.contains("colour_voxels")) {
    const size_t n = h.at("colour_voxels").get<size_t>();
    *colour = std::make_unique<ColourVolume>(v);
    for (size_t k = 0; k < n; ++k) {
      uint64_t index = 0;
      float sums[4];
      if (!f.read(reinterpret_cast<char*>(&index), sizeof index) ||
          !f.read(reinterpret_cast<char*>(sums), sizeof sums))
        throw bad("colour data cut short");
      if (index >= v.voxelCount()) throw bad("colour voxel index out of the volume");
      (*colour)->set(size_t(index), {sums[0], sums[1], sums[2], sums[3]});
    }
  }
}

// A checkpoint's "summary" counters and times (its termination aside).
void readSummaryCounts(const Json& m, ScanSession::Summary* sum) {
  sum->message = m.at("message").get<std::string>();
  sum->grasps = m.at("grasps").get<int>();
  sum->views = m.at("views").get<int>();
  sum->frames = m.at("frames").get<int>();
  sum->frames_rejected = m.value("frames_rejected", 0);
  sum->frames_dropped = m.value("frames_dropped", 0);
  sum->frames_off_path = m.value("frames_off_path", 0);
  sum->frames_unsupported = m.value("frames_unsupported", 0);
  sum->frames_in_free_space = m.value("frames_in_free_space", 0);
  sum->frames_moving = m.value("frames_moving", 0);
  sum->creeps_followed = m.value("creeps_followed", 0);
  if (m.contains("slips")) sum->slips = slipsFrom(m.at("slips"));
  sum->frames_repaired = m.value("frames_repaired", 0);
  sum->tracking_s = m.value("tracking_s", 0.0);
  sum->view_evaluations = m.at("view_evaluations").get<int>();
  sum->view_refinements = m.at("view_refinements").get<int>();
  sum->planning_s = m.at("planning_s").get<double>();
  sum->fusion_s = m.at("fusion_s").get<double>();
  sum->colour_pixels = m.value("colour_pixels", 0L);
  sum->colour_s = m.value("colour_s", 0.0);
  sum->colour_frames_kept = m.value("colour_frames_kept", 0);
  sum->colour_frames_mb = m.value("colour_frames_mb", 0.0);
  sum->colour_shading_falloff = m.value("colour_shading_falloff", 0.0);
}

}  // namespace

void ScanSession::State::readTrackingFilter(const Json& h,
                                            const std::function<Error(const std::string&)>& bad) {
  if (h.contains("tracking_correction")) correction = isoFrom(h.at("tracking_correction"));
  if (h.contains("tracking_correction_q")) {
    const Json& cq = h.at("tracking_correction_q");
    if (!cq.is_array() || cq.size() != size_t(model->variableCount()))
      throw bad("tracking_correction_q must hold one value per joint");
    JointVector v(Eigen::Index(cq.size()));
    for (size_t i = 0; i < cq.size(); ++i) v[Eigen::Index(i)] = cq[i].get<double>();
    correctionQ = v;
  }
  if (h.contains("tracking_jump_pending")) jumpPending = isoFrom(h.at("tracking_jump_pending"));
  filterStarted = h.contains("tracking_filter");
  if (filterStarted) {
    const Json& f = h.at("tracking_filter");
    const auto x = f.at("x").get<std::vector<double>>();
    const auto P = f.at("P").get<std::vector<double>>();
    const auto fq = f.at("q").get<std::vector<double>>();
    if (x.size() != 6 || P.size() != 36 || int(fq.size()) != model->variableCount())
      throw bad("tracking_filter: " + std::to_string(x.size()) + " values in x, " +
                std::to_string(P.size()) + " in P, " + std::to_string(fq.size()) +
                " joints (6, 36 and the robot's)");
    filterX = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(x.data());
    filterP = Eigen::Map<const Eigen::Matrix<double, 6, 6>>(P.data());
    filterQ = Eigen::Map<const Eigen::VectorXd>(fq.data(), Eigen::Index(fq.size()));
  }
}

void ScanSession::State::readTorques(const Json& h) {
  for (const Json& r : h.value("torque_readings", Json::array())) {
    addTorques({vectorFrom(r.at("q")), vectorFrom(r.at("tau")), isoFrom(r.at("T_O_palm")),
                r.value("samples", 1), r.value("scatter_nm2", 0.0)});
  }
}

ScanSession ScanSession::load(const std::filesystem::path& path, const RobotModel& robot,
                              const DepthCameraOptions& camera, const NoiseModelOptions& noise,
                              const ScanOptions& options, const MultiGraspOptions& multi,
                              Json* extra) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(path.string() + ": cannot open the checkpoint");
  auto bad = [&](const std::string& what) {
    return Error(path.string() + ": not a scan checkpoint (" + what + ")");
  };
  char magic[sizeof(kMagic) - 1];
  if (!f.read(magic, sizeof(magic)) || std::memcmp(magic, kMagic, sizeof(magic)) != 0)
    throw bad("no INHAND-SESSION 1 header");
  size_t bytes = 0;
  if (!(f >> bytes) || f.get() != '\n' || bytes > (64u << 20)) throw bad("header size");
  std::string text(bytes, '\0');
  if (!f.read(text.data(), std::streamsize(bytes))) throw bad("header cut short");
  Json h;
  try {
    h = Json::parse(text);
    const Json& vj = h.at("volume");
    const Vec3i dims(vj.at("dims").at(0).get<int>(), vj.at("dims").at(1).get<int>(),
                     vj.at("dims").at(2).get<int>());
    const Vec3 centre = vecFrom(h.at("centre"));
    ScanSession session(robot, camera, noise, options, multi, centre);
    State& s = *session.s_;
    TsdfVolume& v = s.volume;
    ++s.revision;
    checkVolumeMatches(path, vj, dims, v);
    readVolumeData(f, h, v, &s.colour, bad);
    if (h.contains("colour_frames")) s.colourFrames = readColourFrames(f, s.options, bad);
    s.holding = h.at("holding").get<bool>();
    s.grasp = h.at("grasp").get<int>();
    s.T_O_palm = isoFrom(h.at("T_O_palm"));
    s.objectBox = Aabb();
    s.objectBox.extend(vecFrom(h.at("object_box").at(0)));
    s.objectBox.extend(vecFrom(h.at("object_box").at(1)));
    for (const Json& d : h.value("used", Json::array())) s.used.push_back(vecFrom(d));
    for (const Json& d : h.value("initial_dirs", Json::array()))
      s.initialDirs.push_back(vecFrom(d));
    s.alg1Views = h.at("alg1_views").get<int>();
    for (const Json& r : h.value("views", Json::array())) {
      s.views.push_back(viewRecordFrom(r));
      s.viewGrasp.push_back(r.at("grasp").get<int>());
    }
    const Json& m = h.at("summary");
    if (!parseTermination(m.at("termination").get<std::string>(), &s.summary.termination))
      throw bad("unknown termination " + m.at("termination").get<std::string>());
    readSummaryCounts(m, &s.summary);
    s.readTrackingFilter(h, bad);
    const Json& qj = h.at("q_grasp");
    if (s.grasp >= 0 && qj.size() != size_t(robot.variableCount()))
      throw Error(path.string() + ": the checkpoint's joint state has " +
                  std::to_string(qj.size()) + " values, the robot " +
                  std::to_string(robot.variableCount()));
    s.qGrasp = JointVector::Zero(Eigen::Index(qj.size()));
    for (size_t i = 0; i < qj.size(); ++i) s.qGrasp[Eigen::Index(i)] = qj[i].get<double>();
    if (s.holding) {  // the grasp's near-hand grid, rebuilt from the hand as it holds
      s.buildNearHand(robot, s.qGrasp, s.T_O_palm);
    }
    // Tracking's object points as they were (from the model after the last view, or the
    // planning model when the grasp began).
    s.trackingFromFull = h.value("tracking_from_full_model", false);
    s.unsupportedStreak = h.value("unsupported_streak", 0);
    s.readTorques(h);
    if (s.holding && modelPointsNeeded(options)) {
      if (s.trackingFromFull) {
        const ObjectModel m = session.model();
        session.refreshTrackingModel(&m);
      } else {
        session.refreshTrackingModel();
      }
    }
    if (extra) *extra = h.value("extra", Json());
    return session;
  } catch (const Json::exception& e) {
    throw bad(e.what());
  }
}

}  // namespace inhand
