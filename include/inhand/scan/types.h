#pragma once
// The scan's own types: its options (ScanOptions, MultiGraspOptions, TableTopOptions), the
// records it keeps (views, slips, pick-up attempts, grasps, the table-top stage), how it ends
// (Termination) and what it hands back (ScanResult, MultiGraspResult). The session
// (scan/session.h) and the drivers over it (scan/scan.h, scan/multi_grasp.h) share them.
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/core/options.h"
#include "inhand/grasp/grasp.h"
#include "inhand/mesh/extract.h"
#include "inhand/planning/view_selection.h"
#include "inhand/robot/payload.h"
#include "inhand/robot/robot_interface.h"
#include "inhand/robot/robot_scenes.h"
#include "inhand/scan/tracking.h"
#include "inhand/sensor/depth_sensor.h"
#include "inhand/volume/integrate.h"

namespace inhand {

// How measurements near the robot's own hand are used (paper Fig. 3).
enum class HandMode {
  kNaive,          // (a) all measurements add surface
  kCarveOnly,      // (b) measurements within t_hand of the robot only carve free space
  kCarveAndEmpty,  // (c) as (b), and voxels inside the hand are marked empty
};
inline constexpr EnumNames<HandMode, 3> kHandModeNames = {
    {HandMode::kNaive, "naive"},
    {HandMode::kCarveOnly, "carve"},
    {HandMode::kCarveAndEmpty, "carve-empty"}};
std::string handModeName(HandMode m);
bool parseHandMode(const std::string& s, HandMode* out);

// Why a scan (or one grasp's views) ended.
enum class Termination {
  kRunning,                  // not ended
  kNoViewAboveThreshold,     // no reachable view reaches t_q (Alg. 1)
  kMaxViews,                 // the grasp's view limit
  kNoReachableView,          // the arm reaches no view with this grasp
  kMaxGrasps,                // the grasp limit
  kRegraspUnsupported,       // the robot cannot put the object down
  kNoReachableGrasp,         // no grasp candidate is stable, clear of the table and reachable
  kNoGraspAboveThreshold,    // no candidate promises a view above t_q
  kPickUpFailed,             // no candidate picked the object up and held it (first grasp)
  kObjectOutOfView,          // the camera cannot aim at the rest pose
  kObjectNotFound,           // too few points above the table near the rest pose
  kObjectTooLargeForHand,    // the open hand spans none of its extents
  kObjectTooLargeForVolume,  // larger than options.volume_size_m
  kNoStableGrasp,            // no first-grasp pose is force closure
  kInterrupted,              // the caller stopped it (ScanProgress::interrupted, e.g. SIGINT)
  kObjectLost,               // in-hand frames stopped showing the object where the hand held it
  kRegraspFailed,            // a re-grasp's pick-ups failed (grasp.max_failed_pick_ups)
};
// snake_case names as summary.json writes them (no_view_above_threshold, …; running).
std::string terminationName(Termination t);
bool parseTermination(const std::string& s, Termination* out);

// What ScanSession::addFrame refuses to fuse, as real sensors and arms deliver it now and then.
// A refused frame is counted (Summary) and reported (FrameReport::rejected); the scan goes on.
struct FrameChecks {
  // An empty image (0 x 0) is a dropped frame; non-finite or negative depths are no return.
  double min_valid_fraction = 0.002;  // fewer valid pixels than this: an empty frame
  // Reported joints farther than this (rad, any arm joint) from the view's planned path: a
  // jump in the joint states, not a pose to fuse with (0: no check).
  double max_path_deviation_rad = 0.05;
  // The object must be where the hand holds it: of the model's measured surface points in view
  // (at least min_points of them), the fraction the frame bears out (within 2 cm; against: seen
  // more than 3 cm behind) must reach min_support, or the frame is not fused; lost_after such
  // frames in a row end the grasp's views with object_lost (0: no check). A frame tracking
  // cannot align is checked where the last aligned frame held the object.
  double min_support = 0.2;
  int min_points = 100;
  int lost_after = 3;
  // Of the frame's depth pixels (every 2nd row and column, not the robot's) that land in the
  // volume, at most this fraction may land where the model knows space is empty (seen through
  // before), or the frame is not fused (1: no check).
  double max_free_space_fraction = 0.2;

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.num("min_valid_fraction", o.min_valid_fraction,
          "fewer valid depth pixels than this fraction: an empty frame", Range::closedOpen(0, 1));
    v.num("max_path_deviation_rad", o.max_path_deviation_rad,
          "joints farther from the planned path: a jump, not fused (0: no check), rad",
          Range::atLeast(0));
    v.num("min_support", o.min_support,
          "the model's points in view the frame must bear out, or the object is not in the hand "
          "(0: no check)",
          Range::closed(0, 1));
    v.integer("min_points", o.min_points, "… when at least this many are in view",
              Range::atLeast(1));
    v.integer("lost_after", o.lost_after, "that many such frames in a row: object_lost",
              Range::atLeast(1));
    v.num("max_free_space_fraction", o.max_free_space_fraction,
          "at most this fraction of a frame's depth in the volume where the model knows space is "
          "empty (1: no check)",
          Range::openClosed(0, 1));
  }
  std::string validate() const;
};

