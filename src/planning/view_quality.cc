#include "inhand/planning/view_quality.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "inhand/core/error.h"
#include "inhand/core/internal/fast_math.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/geometry/internal/projector_shadows.h"
#include "inhand/geometry/primitives.h"

namespace inhand {

namespace {
// A shadow ray ignores surfaces within this distance of the point and of the projector, m.
constexpr double kShadowMargin = 2e-4;

// Adds a point at depth d and distance dist from the projector to `rows`, blocked as Embree's
// shadow ray with tnear = kShadowMargin would be: by surfaces whose 1/z on its projector ray is at
// least (1/d)/(1 − margin/dist). Both inverse depths from one division.
inline void addShadowPoint(ProjectorShadows* rows, int j, int i, double d, double dist) {
  const double q = 1.0 / (d * (dist - kShadowMargin));
  rows->add(j, i, (dist - kShadowMargin) * q, dist * q);
}
// How many samples ahead the per-sample stage prefetches a triangle's record.
constexpr int kPrefetch = 6;

#if INHAND_FAST_MATH_AVX2
// Eq. 9's integrand at a surface sample at depth d, with sensor variance σ_z² and surface variance
// σ_t²: ½ ln(1 + σ_t²/σ_z²) · d²/(f_x f_y n_z), the pixel's footprint on the surface, written as
// weight · ln(1 + ratio) with one division for both quotients: r = 1/(σ_z² f_x f_y n_z),
// ratio = σ_t² f_x f_y n_z r, weight = ½ d² σ_z² r. Every path of eq. 9 goes through it (the
// rasterised rows defer the division, the same numbers per row).
struct Eq9Terms {
  double weight, ratio;
};
inline Eq9Terms eq9Terms(double d, double sz2, double var, double fxfyNz) {
  const double r = 1.0 / (sz2 * fxfyNz);
  return {0.5 * d * d * sz2 * r, var * fxfyNz * r};
}

// terms[k] = x < 0 ? gain : gain·ln(1 + x), x = logArgs[k], four at a time as far as whole
// fours go (the same values as one at a time); returns how many it did.
__attribute__((target("avx2"))) size_t logTermsFour(const double* gains, const double* logArgs,
                                                    size_t n, double* terms) {
  size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    const __m256d x = _mm256_loadu_pd(logArgs + k), g = _mm256_loadu_pd(gains + k);
    const __m256d t = _mm256_mul_pd(g, log1pNonNegativeFour(_mm256_max_pd(x, _mm256_setzero_pd())));
    _mm256_storeu_pd(terms + k,
                     _mm256_blendv_pd(t, g, _mm256_cmp_pd(x, _mm256_setzero_pd(), _CMP_LT_OQ)));
  }
  return k;
}
#endif

// 10-bit Morton code of a point in [0, 1)³.
uint32_t morton3(const Vec3& u) {
  auto spread = [](uint32_t x) {
    x &= 0x3FF;
    x = (x | (x << 16)) & 0x030000FF;
    x = (x | (x << 8)) & 0x0300F00F;
    x = (x | (x << 4)) & 0x030C30C3;
    x = (x | (x << 2)) & 0x09249249;
    return x;
  };
  auto q = [](double v) { return uint32_t(std::clamp(v, 0.0, 1.0) * 1023.0); };
  return spread(q(u.x())) | (spread(q(u.y())) << 1) | (spread(q(u.z())) << 2);
}

// The same model with its triangles sorted along a Morton curve of their centroids and its
// vertices in order of first use: triangles near one another in space, which a view's
// neighbouring pixels hit, then lie near one another in memory (the per-sample stage looks up
// one triangle per sample; in the contouring's order it missed the cache on most of them).
ObjectModel spatiallyOrdered(const ObjectModel& in) {
  const TriangleMesh& m = in.mesh;
  const Aabb b = m.bounds();
  const Vec3 scale = (b.max - b.min).cwiseMax(Vec3::Constant(1e-9)).cwiseInverse();
  std::vector<std::pair<uint32_t, int>> key(m.triangles.size());
  for (size_t k = 0; k < m.triangles.size(); ++k) {
    const Tri& f = m.triangles[k];
    const Vec3 c =
        (m.vertices[size_t(f[0])].cast<double>() + m.vertices[size_t(f[1])].cast<double>() +
         m.vertices[size_t(f[2])].cast<double>()) /
        3.0;
    key[k] = {morton3((c - b.min).cwiseProduct(scale)), int(k)};
  }
  std::sort(key.begin(), key.end());
  ObjectModel out;
  std::vector<int> newIndex(m.vertices.size(), -1);
  const bool observed = in.observed.size() == m.vertices.size();
  out.mesh.triangles.reserve(m.triangles.size());
  for (const auto& [code, k] : key) {
    Tri f = m.triangles[size_t(k)];
    for (int c = 0; c < 3; ++c) {
      int& n = newIndex[size_t(f[c])];
      if (n < 0) {
        n = int(out.mesh.vertices.size());
        out.mesh.vertices.push_back(m.vertices[size_t(f[c])]);
        out.variance.push_back(in.variance[size_t(f[c])]);
        if (observed) out.observed.push_back(in.observed[size_t(f[c])]);
      }
      f[c] = n;
    }
    out.mesh.triangles.push_back(f);
  }
  return out;
}
}  // namespace

