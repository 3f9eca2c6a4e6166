#include "inhand/geometry/appearance.h"

#include <jpeglib.h>
#include <png.h>
#include <setjmp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/geometry/texture_atlas.h"

namespace inhand {

Vec3f RgbImage::bilinear(double x, double y) const {
  x = std::clamp(x, 0.0, double(width - 1));
  y = std::clamp(y, 0.0, double(height - 1));
  const int u0 = std::min(int(x), width - 1), v0 = std::min(int(y), height - 1);
  const int u1 = std::min(u0 + 1, width - 1), v1 = std::min(v0 + 1, height - 1);
  const float fx = float(x - u0), fy = float(y - v0);
  Vec3f out;
  for (int c = 0; c < 3; ++c) {
    const float top = (1 - fx) * at(u0, v0)[c] + fx * at(u1, v0)[c];
    const float bottom = (1 - fx) * at(u0, v1)[c] + fx * at(u1, v1)[c];
    out[c] = (1 - fy) * top + fy * bottom;
  }
  return out;
}

RgbImage readRgbPng(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error(path.string() + ": no such image");
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str()))
    throw Error(path.string() + ": not a readable PNG (" + image.message + ")");
  // Read with alpha and drop it: libpng would composite transparent pixels onto black, and a
  // texture's colour under alpha 0 is its colour all the same.
  image.format = PNG_FORMAT_RGBA;
  if (image.width == 0 || image.height == 0 || image.width > 32768 || image.height > 32768) {
    png_image_free(&image);
    throw Error(path.string() + ": PNG of " + std::to_string(image.width) + "x" +
                std::to_string(image.height) + " pixels (at most 32768 on a side)");
  }
  RgbImage out(int(image.width), int(image.height));
  std::vector<uint8_t> rgba(size_t(image.width) * size_t(image.height) * 4);
  if (!png_image_finish_read(&image, nullptr, rgba.data(), 0, nullptr)) {
    const std::string why = image.message;
    png_image_free(&image);
    throw Error(path.string() + ": corrupt or truncated PNG (" + why + ")");
  }
  for (size_t i = 0, n = rgba.size() / 4; i < n; ++i) std::memcpy(&out.rgb[3 * i], &rgba[4 * i], 3);
  return out;
}

namespace {
// libjpeg reports errors through error_exit, which must not return: back to the reader's setjmp
// with the message kept.
struct JpegError {
  jpeg_error_mgr mgr;
  jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};
void jpegErrorExit(j_common_ptr cinfo) {
  JpegError* e = reinterpret_cast<JpegError*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, e->message);
  longjmp(e->jump, 1);
}
void jpegSilence(j_common_ptr, int) {}
}  // namespace

RgbImage readRgbJpeg(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error(path.string() + ": no such image");
  FILE* fp = std::fopen(path.c_str(), "rb");
  if (!fp) throw Error(path.string() + ": cannot open for reading");
  jpeg_decompress_struct cinfo;
  JpegError err;
  cinfo.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = jpegErrorExit;
  err.mgr.emit_message = jpegSilence;
  RgbImage out;
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&cinfo);
    std::fclose(fp);
    throw Error(path.string() + ": not a readable JPEG (" + err.message + ")");
  }
  jpeg_create_decompress(&cinfo);
  jpeg_stdio_src(&cinfo, fp);
  jpeg_read_header(&cinfo, TRUE);
  cinfo.out_color_space = JCS_RGB;
  jpeg_start_decompress(&cinfo);
  if (cinfo.output_components != 3 || cinfo.output_width > 32768 || cinfo.output_height > 32768) {
    jpeg_destroy_decompress(&cinfo);
    std::fclose(fp);
    throw Error(path.string() + ": JPEG of an unsupported size or colour layout");
  }
  out = RgbImage(int(cinfo.output_width), int(cinfo.output_height));
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW row = out.at(0, int(cinfo.output_scanline));
    jpeg_read_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  std::fclose(fp);
  return out;
}

RgbImage readRgbImage(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".png") return readRgbPng(path);
  if (ext == ".jpg" || ext == ".jpeg") return readRgbJpeg(path);
  throw Error(path.string() + ": not a PNG or JPEG image (by its extension)");
}

void writeRgbPng(const std::filesystem::path& path, const RgbImage& image) {
  if (image.empty()) throw Error(path.string() + ": an empty image cannot be written");
  const std::vector<uint8_t> png = encodePng(image.rgb.data(), image.width, image.height, 3);
  writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
    FILE* fp = std::fopen(tmp.c_str(), "wb");
    if (!fp) throw Error(path.string() + ": cannot open for writing");
    const bool written = std::fwrite(png.data(), 1, png.size(), fp) == png.size();
    const bool closed = std::fclose(fp) == 0;
    if (!written || !closed) throw Error(path.string() + ": PNG write failed");
  });
}

