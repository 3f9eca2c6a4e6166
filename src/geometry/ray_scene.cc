#include "inhand/geometry/ray_scene.h"

#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <mutex>

#include "inhand/core/error.h"
#include "inhand/core/internal/fast_math.h"
#include "inhand/core/internal/parallel.h"

#include <tbb/task_arena.h>

namespace inhand {

namespace {

void onEmbreeError(void*, RTCError code, const char* str) {
  std::fprintf(stderr, "inhand: embree error %d: %s\n", int(code), str ? str : "");
}

// One Embree device for the process (it owns the thread pool and ISA dispatch).
RTCDevice device() {
  static RTCDevice dev = [] {
    // INHAND_EMBREE_CONFIG is Embree's own configuration string; without it, INHAND_NO_AVX2
    // keeps Embree to its SSE4.2 kernels.
    const char* config = std::getenv("INHAND_EMBREE_CONFIG");
    if (!config && avx2TurnedOff()) config = "max_isa=sse4.2";
    RTCDevice d = rtcNewDevice(config);
    INHAND_CHECK(d != nullptr, "cannot create an Embree device");
    rtcSetDeviceErrorFunction(d, onEmbreeError, nullptr);
    return d;
  }();
  return dev;
}

constexpr unsigned kAllMask = 0xFFFFFFFFu;  // Debian's Embree has ray masks on: mask 0 hits nothing

}  // namespace

RayScene::RayScene() { scene_ = rtcNewScene(device()); }

RayScene::~RayScene() {
  if (scene_) rtcReleaseScene(scene_);
}

RayScene::RayScene(RayScene&& o) noexcept
    : scene_(o.scene_),
      instanceRotation_(std::move(o.instanceRotation_)),
      meshes_(std::move(o.meshes_)),
      bounds_(std::move(o.bounds_)),
      instances_(std::move(o.instances_)),
      geometryCount_(o.geometryCount_),
      committed_(o.committed_) {
  o.scene_ = nullptr;
}

RayScene& RayScene::operator=(RayScene&& o) noexcept {
  if (this != &o) {
    if (scene_) rtcReleaseScene(scene_);
    scene_ = o.scene_;
    instanceRotation_ = std::move(o.instanceRotation_);
    meshes_ = std::move(o.meshes_);
    bounds_ = std::move(o.bounds_);
    instances_ = std::move(o.instances_);
    geometryCount_ = o.geometryCount_;
    committed_ = o.committed_;
    o.scene_ = nullptr;
  }
  return *this;
}

int RayScene::addMesh(const TriangleMesh& mesh, const Iso3& T) {
  INHAND_CHECK(!committed_, "addMesh after commit");
  RTCGeometry geom = rtcNewGeometry(device(), RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.vertices.size()));
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    Vec3f p = (T * mesh.vertices[i].cast<double>()).cast<float>();
    v[3 * i] = p.x();
    v[3 * i + 1] = p.y();
    v[3 * i + 2] = p.z();
  }
  auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                             RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                                             mesh.triangles.size()));
  const bool flip = T.linear().determinant() < 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Tri& f = mesh.triangles[t];
    idx[3 * t] = unsigned(f[0]);
    idx[3 * t + 1] = unsigned(flip ? f[2] : f[1]);
    idx[3 * t + 2] = unsigned(flip ? f[1] : f[2]);
  }
  rtcSetGeometryMask(geom, kAllMask);
  rtcCommitGeometry(geom);
  unsigned id = rtcAttachGeometry(scene_, geom);
  rtcReleaseGeometry(geom);
  INHAND_CHECK(int(id) == geometryCount_, "unexpected Embree geometry id");
  instanceRotation_.push_back(Eigen::Matrix3f::Identity());
  meshes_.push_back(transformed(mesh, T));
  bounds_.push_back(meshes_.back().bounds());
  instances_.emplace_back(nullptr, Iso3::Identity());
  return geometryCount_++;
}