std::string ViewQualityOptions::validate() const { return checkOptionRanges(*this); }

const char* primaryVisibilityName(PrimaryVisibility v) {
  return enumName(kPrimaryVisibilityNames, v);
}

bool parsePrimaryVisibility(const std::string& name, PrimaryVisibility* v) {
  return enumFromName(kPrimaryVisibilityNames, name, v);
}

Iso3 cameraPoseInObject(const Vec3& centre_O, const Vec3& dir_O, double range_m, double roll_rad) {
  Vec3 z = dir_O.normalized();
  Vec3 ref = std::abs(z.z()) < 0.95 ? Vec3::UnitZ() : Vec3::UnitX();
  Vec3 x0 = z.cross(ref).normalized();
  Vec3 y0 = z.cross(x0);
  Vec3 x = std::cos(roll_rad) * x0 + std::sin(roll_rad) * y0;
  Iso3 T = Iso3::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = centre_O - range_m * z;
  return T;
}

// ---- near-hand grid -----------------------------------------------------------------------------

NearHandGrid::NearHandGrid(const HandGeometry& hand, double t_hand, double cell, const Aabb* region)
    : cell_(cell), invCell_(1.0 / cell) {
  Aabb box = hand.mesh().bounds();
  box.min -= Vec3::Constant(t_hand + cell);
  box.max += Vec3::Constant(t_hand + cell);
  if (region) {
    box.min = box.min.cwiseMax(region->min - Vec3::Constant(cell));
    box.max = box.max.cwiseMin(region->max + Vec3::Constant(cell));
    if (box.empty()) return;  // no cell: nothing of the region is near the hand
  }
  origin_ = box.min;
  Vec3 extent = box.size();
  dims_ = Vec3i(int(std::ceil(extent.x() / cell)) + 1, int(std::ceil(extent.y() / cell)) + 1,
                int(std::ceil(extent.z() / cell)) + 1);
  // Built a byte per cell (the blocks run in parallel), then packed a bit per cell: 8× less
  // memory for the per-sample lookups to miss in.
  std::vector<uint8_t> flags(size_t(dims_.prod()), 0);
  // Blocks of B³ cells: the distance is 1-Lipschitz, so a block whose centre lies farther than
  // t_hand + its half-diagonal from the hand holds no near cell and is skipped whole.
  constexpr int B = 8;
  const Vec3i blocks = (dims_.array() + B - 1) / B;
  const double halfDiagonal = 0.5 * std::sqrt(3.0) * (B - 1) * cell_;
  parallelFor(0, blocks.z(), [&](int bz) {
    for (int by = 0; by < blocks.y(); ++by)
      for (int bx = 0; bx < blocks.x(); ++bx) {
        const Vec3i lo(bx * B, by * B, bz * B);
        const Vec3i hi = (lo.array() + B).min(dims_.array()) - 1;
        const Vec3 centre = origin_ + cell_ * 0.5 * (lo + hi).cast<double>();
        if (hand.distance(centre) > t_hand + halfDiagonal) continue;
        for (int z = lo.z(); z <= hi.z(); ++z)
          for (int y = lo.y(); y <= hi.y(); ++y)
            for (int x = lo.x(); x <= hi.x(); ++x)
              flags[(size_t(z) * dims_.y() + y) * dims_.x() + x] =
                  hand.distance(origin_ + cell_ * Vec3(x, y, z)) < t_hand;
      }
  });
  bits_.assign((flags.size() + 63) / 64, 0);
  for (size_t k = 0; k < flags.size(); ++k) bits_[k / 64] |= uint64_t(flags[k]) << (k % 64);
}

bool NearHandGrid::flag(int x, int y, int z) const {
  const size_t k = (size_t(z) * size_t(dims_.y()) + size_t(y)) * size_t(dims_.x()) + size_t(x);
  return (bits_[k / 64] >> (k % 64)) & 1;
}

bool NearHandGrid::near(const Vec3& p) const {
  if (bits_.empty()) return false;
  const Vec3 g = (p - origin_) * invCell_;
  // The nearest cell, as lround would give it, without a libm call: in range only for
  // -½ < g < dims − ½, where int(g + ½) rounds half up like lround.
  if (!(g.x() > -0.5 && g.y() > -0.5 && g.z() > -0.5 && g.x() < dims_.x() - 0.5 &&
        g.y() < dims_.y() - 0.5 && g.z() < dims_.z() - 0.5))
    return false;
  const int x = int(g.x() + 0.5), y = int(g.y() + 0.5), z = int(g.z() + 0.5);
  return flag(x, y, z);
}

