#pragma once
// A textured mesh for tools that take one (model-based pose estimators, renderers, game engines):
// a texture atlas baked from a colour given at every point of the surface, and the two file
// forms such tools read, glTF 2.0 binary (.glb) and Wavefront OBJ with its MTL and PNG.
//
// The atlas gives every triangle a cell of its own: an (n + 2) × (n + 2) texel square in which
// the triangle is the right isosceles half of the inner n × n (corner 0 at the inner square's
// corner, corners 1 and 2 along its two sides), n the triangle's longest edge over the texel
// size; every texel of the cell, its one-texel margin included, takes the colour of the nearest
// point of the triangle, so that bilinear filtering never reads another triangle's colours.
// Cells are packed in rows, largest first.
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

struct TextureAtlas {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // row-major from the top row, 4 bytes per texel (sRGB + alpha)
  std::vector<Vec2f> uv;      // 3 per triangle: (u right, v down) in [0, 1], glTF's convention
  double texel_m = 0;  // the texel size the atlas was baked at (it may be coarser than asked)
  bool empty() const { return width == 0 || height == 0; }
};

// The colour (sRGB 0–255 and alpha) at barycentric (b1, b2) of triangle `tri`, point p.
using SurfaceColourFn =
    std::function<std::array<uint8_t, 4>(int tri, float b1, float b2, const Vec3& p)>;

// Bakes `colour` into an atlas at `texel_m` (> 0). Where the atlas would be wider or taller than
// `max_side` texels the texel size doubles until it fits (TextureAtlas::texel_m says which was
// used). Throws Error on an empty mesh or a texel size that is not positive.
TextureAtlas bakeTextureAtlas(const TriangleMesh& mesh, const SurfaceColourFn& colour,
                              double texel_m, int max_side = 8192);

// The per-vertex colours `rgba` (one per vertex) interpolated over each triangle, baked into an
// atlas (alpha interpolated likewise: 0 where no colour was seen stays 0 between such vertices).
TextureAtlas bakeVertexColours(const TriangleMesh& mesh,
                               const std::vector<std::array<uint8_t, 4>>& rgba, double texel_m,
                               int max_side = 8192);

// glTF 2.0 binary: one mesh, one primitive (positions in metres, smooth normals, TEXCOORD_0; three
// vertices per triangle, not indexed), one material whose base colour texture is the atlas (PNG,
// RGBA, embedded; alpha mode opaque, so the alpha channel is data: 0 marks texels where no colour
// was seen). The node turns the mesh's z-up frame into glTF's y-up one (a rotation of −90° about
// x); the vertices themselves are in the mesh's frame. Atomic. Throws Error naming the file.
void writeGlb(const std::filesystem::path& path, const TriangleMesh& mesh,
              const TextureAtlas& atlas);

// Wavefront OBJ (`v`, `vt` with v up, `vn`, `f v/vt/vn`) with `mtllib` naming `<stem>.mtl`, whose
// one material's `map_Kd` is `<stem>_texture.png` (RGBA), all three written beside `path`, each
// atomically (the texture first, the OBJ last). Throws Error naming the file.
void writeTexturedObj(const std::filesystem::path& path, const TriangleMesh& mesh,
                      const TextureAtlas& atlas);

// PNG bytes of an 8-bit image with `channels` 3 (RGB) or 4 (RGBA), rows from the top.
std::vector<uint8_t> encodePng(const uint8_t* pixels, int width, int height, int channels);

}  // namespace inhand
