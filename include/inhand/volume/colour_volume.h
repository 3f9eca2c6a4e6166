#pragma once
// Colour in the volume: each voxel near the observed surface keeps a weighted mean of the colours
// seen there, weighted like its signed distance (1/σ² of the depth measurement) times the cosine
// of the viewing angle squared, so that head-on, near views dominate grazing, far ones. Stored
// sparsely (only voxels a measured surface point lies beside), in the volume's grid.
#include <array>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

#include "inhand/geometry/appearance.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"
#include "inhand/volume/tsdf_volume.h"

namespace inhand {

class ColourVolume {
 public:
  // The grid of `volume` (origin, voxel size, dims); no colour yet.
  explicit ColourVolume(const TsdfVolume& volume);

  // Adds colour `rgb` (0–255) seen at p_O with weight w to the voxel nearest p_O.
  void add(const Vec3& p_O, const Vec3f& rgb, float w);
  // The weighted mean colour at p_O, trilinear over the 8 voxels around it; where none of them
  // has colour, the coloured voxels of the 4 × 4 × 4 block around them; false where none has.
  // `weight` (optional) receives the interpolated weight.
  bool at(const Vec3& p_O, Vec3f* rgb, float* weight = nullptr) const;

  size_t voxels() const { return voxels_; }  // voxels with colour
  size_t bytes() const;                      // memory the colour takes, roughly
  bool empty() const { return voxels_ == 0; }

  struct Sum {
    float w = 0, r = 0, g = 0, b = 0;
  };
  // The sums of voxel `index` (the volume's voxel index); null where it has none.
  const Sum* find(size_t index) const;
  // Every voxel with colour, by index (checkpoints).
  std::vector<std::pair<size_t, Sum>> entries() const;
  // Sets voxel `index`'s sums (checkpoints); false when index lies outside the grid.
  bool set(size_t index, const Sum& sum);

 private:
  // Stored in blocks of 8 × 8 × 8 voxels, made where a colour first falls: a dense table of
  // block numbers over the grid's blocks (−1: none) and the blocks' sums.
  static constexpr int kBlock = 8;
  Sum& sumAt(const Vec3i& voxel);
  Vec3i dims_, blockDims_;
  Vec3 origin_;
  double voxel_;
  std::vector<int32_t> blockOf_;
  std::vector<int32_t> blockIndex_;  // per block made: its index in the table
  std::vector<Sum> sums_;            // kBlock³ per block made
  size_t voxels_ = 0;
};

struct ColourIntegrationStats {
  int pixels = 0;         // pixels whose colour was added
  int occluded = 0;       // … left out: the colour camera sees something nearer there
  int edge_weighted = 0;  // … added with the edge's lower weight
};

// Adds the colours of one frame: every pixel of `depth` with a measurement, that is not flagged
// in `carve_only` (the robot, the table) and whose surface is seen by the colour camera
// (camera.colour: its image `colour`, pose T_D_RGB) takes the colour there (bilinear) at the
// pixel's surface point, weighted by (1 mm / σ)² · cos²(viewing angle) (σ: measurementSigma);
// pixels within 2 of one with no depth, a depth jump over 1 cm or a carve-only pixel (edges,
// where colour and depth disagree most, and next to the fingers) weigh a tenth. A pixel whose
// point the colour camera sees behind something nearer, at its colour pixel or one beside it
// (another pixel's point 1 cm or more in front, as the fingers hide the object from a camera
// 2.5 cm aside), adds nothing.
ColourIntegrationStats integrateColour(const DepthImage& depth, const RgbImage& colour,
                                       const Iso3& T_O_C, const DepthCameraOptions& camera,
                                       const std::vector<float>& sigma_m, ColourVolume* volume,
                                       const std::vector<uint8_t>* carve_only = nullptr);

// Per vertex: the colour at it (ColourVolume::at) with alpha 255, or mid grey with alpha 0 where
// no colour was seen.
std::vector<std::array<uint8_t, 4>> vertexColours(const ColourVolume& volume,
                                                  const TriangleMesh& mesh);

// The colour frames kept for the model's colours: of every frame added, the part of its colour
// image that saw the object (the box around the colour pixels that the frame's fused depth pixels
// project to, 2 pixels wider), with the depth of the object's surface at each of those pixels
// (the colour camera's z-buffer of the frame's fused points; marked where a point that is not
// fused, the robot's or the table's, lies nearer, or where none projects) and whether the pixel
// lies at a depth edge (within 2 pixels of no depth or a depth jump over 1 cm), and the colour
// camera's pose in the object's frame. A fused pixel within 2 pixels of one that is not fused
// (the robot's, the table's, the object's beside the hand) is not used at all: the colour
// camera, 2.5 cm aside, may see a finger there. A point of the
// model then takes its colour from the frames that saw it head-on, at the colour camera's own
// resolution, rather than from the voxels' means (which blur a colour edge over a voxel on each
// side and average in the oblique views' shading).
//
// Memory: a frame takes 8 bytes per pixel of its box. While the frames kept take more than
// `budget_bytes`, every other one is dropped (the 1st, 3rd, … kept) and from then on only every
// 2nd (4th, …) frame added is kept: the frames stay spread over the whole scan.
class ColourFrames {
 public:
  explicit ColourFrames(size_t budget_bytes);