bool NearHandGrid::anyNear(const Aabb& box) const {
  if (bits_.empty()) return false;
  const Vec3 lo = (box.min - origin_) * invCell_, hi = (box.max - origin_) * invCell_;
  Vec3i a, b;
  for (int k = 0; k < 3; ++k) {
    // near() looks at cell int(g + ½) for −½ < g < dims − ½.
    a[k] = std::max(0, int(std::floor(lo[k] + 0.5)));
    b[k] = std::min(dims_[k] - 1, int(std::floor(hi[k] + 0.5)));
    if (a[k] > b[k]) return false;
  }
  for (int z = a.z(); z <= b.z(); ++z)
    for (int y = a.y(); y <= b.y(); ++y)
      for (int x = a.x(); x <= b.x(); ++x)
        if (flag(x, y, z)) return true;
  return false;
}

// ---- quality ------------------------------------------------------------------------------------

ViewQualityScene::ViewQualityScene(const ObjectModel& model, const DepthCameraOptions& camera,
                                   const NoiseModelOptions& noise,
                                   const ViewQualityOptions& options)
    : camera_(camera), noise_(noise), options_(options) {
  std::string p = options.validate();
  if (!p.empty()) throw Error("view quality options: " + p);
  INHAND_CHECK(model.variance.size() == model.mesh.vertices.size(), "variance per vertex");
  if (options.integrand == QualityIntegrand::kUnknownArea)
    INHAND_CHECK(model.observed.size() == model.mesh.vertices.size(), "observed flag per vertex");
  model_ = spatiallyOrdered(model);
  bounds_ = model_.mesh.bounds();
  cosMaxIncidence_ = std::cos(options.max_incidence_deg * M_PI / 180);
  cosMaxProjector_ = std::cos(options.max_projector_incidence_deg * M_PI / 180);
  cosGrazing_ = std::cos(noise.grazing_start_deg * M_PI / 180);
  closed_ = model_.mesh.isWatertight();
  planes_.reserve(model_.mesh.triangles.size());
  for (const Tri& f : model_.mesh.triangles) {
    const Vec3f& p0 = model_.mesh.vertices[size_t(f[0])];
    // The unnormalised (p1 − p0) × (p2 − p0) in float, as Embree's Ng, which pixelGain normalises.
    const Vec3f Ng =
        (model_.mesh.vertices[size_t(f[1])] - p0).cross(model_.mesh.vertices[size_t(f[2])] - p0);
    // σ_t² = a + (b − a)·β1 + (c − a)·β2 with β the barycentrics of p = A + β1·e1 + β2·e2,
    // β1 = (p − A)·(e2 × N)/|N|², β2 = (p − A)·(N × e1)/|N|², N = e1 × e2.
    const Vec3 A = p0.cast<double>();
    const Vec3 e1 = model_.mesh.vertices[size_t(f[1])].cast<double>() - A;
    const Vec3 e2 = model_.mesh.vertices[size_t(f[2])].cast<double>() - A;
    const Vec3 N = e1.cross(e2);
    const double va = model_.variance[size_t(f[0])], vb = model_.variance[size_t(f[1])],
                 vc = model_.variance[size_t(f[2])];
    TrianglePlane tp;
    tp.n = Ng.cast<double>().normalized();
    tp.offset = tp.n.dot(A);
    const double nn = N.squaredNorm();
    tp.grad =
        nn > 0 ? Vec3(((vb - va) * e2.cross(N) + (vc - va) * N.cross(e1)) / nn) : Vec3::Zero();
    tp.at0 = va - tp.grad.dot(A);
    tp.varMin = std::min({va, vb, vc});
    tp.varMax = std::max({va, vb, vc});
    planes_.push_back(tp);
  }
  facing_ = TriangleFacing(model_.mesh);
  objectScene_.addMesh(model_.mesh);
  objectScene_.commit(/*high=*/true);  // cast hundreds of times per Alg. 1 pass
}

void ViewQualityScene::setNearHand(std::shared_ptr<const NearHandGrid> grid) {
  nearHand_ = std::move(grid);
  mayBeNearHand_.assign(model_.mesh.triangles.size(), 0);
  if (!nearHand_) return;
  const auto& V = model_.mesh.vertices;
  for (size_t k = 0; k < model_.mesh.triangles.size(); ++k) {
    const Tri& f = model_.mesh.triangles[k];
    Aabb b;
    b.min = V[size_t(f[0])]
                .cast<double>()
                .cwiseMin(V[size_t(f[1])].cast<double>())
                .cwiseMin(V[size_t(f[2])].cast<double>());
    b.max = V[size_t(f[0])]
                .cast<double>()
                .cwiseMax(V[size_t(f[1])].cast<double>())
                .cwiseMax(V[size_t(f[2])].cast<double>());
    // A sample on the triangle may land a rounding error outside its corners' box.
    b.min -= Vec3::Constant(1e-6);
    b.max += Vec3::Constant(1e-6);
    mayBeNearHand_[k] = nearHand_->anyNear(b);
  }
}

