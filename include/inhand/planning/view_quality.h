#pragma once
// View quality, the paper's eq. 9: for a candidate camera pose z, ray-cast a virtual 640×480
// depth map of S_obj (the current model, vertex variances σ_t²) among the robot's own surfaces,
// and sum over pixels
//     G(z) = ½ Σ ln(1 + σ_t²/σ_z²) · d² / (f² |n_z|)
// with σ_t² interpolated on the hit triangle, σ_z² from the noise model at the virtual depth d
// and incidence angle, and d²/(f²|n_z|) the surface area the pixel covers. A pixel counts only
// when (§III-B): the ray hits S_obj; no robot surface (hand, wrist, forearm, …, table) is hit
// first; the hit is farther than t_hand from the hand; the camera ray is not too oblique; and
// the projector sees the point, not too obliquely.
#include <memory>
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/internal/raster.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/mesh/extract.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/robot_scenes.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/noise_model.h"

namespace inhand {

class ProjectorShadows;

// What each counted pixel adds to a view's quality.
enum class QualityIntegrand {
  kInformationGain,  // eq. 9: ½ ln(1 + σ_t²/σ_z²) · d²/(f²|n_z|)
  // Baseline after Connolly's planetarium algorithm: d²/(f²|n_z|), the area the pixel covers, on
  // still-unknown surface (a triangle with a hole-filled vertex), else 0. Quality in m².
  kUnknownArea,
};

enum class PrimaryVisibility { kAuto, kRaster, kRayCast };
inline constexpr EnumNames<PrimaryVisibility, 3> kPrimaryVisibilityNames = {
    {PrimaryVisibility::kAuto, "auto"},
    {PrimaryVisibility::kRaster, "raster"},
    {PrimaryVisibility::kRayCast, "ray_cast"}};
const char* primaryVisibilityName(PrimaryVisibility v);  // auto, raster, ray_cast
bool parsePrimaryVisibility(const std::string& name, PrimaryVisibility* v);

struct ViewQualityOptions {
  QualityIntegrand integrand = QualityIntegrand::kInformationGain;
  double t_hand_m = 0.01;                     // hits this close to the hand are skipped, m
  double max_incidence_deg = 75.0;            // camera ray vs surface normal
  double max_projector_incidence_deg = 75.0;  // projector ray vs surface normal
  double near_hand_cell_m = 0.002;            // resolution of the precomputed near-hand grid, m
  // 1: every pixel of the 640×480 map, as the paper. s > 1: every s-th pixel in u and v, each
  // standing for s² pixels (the same surface integral, sampled s² times more coarsely).
  int pixel_stride = 1;
  // How quality() finds the first surface along each pixel's ray, and the projector's shadows.
  // kRaster: a z-buffer rasteriser over S_obj and the robot's triangles; it agrees with
  // qualityReference up to samples on triangle edges and float rounding. Its shadows come from
  // ProjectorShadows (the projector's own view at each point's exact projector column, no ray
  // cast) when the projector is on the camera's x axis, as on the Kinect-style sensor, else
  // from Embree shadow rays. kRayCast: Embree packets for both, the reference's own rays.
  // kAuto: the rasteriser at
  // strides 1 and 2, where it is the faster (its cost is per triangle, a ray caster's per
  // sample; measured 1.5× at stride 1, 1.05–1.2× at stride 2), and ray casting at coarser ones.
  PrimaryVisibility visibility = PrimaryVisibility::kAuto;

  // The options' rows (core/options.h); `integrand` is chosen by the planner, not an option.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.num("t_hand_m", o.t_hand_m, "hits this close to the hand are skipped (eq. 9), m",
          Range::atLeast(0));
    v.num("max_incidence_deg", o.max_incidence_deg, "camera ray vs surface normal at most, degrees",
          Range::open(0, 90));
    v.num("max_projector_incidence_deg", o.max_projector_incidence_deg,
          "projector ray vs surface normal at most, degrees", Range::open(0, 90));
    v.num("near_hand_cell_m", o.near_hand_cell_m, "resolution of the near-hand grid, m",
          Range::above(0));
    v.integer("pixel_stride", o.pixel_stride, "eq. 9 over every n-th pixel in u and v",
              Range::closed(1, 16));
    v.choice("visibility", o.visibility, kPrimaryVisibilityNames,
             "primary visibility: rasterised or ray cast (auto: raster where it is faster)");
  }
  std::string validate() const;
};

