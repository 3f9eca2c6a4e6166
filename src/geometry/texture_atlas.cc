#include "inhand/geometry/texture_atlas.h"

#include <png.h>
#include <setjmp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/json_util.h"

namespace inhand {

namespace {

void appendBytes(png_structp png, png_bytep data, png_size_t n) {
  auto* out = static_cast<std::vector<uint8_t>*>(png_get_io_ptr(png));
  out->insert(out->end(), data, data + n);
}

// libpng's part of encodePng; false when libpng failed (it jumps back here).
bool writePngRows(png_structp png, png_infop info, const uint8_t* pixels, int width, int height,
                  int channels, std::vector<uint8_t>* out) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_write_fn(png, out, appendBytes, nullptr);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8,
               channels == 4 ? PNG_COLOR_TYPE_RGB_ALPHA : PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  const size_t row = size_t(width) * size_t(channels);
  for (int v = 0; v < height; ++v)
    png_write_row(png, const_cast<png_bytep>(pixels + size_t(v) * row));
  png_write_end(png, nullptr);
  return true;
}

// Where each triangle's cell lies in the atlas: its corner (texels) and inner side n.
struct Cell {
  int x = 0, y = 0, n = 1;
};

// Cells of (n + 2)² texels, n = ⌈longest edge / texel⌉, packed in rows of a width near the square
// root of their total area, largest first. Returns the atlas's width and height.
std::pair<int, int> packCells(const TriangleMesh& mesh, double texel_m, std::vector<Cell>* cells) {
  const size_t T = mesh.triangles.size();
  cells->assign(T, Cell{});
  double area = 0;
  for (size_t t = 0; t < T; ++t) {
    const Tri& f = mesh.triangles[t];
    double longest = 0;
    for (int k = 0; k < 3; ++k)
      longest = std::max(
          longest,
          double((mesh.vertices[size_t(f[k])] - mesh.vertices[size_t(f[(k + 1) % 3])]).norm()));
    (*cells)[t].n = std::max(1, int(std::ceil(longest / texel_m - 1e-9)));
    area += double((*cells)[t].n + 2) * double((*cells)[t].n + 2);
  }
  std::vector<size_t> order(T);
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return (*cells)[a].n > (*cells)[b].n; });
  const int widest = (*cells)[order.front()].n + 2;
  const int width = std::max(widest, int(std::ceil(std::sqrt(area) * 1.02)));
  int x = 0, y = 0, rowHeight = 0;
  for (size_t t : order) {
    Cell& c = (*cells)[t];
    const int side = c.n + 2;
    if (x + side > width) {
      y += rowHeight;
      x = 0;
      rowHeight = 0;
    }
    c.x = x;
    c.y = y;
    x += side;
    rowHeight = std::max(rowHeight, side);
  }
  return {width, y + rowHeight};
}

void padTo4(std::string* s, char fill) {
  while (s->size() % 4) s->push_back(fill);
}

template <class T>
void appendRaw(std::vector<uint8_t>* out, const T* data, size_t count) {
  const auto* b = reinterpret_cast<const uint8_t*>(data);
  out->insert(out->end(), b, b + count * sizeof(T));
}

}  // namespace

std::vector<uint8_t> encodePng(const uint8_t* pixels, int width, int height, int channels) {
  if (width <= 0 || height <= 0 || (channels != 3 && channels != 4))
    throw Error("PNG: nothing to encode (" + std::to_string(width) + " x " +
                std::to_string(height) + " x " + std::to_string(channels) + ")");
  std::vector<uint8_t> out;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  const bool ok = png && info && writePngRows(png, info, pixels, width, height, channels, &out);
  png_destroy_write_struct(&png, &info);
  if (!ok) throw Error("PNG: encoding failed");
  return out;
}