RayScene ViewQualityScene::buildScene(const std::vector<Occluder>& occluders,
                                      bool withObject) const {
  RayScene s;
  if (withObject) s.addInstance(objectScene_, Iso3::Identity());  // geometry 0: S_obj
  for (const Occluder& o : occluders) s.addInstance(*o.scene, o.T_O_scene);
  s.commit();
  return s;
}

ViewQualityScene::ViewContext ViewQualityScene::viewContext(const Iso3& T_O_C) const {
  return {T_O_C * camera_.projector_C, T_O_C.linear().col(2)};
}

double ViewQualityScene::pixelGain(const Hit& hit, const Ray& ray, const Iso3& T_O_C, Ray* shadow,
                                   ViewQualityStats* st) const {
  if (!hit.valid()) {
    ++st->missed;
    return 0;
  }
  if (hit.geometry != 0) {
    ++st->robot_first;
    return 0;
  }
  return surfaceGain(ray, hit.t, hit.u, hit.v, hit.triangle, hit.normal.cast<double>().normalized(),
                     viewContext(T_O_C), shadow, st);
}

double ViewQualityScene::surfaceGain(const Ray& ray, float t, float hu, float hv, int triangle,
                                     const Vec3& n, const ViewContext& view, Ray* shadow,
                                     ViewQualityStats* st) const {
  const Vec3 dir = ray.dir.cast<double>();
  const Vec3 p = ray.origin.cast<double>() + double(t) * dir;
  if (nearHand_ && nearHand_->near(p)) {
    ++st->near_hand;
    return 0;
  }
  const double cosInc = std::abs(n.dot(dir)) / dir.norm();
  if (cosInc < cosMaxIncidence_) {
    ++st->too_oblique;
    return 0;
  }
  Vec3 toP = view.projector_O - p;
  const double dist = toP.norm();
  toP /= dist;
  if (std::abs(n.dot(toP)) < cosMaxProjector_) {
    ++st->projector_oblique;
    return 0;
  }
  shadow->origin = p.cast<float>();
  shadow->dir = toP.cast<float>();
  shadow->tnear = float(kShadowMargin);
  shadow->tfar = float(dist - kShadowMargin);
  const Tri& f = model_.mesh.triangles[size_t(triangle)];
  const CameraIntrinsics& K = camera_.intrinsics;
  const double d = t;  // the ray has camera z = 1, so t is the depth
  // n_z in the camera frame: (Rᵀ n).z = R.col(2) · n.
  const double nz = std::max(0.05, std::abs(view.axis_O.dot(n)));
  if (options_.integrand == QualityIntegrand::kUnknownArea) {
    const bool unknown = !model_.observed[f[0]] || !model_.observed[f[1]] || !model_.observed[f[2]];
    return unknown ? d * d / (K.fx * K.fy * nz) : 0.0;
  }
  const double var = (1.0 - hu - hv) * model_.variance[f[0]] + hu * model_.variance[f[1]] +
                     hv * model_.variance[f[2]];
  // θ is only needed beyond the grazing threshold (the axial model is flat below it).
  const double sz = cosInc >= cosGrazing_ ? axialSigma(noise_, d, 0.0)
                                          : axialSigma(noise_, d, std::acos(std::min(1.0, cosInc)));
  const Eq9Terms e = eq9Terms(d, sz * sz, var, K.fx * K.fy * nz);
  return e.weight * std::log1p(e.ratio);
}

bool ViewQualityScene::pixelWindow(const Iso3& T_O_C, int sp, RasterWindow* window) const {
  const CameraIntrinsics& K = camera_.intrinsics;
  const Aabb& box = bounds_;
  const Iso3 T_C_O = T_O_C.inverse();
  int u0 = 0, v0 = 0, u1 = K.width - 1, v1 = K.height - 1;
  bool bounded = true;
  double umin = 1e30, umax = -1e30, vmin = 1e30, vmax = -1e30;
  for (int c = 0; c < 8; ++c) {
    Vec3 pc = T_C_O * box.corner(c);
    if (pc.z() < 1e-3) {
      bounded = false;
      break;
    }
    Vec2 uv = K.project(pc);
    umin = std::min(umin, uv.x());
    umax = std::max(umax, uv.x());
    vmin = std::min(vmin, uv.y());
    vmax = std::max(vmax, uv.y());
  }
  if (bounded) {
    u0 = std::max(0, int(std::floor(umin)) - 1);
    v0 = std::max(0, int(std::floor(vmin)) - 1);
    u1 = std::min(K.width - 1, int(std::ceil(umax)) + 1);
    v1 = std::min(K.height - 1, int(std::ceil(vmax)) + 1);
    if (u0 > u1 || v0 > v1) return false;
  }
  window->stride = sp;
  window->i0 = (u0 + sp - 1) / sp;
  window->i1 = u1 / sp;
  window->j0 = (v0 + sp - 1) / sp;
  window->j1 = v1 / sp;
  return window->size() > 0;
}

