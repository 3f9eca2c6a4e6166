#pragma once
// What the scan needs from a depth camera on a pan-tilt unit, real or simulated.
#include "inhand/geometry/appearance.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"

namespace inhand {

class DepthSensor {
 public:
  virtual ~DepthSensor() = default;
  virtual const DepthCameraOptions& camera() const = 0;
  // Points the camera (pan/tilt) so its pose in the robot base frame is T_B_C.
  virtual void setPose(const Iso3& T_B_C) = 0;
  // The camera pose the pan-tilt reports now (robot base frame).
  virtual Iso3 pose() const = 0;
  // The latest depth image.
  virtual DepthImage capture() = 0;
  // The colour image taken with the latest depth image (camera().colour); empty when the sensor
  // has no colour camera.
  virtual RgbImage captureColour() { return {}; }
};

}  // namespace inhand