Vec3f SurfaceColours::at(const TriangleMesh& mesh, int tri, float b1, float b2) const {
  const float b0 = 1 - b1 - b2;
  const size_t t = size_t(tri);
  const Tri& f = mesh.triangles[t];
  if (!vertex_rgb.empty() && size_t(f.maxCoeff()) < vertex_rgb.size()) {
    Vec3f c = Vec3f::Zero();
    const float b[3] = {b0, b1, b2};
    for (int k = 0; k < 3; ++k)
      for (int ch = 0; ch < 3; ++ch) c[ch] += b[k] * vertex_rgb[size_t(f[k])][size_t(ch)];
    return c;
  }
  const int mi = t < triangle_material.size() ? triangle_material[t] : -1;
  if (mi < 0 || size_t(mi) >= materials.size()) return Vec3f(fallback[0], fallback[1], fallback[2]);
  const Material& m = materials[size_t(mi)];
  if (m.texture.empty() || corner_uv.size() < 3 * (t + 1))
    return Vec3f(m.diffuse[0], m.diffuse[1], m.diffuse[2]);
  const Vec2f uv = b0 * corner_uv[3 * t] + b1 * corner_uv[3 * t + 1] + b2 * corner_uv[3 * t + 2];
  const double u = uv.x() - std::floor(uv.x()), v = uv.y() - std::floor(uv.y());
  // Texture v runs up from the image's bottom row; pixel centres sit at half-integers of uv·size.
  return m.texture.bilinear(u * m.texture.width - 0.5, (1 - v) * m.texture.height - 0.5);
}

SurfaceColours SurfaceColours::withTriangles(const std::vector<int>& kept) const {
  SurfaceColours out = *this;
  out.triangle_material.clear();
  out.corner_uv.clear();
  for (int old : kept) {
    const size_t o = size_t(old);
    if (o < triangle_material.size()) out.triangle_material.push_back(triangle_material[o]);
    if (3 * o + 2 < corner_uv.size())
      for (int k = 0; k < 3; ++k) out.corner_uv.push_back(corner_uv[3 * o + size_t(k)]);
  }
  return out;
}

SurfaceColours checkerColours(const TriangleMesh& mesh, double square_m, std::array<uint8_t, 3> a,
                              std::array<uint8_t, 3> b) {
  SurfaceColours out;
  Material m;
  m.name = "checker";
  // One period (2 × 2 squares) in 64 × 64 texels: bilinear sampling blurs an edge over 1/64 of it.
  constexpr int kTexels = 64;
  m.texture = RgbImage(kTexels, kTexels);
  for (int v = 0; v < kTexels; ++v)
    for (int u = 0; u < kTexels; ++u) {
      const auto& c = ((u < kTexels / 2) != (v < kTexels / 2)) ? a : b;
      std::copy(c.begin(), c.end(), m.texture.at(u, v));
    }
  out.materials.push_back(std::move(m));
  out.triangle_material.assign(mesh.triangles.size(), 0);
  out.corner_uv.reserve(3 * mesh.triangles.size());
  const double period = 2 * square_m;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Vec3 n = mesh.faceNormal(int(t)).cwiseAbs();
    int axis = 0;
    n.maxCoeff(&axis);
    const int i = (axis + 1) % 3, j = (axis + 2) % 3;
    for (int k = 0; k < 3; ++k) {
      const Vec3f& p = mesh.vertices[size_t(mesh.triangles[t][k])];
      out.corner_uv.emplace_back(float(p[i] / period), float(p[j] / period));
    }
  }
  return out;
}

double srgbToLinear(double c) {
  c /= 255.0;
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

double linearToSrgb(double l) {
  const double c = l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(std::max(l, 0.0), 1 / 2.4) - 0.055;
  return std::clamp(255 * c, 0.0, 255.0);
}

namespace {
double labF(double t) {
  constexpr double d = 6.0 / 29.0;
  return t > d * d * d ? std::cbrt(t) : t / (3 * d * d) + 4.0 / 29.0;
}
}  // namespace

Vec3 srgbToLab(const Vec3f& rgb) {
  const double r = srgbToLinear(rgb[0]), g = srgbToLinear(rgb[1]), b = srgbToLinear(rgb[2]);
  // sRGB (D65) to XYZ, normalised by the D65 white.
  const double X = (0.4124564 * r + 0.3575761 * g + 0.1804375 * b) / 0.95047;
  const double Y = 0.2126729 * r + 0.7151522 * g + 0.0721750 * b;
  const double Z = (0.0193339 * r + 0.1191920 * g + 0.9503041 * b) / 1.08883;
  const double fx = labF(X), fy = labF(Y), fz = labF(Z);
  return Vec3(116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz));
}

double deltaE76(const Vec3f& a, const Vec3f& b) { return (srgbToLab(a) - srgbToLab(b)).norm(); }

}  // namespace inhand
