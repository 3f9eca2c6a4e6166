#pragma once
// The depth camera of DESIGN.md: a PrimeSense/Kinect-v1-class structured-light sensor.
// Camera frame C is the optical frame: x right, y down, z forward (metres).
#include <string>

#include "inhand/core/types.h"

namespace inhand {

struct CameraIntrinsics {
  int width = 640;    // pixels
  int height = 480;   // pixels
  double fx = 525.0;  // focal length, pixels
  double fy = 525.0;  // focal length, pixels
  double cx = 319.5;  // principal point, pixels
  double cy = 239.5;  // principal point, pixels

  // Direction of the ray through pixel (u, v) with z = 1 (so a hit's t is its depth z).
  Vec3 rayZ1(double u, double v) const { return Vec3((u - cx) / fx, (v - cy) / fy, 1.0); }
  // Pixel coordinates of a point in the camera frame (z > 0).
  Vec2 project(const Vec3& p_C) const {
    return Vec2(fx * p_C.x() / p_C.z() + cx, fy * p_C.y() / p_C.z() + cy);
  }
  // Empty when valid; otherwise names the bad field.
  std::string validate() const;
};

// A colour camera registered to the depth camera, as on a Kinect-class sensor: its own
// intrinsics, and its optical frame's pose in the depth camera's frame (by default parallel to
// it, 2.5 cm aside, as the Kinect v1's colour camera sits beside its infrared camera).
struct ColourCameraOptions {
  bool enabled = false;
  CameraIntrinsics intrinsics{640, 480, 530.0, 530.0, 318.5, 242.5};
  Iso3 T_D_RGB = Iso3(Eigen::Translation3d(0.025, 0.0, 0.0));
  // A lamp at the camera lights what it sees (as the simulator's does, sim.colour.ambient): the
  // model's colours then divide out the shading it casts, its share fitted to the frames
  // (ColourFrames::shadingFalloff). false: the room's light alone, the colours as seen.
  bool light_at_camera = false;
};

struct DepthCameraOptions {
  CameraIntrinsics intrinsics;
  ColourCameraOptions colour;         // none unless enabled
  Vec3 projector_C{0.075, 0.0, 0.0};  // projector centre in the camera frame, m (7.5 cm baseline)
  double min_range_m = 0.5;           // no return nearer than this depth z, m
  double max_range_m = 5.0;           // no return farther than this depth z, m
  double max_incidence_deg =
      80.0;  // no return when the camera ray meets the surface more obliquely
  double max_projector_incidence_deg = 80.0;  // same for the projector's ray (stereo effects)

  double baseline_m() const { return projector_C.norm(); }
  std::string validate() const;
};

}  // namespace inhand
