#pragma once
// A z-buffer rasteriser for pinhole cameras: which triangle, if any, is nearest along the ray of
// each sample pixel. It answers the same question as casting one ray per pixel through
// (u, v) = sample (rayZ1(u, v) = ((u − cx)/fx, (v − cy)/fy, 1)), but walks the triangles instead
// of the rays: for meshes of sub-pixel triangles seen from one viewpoint it is several times
// cheaper than a BVH traversal per pixel. Coverage uses edge functions inclusive on the edges
// (a sample on a shared edge is covered by both triangles; the z-test keeps either), depth the
// triangle's plane (1/z is affine in the image). Triangles crossing the near plane are clipped.
#include <cstdint>
#include <vector>

// The four-triangle set-up needs GCC or Clang on x86-64 (function-level AVX2, chosen at run time).
#if defined(__x86_64__) && defined(__GNUC__)
#define INHAND_RASTER_AVX2 1
#else
#define INHAND_RASTER_AVX2 0
#endif

#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

// Samples (i, j) at pixel (i·stride, j·stride) for i in [i0, i1], j in [j0, j1].
struct RasterWindow {
  int i0 = 0, i1 = -1, j0 = 0, j1 = -1;
  int stride = 1;
  int width() const { return i1 - i0 + 1; }
  int height() const { return j1 - j0 + 1; }
  int size() const { return width() > 0 && height() > 0 ? width() * height() : 0; }
};

struct PinholeProjection {
  double fx = 1, fy = 1, cx = 0, cy = 0;
};

// floor and ceil to int without a libm call (the baseline x86-64 has no SSE4.1 rounding);
// arguments are clamped to ±1e9 first, far outside any window.
inline int floorToInt(double x) {
  x = x < -1e9 ? -1e9 : (x > 1e9 ? 1e9 : x);
  const int i = int(x);
  return i - (x < double(i));
}
inline int ceilToInt(double x) {
  x = x < -1e9 ? -1e9 : (x > 1e9 ? 1e9 : x);
  const int i = int(x);
  return i + (x > double(i));
}

// Where a box (a mesh's bounds, placed in the camera frame by T_C_box) can appear to a pinhole
// at the camera centre shifted by `shift_x_m` along x (0: the camera itself; a rectified
// projector): its depth range, and, when every corner is in front of `near`, the range of its
// image coordinates in samples (the hull of the corners' projections holds the box's).
struct BoxInView {
  double zmin, zmax;
  bool allInFront;
  double xmin, xmax, ymin, ymax;
};
BoxInView boxInView(const Aabb& box, const Iso3& T_C_box, const PinholeProjection& K, int stride,
                    double shift_x_m, double near);

// Sutherland–Hodgman of the camera-frame triangle (a, b, c) against z = near: the part in front
// as a convex polygon of 0, 3 or 4 corners in `poly` (the count is returned), drawn as a fan
// around poly[0] whose pieces stay on the triangle's plane (so 1/z stays affine across it).
int clipToNearPlane(const Vec3& a, const Vec3& b, const Vec3& c, double near, Vec3 poly[4]);

// Each triangle's plane in float (unit normal n_k, offset n_k·a_k), packed for facing tests of
// all the triangles at once: which may face a viewpoint e (n_k·e > offset_k). A rasteriser that
// culls back faces then loads only those triangles' corners. The test is conservative: a
// triangle facing away by less than 1e-5 of the distance scale (edge-on, where float rounding
// could decide) counts as facing, and its own culling decides; a triangle with no normal
// (degenerate) always counts.
class TriangleFacing {
 public:
  TriangleFacing() = default;
  explicit TriangleFacing(const TriangleMesh& mesh);
  // Bit k % 64 of (*bits)[k / 64]: triangle k may face `eye_M` (a point in the mesh's frame).
  void mayFace(const Vec3& eye_M, std::vector<uint64_t>* bits) const;
  int size() const { return int(nx_.size()); }

 private:
  std::vector<float> nx_, ny_, nz_, offset_;
  double scale_ = 0;  // the largest |corner| of the mesh, m
};

