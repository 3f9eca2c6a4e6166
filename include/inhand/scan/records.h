#pragma once
// One JSON form per scan record, with one key per field, written and read by summary.json,
// checkpoints and the Python bindings alike. Readers also take the keys checkpoints used before
// (dir_O, gain, epsilon, tried, hole_area_m2, attempts), so older checkpoints still load.
#include "inhand/core/json_util.h"
#include "inhand/scan/types.h"

namespace inhand {

// initial, direction_O, T_O_C, quality, predicted_gain (null: unknown), t_q, unresolved, cost_s,
// score, mean_entropy, observed_fraction, coverage, frames, candidates, planning_s.
Json viewRecordJson(const ViewRecord& r);
ViewRecord viewRecordFrom(const Json& j);  // throws Json::exception on a malformed record

// T_O_palm, q, candidates, poses_tried, quality, t_q, model_area_m2, stability_epsilon,
// views, termination, unknown_area_m2, mean_entropy, generation_s, ranking_s, ranked (T_O_palm,
// q, quality, stability_epsilon), pick_up_attempts; not the model (a checkpoint adds it).
Json graspRecordJson(const GraspRecord& g);
// The record without its model; throws Json::exception or Error on a malformed record.
GraspRecord graspRecordFrom(const Json& j);

// In-hand frames not fused, by reason (summary.json's frames_not_fused): each FrameRefusal's
// name and count in a record that keeps them (ScanSession::Summary, ScanResult).
template <class Counts>
Json framesNotFusedJson(const Counts& c) {
  Json j = Json::object();
  for (FrameRefusal r : kEveryFrameRefusal) j[frameRefusalName(r)] = refusedFrames(c, r);
  return j;
}

// frames, points, table_inliers, object_points, table_plane_O (n, d), centroid_O,
// principal_axes (axis_O, extent_m, variance_m2, min_m, max_m), grasp_poses_tried, …_touching,
// …_stable, …_table_free, …_reachable, grasp_rejected (counts per reason, written only),
// pick_up_attempts, grasp_poses (approach_O, roll_rad, spread, preshape, edge, pinch,
// two_finger, epsilon, result), volume (size_m, voxel_m), seconds.
Json tableTopRecordJson(const TableTopRecord& t);
// Throws Json::exception or Error on a malformed record.
TableTopRecord tableTopRecordFrom(const Json& j);

}  // namespace inhand
