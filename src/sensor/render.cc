#include "inhand/sensor/render.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/parallel.h"
#include "inhand/core/random.h"

namespace inhand {

namespace {

constexpr double kSurfaceOffset_m = 2e-4;  // shadow rays start this far off the surface

// Pixels of [u0, u1) × [v0, v1) of a w-wide image, cast in 4×4 tiles so each 16-ray packet is
// coherent.
std::vector<int> tileOrder(int w, int u0, int v0, int u1, int v1) {
  std::vector<int> order;
  order.reserve(size_t(std::max(0, u1 - u0)) * size_t(std::max(0, v1 - v0)));
  for (int ty = v0; ty < v1; ty += 4)
    for (int tx = u0; tx < u1; tx += 4)
      for (int y = ty; y < std::min(ty + 4, v1); ++y)
        for (int x = tx; x < std::min(tx + 4, u1); ++x) order.push_back(y * w + x);
  return order;
}

Ray pixelRay(const Iso3& T_S_C, const CameraIntrinsics& K, double u, double v) {
  Ray r;
  r.origin = T_S_C.translation().cast<float>();
  r.dir = (T_S_C.linear() * K.rayZ1(u, v)).cast<float>();  // camera z = 1, so t is the depth z
  return r;
}

// Cosine of the angle between a surface normal and a direction, two-sided (0 when either is 0).
double cosIncidence(const Vec3& normal, const Vec3& dir) {
  double nn = normal.norm(), dn = dir.norm();
  if (nn == 0 || dn == 0) return 0;
  return std::min(1.0, std::abs(normal.dot(dir)) / (nn * dn));
}

// cosIncidence and the angle itself (rad) in single precision, for the noise's σ per pixel (in
// double precision the arccosine cost as much as casting the ray).
float cosIncidenceF(const Vec3f& normal, const Vec3f& dir) {
  // The products in double: Embree's unnormalised normal of a tiny triangle squared underflows a
  // float.
  const Vec3 n = normal.cast<double>(), d = dir.cast<double>();
  const double nn = n.squaredNorm() * d.squaredNorm();
  if (!(nn > 0)) return 0.f;
  return float(std::min(1.0, std::abs(n.dot(d)) / std::sqrt(nn)));
}
float incidenceF(const Vec3f& normal, const Vec3f& dir) {
  return acosUnitF(cosIncidenceF(normal, dir));
}

// Whether cosIncidence(normal, dir) < limit (limit in (0, 1)): by squares, with no square root
// or division, where the answer is certain, and by cosIncidence itself within a relative 1e-9 of
// the limit (both are exact to ~1e-15), so the answer is cosIncidence's, bit for bit.
bool cosBelow(const Vec3& normal, const Vec3& dir, double limit) {
  const double nd = normal.dot(dir);
  const double bound = limit * limit * (normal.squaredNorm() * dir.squaredNorm());
  if (nd * nd > bound * (1 + 1e-9)) return false;
  if (nd * nd < bound * (1 - 1e-9)) return true;
  return cosIncidence(normal, dir) < limit;
}

// Whether cosIncidenceF(normal, dir) ≥ c0 (c0 in (0, 1)) for certain, by squares: true only where
// the float cosine cannot round below c0 (a relative 1e-6 of margin against its 6e-8).
bool cosCertainlyAtLeastF(const Vec3f& normal, const Vec3f& dir, double c0) {
  const Vec3 n = normal.cast<double>(), d = dir.cast<double>();
  const double nn = n.squaredNorm() * d.squaredNorm(), nd = n.dot(d);
  return nn > 0 && nd * nd >= c0 * c0 * nn * (1 + 1e-6);
}

// The cosines of the sensor's incidence limits: an angle exceeds a limit when its cosine is
// below the limit's (acos falls as its argument rises), so no arccosine is needed per pixel.
struct IncidenceLimits {
  double camera, projector;
  explicit IncidenceLimits(const DepthCameraOptions& cam)
      : camera(std::cos(cam.max_incidence_deg * M_PI / 180)),
        projector(std::cos(cam.max_projector_incidence_deg * M_PI / 180)) {}
};

// The geometric part of whether the sensor returns a depth for this hit: in range, not too oblique
// for the camera or the projector. Returns the shadow ray towards the projector when it does.
bool acceptHit(const Hit& hit, const Ray& ray, const Vec3& projector_S,
               const DepthCameraOptions& cam, const IncidenceLimits& limits, Ray* shadow) {
  if (!hit.valid()) return false;
  double z = hit.t;
  if (z < cam.min_range_m || z > cam.max_range_m) return false;
  Vec3 n = hit.normal.cast<double>();
  if (cosBelow(n, ray.dir.cast<double>(), limits.camera)) return false;
  Vec3 x = (ray.origin + hit.t * ray.dir).cast<double>();
  Vec3 toProjector = projector_S - x;
  if (cosBelow(n, toProjector, limits.projector)) return false;
  double dist = toProjector.norm();
  shadow->origin = x.cast<float>();
  shadow->dir = (toProjector / dist).cast<float>();
  shadow->tnear = float(kSurfaceOffset_m);
  shadow->tfar = float(dist - kSurfaceOffset_m);
  return true;
}

// Rays that missed the scene hit the inside of the background sphere (when there is one): the far
// root of |o + t·d − c|² = r², the normal pointing back in. Rays that start outside it, or whose
// far root lies behind the ray's start, stay misses. Per ray, inside the pass that reads the hit
// next (a pass of its own over every ray cost as much in memory traffic as its arithmetic).
struct Background {
  int id;
  double r2;
  Vec3 centre;
  Background(const RayScene& scene, const RenderOptions& o)
      : id(scene.geometryCount()),
        r2(o.background_radius_m > 0 ? o.background_radius_m * o.background_radius_m : 0),
        centre(o.background_centre) {}
  void fill(const Ray& ray, Hit& h) const {
    if (h.valid() || !(r2 > 0)) return;
    const Vec3 d = ray.dir.cast<double>();
    const Vec3 oc = ray.origin.cast<double>() - centre;
    const double a = d.squaredNorm(), b = oc.dot(d), c = oc.squaredNorm() - r2;
    const double disc = b * b - a * c;
    if (!(a > 0) || disc < 0) return;
    const double t = (-b + std::sqrt(disc)) / a;
    if (!(t > ray.tnear) || !(t < ray.tfar)) return;
    h.t = float(t);
    h.geometry = id;
    h.normal = (-(oc + t * d)).cast<float>();
  }
};

}  // namespace

DepthImage renderDepth(const RayScene& scene, const Iso3& T_S_C, const DepthCameraOptions& camera,
                       const NoiseModelOptions& noise, const RenderOptions& options,
                       std::vector<int>* geometry_out) {
  const CameraIntrinsics& K = camera.intrinsics;
  const int w = K.width, h = K.height;
  // The whole image's tile order is kept per thread (it is the same for every frame).
  thread_local std::vector<int> wholeOrder;
  thread_local int orderW = 0, orderH = 0;
  const bool whole = options.region_u1 < 0 || options.region_v1 < 0;
  if (whole && (orderW != w || orderH != h)) {
    wholeOrder = tileOrder(w, 0, 0, w, h);
    orderW = w;
    orderH = h;
  }
  std::vector<int> regionOrder;
  if (!whole)
    regionOrder =
        tileOrder(w, std::clamp(options.region_u0, 0, w), std::clamp(options.region_v0, 0, h),
                  std::clamp(options.region_u1, 0, w), std::clamp(options.region_v1, 0, h));
  const std::vector<int>& order = whole ? wholeOrder : regionOrder;
  const int n = int(order.size());
  const Vec3 projector_S = T_S_C * camera.projector_C;
  // The pixel centres' rays: K.rayZ1's per-column and per-row terms once, the same values.
  std::vector<double> xs(static_cast<size_t>(w)), ys(static_cast<size_t>(h));
  for (int u = 0; u < w; ++u) xs[size_t(u)] = K.rayZ1(u, 0).x();
  for (int v = 0; v < h; ++v) ys[size_t(v)] = K.rayZ1(0, v).y();
  const Vec3f origin = T_S_C.translation().cast<float>();
  const Mat3 R = T_S_C.linear();
  const Background background(scene, options);
  const IncidenceLimits limits(camera);
  const double f = K.fx;
  const double cosGrazing = std::cos(noise.grazing_start_deg * M_PI / 180);

  DepthImage out(w, h);
  if (geometry_out) geometry_out->assign(size_t(w) * h, -1);
  // Each task takes a band of pixels through every step, rays cast in packets on its own core:
  // the band's rays, hits and shadow rays (~100 KB) stay in the core's cache from one step to the
  // next (passes over the whole image's ~25 MB of them cost as much in memory traffic as the
  // ray casting). A band starts at a multiple of kBand, so the noise draws are the same ones.
  constexpr int kBand = 1024;
  parallelFor(0, (n + kBand - 1) / kBand, [&](int b) {
    thread_local struct Band {
      Ray rays[kBand], shadows[kBand];
      Hit hits[kBand];
      uint8_t ok[kBand], blocked[kBand], packedBlocked[kBand];
      int shadowIndex[kBand];
      uint64_t lateral[kBand], axial[kBand];
      float gu[kBand], gv[kBand], gz[kBand];  // each pixel's standard normal draws
    } band;
    const int i0 = b * kBand, m = std::min(n, i0 + kBand) - i0;
    const int* px = order.data() + i0;
    Ray* rays = band.rays;
    Hit* hits = band.hits;
    for (int k = 0; k < m; ++k) {
      const int p = px[k];
      rays[k] = Ray{};
      rays[k].origin = origin;
      rays[k].dir = (R * Vec3(xs[size_t(p % w)], ys[size_t(p / w)], 1.0)).cast<float>();
    }
    scene.intersect(rays, hits, size_t(m), false);
    if (options.noise) {
      // Each pixel's draws: the lateral pair at index 3p, the axial one at 3p + 2.
      for (int k = 0; k < m; ++k) {
        band.lateral[k] = 3 * uint64_t(px[k]);
        band.axial[k] = band.lateral[k] + 2;
      }
      gaussianPairsF(options.seed, band.lateral, size_t(m), band.gu, band.gv);
      gaussianPairsF(options.seed, band.axial, size_t(m), band.gz, nullptr);
      // Lateral noise: the return comes from a point displaced by N(0, σ_L(θ)) pixels, so
      // re-cast through the displaced sub-pixel position (this also makes ragged, mixed depth
      // edges).
      for (int k = 0; k < m; ++k) {
        background.fill(rays[k], hits[k]);
        if (!hits[k].valid()) continue;
        const int p = px[k];
        const double theta = incidenceF(hits[k].normal, rays[k].dir);
        const double s = lateralSigmaPx(noise, theta);
        const double du = s * band.gu[k], dv = s * band.gv[k];
        rays[k] = pixelRay(T_S_C, K, p % w + du, p / w + dv);
      }
      scene.intersect(rays, hits, size_t(m), false);
    }
    int shadowCount = 0;
    for (int k = 0; k < m; ++k) {
      background.fill(rays[k], hits[k]);
      band.blocked[k] = 0;
      band.ok[k] = acceptHit(hits[k], rays[k], projector_S, camera, limits, &band.shadows[k]);
      // The shadow rays packed in pixel order (over the band's own), so packets stay full.
      if (band.ok[k] && options.projector_shadows) {
        band.shadows[shadowCount] = band.shadows[k];
        band.shadowIndex[shadowCount++] = k;
      }
    }
    if (shadowCount > 0) {
      scene.occluded(band.shadows, band.packedBlocked, size_t(shadowCount), false);
      for (int j = 0; j < shadowCount; ++j)
        band.blocked[band.shadowIndex[j]] = band.packedBlocked[j];
    }
    for (int k = 0; k < m; ++k) {
      if (!band.ok[k] || band.blocked[k]) continue;
      const int p = px[k];
      double z = hits[k].t;
      if (options.noise) {
        // The angle matters to the axial σ only beyond grazing_start_deg.
        double theta = 0;
        if (!(cosGrazing > 0) || !cosCertainlyAtLeastF(hits[k].normal, rays[k].dir, cosGrazing)) {
          const double c = cosIncidenceF(hits[k].normal, rays[k].dir);
          theta = c < cosGrazing ? std::acos(c) : 0.0;
        }
        z += axialSigma(noise, z, theta) * band.gz[k];
        if (noise.quantize) z = quantizeDepth(z, f, camera.baseline_m(), noise.disparity_step_px);
        if (z < camera.min_range_m || z > camera.max_range_m) continue;
      }
      out.depth_m[size_t(p)] = float(z);
      if (geometry_out) (*geometry_out)[size_t(p)] = hits[k].geometry;
    }
  });
  return out;
}

DepthImage renderDepthReference(const RayScene& scene, const Iso3& T_S_C,
                                const DepthCameraOptions& camera) {
  const CameraIntrinsics& K = camera.intrinsics;
  const Vec3 projector_S = T_S_C * camera.projector_C;
  DepthImage out(K.width, K.height);
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      Ray ray = pixelRay(T_S_C, K, u, v);
      Hit hit = scene.intersectOne(ray);
      Ray shadow;
      if (!acceptHit(hit, ray, projector_S, camera, IncidenceLimits(camera), &shadow)) continue;
      if (scene.intersectOne(shadow).valid()) continue;  // projector cannot see the point
      out.at(u, v) = hit.t;
    }
  return out;
}

}  // namespace inhand