namespace {

// Möller–Trumbore on one triangle known to be hit (the rasteriser chose it): t and the
// barycentrics as Embree reports them, clamped onto the triangle for samples on its edges.
void hitTriangle(const Ray& r, const Vec3& p0, const Vec3& p1, const Vec3& p2, Hit* h) {
  const Vec3 o = r.origin.cast<double>(), d = r.dir.cast<double>();
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  const Vec3 pv = d.cross(e2);
  const double det = e1.dot(pv);
  const double inv = 1.0 / det;
  const Vec3 tv = o - p0;
  double u = tv.dot(pv) * inv;
  const Vec3 qv = tv.cross(e1);
  double v = d.dot(qv) * inv;
  h->t = float(e2.dot(qv) * inv);
  u = std::clamp(u, 0.0, 1.0);
  v = std::clamp(v, 0.0, 1.0 - u);
  h->u = float(u);
  h->v = float(v);
}

}  // namespace

struct ViewQualityScene::RasterScratch {
  DepthRaster object;
  std::vector<RayScene::PlacedMesh> robotMeshes;
  std::vector<uint8_t> robotSolid;
  std::vector<uint64_t> facing;
};

// A sample the fast rules kept: the depth d along the ray, the squared distance to the
// projector and the direction towards it, its variance, |cos| of the normal to the optical axis
// (at least 0.05) and the axial σ.
struct ViewQualityScene::FastSample {
  double d, dist2, var, nz, sz;
  Vec3 p, toP;
};

void ViewQualityScene::drawCameraView(const Iso3& T_O_C, const std::vector<Occluder>& occluders,
                                      RasterScratch* scratch) const {
  const Iso3 T_C_O = T_O_C.inverse();
  DepthRaster& object = scratch->object;
  const Vec3 c = T_O_C.translation();
  // A closed S_obj seen from outside: only its triangles that may face the camera are looked at.
  const bool cullObject = closed_ && !bounds_.contains(c);
  if (cullObject) facing_.mayFace(c, &scratch->facing);
  object.draw(model_.mesh, T_C_O, 0, cullObject, 0, nullptr,
              cullObject ? &scratch->facing : nullptr);
  if (occluders.empty()) return;
  // Robot surfaces deeper than S_obj's farthest corner hide nothing of it.
  double far = 0;
  for (int k = 0; k < 8; ++k) far = std::max(far, (T_C_O * bounds_.corner(k)).z());
  for (const Occluder& o : occluders) {
    const size_t first = scratch->robotMeshes.size();
    o.scene->collectMeshes(T_C_O * o.T_O_scene, &scratch->robotMeshes);
    for (size_t k = first; k < scratch->robotMeshes.size(); ++k) {
      const RayScene::PlacedMesh& m = scratch->robotMeshes[k];
      // Back faces of a solid may go when the camera (the origin) is outside its bounds.
      const bool inside = m.bounds->contains(m.T.inverse().translation());
      object.drawOccluder(*m.mesh, m.T, o.solid && !inside, far, m.bounds);
      scratch->robotSolid.push_back(o.solid);
    }
  }
}

bool ViewQualityScene::fastSample(int tri, const Vec3& o, const Vec3& dir, const ViewContext& view,
                                  FastSample* out, ViewQualityStats* st) const {
  // The ray R·((u − cx)/fx, (v − cy)/fy, 1) meets the winning triangle's plane at depth d (the
  // ray's camera z is 1); the rules and the gain as surfaceGain, in squared form where a cosine
  // is compared.
  const TrianglePlane& tp = planes_[size_t(tri)];
  const double nd = tp.n.dot(dir);
  const double d = (tp.offset - tp.n.dot(o)) / nd;
  const Vec3 p = o + d * dir;
  if (nearHand_ && mayBeNearHand_[size_t(tri)] && nearHand_->near(p)) {
    ++st->near_hand;
    return false;
  }
  const double dir2 = dir.squaredNorm();
  if (nd * nd < cosMaxIncidence_ * cosMaxIncidence_ * dir2) {
    ++st->too_oblique;
    return false;
  }
  const Vec3 toP = view.projector_O - p;
  const double dist2 = toP.squaredNorm(), np = tp.n.dot(toP);
  if (np * np < cosMaxProjector_ * cosMaxProjector_ * dist2) {
    ++st->projector_oblique;
    return false;
  }
  out->d = d;
  out->p = p;
  out->toP = toP;
  out->dist2 = dist2;
  out->var = std::clamp(tp.grad.dot(p) + tp.at0, tp.varMin, tp.varMax);
  out->nz = std::max(0.05, std::abs(view.axis_O.dot(tp.n)));
  if (nd * nd >= cosGrazing_ * cosGrazing_ * dir2) {
    const double dz = d - noise_.axial_z0_m;
    out->sz = noise_.axial_c0_m + noise_.axial_c1 * dz * dz;  // axialSigma at θ = 0
  } else {
    out->sz = axialSigma(noise_, d, std::acos(std::min(1.0, std::abs(nd) / std::sqrt(dir2))));
  }
  return true;
}