TextureAtlas bakeTextureAtlas(const TriangleMesh& mesh, const SurfaceColourFn& colour,
                              double texel_m, int max_side) {
  if (mesh.empty()) throw Error("texture atlas: the mesh has no triangles");
  if (!(texel_m > 0) || !std::isfinite(texel_m))
    throw Error("texture atlas: the texel size must be positive (is " + std::to_string(texel_m) +
                ")");
  std::vector<Cell> cells;
  TextureAtlas atlas;
  atlas.texel_m = texel_m;
  for (;; atlas.texel_m *= 2) {
    std::tie(atlas.width, atlas.height) = packCells(mesh, atlas.texel_m, &cells);
    if (atlas.width <= max_side && atlas.height <= max_side) break;
  }
  atlas.rgba.assign(size_t(atlas.width) * size_t(atlas.height) * 4, 0);
  atlas.uv.resize(mesh.triangles.size() * 3);
  const float W = float(atlas.width), H = float(atlas.height);
  parallelFor(
      0, int(mesh.triangles.size()),
      [&](int t) {
        const Cell& c = cells[size_t(t)];
        const Tri& f = mesh.triangles[size_t(t)];
        const Vec3 a = mesh.vertices[size_t(f[0])].cast<double>(),
                   b = mesh.vertices[size_t(f[1])].cast<double>(),
                   d = mesh.vertices[size_t(f[2])].cast<double>();
        // Corners at the inner square's texel edges: 0 at (1, 1), 1 at (1 + n, 1), 2 at (1, 1 + n).
        const float x0 = float(c.x + 1), y0 = float(c.y + 1), n = float(c.n);
        atlas.uv[size_t(t) * 3] = Vec2f(x0 / W, y0 / H);
        atlas.uv[size_t(t) * 3 + 1] = Vec2f((x0 + n) / W, y0 / H);
        atlas.uv[size_t(t) * 3 + 2] = Vec2f(x0 / W, (y0 + n) / H);
        for (int j = 0; j < c.n + 2; ++j)
          for (int i = 0; i < c.n + 2; ++i) {
            // The texel centre's barycentrics, pulled onto the triangle (margin texels).
            float b1 = std::max(0.f, (float(i) + 0.5f - 1) / n);
            float b2 = std::max(0.f, (float(j) + 0.5f - 1) / n);
            if (b1 + b2 > 1) {
              const float s = b1 + b2;
              b1 /= s;
              b2 /= s;
            }
            const Vec3 p = (1.0 - b1 - b2) * a + double(b1) * b + double(b2) * d;
            const std::array<uint8_t, 4> rgba = colour(t, b1, b2, p);
            std::memcpy(&atlas.rgba[(size_t(c.y + j) * size_t(atlas.width) + size_t(c.x + i)) * 4],
                        rgba.data(), 4);
          }
      },
      64);
  return atlas;
}

TextureAtlas bakeVertexColours(const TriangleMesh& mesh,
                               const std::vector<std::array<uint8_t, 4>>& rgba, double texel_m,
                               int max_side) {
  if (rgba.size() != mesh.vertices.size())
    throw Error("texture atlas: " + std::to_string(rgba.size()) + " vertex colours for " +
                std::to_string(mesh.vertices.size()) + " vertices");
  return bakeTextureAtlas(
      mesh,
      [&](int t, float b1, float b2, const Vec3&) {
        const Tri& f = mesh.triangles[size_t(t)];
        const float w[3] = {1 - b1 - b2, b1, b2};
        std::array<uint8_t, 4> out{};
        for (int ch = 0; ch < 4; ++ch) {
          float v = 0;
          for (int k = 0; k < 3; ++k) v += w[k] * float(rgba[size_t(f[k])][size_t(ch)]);
          out[size_t(ch)] = uint8_t(std::clamp(std::lround(v), 0L, 255L));
        }
        return out;
      },
      texel_m, max_side);
}

