#pragma once
// Colour in the volume: each voxel near the observed surface keeps a weighted mean of the colours
// seen there, weighted like its signed distance (1/σ² of the depth measurement) times the cosine
// of the viewing angle squared, so that head-on, near views dominate grazing, far ones. Stored
// sparsely (only voxels a measured surface point lies beside), in the volume's grid.
#include <array>
#include <cstdint>
#include <unordered_map>
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

  size_t voxels() const { return sums_.size(); }  // voxels with colour
  size_t bytes() const;                           // memory the colour takes, roughly
  bool empty() const { return sums_.empty(); }

  struct Sum {
    float w = 0, r = 0, g = 0, b = 0;
  };
  const std::unordered_map<size_t, Sum>& sums() const { return sums_; }
  std::unordered_map<size_t, Sum>& sums() { return sums_; }

 private:
  Vec3i dims_;
  Vec3 origin_;
  double voxel_;
  std::unordered_map<size_t, Sum> sums_;
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

}  // namespace inhand
