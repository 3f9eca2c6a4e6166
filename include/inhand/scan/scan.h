#pragma once
// The autonomous scan against the robot and sensor interfaces (nothing here sees simulator state):
// the object is held at a known grasp; a simple initial trajectory, then Alg. 1 view after view
// until no view reaches t_q or a view limit; every depth frame along every trajectory is fused
// with the pose the robot reports (T_O_C = T_O_palm · T_palm_B(q) · T_B_C), hand-aware (§IV).
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/mesh/extract.h"
#include "inhand/planning/view_selection.h"
#include "inhand/robot/robot_interface.h"
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
std::string handModeName(HandMode m);
bool parseHandMode(const std::string& s, HandMode* out);

struct ScanCheckpoint;
class ScanSession;

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
  // frames in a row end the grasp's views with object_lost (0: no check).
  double min_support = 0.2;
  int min_points = 100;
  int lost_after = 3;
  // Of the frame's depth pixels (every 2nd row and column, not the robot's) that land in the
  // volume, at most this fraction may land where the model knows space is empty (seen through
  // before), or the frame is not fused (1: no check).
  double max_free_space_fraction = 0.2;
  std::string validate() const;
};

struct ScanOptions {
  double voxel_m = 0.002;       // volume voxel size, m
  double volume_size_m = 0.34;  // edge of the cubic volume around the grasped object, m
  // From the table (scanFromTable): fit the volume to the object seen there, a cube of 1.5 times
  // its largest extent + 4 cm (at most volume_size_m) with as many voxels across as
  // volume_size_m / voxel_m (the same cost; finer voxels for smaller objects).
  bool fit_volume = true;
  double t_hand_m = 0.01;   // measurements this close to the robot only carve (§IV), m
  int carve_radius_px = 2;  // … this close to it in the image, too (lateral noise), pixels
  // In the hand, a pixel next to one farther by more than this is not fused (a silhouette: its
  // return may come from across the edge); 0: off. m
  double edge_jump_m = 0.02;
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

// What one added frame did.
struct FrameReport {
  bool fused = true;  // false: tracking could not align it (not fused; `rejected` says why)
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

struct ScanProgress {
  std::function<void(const std::string&)> log;  // one line per event (may be empty)
  // Ground-truth coverage of a model (set when the object's true mesh is known): recorded in
  // each view's record after its frames.
  std::function<double(const ObjectModel&)> coverage;
  // Each in-hand frame as ScanSession::addFrame handled it, with the joints and the camera pose
  // it was given (may be empty).
  std::function<void(const FrameReport&, const JointVector& q, const Iso3& T_B_C)> frame;
  // Each in-hand frame as given to ScanSession::addFrame, before any check: what a robot
  // delivers, for recording it (`inhand scan --save-frames`). May be empty.
  std::function<void(const ScanSession&, const DepthImage&, const JointVector& q,
                     const Iso3& T_B_C)>
      frame_input;
  // Asked before each step and at every frame: true ends the scan at the next frame with
  // Termination::kInterrupted and the model so far (frames after it are not fused). For a
  // SIGINT handler's flag; may be empty.
  std::function<bool()> interrupted;
  // Called at every point a scan can resume from (scan/checkpoint.h): when a grasp's views begin
  // and after each view. May be empty.
  std::function<void(const ScanCheckpoint&)> checkpoint;
  bool stopRequested() const { return interrupted && interrupted(); }
};

struct ScanResult {
  ObjectModel model;           // final S_obj, object frame
  ObjectModel planning_model;  // the same at the planning stride (what Alg. 1 would see next)
  std::vector<ViewRecord> views;
  Termination termination = Termination::kRunning;
  int view_evaluations = 0;  // candidates scored by Alg. 1 (coarse pre-screen or full)
  int view_refinements = 0;  // of those, scored at full resolution
  double planning_s = 0, fusion_s = 0, total_s = 0;
  double tracking_s = 0;  // aligning in-hand frames (ScanOptions::tracking), apart from fusion_s
  int frames = 0;
  // In-hand frames not fused (ScanSession::Summary): tracking could not align them; dropped or
  // empty; joints off the planned path; the object not in the hand. And frames repaired.
  int frames_rejected = 0, frames_dropped = 0, frames_off_path = 0, frames_unsupported = 0,
      frames_repaired = 0, frames_in_free_space = 0;
  int frames_moving = 0;  // not fused: the object moved in the hand (TrackingOptions::slip_check)
  std::vector<SlipRecord> slips;
};

// Scans with the object held at T_O_palm (palm pose in the object frame); the robot must be
// holding it already: a ScanSession around centre_O (the object's expected centre) driven by
// runGraspViews. `object_box_O`: where the object is believed to lie before any model exists (the
// initial trajectory keeps the arm clear of it); empty: a 10 cm cube around centre_O.
ScanResult scanSingleGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm,
                           const Vec3& centre_O, const ScanOptions& options,
                           const NoiseModelOptions& noise, const ScanProgress& progress = {},
                           const Aabb& object_box_O = Aabb());

// The robot's depth image from T_B_C with the robot at q (and with_table its table) over the
// pixels of `window` (clipped to the image; 0 elsewhere): its links' triangles rasterised at the
// pixel centres, the nearest surface kept where it lies in the camera's range and faces it at under
// 89°. The depth renderDepth gives casting a ray per pixel (noise-free, no projector shadows) but
// for pixels on the silhouettes' edges, at a fraction of the cost.
DepthImage robotDepthImage(const RobotOccluders& robotScenes, const JointVector& q,
                           const Iso3& T_B_C, const DepthCameraOptions& camera, bool with_table,
                           const PixelRect& window);

// The pixels of `depth` (taken from T_B_C with the robot at q) that are the robot's own surface:
// the robot's depth (robotDepthImage) lies within t_hand_m of the measurement, at that pixel or
// within radius_px of it (the sensor's lateral noise moves returns across its silhouette). With
// with_table the robot config's table counts as the robot's (as in the air, where it only carves).
// With `region` only its pixels are classified (0 elsewhere; the robot is rendered there and
// radius_px around it), e.g. volumeImageRect: the pixels fusion reads.
std::vector<uint8_t> robotPixelMask(const DepthImage& depth, const Iso3& T_B_C,
                                    const JointVector& q, const RobotOccluders& robotScenes,
                                    const DepthCameraOptions& camera, double t_hand_m,
                                    int radius_px, bool with_table = true,
                                    const PixelRect* region = nullptr);

// The volume a scan centred at centre_O uses.
TsdfVolume makeScanVolume(const Vec3& centre_O, const ScanOptions& options);

}  // namespace inhand
