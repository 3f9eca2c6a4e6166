#pragma once
// Resuming a multi-grasp scan (scanMultiGrasp, scanFromTable). The drivers call
// ScanProgress::checkpoint at every point they can resume from: when a grasp's views begin (the
// robot holds the object) and after each view. saveScanCheckpoint writes that state to one file
// atomically (the session's volume and views, the grasps finished, the table-top record and
// the first table-top frame the model is anchored to, the grasp under way) with the caller's own
// state beside it (e.g. the simulator's); resumeScan goes on from it. With the robot back in the
// state it was in at the checkpoint (the object in the hand as then), the resumed scan is the scan
// that was not interrupted: the same views, frames and model, voxel for voxel
// (tests/test_checkpoint.cc). Work done after the checkpoint (a view under way, a re-grasp) is done
// again.
#include <filesystem>
#include <memory>
#include <optional>

#include "inhand/core/json_util.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/scan/session.h"

namespace inhand {

// Writes `checkpoint` and the caller's `extra` to `path` atomically. Throws Error naming the file.
void saveScanCheckpoint(const std::filesystem::path& path, const ScanCheckpoint& checkpoint,
                        const Json& extra = Json());

// The caller's `extra` in a checkpoint file, without loading the rest (e.g. to learn which scan
// wrote it before loading its robot). Throws Error naming the file.
Json readScanCheckpointExtra(const std::filesystem::path& path);

// A checkpoint read back, ready for resumeScan.
struct LoadedCheckpoint {
  std::unique_ptr<ScanSession> session;
  MultiGraspResult sofar;
  int grasp = 0;
  GraspRecord current;
  Iso3 T_B_O_rest = Iso3::Identity();
  Aabb object_box_O;
  std::optional<TableAnchor> anchor;  // the table-top frame the model is anchored to
  Json extra;                         // what the caller saved beside it
};

// Reads a checkpoint written by saveScanCheckpoint with the same robot, camera, noise and
// options (the volume the table-top stage fitted is taken from the file). Throws Error naming
// the file and what is wrong.
LoadedCheckpoint loadScanCheckpoint(const std::filesystem::path& path, const RobotModel& robot,
                                    const DepthCameraOptions& camera,
                                    const NoiseModelOptions& noise, const ScanOptions& options,
                                    const MultiGraspOptions& multi);

// Goes on with a loaded checkpoint: the rest of the grasp under way, then the re-grasps, as the
// driver that wrote it would have. The robot must be as it was at the checkpoint. `progress`
// replaces the one the scan had (its checkpoint callback keeps being called).
MultiGraspResult resumeScan(RobotInterface& robot, DepthSensor& sensor, LoadedCheckpoint checkpoint,
                            const ScanProgress& progress = {});

}  // namespace inhand
