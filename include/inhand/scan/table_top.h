#pragma once
// The table-top stage (paper §V) in steps a driver of one's own can call: find the object resting
// on the table in a few depth frames, fit the volume to it, mark the table's pixels (they only
// carve), and make the first grasp candidates on what the frames show. scanFromTable is these
// steps over a ScanSession.
#include <vector>

#include "inhand/scan/session.h"

namespace inhand {

// What the table-top frames show.
struct TableTopObject {
  // kRunning: found; else kObjectNotFound, kObjectTooLargeForHand or kObjectTooLargeForVolume.
  Termination problem = Termination::kRunning;
  Plane table_O;                 // the fitted table plane, frame O
  std::vector<Vec3> points_O;    // the object's points (the largest cluster above the table)
  PrincipalAxes axes;            // of those, upright
  double height_m = 0;           // their top above the table
  Vec3 centre_O = Vec3::Zero();  // over the points' box, half-way from the table to the top
  // Where the object may lie: the points' box mirrored about the centre (the camera saw one
  // side), from the table to the top, plus 5 mm.
  Aabb box_O;
  // The same as half-spaces: box_O's six faces and, with TableTopOptions::footprint_region, the
  // four sides of the points' rectangle along their upright principal axes (`axes`' extents,
  // trimmed of stray returns), 5 mm out; a point p lies inside when plane.distance(p) ≥ 0 for
  // every plane. An object turned on the table fills a fraction of its axis-aligned box, and
  // stray returns at depth edges widen that box: the model of what the camera did not see, closed
  // up to the box, stands out beside the object there, and a pinch's fingertips that straddle the
  // object land on it.
  std::vector<Plane> region_O;
};

// Whether p (frame O) lies inside every half-space of `region` (TableTopObject::region_O).
bool insideRegion(const std::vector<Plane>& region, const Vec3& p);

// Finds the object resting at T_B_O_rest (frame O: the object's frame there) in depth frames
// taken from T_B_C, the robot's pixels (robot_masks, per frame) left out: RANSAC fits the table
// plane near where the robot's config puts the table, the points above it near the rest pose are
// clustered and the largest cluster is the object. It is too large for the hand when its smallest
// extent exceeds 85 % of the open hand's span, too large for the volume beyond
// options.volume_size_m − 2 cm. `record` (optional) gets the counts; `log` one line.
TableTopObject findObjectOnTable(const std::vector<DepthImage>& frames,
                                 const std::vector<std::vector<uint8_t>>& robot_masks,
                                 const Iso3& T_B_C, const CameraIntrinsics& K,
                                 const Iso3& T_B_O_rest, const RobotModel& robot,
                                 const ScanOptions& options, const TableTopOptions& table_top,
                                 TableTopRecord* record = nullptr,
                                 const std::function<void(const std::string&)>& log = {});

// The scan options with the volume fitted to the object (ScanOptions::fit_volume): a cube of 1.5
// times its largest extent + 4 cm (at most volume_size_m) with as many voxels across as
// volume_size_m / voxel_m. Unchanged when fit_volume is off.
ScanOptions fitScanVolume(const ScanOptions& options, const TableTopObject& object);

// The pixels of `depth` (camera at T_O_C) whose points lie less than above_m above the table
// plane (or below it): they only carve.
std::vector<uint8_t> tablePixels(const DepthImage& depth, const Iso3& T_O_C,
                                 const CameraIntrinsics& K, const Plane& table_O, double above_m);

// Per voxel of `volume`, 1 where it is unknown and an observed voxel lies above it along up_O
// (the ray from its centre in half-voxel steps, to the volume's bounds), else 0: the unknown
// space beneath measured surface (TableTopOptions::under_measured_only).
std::vector<uint8_t> unknownUnderMeasured(const TsdfVolume& volume, const Vec3& up_O);
// The same, each ray followed step by step to the volume's bounds (what the test compares
// unknownUnderMeasured with; it follows a ray only across the observed voxels' bounds).
std::vector<uint8_t> unknownUnderMeasuredReference(const TsdfVolume& volume, const Vec3& up_O);

// First-grasp candidates on what the table-top frames fused into `session` show (its planning
// model: the observed surface closed over what it hides, up to the table, or with
// TableTopOptions::under_measured_only only beneath measured surface; the table cut off 3 mm
// above its plane, and anything beyond 2 cm of object.box_O), the hand stopping at that model and
// at the table (generateGrasps); most stable first (ε to 10 %), then the cheaper arm motion from
// q_now.
GraspGeneration firstGrasps(const ScanSession& session, const TableTopObject& object,
                            const Iso3& T_B_O_rest, const JointVector& q_now);

// Poses from which to register a model (frame O) to an object resting on the table, seen by a
// camera at camera_B whose points above the table have their centroid at seen_B: each of the
// model's `orientations` most probable resting orientations (stablePoses of its mesh) at
// `headings` headings about the vertical, its lowest point on the table top, placed so that the
// centroid of its surface facing the camera lies over seen_B (the camera sees the near side: the
// object's centre lies beyond the centroid of what it sees). Empty when the mesh spans no volume.
std::vector<Iso3> restingStarts(const TriangleMesh& model_O, const Vec3& seen_B,
                                const Vec3& camera_B, double table_top_z, int orientations = 6,
                                int headings = 12);

}  // namespace inhand
