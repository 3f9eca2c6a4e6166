#pragma once
// Registering a model of the object (frame O) to a depth frame in which the object is seen
// without the hand's help: after a put-down, after a fall, or when a robot meets an object it
// holds an asset of. The model's observed surface is aligned with the frame from each of several
// start poses (a coarse point-to-point alignment brings each within reach, then alignBodyToDepth),
// and a frame tells how far it bears a pose out (depthSupport).
#include <optional>
#include <utility>
#include <vector>

#include "inhand/geometry/surface_distance.h"
#include "inhand/mesh/extract.h"
#include "inhand/robot/robot_model.h"
#include "inhand/scan/tracking.h"
#include "inhand/scan/types.h"
#include "inhand/sensor/depth_sensor.h"
#include "inhand/sensor/noise_model.h"

namespace inhand {

// The model's observed triangles (all three vertices observed): centroids and outward normals,
// every k-th so that about `budget` remain (none for budget <= 0), moved by T; with
// `with_variance`, each point's variance (SurfacePoint::var) the mean of its corners', else 0.
std::vector<SurfacePoint> observedSurface(const ObjectModel& m, int budget, const Iso3& T,
                                          bool with_variance = false);

// Every k-th vertex of the model (about 6000), moved by T: what hides the surface behind it.
std::vector<Vec3> modelOccluders(const ObjectModel& m, const Iso3& T);

// A model as registration aligns it, in its frame: its observed surface (about
// max(2000, options.max_object_points) points, with their variances: a registration decides a
// grasp or a pose once, from a model that may be known to millimetres only, and expects the
// residual that leaves) and the whole model as occluders. Tracking and the slip check align the
// model without its variances: a frame whose residual the sensor's noise does not explain is
// not fused (one frame lost), and a slip is not judged on it.
struct RegistrationModel {
  std::vector<SurfacePoint> points;
  std::vector<Vec3> occluders;
};
RegistrationModel registrationModel(const ObjectModel& m, const TrackingOptions& options);

// The model registered to `depth` (camera at T_B_C, intrinsics K; `hidden`: one per pixel, those
// that pair with nothing, such as the robot's and the table's) from each start pose T_B_O: the
// frame's points within 30 cm of the starts' mean, every other pixel each way, aligned with the
// model's points by point-to-point ICP (nearest model point within a gate shrinking from 4 to
// 1 cm, Umeyama's motion, 20 rounds), then alignBodyToDepth with the sensor's axial σ at the
// model's depth (`in_hand`: with the uncovered pixels' pull, and pixels without depth inside the
// outline: NoDepthPixels::kUnknown). One result per start, in parallel;
// the pose (T_B_O) where alignment succeeded.
std::vector<std::pair<std::optional<Iso3>, TrackResult>> registerModelAt(
    const RegistrationModel& model, const DepthImage& depth, const std::vector<uint8_t>& hidden,
    const Iso3& T_B_C, const CameraIntrinsics& K, const NoiseModelOptions& noise,
    const TrackingOptions& options, const std::vector<Iso3>& starts, bool in_hand = false);

// How far apart poses T_a and T_b put a model's surface: the mean distance of its points
// `points_O` (at most 1000 of them, evenly strided) placed at T_b from its surface `surface_O`
// placed at T_a. About the registration's noise where a frame cannot tell the two apart (a can
// turned about its axis); near the shift where the object really moved. 0 when either is empty.
double surfaceGap(const TriangleDistanceIndex& surface_O, const std::vector<Vec3>& points_O,
                  const Iso3& T_a, const Iso3& T_b);

// How far a depth frame bears out object points `points_B`: of those in view whose pixel
// measured something, the fraction measured within 1 cm of the point's depth, against those
// measured more than 1 cm behind it (the camera sees through where the point should be). Points
// in front of their measurement (occluded) and `hidden` pixels (empty: none) do not count.
// -1: none counted.
double depthSupport(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K,
                    const std::vector<uint8_t>& hidden, const std::vector<Vec3>& points_B);
// The counts behind depthSupport: the points borne out, and those the camera sees through.
struct SupportCounts {
  int support = 0, against = 0;
};
SupportCounts depthSupportCounts(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K,
                                 const std::vector<uint8_t>& hidden,
                                 const std::vector<Vec3>& points_B);

// Pixels of `d` whose point lies below height `below_z` (base frame; the camera at T_B_C)
// marked in `marked` (one per pixel).
void markBelow(const DepthImage& d, const Iso3& T_B_C, const CameraIntrinsics& K, double below_z,
               std::vector<uint8_t>* marked);

// Where a held object may have moved to in the hand (closing fingers push it centimetres),
// as start poses for registerModelAt: its believed pose T_B_O shifted so that the points it would
// show the camera (`points_O` under T_B_O, the front-most) centre on the frame's points near it
// (within the object's radius + 6 cm of where it is believed) that are neither `hidden` nor
// below the table top + 1 cm: as it lies, and turned 45° each way about the vertical through
// there. Empty when the frame has fewer than 50 such points.
std::vector<Iso3> heldObjectStarts(const DepthImage& d, const std::vector<uint8_t>& hidden,
                                   const Iso3& T_B_C, const CameraIntrinsics& K, double table_top_z,
                                   const Iso3& T_B_O, const std::vector<Vec3>& points_O);

// Every 7th observed vertex of the model (all of them observed when `observed` is empty): enough
// for depthSupport to tell where it lies.
std::vector<Vec3> observedVertices(const ObjectModel& model);

// After a pick-up: every finger closed to its limit, so the hand holds nothing.
bool fingersClosedOnNothing(const RobotModel& robot, const JointVector& q);

// How many of the object's points `points_O` the grasp T_O_palm puts more than 3 mm inside the
// hand's links (the hand at q): a model's surface lies within a millimetre or two of the true
// one, so deeper is a pose the links would pass through (a registration to check).
int pointsInsideHand(const RobotModel& robot, const JointVector& q, const Iso3& T_O_palm,
                     const std::vector<Vec3>& points_O);

// A frame from the sensor that can be used: one that arrived (the camera's size) with depth in
// it (checks.min_valid_fraction), non-finite depths as no return; up to `tries` captures. nullopt
// when none came.
std::optional<DepthImage> captureUsable(DepthSensor& sensor, const FrameChecks& checks,
                                        int tries = 5);

}  // namespace inhand