void ViewQualityScene::drawProjectorView(const Iso3& T_O_C, const ViewContext& view,
                                         RasterScratch* scratch, ProjectorShadows* rows) const {
  // The projector's view, at each pending sample's own projector column: S_obj from the
  // vertices its raster already projected, then the robot's surfaces.
  rows->index();
  const Vec3 projector = view.projector_O;
  const bool cullProjector = closed_ && !bounds_.contains(projector);
  if (cullProjector) facing_.mayFace(projector, &scratch->facing);
  rows->draw(model_.mesh, T_O_C.inverse(), cullProjector, &scratch->object.projected(), nullptr,
             cullProjector ? &scratch->facing : nullptr);
  for (size_t k = 0; k < scratch->robotMeshes.size(); ++k) {
    const RayScene::PlacedMesh& m = scratch->robotMeshes[k];
    const bool inside = m.bounds->contains(m.T.inverse() * camera_.projector_C);
    rows->draw(*m.mesh, m.T, scratch->robotSolid[k] && !inside, nullptr, m.bounds);
  }
}

void ViewQualityScene::rasterGains(const Iso3& T_O_C, const RasterWindow& w,
                                   const std::vector<Occluder>& occluders,
                                   std::vector<Ray>* shadows, std::vector<double>* gains,
                                   std::vector<double>* logArgs, ProjectorShadows* rows,
                                   ViewQualityStats* st) const {
  const CameraIntrinsics& K = camera_.intrinsics;
  thread_local RasterScratch scratch;
  scratch.robotMeshes.clear();
  scratch.robotSolid.clear();
  scratch.object.reset(PinholeProjection{K.fx, K.fy, K.cx, K.cy}, w);
  drawCameraView(T_O_C, occluders, &scratch);
  DepthRaster& object = scratch.object;
  const Vec3f origin = T_O_C.translation().cast<float>();
  const Mat3 R = T_O_C.linear();
  const auto& V = model_.mesh.vertices;
  const ViewContext view = viewContext(T_O_C);
  // The fast per-sample stage (eq. 9's integrand); the unknown-area baseline goes through
  // surfaceGain with an exact hit per sample.
  const bool fast = options_.integrand == QualityIntegrand::kInformationGain;
  const Vec3 o = T_O_C.translation();
  const double fxfy = K.fx * K.fy;
  // With the projector's view rasterised, the fast path leaves each sample's last divisions and
  // square root to the end of its row: there the samples are independent and branch-free, so
  // they overlap in the pipeline instead of lengthening each sample's chain of dependent steps.
  struct Pending {
    int i;
    double d, dist2, den, num, ratioNum;  // weight = num / den, ratio = ratioNum / den
  };
  thread_local std::vector<Pending> pending;
  const bool defer = fast && rows && logArgs;
  // Each column's part of the ray direction, once per view rather than a division per sample.
  thread_local std::vector<Vec3> colDir;
  colDir.resize(size_t(std::max(0, w.i1 - w.i0 + 1)));
  for (int i = w.i0; i <= w.i1; ++i)
    colDir[size_t(i - w.i0)] = (i * w.stride - K.cx) / K.fx * R.col(0);
  for (int j = w.j0; j <= w.j1; ++j) {
    const Vec3 dirRow = R.col(2) + (j * w.stride - K.cy) / K.fy * R.col(1);
    // The row's samples outside its surface's extent are empty: counted, not visited.
    int first, last;
    object.rowExtent(j, &first, &last);
    st->missed += w.width() - std::max(0, last - first + 1);
    for (int i = first, s = object.index(first, j); i <= last; ++i, ++s) {
      const int tri = object.id(s);
      // The triangle records live in L3 at best: ask for the one a few samples ahead now.
      if (i + kPrefetch <= last) {
        const int ahead = object.id(s + kPrefetch);
        if (ahead >= 0) {
          __builtin_prefetch(&planes_[size_t(ahead)]);
          __builtin_prefetch(reinterpret_cast<const char*>(&planes_[size_t(ahead)]) + 64);
        }
      }
      if (tri < 0) {  // nothing, or the robot in front of S_obj
        ++(tri == DepthRaster::kOccluded ? st->robot_first : st->missed);
        continue;
      }
      if (fast) {
        FastSample f;
        if (!fastSample(tri, o, dirRow + colDir[size_t(i - w.i0)], view, &f, st)) continue;
        if (defer) {  // eq9Terms, its division done later for a whole row
          const double sz2 = f.sz * f.sz, a = fxfy * f.nz;
          pending.push_back({i, f.d, f.dist2, sz2 * a, 0.5 * f.d * f.d * sz2, f.var * a});
          continue;
        }
        const Eq9Terms e = eq9Terms(f.d, f.sz * f.sz, f.var, fxfy * f.nz);
        if (logArgs) {  // the logarithm later, for the samples the projector sees
          gains->push_back(e.weight);
          logArgs->push_back(e.ratio);
        } else {
          gains->push_back(e.weight * log1pNonNegative(e.ratio));
        }
        const double dist = std::sqrt(f.dist2);
        if (rows) {
          addShadowPoint(rows, j, i, f.d, dist);
        } else {
          Ray shadow;
          shadow.origin = f.p.cast<float>();
          shadow.dir = (f.toP / dist).cast<float>();
          shadow.tnear = float(kShadowMargin);
          shadow.tfar = float(dist - kShadowMargin);
          shadows->push_back(shadow);
        }
        continue;
      }
      Ray r;
      r.origin = origin;
      r.dir = (R * K.rayZ1(i * w.stride, j * w.stride)).cast<float>();  // as the reference
      const Tri& f = model_.mesh.triangles[size_t(tri)];
      Hit h;
      hitTriangle(r, V[size_t(f[0])].cast<double>(), V[size_t(f[1])].cast<double>(),
                  V[size_t(f[2])].cast<double>(), &h);
      Ray shadow;
      shadow.tfar = std::numeric_limits<float>::infinity();
      const double g =
          surfaceGain(r, h.t, h.u, h.v, tri, planes_[size_t(tri)].n, view, &shadow, st);
      if (shadow.tfar != std::numeric_limits<float>::infinity()) {  // passed the other rules
        if (rows) {
          addShadowPoint(rows, j, i, double(h.t), double(shadow.tfar) + kShadowMargin);
        } else {
          shadows->push_back(shadow);
        }
        gains->push_back(g);
        if (logArgs) logArgs->push_back(-1.0);  // final
      }
    }
    for (const Pending& s : pending) {  // as the immediate path above computes them
      const double r = 1.0 / s.den;
      gains->push_back(s.num * r);
      logArgs->push_back(s.ratioNum * r);
      addShadowPoint(rows, j, s.i, s.d, std::sqrt(s.dist2));
    }
    pending.clear();
  }
  if (rows) drawProjectorView(T_O_C, view, &scratch, rows);
}

