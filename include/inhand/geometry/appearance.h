#pragma once
// What a surface looks like: 8-bit RGB images (PNG in and out), the colour of a mesh's surface
// (texture images addressed by per-corner texture coordinates, per-vertex colours, or one flat
// colour per material), and colour differences (CIELAB ΔE76) for judging a scanned colour.
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

struct RgbImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // row-major, 3 bytes per pixel (sRGB)

  RgbImage() = default;
  RgbImage(int w, int h) : width(w), height(h), rgb(size_t(w) * size_t(h) * 3, 0) {}
  bool empty() const { return width <= 0 || height <= 0; }
  const uint8_t* at(int u, int v) const {
    return &rgb[(size_t(v) * size_t(width) + size_t(u)) * 3];
  }
  uint8_t* at(int u, int v) { return &rgb[(size_t(v) * size_t(width) + size_t(u)) * 3]; }
  // Bilinear sample at continuous pixel coordinates (pixel centres at integers), clamped to
  // the image; 0–255 per channel.
  Vec3f bilinear(double x, double y) const;
};

// Reads an 8- or 16-bit PNG (grey, grey + alpha, RGB, RGBA or palette) as 8-bit RGB (alpha
// dropped, not composited). Throws Error naming the file when it is missing, not a PNG or corrupt.
RgbImage readRgbPng(const std::filesystem::path& path);
// Reads a baseline or progressive JPEG (grey or colour) as 8-bit RGB; throws Error naming the file.
RgbImage readRgbJpeg(const std::filesystem::path& path);
// PNG or JPEG by the file's extension (.png, .jpg, .jpeg; any case); other extensions are an
// Error naming the file.
RgbImage readRgbImage(const std::filesystem::path& path);
// Writes an 8-bit RGB PNG atomically; throws Error naming the path.
void writeRgbPng(const std::filesystem::path& path, const RgbImage& image);

// One material: a diffuse colour and, optionally, a texture image that replaces it.
struct Material {
  std::string name;
  std::array<uint8_t, 3> diffuse{180, 180, 180};
  RgbImage texture;  // empty: the diffuse colour
};

// The colour of every point of a mesh's surface (its albedo, sRGB 0–255). Triangles are addressed
// by index: a triangle past the end of the per-triangle arrays (one a hole filler added) has
// `fallback`.
struct SurfaceColours {
  std::vector<Material> materials;
  std::vector<int> triangle_material;  // per triangle: index into materials, or -1 (fallback)
  std::vector<Vec2f> corner_uv;        // 3 per triangle (texture u right, v up), or empty
  std::vector<std::array<uint8_t, 3>> vertex_rgb;  // per vertex, or empty
  std::array<uint8_t, 3> fallback{180, 180, 180};

  bool empty() const { return materials.empty() && vertex_rgb.empty(); }
  // The colour at barycentric (b1, b2) of triangle `tri` (point = (1−b1−b2)·a + b1·b + b2·c):
  // per-vertex colours interpolated where there are any, else the triangle's material (its
  // texture sampled bilinearly at the interpolated coordinates, repeating outside [0, 1]).
  Vec3f at(const TriangleMesh& mesh, int tri, float b1, float b2) const;
  // Keeps the entries of the triangles `kept` lists (kept[i]: the old index of new triangle i).
  SurfaceColours withTriangles(const std::vector<int>& kept) const;
};

struct TexturedMesh {
  TriangleMesh mesh;
  SurfaceColours colours;
};

// A checkerboard of `square_m` squares in two colours over the whole surface: each triangle
// textured by projecting its corners along the axis nearest its normal (a box's faces get true
// squares), so that the colour anywhere on the surface is known exactly.
SurfaceColours checkerColours(const TriangleMesh& mesh, double square_m,
                              std::array<uint8_t, 3> a = {200, 40, 40},
                              std::array<uint8_t, 3> b = {235, 225, 190});
// The built-in objects' checker square when the colour camera is on (2 cm).
constexpr double kBuiltinCheckerSquare_m = 0.02;

// An sRGB value (0–255) as linear intensity (0–1), and back (clamped to 0–255, not rounded).
double srgbToLinear(double c255);
double linearToSrgb(double linear);
// CIELAB (D65 white) of an sRGB colour given as 0–255 per channel.
Vec3 srgbToLab(const Vec3f& rgb255);
// ΔE76: the Euclidean distance between two colours in CIELAB.
double deltaE76(const Vec3f& a_rgb255, const Vec3f& b_rgb255);

}  // namespace inhand
