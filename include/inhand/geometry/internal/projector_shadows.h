#pragma once
// Projector shadows of a rectified structured-light pair, without casting a ray.
//
// The projector sits at (b, 0, 0) in the camera frame (on the camera's x axis, axes parallel).
// The segment from a surface point on the camera's sample row j to the projector lies in the
// plane through both centres and that row (its epipolar plane), and along it the projector-image
// column W = x − (f_x·b / stride)·(1/z) (x the camera's sample column, z the depth) is constant
// while 1/z grows towards the projector. So the segment is blocked exactly when some triangle
// covers the point (W, j) of the projector's image (in the camera's sample units) with a 1/z
// there greater than the point's own (plus a margin): a z-test in the projector's image, but at
// each point's own W, not at grid positions, so no blocker is missed for being thinner than a
// sample (the weakness of a shadow map). Each triangle is walked over the sample rows it spans and
// tested against the points whose W falls in its span on that row (points are bucketed by row and
// by whole W). Coverage is inclusive on the edges: a segment through a shared edge is blocked.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "inhand/core/error.h"
#include "inhand/geometry/internal/raster.h"
#include "inhand/geometry/triangle_mesh.h"

namespace inhand {

class ProjectorShadows {
 public:
  // Whether a projector at projector_C (camera frame) is rectified with the camera: on its x axis.
  static bool applicable(const Vec3& projector_C) {
    return projector_C.y() == 0 && projector_C.z() == 0 && projector_C.x() != 0;
  }

  // Starts a view: camera intrinsics K, the sample window, the projector's offset b along x.
  void reset(const PinholeProjection& K, const RasterWindow& window, double baseline_x_m);
  // Adds a point on sample row j (window.j0 ≤ j ≤ window.j1) at sample column x with inverse
  // depth iz; it is blocked by a surface whose 1/z on its projector ray is at least iz_block
  // (> iz: nearer than the point by the margin). Returns the point's index.
  int add(int j, double x, double iz, double iz_block) {
    const double W = x - shift_ * iz;
    INHAND_CHECK(std::isfinite(W) && std::isfinite(iz_block) && j >= window_.j0 && j <= window_.j1,
                 "ProjectorShadows::add: a finite point on a window row");
    points_.push_back({j, W, iz_block});
    minIzBlock_ = std::min(minIzBlock_, iz_block);
    minW_ = std::min(minW_, W);
    maxW_ = std::max(maxW_, W);
    return int(points_.size()) - 1;
  }
  // After the last add and before the first draw: buckets the points.
  void index();
  // Marks the points that triangles of `mesh`, placed in the camera frame by T_C_mesh, block.
  // `cull_back_faces`: skip triangles facing away from the projector (exact for a closed,
  // outward-oriented mesh with the projector outside it: a blocked segment leaves the solid for
  // the last time through a face that faces the projector). `projected`: the mesh's vertices as a
  // DepthRaster just projected them for this camera and window (saves projecting them again).
  // `bounds`: the mesh's bounding box in its own frame, when known: a mesh whose box can block
  // no point (behind the near plane or every point, or beside them in the projector's image) is
  // skipped whole. `only`: with cull_back_faces, a bit per triangle (TriangleFacing::mayFace for
  // the projector): triangles whose bit is clear face away and are not looked at.
  void draw(const TriangleMesh& mesh, const Iso3& T_C_mesh, bool cull_back_faces,
            const std::vector<DepthRaster::ProjectedVertex>* projected = nullptr,
            const Aabb* bounds = nullptr, const std::vector<uint64_t>* only = nullptr);

  // Whether draw() sets triangles up four at a time in AVX2 (when the CPU has it; the default),
  // or one at a time. Both block the same points; returns the setting in effect.
  bool setVectorised(bool on) {
    vectorised_ = on && DepthRaster::avx2Available();
    return vectorised_;
  }

  int size() const { return int(points_.size()); }
  bool blocked(int k) const { return sortedBlocked_[size_t(position_[size_t(k)])] != 0; }

 private:
  struct Point {
    int j;
    double W, izBlock;
  };
  // One triangle in projector-image coordinates (W, y) with its 1/z at the corners.
  void triangle(const double* W, const double* y, const double* iz, bool cull);
  // A triangle's set-up for the walk over its rows: edge k is eW[k·step]·W + eY[k·step]·y +
  // e0[k·step] (≥ 0 inside), 1/z·|area| is zW·W + zY·y + z0, over rows ja..jb and W in
  // [Wmin, Wmax].
  struct RowWalk {
    const double *eW, *eY, *e0;
    int step;
    double zW, zY, z0, absArea, Wmin, Wmax;
    int ja, jb;
  };
  // Row j of the walk: the edge functions and 1/z·|area| at W = 0 of that row (base, zRow) and
  // the sorted points [s0, s1) it may block; false when it can block none there.
  bool rowSpan(const RowWalk& t, bool wide, int c0, int c1, int j, double* base, double* zRow,
               int* s0, int* s1) const;
  // triangle()'s walk over the rows, one point at a time.
  void triangleRows(const RowWalk& t);
  // The same walk testing four points at a time (AVX2): the same points come out blocked.
  void triangleRowsFour(const RowWalk& t);
  // triangle() for the four triangles k[0..3] at once (AVX2), their corners projected in
  // `verts`; returns a bit per triangle left to the one-at-a-time path (the clipped ones).
  int drawFour(const TriangleMesh& mesh, const DepthRaster::ProjectedVertex* verts, const size_t* k,
               bool cull);
  bool vectorised_ = DepthRaster::avx2Available();
  // A triangle given in the camera frame, clipped at the near plane first.
  void triangleCamera(const Vec3& a, const Vec3& b, const Vec3& c, bool cull);

  PinholeProjection K_;
  RasterWindow window_;
  double baseline_ = 0;         // the projector's x in the camera frame, m
  double shift_ = 0;            // f_x·b / stride: W = x − shift·iz
  double minIzBlock_ = 0;       // a triangle whose corners all lie farther than this blocks nothing
  double minW_ = 0, maxW_ = 0;  // the points' W range
  std::vector<Point> points_;
  // Bucketed points: bucket (r, c), r = j − j0, c = ⌊W⌋ − base_, is r·pitch_ + c and holds the
  // points [first_[b], first_[b + 1]) of the sorted arrays.
  int base_ = 0, pitch_ = 0;
  std::vector<int> first_;
  std::vector<double> rowMinIzBlock_;  // per row: the least iz_block of its points (∞: none)
  // The points in bucket order: their W and iz_block, with four entries of padding (loads four
  // at a time start at most at the last point's index + 1: an empty row at the end).
  std::vector<double> sortedW_, sortedIzBlock_;
  std::vector<uint8_t> sortedBlocked_;
  std::vector<int> position_;  // point k sits at position_[k] of the sorted arrays
  std::vector<DepthRaster::ProjectedVertex> verts_;
};

}  // namespace inhand