struct ScanOptions {
  double voxel_m = 0.002;       // volume voxel size, m
  double volume_size_m = 0.34;  // edge of the cubic volume around the grasped object, m
  // From the table (scanFromTable): fit the volume to the object seen there, a cube of 1.5 times
  // its largest extent + 4 cm (at most volume_size_m) with as many voxels across as
  // volume_size_m / voxel_m (the same cost; finer voxels for smaller objects).
  bool fit_volume = true;
  // Joint-torque readings (RobotInterface::jointTorques) taken in a row at the end of each view,
  // the arm holding still, that weigh the object (PayloadEstimator): their noise averages down
  // as 1/√N. 500: a second of a WAM's 500 Hz.
  int torque_readings = 500;
  double t_hand_m = 0.01;   // measurements this close to the robot only carve (§IV), m
  int carve_radius_px = 2;  // … this close to it in the image, too (lateral noise), pixels
  // In the hand, a pixel next to one farther by more than this, or beside a gap of no return
  // whose first return across it is that much farther or missing, is not fused (a silhouette:
  // its return may come from across the edge); 0: off. m
  double edge_jump_m = 0.02;
  // Every frame's silhouette pixels (depthDiscontinuities at the noise model's
  // discontinuity_jump_m) only carve, beyond the band (kCarveBeyondBand): a return there may come
  // from across the edge (lateral noise, a mixed pixel), and fused, even with the noise model's
  // larger σ, it grows flakes beyond the object's edges wherever no other frame measures the edge
  // head-on. Off by default: on thin objects (a 12 mm pen) the slip check then finds slips that
  // did not happen (docs/volume.md). false: fused with that larger σ.
  bool discontinuities_carve_only = false;
  // The same for the frames of an object that is not held (addFrameOfObjectAt: the table-top
  // frames). The camera looks down on it from about a metre and grazes its sides: returns at its
  // silhouette lie millimetres beyond its edges, and where the hand later covers an edge in
  // every view (a grasp on it) nothing measures it head-on and they stay as flakes.
  bool discontinuities_carve_only_on_table = true;
  // With a colour camera: memory for the colour frames kept (ColourFrames), from which the
  // model's colours come where they saw it (at the colour camera's resolution, head-on views
  // first); 0: colours from the volume's voxels only. MiB
  double colour_frames_mb = 64;
  HandMode hand_mode = HandMode::kCarveAndEmpty;
  int initial_views = 4;    // the simple initial trajectory: this many directions
  int max_views = 20;       // Alg. 1 views per grasp at most (after the initial ones)
  int planning_stride = 2;  // S_obj for planning from every n-th voxel (output: full res)
  // S_obj for planning by surface nets (a fifth of the triangles to ray cast; output: tetrahedra)
  SurfaceMethod planning_method = SurfaceMethod::kSurfaceNets;
  ViewPlannerOptions planner;
  TrackingOptions tracking;  // in-hand frames aligned with hand and model (arm error, §II)
  FrameChecks checks;        // in-hand frames that are not fused
  MeshOptions mesh;
  // Memory budget, truncation, the reach behind each measurement and depth smoothing (voxel size
  // above wins). Scans and `inhand fuse` keep thin walls: band_sigmas 2 behind each pixel's
  // smoothed surface, voxels updated from it (docs/volume.md).
  VolumeOptions volume_budget = [] {
    VolumeOptions o;
    o.band_sigmas = 2.0;
    o.smooth_depth = true;
    return o;
  }();