namespace {

// The glb's binary chunk: positions, normals and texture coordinates per triangle corner, then
// the PNG, each at a 4-byte offset; where each starts, and the positions' bounds.
struct GlbBuffer {
  std::vector<uint8_t> bin;
  size_t norAt = 0, uvAt = 0, pngAt = 0, pngBytes = 0, corners = 0;
  Vec3f lo = Vec3f::Constant(std::numeric_limits<float>::infinity()), hi = -lo;
};
GlbBuffer glbBuffer(const TriangleMesh& mesh, const TextureAtlas& atlas) {
  const std::vector<Vec3f> normals = vertexNormals(mesh);
  GlbBuffer g;
  g.corners = mesh.triangles.size() * 3;
  std::vector<float> pos, nor, uv;
  pos.reserve(g.corners * 3);
  nor.reserve(g.corners * 3);
  uv.reserve(g.corners * 2);
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const size_t v = size_t(mesh.triangles[t][k]);
      const Vec3f& p = mesh.vertices[v];
      g.lo = g.lo.cwiseMin(p);
      g.hi = g.hi.cwiseMax(p);
      pos.insert(pos.end(), {p.x(), p.y(), p.z()});
      nor.insert(nor.end(), {normals[v].x(), normals[v].y(), normals[v].z()});
      const Vec2f& q = atlas.uv[t * 3 + size_t(k)];
      uv.insert(uv.end(), {q.x(), q.y()});
    }
  const std::vector<uint8_t> png = encodePng(atlas.rgba.data(), atlas.width, atlas.height, 4);
  appendRaw(&g.bin, pos.data(), pos.size());
  g.norAt = g.bin.size();
  appendRaw(&g.bin, nor.data(), nor.size());
  g.uvAt = g.bin.size();
  appendRaw(&g.bin, uv.data(), uv.size());
  g.pngAt = g.bin.size();
  g.pngBytes = png.size();
  g.bin.insert(g.bin.end(), png.begin(), png.end());
  while (g.bin.size() % 4) g.bin.push_back(0);
  return g;
}

}  // namespace

void writeGlb(const std::filesystem::path& path, const TriangleMesh& mesh,
              const TextureAtlas& atlas) {
  if (mesh.empty() || atlas.empty() || atlas.uv.size() != mesh.triangles.size() * 3)
    throw Error(path.string() + ": no textured mesh to write");
  const GlbBuffer g = glbBuffer(mesh, atlas);
  const std::vector<uint8_t>& bin = g.bin;
  const size_t corners = g.corners, posAt = 0, norAt = g.norAt, uvAt = g.uvAt, pngAt = g.pngAt;
  const Vec3f lo = g.lo, hi = g.hi;
  const double s = std::sqrt(0.5);
  Json gltf = {
      {"asset", {{"version", "2.0"}, {"generator", "inhand"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}, {"name", "model"}, {"rotation", {-s, 0.0, 0.0, s}}}}},
      {"meshes",
       {{{"name", "model"},
         {"primitives",
          {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}, {"TEXCOORD_0", 2}}},
            {"material", 0},
            {"mode", 4}}}}}}},
      {"materials",
       {{{"name", "scanned"},
         {"pbrMetallicRoughness",
          {{"baseColorTexture", {{"index", 0}}},
           {"metallicFactor", 0.0},
           {"roughnessFactor", 1.0}}},
         {"doubleSided", false},
         {"extras",
          {{"alpha", "0 where no colour was seen (hole-filled or never-seen surface)"}}}}}},
      {"textures", {{{"source", 0}, {"sampler", 0}}}},
      {"samplers",
       {{{"magFilter", 9729}, {"minFilter", 9729}, {"wrapS", 33071}, {"wrapT", 33071}}}},
      {"images", {{{"bufferView", 3}, {"mimeType", "image/png"}}}},
      {"buffers", {{{"byteLength", bin.size()}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", posAt}, {"byteLength", corners * 12}, {"target", 34962}},
        {{"buffer", 0}, {"byteOffset", norAt}, {"byteLength", corners * 12}, {"target", 34962}},
        {{"buffer", 0}, {"byteOffset", uvAt}, {"byteLength", corners * 8}, {"target", 34962}},
        {{"buffer", 0}, {"byteOffset", pngAt}, {"byteLength", g.pngBytes}}}},
      {"accessors",
       {{{"bufferView", 0},
         {"componentType", 5126},
         {"count", corners},
         {"type", "VEC3"},
         {"min", {lo.x(), lo.y(), lo.z()}},
         {"max", {hi.x(), hi.y(), hi.z()}}},
        {{"bufferView", 1}, {"componentType", 5126}, {"count", corners}, {"type", "VEC3"}},
        {{"bufferView", 2}, {"componentType", 5126}, {"count", corners}, {"type", "VEC2"}}}}};
  std::string json = gltf.dump();
  padTo4(&json, ' ');
  const uint32_t total = uint32_t(12 + 8 + json.size() + 8 + bin.size());
  writeFileAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(path.string() + ": cannot open for writing");
    auto u32 = [&](uint32_t v) { out.write(reinterpret_cast<const char*>(&v), 4); };
    u32(0x46546C67);  // "glTF"
    u32(2);
    u32(total);
    u32(uint32_t(json.size()));
    u32(0x4E4F534A);  // "JSON"
    out.write(json.data(), std::streamsize(json.size()));
    u32(uint32_t(bin.size()));
    u32(0x004E4942);  // "BIN\0"
    out.write(reinterpret_cast<const char*>(bin.data()), std::streamsize(bin.size()));
    if (!out.flush()) throw Error(path.string() + ": write failed");
  });
}