  // Keeps frame `depth` (in the depth camera; T_O_C its pose in the object's frame) with its
  // colour image (camera.colour: intrinsics, T_D_RGB). `carve_only` flags pixels that are not
  // fused (the robot, the table); `sigma_m` pixels without a positive σ are not fused either.
  // Nothing is kept where no fused pixel projects into the colour image, or when the images'
  // sizes are not the cameras'. `robot_in_colour` (may be null): the robot's own depth as the
  // colour camera sees it (robotDepthImage from the colour camera's pose; 0 where it is not);
  // where it lies in front of the object's surface or touches it (less than 1 cm behind), the
  // colour is the robot's: a finger on the object covers it in the colour camera at its depth,
  // where the depth camera, 2.5 cm aside, may see the surface beside it.
  // Whether the next frame added (of the cameras' sizes) is kept: every stride()-th one is.
  bool keepsNext() const { return added_ % stride_ == 0; }
  void add(const DepthImage& depth, const RgbImage& colour, const Iso3& T_O_C,
           const DepthCameraOptions& camera, const std::vector<float>& sigma_m,
           const std::vector<uint8_t>* carve_only = nullptr,
           const DepthImage* robot_in_colour = nullptr);

  // The colour (0–255) at p_O on a surface whose outward unit normal is n_O, from the frames
  // that saw p_O (its depth in the frame within 1 cm of the surface's there, nothing nearer at
  // its colour pixel or beside it): each frame's colour at the pixel p_O falls in (a measured
  // colour, not a blend of pixels), as linear intensity divided by the shading
  // 1 − falloff · (1 − cos θ), weighted by exp(kAngleSharpness · (cos θ − 1)), θ between n_O and
  // the direction to the colour camera (at most 70°). Of these, the weighted median of each
  // channel, then the weighted mean of the sights within kAgreeLevels of it in every channel: near
  // a colour edge the sights that fell across it (a pose a little off, a pixel half over the edge)
  // are left out, not blended in. Sights at a depth edge (within 2 pixels of no depth, a jump over
  // 1 cm, the robot's or the table's pixels) count only where no frame saw p_O away from one (a
  // finger's rim the robot's mask missed shows the finger's colour there). False where no frame saw
  // it.
  bool at(const Vec3& p_O, const Vec3& n_O, Vec3f* rgb, double falloff = 0) const;

  // The share of the light that falls off with the angle between the surface and the camera's
  // ray (a light at the camera beside the room's: shading 1 − k · (1 − cos θ), 1 head-on), in
  // 0–0.9, fitted to the frames: the k that makes the luminance each vertex shows (every 8th
  // vertex seen over a range of angles, away from depth edges) vary least from frame to frame.
  // 0 when the frames show no such fall-off (the room's light alone).
  double shadingFalloff(const TriangleMesh& mesh, const std::vector<Vec3f>& normals) const;

  // e^-1 of the weight 37° off head-on, e^-2.5 at 60°: the median has several frames to choose
  // among, the head-on ones weigh most.
  static constexpr double kAngleSharpness = 5;
  static constexpr double kAgreeLevels = 12;  // sRGB levels (0-255)

  // The frames kept and the keeping's state, binary (checkpoints); read() replaces them and
  // returns what is wrong with the data (empty: nothing), leaving them empty then.
  void write(std::ostream& out) const;
  std::string read(std::istream& in);

  size_t frames() const { return frames_.size(); }  // frames kept
  size_t bytes() const { return bytes_; }
  int stride() const { return stride_; }  // every stride-th frame added is kept
  bool empty() const { return frames_.empty(); }

 private:
  struct Frame {
    int index = 0;              // the frame's number among those added
    Iso3 T_RGB_O;               // the object's frame in the colour camera's
    CameraIntrinsics K;         // the colour camera's
    int u0 = 0, v0 = 0;         // the box's first pixel in the colour image
    RgbImage rgb;               // the box
    std::vector<float> z;       // per pixel of the box: the surface's depth (m); 0: none, < 0:
                                // something that is not the object nearer
    std::vector<uint8_t> edge;  // per pixel of the box: 1 at a depth edge
    size_t bytes() const { return rgb.rgb.size() + z.size() * sizeof(float) + edge.size(); }
  };
  // Calls fn(frame, cos θ, x, y, at an edge) for every frame that saw p_O (as at()).
  template <class Fn>
  void sights(const Vec3& p_O, const Vec3& n_O, Fn&& fn) const;

  std::vector<Frame> frames_;
  size_t budget_ = 0, bytes_ = 0;
  int stride_ = 1, added_ = 0;
};

// Per vertex: its colour from the frames (ColourFrames::at, the mesh's area-weighted vertex
// normals; with `light_at_camera`, the shading fall-off shadingFalloff fits divided out) where
// they saw it, else from `volume` (ColourVolume::at), alpha 255; mid grey with alpha 0 where
// neither has colour. `falloff` (optional) receives the fall-off used (0 without
// light_at_camera). Both cores.
std::vector<std::array<uint8_t, 4>> vertexColours(const ColourFrames& frames,
                                                  const ColourVolume& volume,
                                                  const TriangleMesh& mesh, bool light_at_camera,
                                                  double* falloff = nullptr);

}  // namespace inhand