  // The options' rows (core/options.h), the volume's among them (volume_budget's voxel size is
  // voxel_m's).
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.num("voxel_m", o.voxel_m, "volume voxel size, m", Range::open(0, 0.05));
    v.num("volume_size_m", o.volume_size_m, "edge of the cubic volume (over 10 voxels), m",
          Range::open(0, 2));
    v.num("truncation_m", o.volume_budget.truncation_m,
          "half-width μ of the signed-distance band (at least a voxel; 0: 4 voxels), m",
          Range::closedOpen(0, 0.1));
    v.num("band_sigmas", o.volume_budget.band_sigmas,
          "a measurement reaches this many of its σ behind its smoothed surface (at least a voxel "
          "across the surface, at most μ), so that both sides of a thin wall are kept; 0: μ "
          "behind its depth",
          Range::closed(0, 100));
    v.boolean("smooth_depth", o.volume_budget.smooth_depth,
              "update the voxels from each pixel's surface smoothed over its 5×5 neighbourhood "
              "(a fitted plane) rather than from its raw depth");
    v.num("memory_budget_mb", o.volume_budget.memory_budget_mb,
          "a volume needing more memory than this is refused, MiB", Range::above(0));
    v.boolean("fit_volume", o.fit_volume,
              "from the table: a cube of 1.5 × the object's extent + 4 cm, as many voxels across");
    v.integer("torque_readings", o.torque_readings,
              "joint-torque readings at rest after each view that weigh the object (noise 1/√N)",
              Range::closed(1, 100000));
    v.num("t_hand_m", o.t_hand_m, "measurements this close to the robot only carve (§IV), m",
          Range::atLeast(0));
    v.integer("carve_radius_px", o.carve_radius_px, "… or this close to it in the image, pixels",
              Range::closed(0, 10));
    v.num("edge_jump_m", o.edge_jump_m,
          "in the hand, a pixel next to one farther by more than this, or beside a gap of no "
          "return whose far side is that much farther or missing, is not fused (a silhouette); "
          "0: off, m",
          Range::closedOpen(0, 1));
    v.boolean("discontinuities_carve_only", o.discontinuities_carve_only,
              "silhouette pixels (a 4-neighbour, or the first return across a gap of no return, "
              "farther by more than the sensor's discontinuity_jump_m) only carve, in every "
              "frame: their return may come from across the edge");
    v.boolean("discontinuities_carve_only_on_table", o.discontinuities_carve_only_on_table,
              "… in the frames of the object not held (on the table): seen from afar, its sides "
              "graze, and an edge the hand covers later is never measured head-on");
    v.num("colour_frames_mb", o.colour_frames_mb,
          "with a colour camera: memory for the colour frames the model's colours come from "
          "(head-on views first, at the camera's resolution); 0: from the voxels only, MiB",
          Range::closed(0, 65536));
    v.choice("hand_mode", o.hand_mode, kHandModeNames,
             "the robot's own measurements (Fig. 3 a, b, c)");
    v.integer("initial_views", o.initial_views, "directions of the initial trajectory",
              Range::atLeast(0));
    v.integer("max_views", o.max_views, "Alg. 1 views per grasp at most", Range::atLeast(0));
    v.integer("planning_stride", o.planning_stride, "S_obj for planning from every n-th voxel",
              Range::closed(1, 4));
    v.choice("planning_mesh", o.planning_method, kSurfaceMethodNames, "S_obj for planning");
    v.object("planner", "the view planner (Alg. 1)",
             [&](auto& p) { ViewPlannerOptions::fields(p, o.planner); });
    v.object("tracking", "in-hand frames aligned with the hand and the model (arm error, §II)",
             [&](auto& t) { TrackingOptions::fields(t, o.tracking); });
    v.object("checks", "in-hand frames that are not fused (docs/reliability.md)",
             [&](auto& k) { FrameChecks::fields(k, o.checks); });
    v.object("mesh", "the model's surface", [&](auto& m) { MeshOptions::fields(m, o.mesh); });
  }
  std::string validate() const;
};

