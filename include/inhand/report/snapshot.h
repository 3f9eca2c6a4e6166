#pragma once
// Quick offline pictures of a model: ray-cast (Embree) views with per-vertex colours and
// headlight shading, tiled into one RGB PNG. For looking at results without a mesh viewer.
#include <array>
#include <filesystem>
#include <vector>

#include "inhand/geometry/appearance.h"
#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

struct SnapshotOptions {
  int tile_px = 400;          // size of each view, pixels
  int columns = 3;            // views per row
  double elevation_deg = 25;  // camera elevation above the object's x–y plane
  int views = 6;              // azimuths spread over 360°, plus one from below when views > 4
};

// Renders `mesh` (colours per vertex, or uniform grey when empty) from several directions.
RgbImage renderSnapshot(const TriangleMesh& mesh, const std::vector<std::array<uint8_t, 3>>& colors,
                        const SnapshotOptions& options = {});

}  // namespace inhand
