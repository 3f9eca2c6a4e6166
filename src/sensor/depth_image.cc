#include "inhand/sensor/depth_image.h"

#include <png.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"

namespace inhand {

int DepthImage::validCount() const {
  int n = 0;
  for (float d : depth_m) n += d > 0;
  return n;
}

namespace {
struct FileCloser {
  void operator()(FILE* f) const {
    if (f) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<FILE, FileCloser>;

[[noreturn]] void pngError(png_structp png, png_const_charp msg) {
  auto* where = static_cast<std::string*>(png_get_error_ptr(png));
  *where += std::string(": ") + msg;
  png_longjmp(png, 1);
}
void pngWarning(png_structp, png_const_charp) {}
}  // namespace

void writeDepthPng(const std::filesystem::path& path, const DepthImage& image, double scale) {
  if (image.width <= 0 || image.height <= 0 ||
      image.depth_m.size() != size_t(image.width) * image.height)
    throw Error(path.string() + ": depth image has inconsistent size");
  std::vector<uint16_t> rows(image.depth_m.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    double units = std::round(image.depth_m[i] / scale);
    rows[i] = (image.depth_m[i] > 0 && units <= 65535.0) ? uint16_t(units) : 0;
  }
  writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
    FilePtr fp(std::fopen(tmp.c_str(), "wb"));
    if (!fp) throw Error(path.string() + ": cannot open for writing");
    std::string message = path.string();
    png_structp png =
        png_create_write_struct(PNG_LIBPNG_VER_STRING, &message, pngError, pngWarning);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info) {
      png_destroy_write_struct(&png, &info);
      throw Error(path.string() + ": cannot initialise libpng");
    }
    if (setjmp(png_jmpbuf(png))) {
      png_destroy_write_struct(&png, &info);
      throw Error(message);
    }
    png_init_io(png, fp.get());
    png_set_compression_level(png, 1);
    png_set_IHDR(png, info, png_uint_32(image.width), png_uint_32(image.height), 16,
                 PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    png_set_swap(png);  // PNG is big-endian; our uint16 are little-endian
    for (int v = 0; v < image.height; ++v)
      png_write_row(png, reinterpret_cast<png_const_bytep>(rows.data() + size_t(v) * image.width));
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    if (std::fflush(fp.get()) != 0) throw Error(path.string() + ": write failed (disk full?)");
  });
}

namespace {

enum class PngProblem { kNone, kCorrupt, kBitDepth, kColour, kSize };

// The setjmp-protected part of reading, with only trivially destructible locals.
PngProblem readPngRows(FILE* fp, std::string* message, int expectedW, int expectedH, int* w, int* h,
                       int* bitDepth, std::vector<uint16_t>* rows) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, message, pngError, pngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_read_struct(&png, &info, nullptr);
    return PngProblem::kCorrupt;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return PngProblem::kCorrupt;
  }
  png_init_io(png, fp);
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  *w = int(png_get_image_width(png, info));
  *h = int(png_get_image_height(png, info));
  *bitDepth = png_get_bit_depth(png, info);
  PngProblem result = PngProblem::kNone;
  if (*bitDepth != 16)
    result = PngProblem::kBitDepth;
  else if (png_get_color_type(png, info) != PNG_COLOR_TYPE_GRAY)
    result = PngProblem::kColour;
  else if (expectedW > 0 && (*w != expectedW || *h != expectedH))
    result = PngProblem::kSize;
  if (result == PngProblem::kNone) {
    png_set_swap(png);
    rows->resize(size_t(*w) * size_t(*h));
    for (int v = 0; v < *h; ++v)
      png_read_row(png, reinterpret_cast<png_bytep>(rows->data() + size_t(v) * size_t(*w)),
                   nullptr);
  }
  png_destroy_read_struct(&png, &info, nullptr);
  return result;
}

}  // namespace

DepthImage readDepthPng(const std::filesystem::path& path, double scale, int expectedW,
                        int expectedH) {
  const std::string where = path.string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error(where + ": no such depth image");
  FilePtr fp(std::fopen(path.c_str(), "rb"));
  if (!fp) throw Error(where + ": cannot open for reading");
  unsigned char sig[8] = {};
  if (std::fread(sig, 1, 8, fp.get()) != 8 || png_sig_cmp(sig, 0, 8) != 0)
    throw Error(where + ": not a PNG file");
  std::string message = where;
  std::vector<uint16_t> rows;
  int w = 0, h = 0, bitDepth = 0;
  switch (readPngRows(fp.get(), &message, expectedW, expectedH, &w, &h, &bitDepth, &rows)) {
    case PngProblem::kNone:
      break;
    case PngProblem::kCorrupt:
      throw Error(message + " (corrupt or truncated PNG)");
    case PngProblem::kBitDepth:
      throw Error(where + ": depth PNG must be 16-bit, this one is " + std::to_string(bitDepth) +
                  "-bit");
    case PngProblem::kColour:
      throw Error(where + ": depth PNG must be single-channel grey");
    case PngProblem::kSize:
      throw Error(where + ": depth PNG is " + std::to_string(w) + "x" + std::to_string(h) +
                  ", expected " + std::to_string(expectedW) + "x" + std::to_string(expectedH) +
                  " (from the intrinsics)");
  }
  DepthImage image(w, h);
  // 0 and 65535 are "no depth" (the sentinels sensors and their drivers write).
  for (size_t i = 0; i < rows.size(); ++i)
    image.depth_m[i] = rows[i] == 65535 ? 0.f : float(rows[i] * scale);
  return image;
}

}  // namespace inhand