struct ViewRecord {
  bool initial = false;  // part of the initial trajectory (not chosen by Alg. 1)
  Vec3 dir_O = Vec3::Zero();
  Iso3 T_O_C = Iso3::Identity();  // the chosen camera pose in the object frame
  double quality = 0, cost_s = 0, score = 0;
  // eq. 9 gain the planner predicted for the view (nats·m²; for a baseline, computed under the
  // relative rule) and the threshold in force; NaN when unknown (initial views).
  double gain = std::numeric_limits<double>::quiet_NaN();
  double t_q = std::numeric_limits<double>::quiet_NaN();
  // Information the model leaves unresolved after the view (ObjectModel::unresolvedInformation at
  // the sensor's σ at the view range), nats·m²: the drop from the view before is the realised
  // gain, in eq. 9's units.
  double unresolved = 0;
  double mean_entropy = 0;  // of the model after the view's frames
  double observed_fraction = 0;
  double coverage = -1;  // of the true surface after the view (ScanProgress::coverage), −1: unknown
  int frames = 0;        // depth frames fused along the way
  int candidates = 0;    // quality evaluations in the Alg. 1 pass that chose it
  double planning_s = 0;
};

// The object moved in the hand during a grasp's views (TrackingOptions::slip_check): found in
// the frames, the grasp corrected from then on.
struct SlipRecord {
  int grasp = 0, view = 0;  // 0-based; the view counted over every grasp
  // The motion of the model in the hand from the last frame that showed it at rest to the first
  // that showed it at rest again: RMS over its observed points, and the turn.
  double moved_m = 0, turned_rad = 0;
  int frames = 0;        // frames not fused while it moved
  bool settled = false;  // a frame showed it at rest again (false: the views ended first)
};

// Slip records in summary.json and checkpoints (moved_mm, turned_deg); slipsFrom throws Error on
// a malformed list.
Json slipsJson(const std::vector<SlipRecord>& slips);
std::vector<SlipRecord> slipsFrom(const Json& j);

// Why an in-hand frame was not fused (FrameReport::refusal): no image or too few depth pixels,
// the joints off the planned path, the object moving in the hand, tracking could not align it,
// the object not where the hand holds it, depth where the model knows space is empty.
enum class FrameRefusal {
  kNone,
  kDroppedOrEmpty,
  kOffPath,
  kObjectMovingInHand,
  kTracking,
  kObjectNotInHand,
  kInKnownFreeSpace
};
inline constexpr FrameRefusal kEveryFrameRefusal[] = {
    FrameRefusal::kTracking,         FrameRefusal::kDroppedOrEmpty,
    FrameRefusal::kOffPath,          FrameRefusal::kObjectNotInHand,
    FrameRefusal::kInKnownFreeSpace, FrameRefusal::kObjectMovingInHand};