int RayScene::addInstance(const RayScene& inner, const Iso3& T) {
  INHAND_CHECK(!committed_, "addInstance after commit");
  INHAND_CHECK(inner.committed_, "instanced scene must be committed");
  RTCGeometry geom = rtcNewGeometry(device(), RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(geom, inner.scene_);
  float xfm[12];  // 3×4, column major
  const Eigen::Matrix<double, 3, 4> M = T.matrix().topRows<3>();
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 3; ++r) xfm[c * 3 + r] = float(M(r, c));
  rtcSetGeometryTransform(geom, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm);
  rtcSetGeometryMask(geom, kAllMask);
  rtcCommitGeometry(geom);
  unsigned id = rtcAttachGeometry(scene_, geom);
  rtcReleaseGeometry(geom);
  INHAND_CHECK(int(id) == geometryCount_, "unexpected Embree geometry id");
  instanceRotation_.push_back(T.linear().cast<float>());
  meshes_.emplace_back();
  bounds_.emplace_back();
  instances_.emplace_back(&inner, T);
  return geometryCount_++;
}

void RayScene::makeHit(float t, unsigned geomID, unsigned instID, unsigned primID, float u, float v,
                       const Vec3f& Ng, Hit* h) const {
  if (geomID == RTC_INVALID_GEOMETRY_ID) {
    *h = Hit();
    return;
  }
  h->t = t;
  h->triangle = int(primID);
  h->u = u;
  h->v = v;
  if (instID != RTC_INVALID_GEOMETRY_ID) {
    h->geometry = int(instID);
    h->inner = int(geomID);
    h->normal = instanceRotation_[instID] * Ng;  // Embree reports Ng in the instance's space
  } else {
    h->geometry = int(geomID);
    h->inner = -1;
    h->normal = Ng;
  }
}

void RayScene::collectMeshes(const Iso3& T, std::vector<PlacedMesh>* out) const {
  for (int g = 0; g < geometryCount_; ++g) {
    if (instances_[size_t(g)].first)
      instances_[size_t(g)].first->collectMeshes(T * instances_[size_t(g)].second, out);
    else
      out->push_back({&meshes_[size_t(g)], T, &bounds_[size_t(g)]});
  }
}

void RayScene::commit(bool high) {
  rtcSetSceneBuildQuality(scene_, high ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
  rtcCommitScene(scene_);
  committed_ = true;
}

namespace {
constexpr size_t kPacket =
    8;  // native width on AVX2 (rtcIntersect16 falls back to the stream path there)

void loadPacket(const Ray* rays, size_t n, RTCRay8& r, int* valid) {
  for (size_t k = 0; k < kPacket; ++k) {
    const Ray& ray = rays[k < n ? k : 0];
    valid[k] = k < n ? -1 : 0;
    r.org_x[k] = ray.origin.x();
    r.org_y[k] = ray.origin.y();
    r.org_z[k] = ray.origin.z();
    r.dir_x[k] = ray.dir.x();
    r.dir_y[k] = ray.dir.y();
    r.dir_z[k] = ray.dir.z();
    r.tnear[k] = ray.tnear;
    r.tfar[k] = ray.tfar;
    r.time[k] = 0.f;
    r.mask[k] = kAllMask;
    r.id[k] = unsigned(k);
    r.flags[k] = 0;
  }
}

#if INHAND_FAST_MATH_AVX2
// loadPacket for eight rays: a Ray is eight floats (origin, direction, tnear, tfar), so the packet
// is the 8 × 8 transpose of the rays, its rows stored to the packet's fields.
static_assert(sizeof(Ray) == 8 * sizeof(float) && offsetof(Ray, tnear) == 6 * sizeof(float) &&
                  offsetof(Ray, tfar) == 7 * sizeof(float),
              "Ray: origin, dir, tnear, tfar as eight floats");
__attribute__((target("avx2"))) void loadPacketEight(const Ray* rays, RTCRay8& r, int* valid) {
  const float* f = reinterpret_cast<const float*>(rays);
  __m256 row[8], t[8], u[8];
  for (int k = 0; k < 8; ++k) row[k] = _mm256_loadu_ps(f + 8 * k);
  for (int k = 0; k < 8; k += 2) {
    t[k] = _mm256_unpacklo_ps(row[k], row[k + 1]);
    t[k + 1] = _mm256_unpackhi_ps(row[k], row[k + 1]);
  }
  for (int k = 0; k < 8; k += 4) {
    u[k] = _mm256_shuffle_ps(t[k], t[k + 2], 0x44);
    u[k + 1] = _mm256_shuffle_ps(t[k], t[k + 2], 0xEE);
    u[k + 2] = _mm256_shuffle_ps(t[k + 1], t[k + 3], 0x44);
    u[k + 3] = _mm256_shuffle_ps(t[k + 1], t[k + 3], 0xEE);
  }
  // Column c of the rays: field c of each.
  float* field[8] = {r.org_x, r.org_y, r.org_z, r.dir_x, r.dir_y, r.dir_z, r.tnear, r.tfar};
  for (int c = 0; c < 4; ++c) {
    _mm256_storeu_ps(field[c], _mm256_permute2f128_ps(u[c], u[c + 4], 0x20));
    _mm256_storeu_ps(field[c + 4], _mm256_permute2f128_ps(u[c], u[c + 4], 0x31));
  }
  _mm256_storeu_ps(r.time, _mm256_setzero_ps());
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(r.mask), _mm256_set1_epi32(int(kAllMask)));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(r.id), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(r.flags), _mm256_setzero_si256());
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(valid), _mm256_set1_epi32(-1));
}
#endif

