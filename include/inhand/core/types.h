#pragma once
// Eigen aliases used across inhand. Double precision for poses and geometry; float for bulk
// per-voxel / per-pixel data.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

namespace inhand {

using Vec2 = Eigen::Vector2d;
using Vec2f = Eigen::Vector2f;
using Vec3 = Eigen::Vector3d;
using Vec4 = Eigen::Vector4d;
using Vec3f = Eigen::Vector3f;
using Vec3i = Eigen::Vector3i;
using Mat3 = Eigen::Matrix3d;
using Mat4 = Eigen::Matrix4d;
// A rigid transform. Named T_A_B: maps points from frame B into frame A (p_A = T_A_B * p_B).
using Iso3 = Eigen::Isometry3d;

}  // namespace inhand
