#pragma once
// A directory of depth frames with known camera poses: DIR/frames.json plus one 16-bit PNG per
// frame. This is what `inhand render` writes and `inhand fuse` reads, and what a user records
// from a real robot:
//   { "depth_scale_m": 0.001,
//     "intrinsics": { "width": 640, "height": 480, "fx": 525, "fy": 525, "cx": 319.5, "cy": 239.5
//     }, "frames": [ { "file": "depth_0000.png", "T_O_C": [16 numbers, row-major] }, … ],
//     "bounds_O": { "min": [x, y, z], "max": [x, y, z] } }   (optional)
// T_O_C is the camera pose in the object frame (maps camera points into the object frame).
// Frames from a robot holding the object may carry, for `inhand fuse --robot`, the joints as the
// robot reported them and the camera in its base frame, and the palm's pose in the object frame
// (per frame, or once at the top for every frame):
//     "T_O_palm": [16 numbers],                                       (top level, optional)
//     "frames": [ { "file": ..., "q": { "joint_name": value, … }, "T_B_C": [16 numbers],
//                   "T_O_palm": [16 numbers] (optional), "T_O_C": (optional with q and T_B_C) } ]
// Frames may carry a colour image ("colour": a PNG or JPEG file, per frame), taken by a colour
// camera with its own intrinsics ("colour_intrinsics", top level; default: the depth camera's)
// and pose in the depth camera's frame ("T_D_RGB", 16 numbers; default: the identity, an image
// registered to the depth image).
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/geometry/appearance.h"
#include "inhand/geometry/triangle_mesh.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"

namespace inhand {

struct FrameRecord {
  FrameRecord() = default;
  FrameRecord(std::string file_, const Iso3& T_O_C_) : file(std::move(file_)), T_O_C(T_O_C_) {}
  std::string file;  // PNG path relative to the directory
  Iso3 T_O_C = Iso3::Identity();
  bool has_T_O_C = true;  // false: only the robot's fields give the pose (fuse --robot)
  // The robot's fields (all optional): joints as reported, by name (radians or metres), the
  // camera in the robot's base frame, the palm in the object frame (else FrameSet::T_O_palm).
  std::vector<std::pair<std::string, double>> q;
  std::optional<Iso3> T_B_C, T_O_palm;
  std::string colour_file;  // the colour image taken with it (relative path), or empty
};

struct FrameSet {
  CameraIntrinsics intrinsics;
  double depth_scale_m = 0.001;  // metres per PNG unit
  std::vector<FrameRecord> frames;
  // Optional "bounds_O": {"min": [x,y,z], "max": [x,y,z]}: where the object is, in O (m). fuse
  // uses it for the volume unless --bounds is given.
  std::optional<Aabb> bounds_O;
  std::optional<Iso3> T_O_palm;  // the palm in the object frame, for frames that give none
  // The colour camera: enabled when a frame has a colour image.
  ColourCameraOptions colour;
  // Poses whose rotation was not orthonormal to 1e-9 (max |RᵀR − I| up to 1e-2, as pose files
  // with 7–8 significant digits give) were replaced by the nearest rotation: how many, and the
  // largest deviation.
  int reorthonormalised = 0;
  double max_rotation_deviation = 0;
};

// Reads and validates DIR/frames.json (every field; poses must be rigid to 1e-2, nearer ones are
// re-orthonormalised; every PNG must exist).
// Throws Error naming the file and field.
FrameSet readFrameSet(const std::filesystem::path& dir);

// A pinhole camera's intrinsics from {width, height, fx, fy, cx, cy}, checked; errors name
// `where` (frames.json's intrinsics, a robot config's colour camera).
CameraIntrinsics readIntrinsics(const Json& K, const std::string& where);
// A rigid transform from a JSON array of 16 row-major numbers (core/pose.h poseFromRowMajor,
// rotation within `tol` of orthonormal; *deviation as there); errors name `where`.
Iso3 readRowMajorPose(const Json& T, const std::string& where, double tol = 1e-2,
                      double* deviation = nullptr);
// Loads frame i's depth image, checking its size against the intrinsics.
DepthImage loadFrameDepth(const std::filesystem::path& dir, const FrameSet& set, size_t i);
// Loads frame i's colour image (empty when it has none), checking its size against the colour
// intrinsics.
RgbImage loadFrameColour(const std::filesystem::path& dir, const FrameSet& set, size_t i);
// Writes DIR/frames.json atomically.
void writeFrameSet(const std::filesystem::path& dir, const FrameSet& set);

}  // namespace inhand