// Rays into a packet: eight at once where the CPU has AVX2, else (and for a last packet of fewer)
// one at a time.
void loadRays(const Ray* rays, size_t n, RTCRay8& r, int* valid) {
#if INHAND_FAST_MATH_AVX2
  if (n == kPacket && fastMathAvx2()) return loadPacketEight(rays, r, valid);
#endif
  loadPacket(rays, n, r, valid);
}

// Calls packet(first, n) for each packet of `count` rays: on the calling thread, or spread over
// the cores.
template <typename F>
void forEachPacket(size_t count, bool parallel, const F& packet) {
  const int packets = int((count + kPacket - 1) / kPacket);
  auto one = [&](int p) {
    const size_t first = size_t(p) * kPacket;
    packet(first, std::min(kPacket, count - first));
  };
  if (parallel)
    parallelFor(0, packets, one, 8);
  else
    for (int p = 0; p < packets; ++p) one(p);
}
}  // namespace

void RayScene::intersect(const Ray* rays, Hit* hits, size_t count, bool parallel) const {
  INHAND_CHECK(committed_, "intersect before commit");
  forEachPacket(count, parallel, [&](size_t first, size_t n) {
    alignas(64) RTCRayHit8 rh;
    alignas(64) int valid[kPacket];
    loadRays(rays + first, n, rh.ray, valid);
    for (size_t k = 0; k < kPacket; ++k) {
      rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    rtcIntersect8(valid, scene_, &ctx, &rh);
    for (size_t k = 0; k < n; ++k)
      makeHit(rh.ray.tfar[k], rh.hit.geomID[k], rh.hit.instID[0][k], rh.hit.primID[k], rh.hit.u[k],
              rh.hit.v[k], Vec3f(rh.hit.Ng_x[k], rh.hit.Ng_y[k], rh.hit.Ng_z[k]), &hits[first + k]);
  });
}

void RayScene::occluded(const Ray* rays, uint8_t* blocked, size_t count, bool parallel) const {
  INHAND_CHECK(committed_, "occluded before commit");
  forEachPacket(count, parallel, [&](size_t first, size_t n) {
    alignas(64) RTCRay8 r;
    alignas(64) int valid[kPacket];
    loadRays(rays + first, n, r, valid);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcOccluded8(valid, scene_, &ctx, &r);
    // Embree sets tfar to −inf for occluded rays.
    for (size_t k = 0; k < n; ++k) blocked[first + k] = r.tfar[k] < 0.f ? 1 : 0;
  });
}

Hit RayScene::intersectOne(const Ray& ray) const {
  INHAND_CHECK(committed_, "intersect before commit");
  RTCRayHit rh;
  rh.ray.org_x = ray.origin.x();
  rh.ray.org_y = ray.origin.y();
  rh.ray.org_z = ray.origin.z();
  rh.ray.dir_x = ray.dir.x();
  rh.ray.dir_y = ray.dir.y();
  rh.ray.dir_z = ray.dir.z();
  rh.ray.tnear = ray.tnear;
  rh.ray.tfar = ray.tfar;
  rh.ray.time = 0.f;
  rh.ray.mask = kAllMask;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  rtcIntersect1(scene_, &ctx, &rh);
  Hit h;
  makeHit(rh.ray.tfar, rh.hit.geomID, rh.hit.instID[0], rh.hit.primID, rh.hit.u, rh.hit.v,
          Vec3f(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z), &h);
  return h;
}

}  // namespace inhand