void ViewQualityScene::primaryHitsRayCast(const Iso3& T_O_C, const RasterWindow& w,
                                          const RayScene* robot, std::vector<Ray>* out,
                                          std::vector<Hit>* outHits, ViewQualityStats* st) const {
  const CameraIntrinsics& K = camera_.intrinsics;
  thread_local std::vector<Ray> rays, toHit;
  thread_local std::vector<Hit> hits;
  thread_local std::vector<uint8_t> blocked;
  thread_local std::vector<int> index;
  rays.clear();
  const Vec3f origin = T_O_C.translation().cast<float>();
  const Mat3 R = T_O_C.linear();
  const int sp = w.stride;
  // Samples in coherent 4×4 tiles.
  for (int tj = w.j0; tj <= w.j1; tj += 4)
    for (int ti = w.i0; ti <= w.i1; ti += 4)
      for (int j = tj; j < std::min(tj + 4, w.j1 + 1); ++j)
        for (int i = ti; i < std::min(ti + 4, w.i1 + 1); ++i) {
          Ray r;
          r.origin = origin;
          r.dir = (R * K.rayZ1(i * sp, j * sp)).cast<float>();  // as the reference computes it
          rays.push_back(r);
        }
  hits.resize(rays.size());
  objectScene_.intersect(rays.data(), hits.data(), rays.size(), /*parallel=*/false);
  // Robot in front of the S_obj hit?
  index.clear();
  for (size_t i = 0; i < rays.size(); ++i) {
    if (!hits[i].valid()) {
      ++st->missed;
      continue;
    }
    index.push_back(int(i));
  }
  if (robot) {
    toHit.resize(index.size());
    for (size_t j = 0; j < index.size(); ++j) {
      toHit[j] = rays[size_t(index[j])];
      toHit[j].tfar = hits[size_t(index[j])].t;
    }
    blocked.resize(toHit.size());
    robot->occluded(toHit.data(), blocked.data(), toHit.size(), /*parallel=*/false);
    size_t kept = 0;
    for (size_t j = 0; j < index.size(); ++j) {
      if (blocked[j])
        ++st->robot_first;
      else
        index[kept++] = index[j];
    }
    index.resize(kept);
  }
  for (int i : index) {
    out->push_back(rays[size_t(i)]);
    outHits->push_back(hits[size_t(i)]);
  }
}