// Calls fn(k) for each triangle k < n whose bit is set in `only` (as TriangleFacing::mayFace
// fills it), or for every k when `only` is null, in increasing order.
template <typename Fn>
inline void forEachMarked(size_t n, const std::vector<uint64_t>* only, Fn&& fn) {
  for (size_t word = 0; word < (n + 63) / 64; ++word) {
    uint64_t bits = only ? (*only)[word] : ~uint64_t(0);
    if (!only && word * 64 + 64 > n) bits = (uint64_t(1) << (n - word * 64)) - 1;
    for (; bits; bits &= bits - 1) fn(word * 64 + size_t(__builtin_ctzll(bits)));
  }
}

// forEachMarked in groups of four: four(k) takes the triangles k[0..3] at once and returns a bit
// per triangle it leaves to one(k[l]); the last (fewer than four) go to one() directly.
template <typename Four, typename One>
inline void forEachMarkedInFours(size_t n, const std::vector<uint64_t>* only, Four&& four,
                                 One&& one) {
  size_t batch[4];
  int m = 0;
  forEachMarked(n, only, [&](size_t k) {
    batch[m++] = k;
    if (m < 4) return;
    m = 0;
    for (int rest = four(static_cast<const size_t*>(batch)); rest; rest &= rest - 1)
      one(batch[__builtin_ctz(unsigned(rest))]);
  });
  for (int q = 0; q < m; ++q) one(batch[q]);
}

class DepthRaster {
 public:
  // Empties the buffer (every sample: nothing hit) for a new view.
  void reset(const PinholeProjection& K, const RasterWindow& window);
  // Draws `mesh` placed in the camera frame by T_C_mesh (camera looks along +z). Sample ids are
  // id_base + triangle index. Only triangles nearer than what is already there win.
  // `cull_back_faces`: skip triangles that face away from the camera (wound clockwise as seen
  // from it). Exact for a closed, outward-oriented mesh seen from outside (every ray enters it
  // through a front face first), and about half the work.
  // `max_depth` > 0: triangles whose three vertices all lie deeper than it are skipped, and
  // large triangles' samples deeper than it may be (for occluders of something known to be
  // nearer).
  // `bounds`: the mesh's bounding box in its own frame, when known: a mesh whose box lies
  // entirely behind the near plane, beyond max_depth or outside the window is skipped whole.
  // `only`: with cull_back_faces, a bit per triangle (TriangleFacing::mayFace for the camera):
  // triangles whose bit is clear face away and are not looked at.
  void draw(const TriangleMesh& mesh, const Iso3& T_C_mesh, int id_base = 0,
            bool cull_back_faces = false, double max_depth = 0, const Aabb* bounds = nullptr,
            const std::vector<uint64_t>* only = nullptr);
  // Draws an occluder over what draw() left: a sample that holds a surface (id ≥ 0) and that
  // `mesh` covers nearer takes id kOccluded and the occluder's 1/z; a sample that holds nothing
  // stays empty (an occluder in front of nothing hides nothing). So after the surfaces of
  // interest and then every occluder, id(s) == kOccluded exactly where the nearest occluder is
  // nearer than the nearest surface. Options as draw's. Wide triangles visit only the part of
  // each row between its first and last surface sample.
  void drawOccluder(const TriangleMesh& mesh, const Iso3& T_C_mesh, bool cull_back_faces = false,
                    double max_depth = 0, const Aabb* bounds = nullptr);
  static constexpr int kOccluded = -2;
  // Whether draw() sets triangles up four at a time in AVX2 (when the CPU has it; the default),
  // or one at a time. Both give the same buffers bit for bit; returns the setting in effect.
  bool setVectorised(bool on) {
    vectorised_ = on && avx2Available();
    return vectorised_;
  }
  // Whether this build and CPU can run the AVX2 set-up.
  static bool avx2Available();
  // Draws one triangle given in the camera frame.
  void drawTriangle(const Vec3& a, const Vec3& b, const Vec3& c, int id);

