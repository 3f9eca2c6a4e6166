#pragma once
// The autonomous multi-grasp scan (paper §IV, §V-B): scan with the current grasp until no view
// reaches t_q, put the object down, generate grasp candidates on the model so far, rank them by
// the best view Alg. 1 finds with the hand there, pick the object up with the best one, and go
// on, the model kept in the object frame throughout, until no candidate grasp promises a view
// above t_q or a grasp limit.
#include "inhand/scan/session.h"

namespace inhand {

// `T_O_palm` and the robot's state: the first grasp (the robot holds the object); `T_B_O_rest`:
// where the object rests on the table between grasps (frame O kept).
MultiGraspResult scanMultiGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm,
                                const Vec3& centre_O, const Iso3& T_B_O_rest,
                                const ScanOptions& options, const MultiGraspOptions& multi,
                                const NoiseModelOptions& noise, const ScanProgress& progress = {});

// The whole autonomous scan (§V): the object rests on the table at T_B_O_rest (its frame O is the
// model's frame; nothing of its shape is known). The camera takes table_top.frames of it; the
// table plane is fitted (RANSAC) and the points above it near the rest pose are the object; the
// volume is centred on them and the frames are fused (table and robot pixels only carve); the
// first grasp comes from generateGrasps on the model those frames give (the observed surface,
// closed over what it hides); the robot picks the object up with the first candidate that holds
// (by what it observes after the lift) and the multi-grasp scan goes on as scanMultiGrasp.
// Terminations of its own: object_not_found, object_too_large_for_volume,
// object_too_large_for_hand, no_reachable_grasp, pick_up_failed (the model so far is returned with
// each).
MultiGraspResult scanFromTable(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_B_O_rest,
                               const ScanOptions& options, const MultiGraspOptions& multi,
                               const NoiseModelOptions& noise, const ScanProgress& progress = {});

// Whether a grasp (the palm at T_O_palm in the object's frame) repeats a pick-up of `attempts`
// that failed: its palm within 1 cm and 15° of the attempt's. The same grasp fails as it did
// while the object rests as it did (a lying bleach bottle slid out of the same grasp twice, the
// re-find on the table between them planning it first again); the scan tries such a candidate
// only once every other has been tried.
bool repeatsAFailedPickUp(const Iso3& T_O_palm, const std::vector<PickAttempt>& attempts);

// The finished model (out->scan.model, frame O) aligned with `anchor`, a frame of the object
// where it rested before the first pick-up (frame O is its pose there): a grasp's pose taken a
// few degrees off turns every later frame, and so the model as a whole. The model is moved by
// that alignment where it moves its surface more than gap_m on average (surfaceGap); below, the
// alignment is not told from the frame's noise and bias. What was found and done:
// out->table_top->reanchor (nothing without a table-top record or after a stop request).
// scanFromTable and resumeScan call it last (TableTopOptions::reanchor).
void reanchorModel(ScanSession& session, const TableAnchor& anchor, double gap_m,
                   MultiGraspResult* out);

}  // namespace inhand