double ViewQualityScene::quality(const Iso3& T_O_C, const std::vector<Occluder>& occluders,
                                 ViewQualityStats* stats, int pixel_stride) const {
  ViewQualityStats local;
  ViewQualityStats& st = stats ? *stats : local;
  st = ViewQualityStats{};
  const int sp = pixel_stride > 0 ? pixel_stride : options_.pixel_stride;
  RasterWindow w;
  if (!pixelWindow(T_O_C, sp, &w)) return 0.0;
  st.cast = w.size();
  // The robot, a handful of instanced links, as one Embree scene for the shadow rays that S_obj
  // itself does not block (and, when not rasterising, for the primary rays that hit S_obj).
  thread_local std::vector<Ray> rays, shadows, toHit;
  thread_local std::vector<Hit> hits;
  thread_local std::vector<double> gains, logArgs;
  thread_local std::vector<uint8_t> blocked, robotBlocked;
  thread_local std::vector<int> index;
  rays.clear();
  hits.clear();
  const bool raster = options_.visibility == PrimaryVisibility::kRaster ||
                      (options_.visibility == PrimaryVisibility::kAuto && w.stride <= 2);
  shadows.clear();
  gains.clear();
  // Rasterised with a projector on the camera's x axis: the projector's view decides the
  // shadows too (ProjectorShadows), with no ray cast at all.
  const bool rowShadows = raster && ProjectorShadows::applicable(camera_.projector_C);
  if (rowShadows) {
    thread_local ProjectorShadows rows;
    const CameraIntrinsics& K = camera_.intrinsics;
    rows.reset({K.fx, K.fy, K.cx, K.cy}, w, camera_.projector_C.x());
    logArgs.clear();
    rasterGains(T_O_C, w, occluders, &shadows, &gains, &logArgs, &rows, &st);
    // Each sample's term (its gain, or its weight times the logarithm), then their sum in
    // sample order over those the projector sees.
    const size_t n = size_t(rows.size());
    thread_local std::vector<double> terms;
    terms.resize(n);
    size_t k = 0;
#if INHAND_FAST_MATH_AVX2
    if (fastMathAvx2()) k = logTermsFour(gains.data(), logArgs.data(), n, terms.data());
#endif
    for (; k < n; ++k) {
      const double x = logArgs[k];
      terms[k] = x < 0 ? gains[k] : gains[k] * log1pNonNegative(x);
    }
    double G = 0;
    for (k = 0; k < n; ++k) {
      if (rows.blocked(int(k))) {
        ++st.projector_blocked;
        continue;
      }
      ++st.counted;
      G += terms[k];
    }
    return G * double(sp) * double(sp);  // each sample stands for stride² pixels
  }
  std::optional<RayScene> robot;
  if (!occluders.empty()) robot.emplace(buildScene(occluders, false));
  if (raster)
    rasterGains(T_O_C, w, occluders, &shadows, &gains, nullptr, nullptr, &st);
  else
    primaryHitsRayCast(T_O_C, w, robot ? &*robot : nullptr, &rays, &hits, &st);
  for (size_t i = 0; i < rays.size(); ++i) {
    Ray shadow;
    shadow.tfar = std::numeric_limits<float>::infinity();
    double g = pixelGain(hits[i], rays[i], T_O_C, &shadow, &st);
    if (shadow.tfar != std::numeric_limits<float>::infinity()) {  // passed the other rules
      shadows.push_back(shadow);
      gains.push_back(g);
    }
  }
  blocked.resize(shadows.size());
  objectScene_.occluded(shadows.data(), blocked.data(), shadows.size(), /*parallel=*/false);
  if (robot) {
    toHit.clear();
    index.clear();
    for (size_t i = 0; i < shadows.size(); ++i)
      if (!blocked[i]) {
        toHit.push_back(shadows[i]);
        index.push_back(int(i));
      }
    robotBlocked.resize(toHit.size());
    robot->occluded(toHit.data(), robotBlocked.data(), toHit.size(), /*parallel=*/false);
    for (size_t j = 0; j < index.size(); ++j) blocked[size_t(index[j])] = robotBlocked[j];
  }
  double G = 0;
  for (size_t i = 0; i < shadows.size(); ++i) {
    if (blocked[i]) {
      ++st.projector_blocked;
      continue;
    }
    ++st.counted;
    G += gains[i];
  }
  return G * double(sp) * double(sp);  // each sample stands for stride² pixels
}

double ViewQualityScene::qualityReference(const Iso3& T_O_C, const std::vector<Occluder>& occluders,
                                          ViewQualityStats* stats) const {
  ViewQualityStats local;
  ViewQualityStats& st = stats ? *stats : local;
  st = ViewQualityStats{};
  const CameraIntrinsics& K = camera_.intrinsics;
  RayScene scene = buildScene(occluders, true);
  const int sp = options_.pixel_stride;
  double G = 0;
  for (int v = 0; v < K.height; v += sp)
    for (int u = 0; u < K.width; u += sp) {
      Ray r;
      r.origin = T_O_C.translation().cast<float>();
      r.dir = (T_O_C.linear() * K.rayZ1(u, v)).cast<float>();
      ++st.cast;
      Hit h = scene.intersectOne(r);
      if (h.valid() && h.geometry != 0 && !objectScene_.intersectOne(r).valid())
        h = Hit{};  // the robot hides nothing of S_obj here: counts as a miss
      Ray shadow;
      shadow.tfar = std::numeric_limits<float>::infinity();
      double g = pixelGain(h, r, T_O_C, &shadow, &st);
      if (shadow.tfar == std::numeric_limits<float>::infinity()) continue;
      if (scene.intersectOne(shadow).valid()) {
        ++st.projector_blocked;
        continue;
      }
      ++st.counted;
      G += g;
    }
  return G * double(sp) * double(sp);
}

}  // namespace inhand