void writeTexturedObj(const std::filesystem::path& path, const TriangleMesh& mesh,
                      const TextureAtlas& atlas) {
  if (mesh.empty() || atlas.empty() || atlas.uv.size() != mesh.triangles.size() * 3)
    throw Error(path.string() + ": no textured mesh to write");
  const std::string stem = path.stem().string();
  const fs::path dir = path.parent_path();
  const std::string texture = stem + "_texture.png", mtl = stem + ".mtl";
  const std::vector<uint8_t> png = encodePng(atlas.rgba.data(), atlas.width, atlas.height, 4);
  writeFileAtomically(dir / texture, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(reinterpret_cast<const char*>(png.data()), std::streamsize(png.size()));
    if (!out.flush()) throw Error((dir / texture).string() + ": write failed");
  });
  writeTextAtomically(dir / mtl,
                      "# inhand: the scanned colours; alpha 0 where none was seen\n"
                      "newmtl scanned\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd " +
                          texture + "\n");
  const std::vector<Vec3f> normals = vertexNormals(mesh);
  std::string s;
  s.reserve(mesh.vertices.size() * 80 + mesh.triangles.size() * 120);
  s += "# inhand scanned model, metres\nmtllib " + mtl + "\nusemtl scanned\n";
  char line[128];
  for (const Vec3f& v : mesh.vertices) {
    std::snprintf(line, sizeof line, "v %.7g %.7g %.7g\n", v.x(), v.y(), v.z());
    s += line;
  }
  for (const Vec3f& n : normals) {
    std::snprintf(line, sizeof line, "vn %.5g %.5g %.5g\n", n.x(), n.y(), n.z());
    s += line;
  }
  for (const Vec2f& q : atlas.uv) {  // OBJ's v runs up the image
    std::snprintf(line, sizeof line, "vt %.7g %.7g\n", q.x(), 1.0 - q.y());
    s += line;
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri& f = mesh.triangles[t];
    std::snprintf(line, sizeof line, "f %d/%zu/%d %d/%zu/%d %d/%zu/%d\n", f[0] + 1, 3 * t + 1,
                  f[0] + 1, f[1] + 1, 3 * t + 2, f[1] + 1, f[2] + 1, 3 * t + 3, f[2] + 1);
    s += line;
  }
  writeTextAtomically(path, s);
}

}  // namespace inhand