// Per-pixel outcome counts of one evaluation (for tests and diagnostics); samples at a stride.
struct ViewQualityStats {
  int cast = 0;    // samples looked at: inside the model's projected box (rays cast or rasterised)
  int missed = 0;  // the ray misses S_obj (whatever else it hits)
  int robot_first = 0;        // a robot surface hides the S_obj hit
  int near_hand = 0;          // S_obj hit within t_hand of the hand
  int too_oblique = 0;        // camera incidence too large
  int projector_oblique = 0;  // projector incidence too large
  int projector_blocked = 0;  // projector's ray to the point blocked
  int counted = 0;            // pixels that contribute to G
};

// Cells within t_hand of the hand, precomputed once per grasp in the object frame.
class NearHandGrid {
 public:
  NearHandGrid() = default;
  // Cells within t_hand of the hand, over the hand's bounds (intersected with `region_O` when
  // given: only points of S_obj are ever looked up, so its bounds suffice).
  NearHandGrid(const HandGeometry& hand_O, double t_hand_m, double cell_m,
               const Aabb* region_O = nullptr);
  bool near(const Vec3& p_O) const;
  // Whether any point of `box` (frame O) could be near: some near cell is the nearest cell of a
  // point in it (false means near() is false everywhere in the box).
  bool anyNear(const Aabb& box_O) const;

 private:
  Vec3 origin_ = Vec3::Zero();
  double cell_ = 1.0, invCell_ = 1.0;
  Vec3i dims_ = Vec3i::Zero();
  bool flag(int x, int y, int z) const;  // cell (x, y, z) is near
  std::vector<uint64_t> bits_;           // a bit per cell, x fastest, then y, then z
};

// S_obj (mesh + variances) ready for many evaluations. Thread-safe after construction.
class ViewQualityScene {
 public:
  ViewQualityScene(const ObjectModel& model, const DepthCameraOptions& camera,
                   const NoiseModelOptions& noise, const ViewQualityOptions& options);

  // Sets the grasp's near-hand grid (no grid: no t_hand rule).
  void setNearHand(std::shared_ptr<const NearHandGrid> grid);
  const std::shared_ptr<const NearHandGrid>& nearHand() const { return nearHand_; }

  // eq. 9 for a camera at T_O_C among `occluders` (robot surfaces in frame O). Looks only at the
  // pixels inside the projection of the model's bounding box (no pixel outside can hit S_obj),
  // on the calling thread: rasterised or cast in coherent 4×4 packets (options.visibility).
  // `pixel_stride` > 0 overrides options.pixel_stride for this evaluation (Alg. 1's coarse
  // pre-screen).
  double quality(const Iso3& T_O_C, const std::vector<Occluder>& occluders = {},
                 ViewQualityStats* stats = nullptr, int pixel_stride = 0) const;

  // Brute-force reference: every pixel of the full image, one ray at a time (rtcIntersect1).
  double qualityReference(const Iso3& T_O_C, const std::vector<Occluder>& occluders = {},
                          ViewQualityStats* stats = nullptr) const;

  const ObjectModel& model() const { return model_; }