// "", "dropped_or_empty", "off_path", "object_moving_in_hand", "tracking", "object_not_in_hand",
// "in_known_free_space": the keys of summary.json's frames_not_fused.
const char* frameRefusalName(FrameRefusal r);
// The counter of frames refused for `r` in a record that keeps them (ScanSession::Summary,
// ScanResult): frames_dropped, frames_off_path, frames_moving, frames_rejected (tracking),
// frames_unsupported, frames_in_free_space.
template <class Counts>
auto& refusedFrames(Counts& c, FrameRefusal r) {
  switch (r) {
    case FrameRefusal::kDroppedOrEmpty:
      return c.frames_dropped;
    case FrameRefusal::kOffPath:
      return c.frames_off_path;
    case FrameRefusal::kObjectMovingInHand:
      return c.frames_moving;
    case FrameRefusal::kTracking:
      return c.frames_rejected;
    case FrameRefusal::kObjectNotInHand:
      return c.frames_unsupported;
    case FrameRefusal::kInKnownFreeSpace:
    case FrameRefusal::kNone:
      break;
  }
  return c.frames_in_free_space;
}

// What one added frame did.
struct FrameReport {
  bool fused = true;  // false: not fused (`refusal` says why, `rejected` in words)
  FrameRefusal refusal = FrameRefusal::kNone;
  TrackRefusal tracking_refusal = TrackRefusal::kNone;  // the alignment's, when it refused
  std::string rejected;
  int pixels = 0;        // valid depth pixels
  int carve_pixels = 0;  // of those, only carving (the robot's own where the volume is in view,
                         // or the caller's mask)
  Iso3 T_B_C = Iso3::Identity();  // the camera pose it was fused with (tracked, or as given)
  int tracking_inliers = 0;       // points aligned with the frame (tracking)
  int tracking_hand_inliers = 0, tracking_hand_see_through = 0;  // of the hand's
  double tracking_rms_m = 0;
  double seconds = 0;
};

struct ScanResult {
  ObjectModel model;           // final S_obj, object frame
  ObjectModel planning_model;  // the same at the planning stride (what Alg. 1 would see next)
  std::vector<ViewRecord> views;
  Termination termination = Termination::kRunning;
  int view_evaluations = 0;  // candidates scored by Alg. 1 (coarse pre-screen or full)
  int view_refinements = 0;  // of those, scored at full resolution
  double planning_s = 0, fusion_s = 0, total_s = 0;
  double tracking_s = 0;   // aligning in-hand frames (ScanOptions::tracking), apart from fusion_s
  long colour_pixels = 0;  // pixels whose colour was fused (camera.colour)
  double colour_s = 0;     // … the time that took (part of fusion_s)
  // The colour frames kept for the model's colours and the shading fall-off fitted to them
  // (ColourFrames).
  int colour_frames_kept = 0;
  double colour_frames_mb = 0, colour_shading_falloff = 0;
  // The object's weight from the arm's joint torques at rest (its centre of mass in O), when
  // the robot reports torques (ScanSession::addJointTorques).
  std::optional<PayloadEstimate> payload;
  int frames = 0;
  // In-hand frames not fused (ScanSession::Summary): tracking could not align them; dropped or
  // empty; joints off the planned path; the object not in the hand. And frames repaired.
  int frames_rejected = 0, frames_dropped = 0, frames_off_path = 0, frames_unsupported = 0,
      frames_repaired = 0, frames_in_free_space = 0;
  int frames_moving = 0;    // not fused: the object moved in the hand (TrackingOptions::slip_check)
  int creeps_followed = 0;  // grasp corrections for creep (TrackingOptions::creep_m)
  std::vector<SlipRecord> slips;
};

// The volume a scan centred at centre_O uses.
TsdfVolume makeScanVolume(const Vec3& centre_O, const ScanOptions& options);