  const RasterWindow& window() const { return window_; }
  // The first and last column of window row j with a sample that holds a surface (or, after
  // drawOccluder, kOccluded); first > last: none. Every sample outside them is empty.
  void rowExtent(int j, int* first, int* last) {
    if (!extentsValid_) findRowExtents();
    *first = rowFirst_[size_t(j - window_.j0)];
    *last = rowLast_[size_t(j - window_.j0)];
  }
  // Sample index of (i, j) in the window, row-major.
  int index(int i, int j) const { return (j - window_.j0) * window_.width() + (i - window_.i0); }
  // 1/depth of the nearest surface at sample s (0: none), and its id (-1: none).
  float inverseDepth(int s) const { return invZ_[size_t(s)]; }
  int id(int s) const { return id_[size_t(s)]; }

  static constexpr double kNear = 1e-3;  // near clipping plane, m

  // Each vertex in sample coordinates with its 1/z (iz < 0: behind the near plane), packed so a
  // triangle's corners cost three cache lines, not twelve.
  struct ProjectedVertex {
    double x, y, iz;
  };
  // The vertices of the mesh last passed to draw() (not drawOccluder), as it projected them.
  const std::vector<ProjectedVertex>& projected() const { return verts_; }
  // Each vertex of `mesh` into the camera frame and, in front of the near plane, to sample
  // coordinates and 1/z (iz = −1 behind it).
  static void projectVertices(const TriangleMesh& mesh, const Iso3& T_C_mesh,
                              const PinholeProjection& K, int stride,
                              std::vector<ProjectedVertex>* out);

 private:
  // Fills the samples of [ia, ib] × [ja, jb] inside the triangle (px, py) (sample coordinates,
  // signed doubled area `area`), with 1/z interpolated from the vertices' piz.
  // Over: occluder mode (drawOccluder): only samples with id ≥ 0 are candidates, and wide rows
  // are clipped to [rowFirst_, rowLast_].
  template <bool Over>
  void fill(const double* px, const double* py, const double* piz, int ia, int ib, int ja, int jb,
            double area, int id);
  // The same for a bounding box of at most 4 × 4 samples that ends at least 4 samples before the
  // window's right edge: four samples of a row at once (SSE2), edge functions in float relative
  // to the box's corner. Agrees with fill() except for samples within float rounding (~1e-6
  // sample) of an edge.
  template <bool Over>
  void fillSmall(const double* px, const double* py, const double* piz, int ia, int ib, int ja,
                 int jb, double area, int id);
  // fillSmall's rows, from its set-up: edge e is A[e·step]·i + B[e·step]·j + C[e·step] and 1/z
  // is zi·i + zj·j + z0, with (i, j) relative to (ia, ja).
  template <bool Over>
  void fillSmallRows(const double* A, const double* B, const double* C, int step, double zi,
                     double zj, double z0, int ia, int ib, int ja, int jb, int id);
  // fillSmallRows (surface mode) for a set-up transposed by drawFour (AVX2).
  void fillSmallRowsFour(const double* a, const double* b, const double* c, int ia, int ib, int ja,
                         int jb, int id);
  // draw()'s per-triangle steps for the four triangles k[0..3] of a surface mesh at once
  // (AVX2): fills those that need fillSmall; returns a bit per triangle left to the
  // one-at-a-time path.
  int drawFour(const TriangleMesh& mesh, const size_t* k, int id_base, bool cull);
  bool vectorised_ = avx2Available();
  // The triangles of `mesh` (draw's loop), in surface or occluder mode.
  template <bool Over>
  void drawMesh(const TriangleMesh& mesh, const Iso3& T_C_mesh, int id_base, bool cull_back_faces,
                double max_depth, const Aabb* bounds, const std::vector<uint64_t>* only);
  template <bool Over>
  void drawClipped(const Vec3& a, const Vec3& b, const Vec3& c, int id);
  // Per row of the window: the first and last sample holding a surface (first > last: none),
  // found once the occluders start.
  void findRowExtents();
  PinholeProjection K_;
  RasterWindow window_;
  double minInvZ_ = 0;  // within draw(): 1/max_depth (0: none); wide fills skip samples beyond
  bool extentsValid_ = false;
  std::vector<int> rowFirst_, rowLast_;
  std::vector<float> invZ_;
  std::vector<int> id_;
  std::vector<ProjectedVertex> verts_, occluderVerts_;
};

}  // namespace inhand
