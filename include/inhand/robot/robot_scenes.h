#pragma once
// The robot's own geometry as the camera sees it: its links (and the table) as ray-casting
// scenes placed at a joint configuration, the depth image they make and the pixels of a frame
// that are the robot's. What view planning (eq. 9's occluders), the scan's hand-aware fusion and
// the simulator's renderer share.
#include <memory>
#include <vector>

#include "inhand/geometry/ray_scene.h"
#include "inhand/robot/robot_model.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"

namespace inhand {

// A committed scene placed in the object frame: something that can block the view of S_obj.
struct Occluder {
  const RayScene* scene;
  Iso3 T_O_scene;
  // Every mesh of the scene is watertight and outward-facing: the rasteriser may skip its back
  // faces when the camera is outside it.
  bool solid = false;
};

// One robot's links as Embree scenes in their link frames, built once and instanced per view.
class RobotOccluders {
 public:
  explicit RobotOccluders(const RobotModel& model);
  // Every link with geometry at q, and the table, placed in frame O by T_O_B.
  std::vector<Occluder> at(const JointVector& q, const Iso3& T_O_B, bool with_table = true) const;

 private:
  const RobotModel* model_;
  std::vector<int> links_;
  std::vector<std::unique_ptr<RayScene>> scenes_;
  std::vector<uint8_t> solid_;  // per link scene: watertight with positive volume
  std::unique_ptr<RayScene> table_;
};

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

}  // namespace inhand