// The table-top stage (paper §V): the object starts on the table, unknown.
struct TableTopOptions {
  int frames = 3;              // depth frames taken of it there (fused; the table hides the bottom)
  double aim_height_m = 0.05;  // the camera aims this far above the rest pose's origin, m
  double search_radius_m = 0.25;  // object points lie within this of the rest pose (horizontal), m
  double above_table_m = 0.008;   // … and at least this far above the fitted table plane, m
  double cluster_cell_m = 0.01;   // the object is the largest cluster at this linking cell, m
  int min_points = 200;           // fewer object points than this: object_not_found
  PlaneFitOptions plane;          // RANSAC of the table plane
  // The first grasp's model (candidates and hold test) clipped to the points' upright rectangle
  // (TableTopObject::region_O); off: to their axis-aligned box (the candidates' 2 cm out).
  bool footprint_region = false;
  // The hold test alone takes the model clipped to that rectangle (the candidates as
  // footprint_region says). The model's filled-in space beside the far faces slopes down to the
  // table, and a finger closing on that slope presses the model into the table; the rectangle,
  // 5 mm out, cuts part of that slope, not all of it (docs/physics.md).
  bool footprint_hold_test = false;
  // The first grasp's model (candidates and hold test) keeps the space the camera did not see
  // only beneath measured surface, along the table's normal: the far faces stand straight down
  // from the edges seen from above, where by default the filled-in space slopes from them to the
  // table (the camera's shadow) and fingers close on that slope.
  bool under_measured_only = true;
  // … and, with it, the first this many candidates that held that model are brought in against
  // the model with all the unseen space kept and tried from where it stops them
  // (preferHoldingUnseen): the first that holds so goes first. 0: not checked (measured at 4 on
  // the physics test set and not kept: docs/physics.md).
  int unseen_hold_checked = 0;
  // The finished model aligned once more with the first frame of the object where it rested
  // (frame O is that pose; the in-hand frames may have turned the model as a whole, where a
  // grasp's pose was taken a few degrees off), and moved by the result where that moves its
  // surface more than reanchor_gap_m on average (surfaceGap); below it, the alignment is not
  // told from the frame's noise and bias.
  bool reanchor = true;
  double reanchor_gap_m = 0.001;

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.integer("frames", o.frames, "depth frames of the object where it rests",
              Range::closed(1, 30));
    v.num("aim_height_m", o.aim_height_m, "the camera aims this far above the rest pose, m",
          Range::closed(-0.5, 0.5));
    v.num("search_radius_m", o.search_radius_m, "object points within this of the rest pose, m",
          Range::open(0, 2));
    v.num("above_table_m", o.above_table_m, "… and this far above the fitted table plane, m",
          Range::open(0, 0.1));
    v.num("cluster_cell_m", o.cluster_cell_m, "the object: the largest cluster at this cell, m",
          Range::open(0, 0.1));
    v.integer("min_points", o.min_points, "fewer object points: object_not_found",
              Range::atLeast(3));
    v.num("plane_inlier_m", o.plane.inlier_m, "RANSAC: a point this close supports a plane, m",
          Range::open(0, 0.05));
    v.integer("plane_iterations", o.plane.iterations, "RANSAC hypotheses", Range::atLeast(1));
    v.num("plane_max_tilt_deg", o.plane.max_tilt_deg,
          "RANSAC: planes tilted more from the table's normal lose, degrees",
          Range::openClosed(0, 90));
    v.boolean("footprint_region", o.footprint_region,
              "the first grasp's model clipped to the points' upright rectangle, 5 mm out (off: "
              "to their axis-aligned box)");
    v.boolean("footprint_hold_test", o.footprint_hold_test,
              "the hold test alone takes the first grasp's model clipped to the points' upright "
              "rectangle, 5 mm out");
    v.boolean("under_measured_only", o.under_measured_only,
              "the first grasp's model keeps unseen space only beneath measured surface (along "
              "the table's normal): far faces straight down from the edges seen from above, not "
              "sloping to the table");
    v.integer("unseen_hold_checked", o.unseen_hold_checked,
              "… and the first this many candidates that held are brought in against the model "
              "with all unseen space kept and tried from where it stops them: the first that "
              "holds so goes first (0: not checked)",
              Range::closed(0, 48));
    v.boolean("reanchor", o.reanchor,
              "the finished model aligned again with the first frame of the object where it "
              "rested");
    v.num("reanchor_gap_m", o.reanchor_gap_m,
          "… and moved by that alignment where it moves its surface more than this on average, m",
          Range::closed(0, 0.05));
  }
  std::string validate() const;
};

