#pragma once
// Fusing depth images into the TsdfVolume (paper §III-B). For each voxel, projected into the
// image, with d = D − z (measured depth minus voxel depth along the optical axis; positive in
// front of the surface) and band half-width μ:
//   d > μ        the ray passed through: an unknown voxel becomes empty; an observed voxel gets
//                the truncated value +μ with weight w (KinectFusion-style), so free space seen
//                later corrects flying pixels;
//   |d| ≤ μ      Σw·d += w·d, Σw += w with w = 1/σ² of the pixel; the voxel becomes observed;
//   d < −μ       behind the band: unchanged (stays unknown if never seen).
// Pixels flagged carve-only are not the object's surface; what they say of the space in front of
// them depends on the flag:
//  - kCarveToSurface (measurements of the robot's own hand, §IV; the table): unknown voxels up to
//    μ/4 in front of the measured surface become empty (it is a known surface, not the object's),
//    and an observed voxel more than μ in front of it gets +μ as from any measurement, with the
//    pixel's weight: the ray passed through it. Without that, a band that a ray grazing an edge
//    wrote beyond the object (behind the edge, where it is not) stayed wherever the hand hid the
//    face beyond the edge from every later view, a fin of surface millimetres off the object.
//  - kCarveUnknownToSurface (such a pixel at a depth edge, whose depth may be of either side):
//    unknown voxels only, up to μ/4 in front.
//  - kCarveBeyondBand (a return at a depth edge, whose side of the edge is uncertain): unknown
//    voxels only, beyond μ in front of it, as any measurement's free space, so that a ray grazing
//    a surface does not empty the voxels of its band.
#include <cstdint>
#include <functional>
#include <vector>

#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"
#include "inhand/sensor/noise_model.h"
#include "inhand/volume/tsdf_volume.h"

