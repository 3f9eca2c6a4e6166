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
  // Scratch buffers live on per thread: allocating ~40 MB afresh per frame costs more in page
  // faults than the ray casting itself (measured: 37 ms → see README).
  thread_local struct Scratch {
    std::vector<int> order;
    std::vector<Ray> rays, shadows, compact;
    std::vector<Hit> hits;
    std::vector<uint8_t> ok, blocked, compactBlocked;
    std::vector<int> shadowIndex;
    std::vector<float> noiseU, noiseV, noiseZ;  // the standard normal draws of each pixel
    int w = 0, h = 0;
  } scratch;
  const bool whole = options.region_u1 < 0 || options.region_v1 < 0;
  if (whole && (scratch.w != w || scratch.h != h)) {
    scratch.order = tileOrder(w, 0, 0, w, h);
    scratch.w = w;
    scratch.h = h;
  }
  std::vector<int> regionOrder;
  if (!whole)
    regionOrder =
        tileOrder(w, std::clamp(options.region_u0, 0, w), std::clamp(options.region_v0, 0, h),
                  std::clamp(options.region_u1, 0, w), std::clamp(options.region_v1, 0, h));
  const std::vector<int>& order = whole ? scratch.order : regionOrder;
  const int n = int(order.size());
  const Vec3 projector_S = T_S_C * camera.projector_C;
  std::vector<Ray>& rays = scratch.rays;
  std::vector<Hit>& hits = scratch.hits;
  rays.resize(n);
  hits.resize(n);
  // The pixel centres' rays: K.rayZ1's per-column and per-row terms once, the same values.
  std::vector<double> xs(static_cast<size_t>(w)), ys(static_cast<size_t>(h));
  for (int u = 0; u < w; ++u) xs[size_t(u)] = K.rayZ1(u, 0).x();
  for (int v = 0; v < h; ++v) ys[size_t(v)] = K.rayZ1(0, v).y();
  const Vec3f origin = T_S_C.translation().cast<float>();
  const Mat3 R = T_S_C.linear();
  parallelFor(
      0, n,
      [&](int i) {
        const int p = order[i];
        rays[i] = Ray{};
        rays[i].origin = origin;
        rays[i].dir = (R * Vec3(xs[size_t(p % w)], ys[size_t(p / w)], 1.0)).cast<float>();
      },
      4096);
  scene.intersect(rays.data(), hits.data(), n);
  const Background background(scene, options);

  // (The scratch through references: inside a parallel loop `scratch` is the worker's own.)
  std::vector<float>&gu = scratch.noiseU, &gv = scratch.noiseV, &gz = scratch.noiseZ;
  if (options.noise) {
    // Each pixel's draws, eight at a time: the lateral pair at index 3p, the axial one at 3p + 2.
    gu.resize(size_t(n));
    gv.resize(size_t(n));
    gz.resize(size_t(n));
    constexpr int kBlock = 1024;
    parallelFor(0, (n + kBlock - 1) / kBlock, [&](int b) {
      const int i0 = b * kBlock, m = std::min(n, i0 + kBlock) - i0;
      uint64_t lateral[kBlock], axial[kBlock];
      for (int k = 0; k < m; ++k) {
        lateral[k] = 3 * uint64_t(order[size_t(i0 + k)]);
        axial[k] = lateral[k] + 2;
      }
      gaussianPairsF(options.seed, lateral, size_t(m), &gu[size_t(i0)], &gv[size_t(i0)]);
      gaussianPairsF(options.seed, axial, size_t(m), &gz[size_t(i0)], nullptr);
    });
    // Lateral noise: the return comes from a point displaced by N(0, σ_L(θ)) pixels, so re-cast
    // through the displaced sub-pixel position (this also makes ragged, mixed depth edges).
    parallelFor(
        0, n,
        [&](int i) {
          background.fill(rays[i], hits[i]);
          if (!hits[i].valid()) return;
          int p = order[i];
          const double theta = incidenceF(hits[i].normal, rays[i].dir);
          const double s = lateralSigmaPx(noise, theta);
          const double du = s * gu[size_t(i)], dv = s * gv[size_t(i)];
          rays[i] = pixelRay(T_S_C, K, p % w + du, p / w + dv);
        },
        4096);
    scene.intersect(rays.data(), hits.data(), n);
  }

  std::vector<Ray>& shadows = scratch.shadows;
  std::vector<uint8_t>& ok = scratch.ok;
  std::vector<uint8_t>& blocked = scratch.blocked;
  const IncidenceLimits limits(camera);
  shadows.resize(n);
  ok.assign(n, 0);
  blocked.assign(n, 0);
  parallelFor(
      0, n,
      [&](int i) {
        background.fill(rays[i], hits[i]);
        ok[i] = acceptHit(hits[i], rays[i], projector_S, camera, limits, &shadows[i]);
      },
      4096);
  if (options.projector_shadows) {
    // Compact the shadow rays so packets stay full, in pixel order: each chunk's count, their
    // running sum, then each chunk writes its own part.
    constexpr int kChunk = 8192;
    const int chunks = (n + kChunk - 1) / kChunk;
    std::vector<int> offset(size_t(chunks) + 1, 0);
    parallelFor(0, chunks, [&](int c) {
      int count = 0;
      for (int i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) count += ok[i];
      offset[size_t(c) + 1] = count;
    });
    for (int c = 0; c < chunks; ++c) offset[size_t(c) + 1] += offset[size_t(c)];
    std::vector<int>& shadowIndex = scratch.shadowIndex;
    std::vector<Ray>& compact = scratch.compact;
    const size_t total = size_t(offset.back());
    shadowIndex.resize(total);
    compact.resize(total);
    parallelFor(0, chunks, [&](int c) {
      int k = offset[size_t(c)];
      for (int i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i)
        if (ok[i]) {
          shadowIndex[size_t(k)] = i;
          compact[size_t(k++)] = shadows[i];
        }
    });
    std::vector<uint8_t>& compactBlocked = scratch.compactBlocked;
    compactBlocked.resize(total);
    scene.occluded(compact.data(), compactBlocked.data(), total);
    parallelFor(
        0, int(total), [&](int k) { blocked[shadowIndex[size_t(k)]] = compactBlocked[size_t(k)]; },
        16384);
  }

  DepthImage out(w, h);
  if (geometry_out) geometry_out->assign(size_t(w) * h, -1);
  const double f = K.fx;
  const double cosGrazing = std::cos(noise.grazing_start_deg * M_PI / 180);
  parallelFor(
      0, n,
      [&](int i) {
        if (!ok[i] || blocked[i]) return;
        int p = order[i];
        double z = hits[i].t;
        if (options.noise) {
          // The angle matters to the axial σ only beyond grazing_start_deg.
          double theta = 0;
          if (!(cosGrazing > 0) || !cosCertainlyAtLeastF(hits[i].normal, rays[i].dir, cosGrazing)) {
            const double c = cosIncidenceF(hits[i].normal, rays[i].dir);
            theta = c < cosGrazing ? std::acos(c) : 0.0;
          }
          z += axialSigma(noise, z, theta) * gz[size_t(i)];
          if (noise.quantize) z = quantizeDepth(z, f, camera.baseline_m(), noise.disparity_step_px);
          if (z < camera.min_range_m || z > camera.max_range_m) return;
        }
        out.depth_m[p] = float(z);
        if (geometry_out) (*geometry_out)[p] = hits[i].geometry;
      },
      4096);
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
