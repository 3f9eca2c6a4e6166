#pragma once
// Simulated depth images: Embree ray casting of a scene, with the sensor's failure modes
// (miss, out of range, too oblique, projector shadow) and seeded noise (lateral jitter, axial
// Gaussian, disparity quantisation).
#include <cstdint>

#include "inhand/geometry/ray_scene.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"
#include "inhand/sensor/noise_model.h"

namespace inhand {

struct RenderOptions {
  bool noise = true;  // false: exact depth of the first hit (failure modes still apply)
  uint64_t seed = 1;  // noise seed; the same seed gives the same image on any thread count
  // A background behind everything: rays that miss the scene hit the inside of this sphere
  // (centre in the scene's frame, radius; 0: none), computed in closed form rather than cast
  // (a room around the camera gives every pixel a return: as many pixels again as the scene).
  // Its returns get the geometry id scene.geometryCount().
  Vec3 background_centre = Vec3::Zero();
  double background_radius_m = 0;
  // false: no projector shadows (a return wherever the camera sees a surface within its
  // incidence limit), for rendering a known surface's depth rather than a sensor's image.
  bool projector_shadows = true;
  // Only the pixels [u0, u1) × [v0, v1) are rendered (the rest return nothing); u1 or v1 < 0:
  // the whole image.
  int region_u0 = 0, region_v0 = 0, region_u1 = -1, region_v1 = -1;
  // The per-pixel steps four pixels at a time in AVX2 where the CPU has it (false: one at a
  // time). The image is the same bit for bit either way.
  bool vectorised = true;
};

// Renders the depth image seen by a camera at T_S_C (camera pose in the scene's frame S).
// If `geometry_out` is given it receives, per pixel, the scene geometry id that produced the
// return (−1 for no return).
DepthImage renderDepth(const RayScene& scene, const Iso3& T_S_C, const DepthCameraOptions& camera,
                       const NoiseModelOptions& noise, const RenderOptions& options,
                       std::vector<int>* geometry_out = nullptr);

// Scalar single-threaded reference of renderDepth with noise off (rtcIntersect1 per pixel).
DepthImage renderDepthReference(const RayScene& scene, const Iso3& T_S_C,
                                const DepthCameraOptions& camera);

}  // namespace inhand
