#pragma once
// Where can the arm present a held object to the camera? For object positions on a grid in
// front of the camera (pan/tilt offsets around the config's look_at point, at a fixed range), the
// fraction of viewing directions (spread over the sphere, in the object's frame) for which some
// roll about the optical axis has a collision-free IK solution, with the object held at the
// config's grasp offset in front of the palm. This is how a user checks a new robot.
#include <vector>

#include "inhand/robot/ik.h"

namespace inhand {

struct ReachabilityOptions {
  double range_m = 0.7;       // camera-to-object distance, m (the paper's view range)
  int directions = 100;       // viewing directions over the sphere
  int rolls = 8;              // rolls about the optical axis tried per direction
  int grid = 3;               // grid × grid object positions
  double grid_step_deg = 15;  // pan/tilt spacing of the grid, degrees
  uint64_t seed = 1;          // IK restarts
  IkOptions ik{8, 300, 1e-5, 1e-4};
  std::string validate() const;
};

struct ReachabilityCell {
  Vec3 object_B = Vec3::Zero();  // object centre, base frame
  double pan_deg = 0, tilt_deg = 0;
  bool aimable = true;           // the pan-tilt can look there
  int reachable = 0, total = 0;  // directions with a solution / tried
};

// Palm pose T_B_palm that shows the object (centre at object_B, held `offset` in front of the
// palm along its z) to a camera at camera_B along viewing direction dir_O (object frame, pointing
// from the camera to the object), rolled by `roll` about the optical axis.
Iso3 presentationPalmPose(const Vec3& object_B, const Vec3& camera_B, const Vec3& dir_O,
                          double roll, double offset);

std::vector<ReachabilityCell> reachabilityMap(const RobotModel& model,
                                              const ReachabilityOptions& options = {});

}  // namespace inhand
