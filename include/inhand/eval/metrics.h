#pragma once
// Ground-truth metrics of a scan of a known mesh, in the mesh's own frame (the model is written in
// the object's input frame, so the two lie on each other as they are):
//   coverage  — the fraction of uniform samples of the true surface within τ of the observed part
//               of the model (triangles whose three vertices came from measurements, not from the
//               σ = 5 cm hole filling);
//   accuracy  — distances from uniform samples of the observed model surface to the true surface
//               (mean, RMS, 95th percentile);
//   F-score   — at each threshold d: 2PR/(P+R) with precision P the fraction of observed-model
//               samples within d of the truth and recall R the fraction of truth samples within d
//               of the observed model;
//   detached  — the area of the model's connected pieces (triangles sharing vertices, observed or
//               hole-filled) none of whose vertices lies within EvalOptions::detached_m of the true
//               surface: debris that is not the object.
#include <cstdint>
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/appearance.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/mesh/extract.h"
#include "inhand/sensor/depth_camera.h"

namespace inhand {

struct EvalOptions {
  int samples = 20000;   // points drawn on each surface (truth and observed model)
  uint64_t seed = 1;     // of those draws
  double tau_m = 0.003;  // coverage radius τ
  std::vector<double> fscore_m{0.002, 0.005, 0.010};
  double detached_m = 0.005;  // a model piece with no vertex this near the truth is detached

  // The options' rows (core/options.h); the seed is the caller's.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.integer("samples", o.samples, "points drawn on each surface", Range::closed(100, 1e7));
    v.num("tau_m", o.tau_m, "coverage radius τ, m", Range::open(0, 1));
    v.numbers("fscore_m", o.fscore_m, "F-score thresholds, m", Range::open(0, 1));
    v.num("detached_m", o.detached_m,
          "a model piece none of whose vertices lies this near the true surface is detached "
          "(summary detached_area_m2), m",
          Range::open(0, 1));
  }
  std::string validate() const;
};

struct SurfaceMetrics {
  double coverage = 0;  // in [0, 1]
  double accuracy_mean_mm = 0, accuracy_rms_mm = 0, accuracy_p95_mm = 0;
  std::vector<double> fscore, precision, recall;  // one per EvalOptions::fscore_m
  double observed_area_m2 = 0;                    // area of the observed model surface
  double detached_area_m2 = 0;  // area of the model pieces detached from the true surface
  int detached_pieces = 0;      // how many such pieces
};

// The model's colour against the true surface's (issue: colour accuracy): every vertex observed
// (measured, not hole-filled) with colour (alpha 255) against the albedo at the nearest point of
// the true surface, as CIELAB ΔE76.
struct ColourMetrics {
  int vertices = 0;  // vertices compared
  double delta_e_mean = 0, delta_e_p95 = 0;
  // The vertices at a colour edge of the truth (its albedo kColourEdgeRadius_m away along the
  // surface, one of 4 ways, more than kColourEdgeDeltaE from the vertex's): their share, and the
  // mean ΔE76 at them and off them. A camera pixel (about 1 mm at the scans' range) blurs what
  // lies within it of an edge, so the mean over a finely patterned texture is mostly its edges'.
  double edge_share = 0, delta_e_mean_at_edges = 0, delta_e_mean_off_edges = 0;
  double psnr_db = 0;  // colourPsnr over 8 views
};
constexpr double kColourEdgeRadius_m = 0.001;
constexpr double kColourEdgeDeltaE = 10;
ColourMetrics colourAccuracy(const ObjectModel& model, const TriangleMesh& truth,
                             const SurfaceColours& truth_colours);

// `mesh` with per-vertex colours (`rgba`: alpha 0 drawn mid grey) rendered unlit from the camera
// at T_O_C (pinhole K) by ray casting: black where the rays meet nothing.
RgbImage renderVertexColours(const TriangleMesh& mesh,
                             const std::vector<std::array<uint8_t, 4>>& rgba, const Iso3& T_O_C,
                             const CameraIntrinsics& K);

// `mesh` in its surface colours (its albedo) rendered unlit from the camera at T_O_C (pinhole K)
// by ray casting: black where the rays meet nothing.
RgbImage renderSurfaceColours(const TriangleMesh& mesh, const SurfaceColours& colours,
                              const Iso3& T_O_C, const CameraIntrinsics& K);

// The model with its per-vertex colours (rgba; vertices without colour in mid grey) and the true
// mesh with its colours, each rendered unlit (albedo only) by ray casting from `views` cameras
// around the true mesh's box centre (directions spread over the sphere, 3 box diagonals away,
// 320 × 240, 60° across), none of them the scan's: the PSNR (dB) of the model's images against
// the truth's over every pixel where either shows its surface (a pixel only one shows counts
// against the black of the other). `images` (optional) receives the pairs, truth then model.
double colourPsnr(const ObjectModel& model, const TriangleMesh& truth,
                  const SurfaceColours& truth_colours, int views = 8,
                  std::vector<RgbImage>* images = nullptr);

// The true surface sampled once, ready to score many models (thread-safe after construction).
class GroundTruth {
 public:
  GroundTruth(const TriangleMesh& truth, const EvalOptions& options = {});
  // Coverage only (cheap: per-view curves).
  double coverage(const ObjectModel& model) const;
  SurfaceMetrics evaluate(const ObjectModel& model) const;
  const EvalOptions& options() const { return options_; }

 private:
  EvalOptions options_;
  TriangleDistanceIndex truthIndex_;
  std::vector<Vec3> truthSamples_;
};

// The connected pieces of a mesh: per triangle, the index of its piece (triangles sharing a vertex
// are in one piece); `pieces` receives their number.
std::vector<int> meshPieces(const TriangleMesh& mesh, int* pieces);

// Per-triangle flag: all three vertices observed.
std::vector<uint8_t> observedTriangles(const ObjectModel& model);

}  // namespace inhand
