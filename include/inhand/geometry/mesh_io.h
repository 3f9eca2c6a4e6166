#pragma once
#include <array>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "inhand/geometry/appearance.h"
#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

// Imports a mesh file: PLY, OBJ and STL with inhand's own readers (errors name the line or
// field), everything else with assimp (OFF, glTF, DAE, 3DS, …).
// Missing material files are ignored; all sub-meshes are merged with their node transforms applied;
// vertices are welded. Coordinates are taken as metres. Throws Error naming the file on failure.
TriangleMesh importMesh(const std::filesystem::path& path);

// Imports a mesh with its colours: OBJ with its MTL (`Kd`, `map_Kd` PNG or JPEG textures, `vt`
// coordinates), PLY with per-vertex `red`/`green`/`blue`, anything else as importMesh reads it
// (flat grey). Vertices are welded as importMesh welds them. Throws Error naming the file (the
// MTL or the texture as well) when something cannot be read; a texture that is not PNG or JPEG
// is an error, not a silent grey.
TexturedMesh importTexturedMesh(const std::filesystem::path& path);

// Per-vertex colour from variance (m²), the paper's convention: grey where confident, through
// shades of pink for low confidence, to red for never-observed (hole-filled, σ ≥ 5 cm) surface.
std::array<uint8_t, 3> confidenceColor(float variance_m2);

struct PlyData {
  TriangleMesh mesh;
  std::map<std::string, std::vector<float>> vertexProperties;  // other than x, y, z
};

// Writes binary little-endian PLY with float x, y, z; a float `variance` (m²) per vertex when
// given (size must match); and uchar red, green, blue per vertex (confidenceColor of the variance)
// when variance is given; with `rgba` (per vertex) red, green, blue are those colours instead and
// an alpha follows. Atomic: the file appears whole or not at all. Throws Error on failure.
void writePly(const std::filesystem::path& path, const TriangleMesh& mesh,
              const std::vector<float>* variance_m2 = nullptr,
              const std::vector<std::array<uint8_t, 4>>* rgba = nullptr);

// Writes binary STL (float coordinates, each triangle's unit normal). Atomic. Throws Error on
// failure.
void writeStl(const std::filesystem::path& path, const TriangleMesh& mesh);

// Reads a PLY file (ASCII, binary little- or big-endian) keeping every per-vertex scalar property.
// Faces must be a list property; polygons are fan-triangulated. Throws Error naming the file.
PlyData readPly(const std::filesystem::path& path);

}  // namespace inhand