// What became of a pick-up attempt: it held after the lift (picked), the hand met nothing
// (no_contact), the fingers closed on nothing (empty_hand), the lift's frame did not show it in
// the hand (dropped), a second frame after the hand held still showed it moving in the hand or
// gone (slid: GraspOptions::settle_s).
enum class PickOutcome { kPicked, kNoContact, kEmptyHand, kDropped, kSlid };
// "picked", "no_contact", "empty_hand", "dropped", "slid" (summary.json's and checkpoints' names).
const char* pickOutcomeName(PickOutcome o);
bool parsePickOutcome(const std::string& name, PickOutcome* out);  // false: not one of them

// One pick-up attempt: the candidate tried and what became of it.
struct PickAttempt {
  PickOutcome outcome = PickOutcome::kPicked;
  int rank = 0;          // the candidate's place in the ranking it was tried from (0: the first)
  int pose = -1;         // its index among the poses generated (GraspCandidate::pose)
  int hold_test = -1;    // the hold test's verdict on the model: 1 held, 0 not, -1 untested
  int hold_margin = -1;  // … and with its margin (GraspCandidate::hold_margin)
  int hold_unseen = -1;  // … and from where the unseen space stops the hand (GraspCandidate)
  double hold_close_m = -1;  // … how far its close pushed the model (GraspCandidate)
  // Where it failed the hold test (HoldTrial::failure; kNone when it held or was not tested).
  HoldFailure hold_failure = HoldFailure::kNone;
  bool palm_contact = false;  // enveloping (the palm touches) or fingertips only
  double epsilon = 0;         // its force-closure ε
  bool pinch = false;         // a pinch pose (GraspCandidate::pinch)
  // After the lift: how far the object sat in the hand from the planned grasp (−1: not seen).
  double shift_m = -1;
  // When the outcome was decided (seconds since the scan's session began), what the lift's frame
  // bore out of the object's points where the hand holds it and where it rested (−1: none in
  // view, or no lift), and what decided it (a sentence).
  double at_s = -1;
  double lift_in_hand = -1, lift_on_table = -1;
  std::string evidence;
  // The grasp: the palm in the object's frame, and the hand's joints (by URDF name) as it came
  // in (the preshape) and as planned closed on the model. Absent from records of older scans.
  std::optional<Iso3> T_O_palm;
  std::vector<std::pair<std::string, double>> preshape, closed;
};
Json attemptsJson(const std::vector<PickAttempt>& attempts);
// Throws Error on a malformed list; a list of outcome strings (older checkpoints) is read too.
std::vector<PickAttempt> attemptsFrom(const Json& j);
int countOutcome(const std::vector<PickAttempt>& attempts, PickOutcome outcome);

// What the table-top stage saw and chose.
struct TableTopRecord {
  int frames = 0;
  int points = 0;         // measured points near the rest pose
  int table_inliers = 0;  // of those, on the fitted plane
  int object_points = 0;  // above it
  Plane table_O;          // the fitted table plane, frame O
  PrincipalAxes axes;     // of the object points, frame O
  // First-grasp candidates (generateGrasps on the table-top model): poses tried, those whose
  // closed hand touches with two links or more, of those force closure, clear of the table, and
  // reachable; then the pick-up attempts in order (picked, no_contact, empty_hand, dropped, slid).
  int tried = 0, touching = 0, stable = 0, table_free = 0, reachable = 0;
  std::vector<GraspPoseRecord> poses;     // every pose tried and what became of it
  double volume_size_m = 0, voxel_m = 0;  // the volume as fitted to the object
  std::vector<PickAttempt> attempts;
  double seconds = 0;
  // The finished model aligned with the first table-top frame (TableTopOptions::reanchor): found
  // (the alignment passed its checks; `reason` where not), how far it moved the model's surface
  // (surfaceGap) and the motion (shift of frame O's origin, turn), applied or not.
  struct Reanchor {
    bool tried = false, found = false, applied = false;
    double gap_m = 0, shift_m = 0, turn_rad = 0;
    std::string reason;
  } reanchor;
};