 private:
  // The occluders as instances; with S_obj first (geometry 0) when `withObject`.
  RayScene buildScene(const std::vector<Occluder>& occluders, bool withObject) const;
  // Pixel window covering the projection of the model's bounding box; false when it is empty.
  bool pixelWindow(const Iso3& T_O_C, int stride, RasterWindow* window) const;
  // Per view: the projector's centre and the camera's optical axis in frame O.
  struct ViewContext {
    Vec3 projector_O, axis_O;
  };
  ViewContext viewContext(const Iso3& T_O_C) const;
  // Rasterised: per sample of `window` whose first surface is S_obj, the pixel rules and gain at
  // once (gains[i] with its projector visibility still to decide: the point added to `rows`,
  // which this then draws S_obj and the robot into, or with rows null the shadow ray
  // shadows[i]; counts the other outcomes). With `logArgs`, eq. 9's logarithm is left to the
  // caller: sample i's gain is gains[i]·ln(1 + logArgs[i]), or gains[i] where logArgs[i] < 0.
  void rasterGains(const Iso3& T_O_C, const RasterWindow& window,
                   const std::vector<Occluder>& occluders, std::vector<Ray>* shadows,
                   std::vector<double>* gains, std::vector<double>* logArgs, ProjectorShadows* rows,
                   ViewQualityStats* st) const;
  // rasterGains' stages (RasterScratch: this thread's rasters and lists, view_quality.cc): S_obj
  // and the robot's surfaces drawn as the camera sees them; the fast per-sample rules (eq. 9's
  // integrand) for a sample on triangle `tri` along `dir` (false: a rule refused it, counted);
  // the projector's view drawn into `rows`.
  struct RasterScratch;
  struct FastSample;
  void drawCameraView(const Iso3& T_O_C, const std::vector<Occluder>& occluders,
                      RasterScratch* scratch) const;
  bool fastSample(int tri, const Vec3& o, const Vec3& dir, const ViewContext& view, FastSample* out,
                  ViewQualityStats* st) const;
  void drawProjectorView(const Iso3& T_O_C, const ViewContext& view, RasterScratch* scratch,
                         ProjectorShadows* rows) const;
  // First S_obj hit per sample of `window` not hidden by a robot surface (rays[i], hits[i];
  // counts misses and robot-first pixels), by Embree.
  void primaryHitsRayCast(const Iso3& T_O_C, const RasterWindow& window, const RayScene* robot,
                          std::vector<Ray>* rays, std::vector<Hit>* hits,
                          ViewQualityStats* st) const;
  // Per-pixel rule given the first hit; returns the gain or 0, and the shadow ray when the pixel
  // still needs the projector visibility test.
  double pixelGain(const Hit& hit, const Ray& ray, const Iso3& T_O_C, Ray* shadow,
                   ViewQualityStats* stats) const;
  // The same for a hit on S_obj at ray parameter t, barycentrics (u, v) of `triangle`, unit
  // normal n: the rules after "S_obj is the first surface".
  double surfaceGain(const Ray& ray, float t, float u, float v, int triangle, const Vec3& n,
                     const ViewContext& view, Ray* shadow, ViewQualityStats* stats) const;

  ObjectModel model_;
  Aabb bounds_;
  double cosMaxIncidence_ = 0, cosMaxProjector_ = 0, cosGrazing_ = 0;
  DepthCameraOptions camera_;
  NoiseModelOptions noise_;
  ViewQualityOptions options_;
  RayScene objectScene_;
  bool closed_ = false;  // S_obj watertight: back faces can be culled for cameras outside it
  std::shared_ptr<const NearHandGrid> nearHand_;
  // Per triangle of S_obj, for the rasterised per-sample stage: its plane n·p = offset (n the
  // unit normal), σ_t² as an affine function grad·p + at0 of the point on it (what interpolating
  // the corners' variances with barycentrics gives), clamped to the corners' range on edges.
  struct TrianglePlane {
    Vec3 n;
    double offset;
    Vec3 grad;
    double at0;
    double varMin, varMax;
  };
  std::vector<TrianglePlane> planes_;
  // S_obj's triangle planes packed for facing tests: the rasterisers load only the corners of
  // triangles that may face the camera (or the projector).
  TriangleFacing facing_;
  std::vector<uint8_t> mayBeNearHand_;  // per triangle: some point of it may be near the hand
};

// Camera pose in the object frame looking along dir_O at centre_O from `range_m`, rolled by
// roll_rad about the optical axis (roll 0: image x axis as perpendicular to dir_O and the
// object's z axis as possible).
Iso3 cameraPoseInObject(const Vec3& centre_O, const Vec3& dir_O, double range_m, double roll_rad);

}  // namespace inhand