namespace inhand {

// The values of a carve-only mask (0: a measurement).
constexpr uint8_t kCarveToSurface = 1;
constexpr uint8_t kCarveBeyondBand = 2;
constexpr uint8_t kCarveUnknownToSurface = 3;

struct IntegrationStats {
  int64_t visited = 0;  // voxels whose centre projected onto a pixel with a depth
  int64_t updated = 0;  // voxels whose state or sums changed
};

// The pixels a volume's voxels can project to from camera pose T_O_C (the image rectangle of
// its eight corners, a pixel wider each side, clipped to the image); the whole image when a
// corner lies behind the camera. integrate() reads no pixel outside it.
PixelRect volumeImageRect(const TsdfVolume& volume, const Iso3& T_O_C, const CameraIntrinsics& K);

// Per-pixel measurement σ (m) of a depth image: the axial noise model at the pixel's depth and its
// incidence angle (normal estimated from neighbouring pixels), multiplied by
// noise.discontinuity_factor next to depth discontinuities and missing returns. 0 where no depth.
// With `region`, only its pixels get a σ (0 elsewhere); with `carve_only`, pixels flagged there
// get none either, but for kCarveToSurface (integrate() weighs the free space in front of those
// by their σ, and uses no σ of another carve-only pixel). Both leave the σ of every other pixel
// as it would be without them.
std::vector<float> measurementSigma(const DepthImage& depth, const CameraIntrinsics& K,
                                    const NoiseModelOptions& noise,
                                    const PixelRect* region = nullptr,
                                    const std::vector<uint8_t>* carve_only = nullptr);

// The pixels on the near side of a silhouette (1): a 4-neighbour farther by more than `jump_m`, or
// a gap of no return after which, within 8 pixels in that direction, the first return is farther
// by more than `jump_m` or there is none (a projector shadow beside an edge, the background out of
// range). Their return may come from across the edge (lateral noise, a mixed pixel). A shadow on
// the pixel's own surface, or a nearer edge, does not mark it. Only pixels with a depth are
// marked, only in `region` if given.
std::vector<uint8_t> depthDiscontinuities(const DepthImage& depth, double jump_m,
                                          const PixelRect* region = nullptr);

// `depth` with each pixel flagged in `mask` set to the nearest depth (the smallest > 0) within
// `radius` pixels of it, itself included: a silhouette pixel's return may come from behind the
// object's edge, and what it carves in front of itself must stop before the edge.
DepthImage nearestAround(const DepthImage& depth, const std::vector<uint8_t>& mask, int radius);

// The pixels marked kCarveToSurface in `carve` that lie within 2 pixels (5 × 5) of a pixel not
// marked at all whose depth is nearer by more than `jump_m` become kCarveUnknownToSurface: the
// robot's (or the table's) pixels on the far side of the object's silhouette against them. Only
// pixels in `rect` change. A 5 × 5 minimum filter of the unmarked depths, separable (rows, then
// columns); farSideOfSilhouettesReference is the direct 25-pixel search, the same to the bit.
void farSideOfSilhouettesOnlyCarveUnknown(const DepthImage& depth, float jump_m,
                                          const PixelRect& rect, std::vector<uint8_t>* carve);
void farSideOfSilhouettesReference(const DepthImage& depth, float jump_m, const PixelRect& rect,
                                   std::vector<uint8_t>* carve);

// Pixel (u, v)'s surface with the noise smoothed out: a least-squares plane through the depths of
// its (2·kSmoothingRadius + 1)² neighbourhood that lie within `max_jump` of its own (the same
// surface), evaluated at the pixel, and the cosine between that plane's normal and the pixel's ray
// (their mean and 1 when fewer than six or degenerate); depth 0 where the pixel has none.
// With VolumeOptions::band_sigmas = k > 0 a measurement reaches behind this smoothed depth by
// max(k·σ, voxel / cos θ) (a voxel across the surface, seen at incidence θ; cos θ at least
// kMinBandCosine), at most μ, and never more than μ behind its own depth: which voxels a
// measurement updates then hardly depends on its own noise, so the values it adds are not biased
// outwards (a limit taken from the noisy depth drops the measurements that fell behind more often
// than those in front).
constexpr int kSmoothingRadius = 2;
constexpr float kMinBandCosine = 0.2f;
struct SmoothedSurface {
  float depth = 0.f;
  float cos_incidence = 1.f;
};
SmoothedSurface smoothedSurface(const DepthImage& depth, const CameraIntrinsics& K, int u, int v,
                                float max_jump);
// smoothedSurface() at each pixel of `rect` whose byte in `fit` (width·height, only the rect's
// read) is non-zero, the same values bit for bit, handed to `out(index, surface)` once per pixel,
// from both cores. Where a pixel's whole neighbourhood lies on its surface the plane comes from
// sliding sums over rows (the sums of depths in double are exact in any order there); elsewhere
// from smoothedSurface().
void smoothedSurfaces(const DepthImage& depth, const CameraIntrinsics& K, const PixelRect& rect,
                      const uint8_t* fit, float max_jump,
                      const std::function<void(size_t, const SmoothedSurface&)>& out);
// That reach as a camera depth: min(D + μ, Ds + min(μ, max(k·σ, voxel / cos θ))); D + μ when k or
// σ is not positive.
float farLimit(float D, const SmoothedSurface& surface, float sigma, float k, float voxel,
               float mu);

// Optimised kernel: both cores, rows of voxels clipped analytically to the camera frustum.
// `sigma_m` is measurementSigma's output; `carve_only` (optional, width·height) flags pixels that
// may only carve. Bricks of 8³ voxels that the frame cannot change are skipped from their corners
// and the image's depth range under them (8×8-pixel tiles): all behind every depth by more than μ,
// or all in front by more than μ and already empty. Four voxels are tested at a time in SSE2.
// `skip_unchanged_bricks` = false visits every voxel in the frustum one at a time (the same
// volume to the bit; `visited` then counts all of them).
IntegrationStats integrate(const DepthImage& depth, const Iso3& T_O_C, const CameraIntrinsics& K,
                           const std::vector<float>& sigma_m, TsdfVolume* volume,
                           const std::vector<uint8_t>* carve_only = nullptr,
                           bool skip_unchanged_bricks = true);

// Simple reference: single thread, every voxel transformed independently in double precision.
IntegrationStats integrateReference(const DepthImage& depth, const Iso3& T_O_C,
                                    const CameraIntrinsics& K, const std::vector<float>& sigma_m,
                                    TsdfVolume* volume,
                                    const std::vector<uint8_t>* carve_only = nullptr);

}  // namespace inhand