struct MultiGraspOptions {
  int max_grasps = 3;  // grasps in all (1: the single-grasp scan)
  TableTopOptions table_top;
  GraspOptions grasp;
  // Alg. 1 as used to rank grasp candidates: coarser than the view planner's (fewer directions
  // and rolls, every 4th pixel), since it runs once per candidate.
  ViewPlannerOptions ranking = defaultRankingPlanner();
  int keep_ranked = 12;  // candidates kept per grasp in its record (for the report)
  static ViewPlannerOptions defaultRankingPlanner();

  // The options' rows (core/options.h); Alg. 1's ranking options are grasp.ranking.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.integer("max_grasps", o.max_grasps, "grasps in all (1: no re-grasping)",
              Range::closed(1, 50));
    v.integer("keep_ranked", o.keep_ranked,
              "ranked candidates kept per grasp in its record (the report)", Range::atLeast(0));
    v.object("table_top", "the table-top stage",
             [&](auto& t) { TableTopOptions::fields(t, o.table_top); });
    v.object("grasp", "grasp candidates and their ranking", [&](auto& g) {
      GraspOptions::fields(g, o.grasp);
      g.object("ranking", "Alg. 1 as used to rank grasp candidates",
               [&](auto& p) { ViewPlannerOptions::fields(p, o.ranking); });
    });
  }
  std::string validate() const;
};

// A ranked candidate as the report shows it.
struct RankedGrasp {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;  // hand closed to contact
  double quality = 0, epsilon = 0;
};

struct GraspRecord {
  Iso3 T_O_palm = Iso3::Identity();
  JointVector q;  // the robot's joints when the grasp's views began (hand as it holds the object)
  int candidates = 0;  // ranked candidates this grasp was chosen from (0: the first grasp)
  int tried = 0;       // candidate poses tried
  double quality = 0;  // its best view quality when ranked
  double t_q = 0;      // the threshold that quality passed (relative rule: scaled by the area)
  double model_area_m2 = 0;                         // of the planning model it was ranked on
  double epsilon = 0;                               // its stability (Ferrari–Canny ε)
  int views = 0;                                    // views taken with it
  Termination termination = Termination::kRunning;  // why its views ended
  double views_ended_at_s = -1;                     // when (seconds since the scan's session began)
  double hole_area_m2 = 0;  // σ = 5 cm (unknown) area of the model after its views
  double mean_entropy = 0;  // of the model after its views
  double generation_s = 0, ranking_s = 0;
  std::vector<RankedGrasp> ranked;    // the best candidates it was chosen from, best first
  std::vector<PickAttempt> attempts;  // pick-up attempts, the last the one that held
  ObjectModel model;                  // the model after its views (at the planning stride)
};

struct MultiGraspResult {
  ScanResult scan;  // views of all grasps, model, timings; termination of the whole scan
  std::vector<GraspRecord> grasps;
  // The grasp planning that led to no further grasp (no candidate above t_q, none reachable or
  // none picked up): its time is in no GraspRecord.
  double unused_generation_s = 0, unused_ranking_s = 0;
  // The attempts of a re-grasp that never held (regrasp_failed, object_lost): no GraspRecord
  // carries them.
  std::vector<PickAttempt> failed_regrasp_attempts;
  // After each put-down, the residual (RMS, m) of the model registered where the object rests.
  std::vector<double> refind_residuals_m;
  std::optional<TableTopRecord> table_top;  // when the scan began with the object on the table
};

}  // namespace inhand
