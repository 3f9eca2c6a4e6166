#include "inhand/eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/sensor/depth_camera.h"

namespace inhand {

std::string EvalOptions::validate() const { return checkOptionRanges(*this); }

std::vector<uint8_t> observedTriangles(const ObjectModel& model) {
  INHAND_CHECK(model.observed.size() == model.mesh.vertices.size(), "observed flag per vertex");
  std::vector<uint8_t> use(model.mesh.triangles.size());
  for (size_t t = 0; t < use.size(); ++t) {
    const Tri& f = model.mesh.triangles[t];
    use[t] = model.observed[f[0]] && model.observed[f[1]] && model.observed[f[2]];
  }
  return use;
}

GroundTruth::GroundTruth(const TriangleMesh& truth, const EvalOptions& options)
    : options_(options), truthIndex_(truth) {
  const std::string p = options.validate();
  if (!p.empty()) throw Error("eval options: " + p);
  if (truthIndex_.empty()) throw Error("ground truth mesh has no triangles");
  truthSamples_ = sampleSurfaceUniform(truth, options.samples, options.seed);
  if (truthSamples_.empty()) throw Error("ground truth mesh has zero area");
}

namespace {
// Distances (capped at `cap`) from each point to the index, on both cores.
std::vector<double> distances(const TriangleDistanceIndex& index, const std::vector<Vec3>& pts,
                              double cap) {
  std::vector<double> d(pts.size());
  parallelFor(
      0, int(pts.size()), [&](int i) { d[i] = index.distance(pts[i], cap); }, 256);
  return d;
}
double fractionWithin(const std::vector<double>& d, double r) {
  if (d.empty()) return 0;
  size_t n = 0;
  for (double x : d) n += x <= r;
  return double(n) / double(d.size());
}
}  // namespace

double GroundTruth::coverage(const ObjectModel& model) const {
  const TriangleDistanceIndex observed(model.mesh, observedTriangles(model));
  if (observed.empty() || truthSamples_.empty()) return 0;
  std::vector<uint8_t> in(truthSamples_.size());
  parallelFor(
      0, int(truthSamples_.size()),
      [&](int i) { in[size_t(i)] = observed.within(truthSamples_[size_t(i)], options_.tau_m); },
      256);
  size_t n = 0;
  for (uint8_t x : in) n += x;
  return double(n) / double(truthSamples_.size());
}

std::vector<int> meshPieces(const TriangleMesh& mesh, int* pieces) {
  // Union-find over vertices, joined along every triangle's edges.
  std::vector<int> parent(mesh.vertices.size());
  for (size_t i = 0; i < parent.size(); ++i) parent[i] = int(i);
  auto root = [&](int i) {
    while (parent[size_t(i)] != i) i = parent[size_t(i)] = parent[size_t(parent[size_t(i)])];
    return i;
  };
  for (const auto& t : mesh.triangles)
    for (int k = 1; k < 3; ++k) {
      const int a = root(int(t[0])), b = root(int(t[k]));
      if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
    }
  std::vector<int> id(mesh.vertices.size(), -1), piece(mesh.triangles.size());
  int n = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    int& p = id[size_t(root(int(mesh.triangles[t][0])))];
    if (p < 0) p = n++;
    piece[t] = p;
  }
  if (pieces) *pieces = n;
  return piece;
}

namespace {
// The area of the pieces of `mesh` none of whose vertices lies within `near_m` of the indexed
// truth, and their number.
std::pair<double, int> detachedArea(const TriangleMesh& mesh, const TriangleDistanceIndex& truth,
                                    double near_m) {
  int n = 0;
  const std::vector<int> piece = meshPieces(mesh, &n);
  std::vector<std::vector<int>> vertices(static_cast<size_t>(n));
  std::vector<int> seen(mesh.vertices.size(), -1);
  for (size_t t = 0; t < piece.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int v = int(mesh.triangles[t][k]);
      if (seen[size_t(v)] < 0) {
        seen[size_t(v)] = piece[t];
        vertices[size_t(piece[t])].push_back(v);
      }
    }
  std::vector<uint8_t> attached(size_t(n), 0);
  parallelFor(0, n, [&](int p) {
    for (int v : vertices[size_t(p)])
      if (truth.within(mesh.vertices[size_t(v)].cast<double>(), near_m)) {
        attached[size_t(p)] = 1;
        return;
      }
  });
  double area = 0;
  int count = 0;
  for (int p = 0; p < n; ++p) count += !attached[size_t(p)];
  for (size_t t = 0; t < piece.size(); ++t)
    if (!attached[size_t(piece[t])]) area += mesh.triangleArea(int(t));
  return {area, count};
}
}  // namespace

SurfaceMetrics GroundTruth::evaluate(const ObjectModel& model) const {
  SurfaceMetrics m;
  std::tie(m.detached_area_m2, m.detached_pieces) =
      detachedArea(model.mesh, truthIndex_, options_.detached_m);
  const std::vector<uint8_t> use = observedTriangles(model);
  for (size_t t = 0; t < use.size(); ++t)
    if (use[t]) m.observed_area_m2 += model.mesh.triangleArea(int(t));
  const size_t nf = options_.fscore_m.size();
  m.fscore.assign(nf, 0);
  m.precision.assign(nf, 0);
  m.recall.assign(nf, 0);
  const TriangleDistanceIndex observed(model.mesh, use);
  if (observed.empty()) return m;
  double cap = options_.tau_m;
  for (double d : options_.fscore_m) cap = std::max(cap, d);
  const std::vector<double> toModel = distances(observed, truthSamples_, cap);
  m.coverage = fractionWithin(toModel, options_.tau_m);
  // Accuracy: every observed-model sample's exact distance to the truth (no cap).
  const std::vector<Vec3> modelSamples =
      sampleSurfaceUniform(model.mesh, options_.samples, options_.seed + 1, use);
  std::vector<double> toTruth =
      distances(truthIndex_, modelSamples, std::numeric_limits<double>::infinity());
  double sum = 0, sum2 = 0;
  for (double x : toTruth) {
    sum += x;
    sum2 += x * x;
  }
  const double n = double(std::max<size_t>(1, toTruth.size()));
  m.accuracy_mean_mm = 1000 * sum / n;
  m.accuracy_rms_mm = 1000 * std::sqrt(sum2 / n);
  for (size_t k = 0; k < nf; ++k) {
    const double P = fractionWithin(toTruth, options_.fscore_m[k]);
    const double R = fractionWithin(toModel, options_.fscore_m[k]);
    m.precision[k] = P;
    m.recall[k] = R;
    m.fscore[k] = P + R > 0 ? 2 * P * R / (P + R) : 0;
  }
  if (!toTruth.empty()) {
    const size_t k = std::min(toTruth.size() - 1, size_t(std::ceil(0.95 * toTruth.size())) - 1);
    std::nth_element(toTruth.begin(), toTruth.begin() + k, toTruth.end());
    m.accuracy_p95_mm = 1000 * toTruth[k];
  }
  return m;
}

ColourMetrics colourAccuracy(const ObjectModel& model, const TriangleMesh& truth,
                             const SurfaceColours& truth_colours) {
  ColourMetrics out;
  if (model.rgba.size() != model.mesh.vertices.size() || truth.empty()) return out;
  const TriangleDistanceIndex index(truth);
  std::vector<size_t> which;
  for (size_t i = 0; i < model.rgba.size(); ++i)
    if (model.rgba[i][3] == 255 && (model.observed.empty() || model.observed[i]))
      which.push_back(i);
  // The true albedo at the point of the true surface nearest p (its triangle in *tri); false
  // where none lies within max_m.
  auto truthAt = [&](const Vec3& p, int* tri, Vec3* q, Vec3f* albedo,
                     double max_m = std::numeric_limits<double>::infinity()) {
    if (!(index.nearest(p, tri, q, max_m) < max_m) || *tri < 0) return false;
    // q's barycentrics in its triangle.
    const Tri& f = truth.triangles[size_t(*tri)];
    const Vec3 a = truth.vertices[size_t(f[0])].cast<double>();
    const Vec3 e1 = truth.vertices[size_t(f[1])].cast<double>() - a;
    const Vec3 e2 = truth.vertices[size_t(f[2])].cast<double>() - a;
    const Vec3 d = *q - a;
    const double d11 = e1.dot(e1), d12 = e1.dot(e2), d22 = e2.dot(e2);
    const double det = d11 * d22 - d12 * d12;
    double b1 = 0, b2 = 0;
    if (det > 0) {
      b1 = (d22 * e1.dot(d) - d12 * e2.dot(d)) / det;
      b2 = (d11 * e2.dot(d) - d12 * e1.dot(d)) / det;
    }
    *albedo = truth_colours.at(truth, *tri, float(b1), float(b2));
    return true;
  };
  std::vector<double> de(which.size());
  std::vector<uint8_t> atEdge(which.size(), 0);
  parallelFor(0, int(which.size()), [&](int k) {
    const size_t i = which[size_t(k)];
    int tri = -1;
    Vec3 q;
    Vec3f want;
    truthAt(model.mesh.vertices[i].cast<double>(), &tri, &q, &want);
    const auto& c = model.rgba[i];
    de[size_t(k)] = deltaE76(Vec3f(c[0], c[1], c[2]), want);
    // A colour edge of the truth within kColourEdgeRadius_m: the albedo 4 ways along the
    // surface (in the nearest triangle's plane, snapped back onto the surface, which lies within
    // the radius of each such point).
    const Vec3 n = truth.faceNormal(tri).cast<double>().normalized();
    const Vec3 t1 = n.unitOrthogonal(), t2 = n.cross(t1);
    for (const Vec3& t : {t1, Vec3(-t1), t2, Vec3(-t2)}) {
      int tt = -1;
      Vec3 qq;
      Vec3f there;
      if (truthAt(q + kColourEdgeRadius_m * t, &tt, &qq, &there, 2 * kColourEdgeRadius_m) &&
          deltaE76(there, want) > kColourEdgeDeltaE) {
        atEdge[size_t(k)] = 1;
        break;
      }
    }
  });
  out.vertices = int(de.size());
  if (de.empty()) return out;
  double sum = 0, sumAway = 0, sumEdge = 0;
  int edges = 0;
  for (size_t k = 0; k < de.size(); ++k) {
    sum += de[k];
    (atEdge[k] ? sumEdge : sumAway) += de[k];
    edges += atEdge[k];
  }
  out.delta_e_mean = sum / double(de.size());
  out.edge_share = double(edges) / double(de.size());
  if (edges > 0) out.delta_e_mean_at_edges = sumEdge / edges;
  if (edges < int(de.size())) out.delta_e_mean_off_edges = sumAway / double(int(de.size()) - edges);
  std::vector<double> sorted = de;
  const size_t k95 = std::min(sorted.size() - 1, size_t(std::floor(0.95 * double(sorted.size()))));
  std::nth_element(sorted.begin(), sorted.begin() + long(k95), sorted.end());
  out.delta_e_p95 = sorted[k95];
  return out;
}

namespace {
// The mesh rendered unlit from T_O_C (pinhole K): each pixel's colour from `colourAt(triangle,
// b1, b2)`, black where the ray meets nothing; `hit` marks the pixels that meet the mesh.
template <class ColourAt>
RgbImage renderUnlit(const RayScene& scene, const Iso3& T_O_C, const CameraIntrinsics& K,
                     const ColourAt& colourAt, std::vector<uint8_t>* hit) {
  const size_t n = size_t(K.width) * size_t(K.height);
  std::vector<Ray> rays(n);
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      Ray& r = rays[size_t(v) * size_t(K.width) + size_t(u)];
      r.origin = T_O_C.translation().cast<float>();
      r.dir = (T_O_C.linear() * K.rayZ1(u, v)).cast<float>();
    }
  std::vector<Hit> hits(n);
  scene.intersect(rays.data(), hits.data(), n);
  RgbImage img(K.width, K.height);
  hit->assign(n, 0);
  for (size_t i = 0; i < n; ++i) {
    if (!hits[i].valid()) continue;
    (*hit)[i] = 1;
    const Vec3f c = colourAt(hits[i].triangle, hits[i].u, hits[i].v);
    for (int k = 0; k < 3; ++k)
      img.rgb[3 * i + size_t(k)] = uint8_t(std::clamp(std::lround(c[k]), 0L, 255L));
  }
  return img;
}
// The per-vertex colour interpolated at barycentric (b1, b2) of triangle t (alpha 0: mid grey).
Vec3f vertexColourAt(const TriangleMesh& mesh, const std::vector<std::array<uint8_t, 4>>& rgba,
                     int t, float b1, float b2) {
  const Tri& f = mesh.triangles[size_t(t)];
  const float b[3] = {1 - b1 - b2, b1, b2};
  Vec3f c = Vec3f::Zero();
  for (int k = 0; k < 3; ++k) {
    const auto& q = rgba[size_t(f[k])];
    c += b[k] * (q[3] ? Vec3f(q[0], q[1], q[2]) : Vec3f(128, 128, 128));
  }
  return c;
}
}  // namespace

RgbImage renderVertexColours(const TriangleMesh& mesh,
                             const std::vector<std::array<uint8_t, 4>>& rgba, const Iso3& T_O_C,
                             const CameraIntrinsics& K) {
  if (rgba.size() != mesh.vertices.size())
    throw Error("renderVertexColours: " + std::to_string(rgba.size()) + " colours for " +
                std::to_string(mesh.vertices.size()) + " vertices");
  RayScene scene;
  scene.addMesh(mesh);
  scene.commit();
  std::vector<uint8_t> hit;
  return renderUnlit(
      scene, T_O_C, K,
      [&](int t, float b1, float b2) { return vertexColourAt(mesh, rgba, t, b1, b2); }, &hit);
}

RgbImage renderSurfaceColours(const TriangleMesh& mesh, const SurfaceColours& colours,
                              const Iso3& T_O_C, const CameraIntrinsics& K) {
  RayScene scene;
  scene.addMesh(mesh);
  scene.commit();
  std::vector<uint8_t> hit;
  return renderUnlit(
      scene, T_O_C, K, [&](int t, float b1, float b2) { return colours.at(mesh, t, b1, b2); },
      &hit);
}

double colourPsnr(const ObjectModel& model, const TriangleMesh& truth,
                  const SurfaceColours& truth_colours, int views, std::vector<RgbImage>* images) {
  if (model.mesh.empty() || truth.empty() || model.rgba.size() != model.mesh.vertices.size())
    return 0;
  RayScene truthScene, modelScene;
  truthScene.addMesh(truth);
  truthScene.commit();
  modelScene.addMesh(model.mesh);
  modelScene.commit();
  const Aabb box = truth.bounds();
  const Vec3 centre = box.center();
  const double range = 3 * box.size().norm();
  CameraIntrinsics K;
  K.width = 320;
  K.height = 240;
  K.fx = K.fy = 0.5 * K.width / std::tan(M_PI / 6);
  K.cx = 0.5 * (K.width - 1);
  K.cy = 0.5 * (K.height - 1);
  auto truthAt = [&](int t, float b1, float b2) { return truth_colours.at(truth, t, b1, b2); };
  auto modelAt = [&](int t, float b1, float b2) {
    return vertexColourAt(model.mesh, model.rgba, t, b1, b2);
  };
  double sse = 0;
  size_t count = 0;
  for (const Vec3& d : fibonacciSphere(views)) {
    // The camera on direction d from the centre, looking at it (z forward, y down).
    const Vec3 z = -d;
    Vec3 x = z.cross(std::abs(z.z()) < 0.9 ? Vec3::UnitZ() : Vec3::UnitX()).normalized();
    const Vec3 y = z.cross(x);
    Iso3 T_O_C = Iso3::Identity();
    T_O_C.linear().col(0) = x;
    T_O_C.linear().col(1) = y;
    T_O_C.linear().col(2) = z;
    T_O_C.translation() = centre + range * d;
    std::vector<uint8_t> hitTruth, hitModel;
    const RgbImage a = renderUnlit(truthScene, T_O_C, K, truthAt, &hitTruth);
    const RgbImage b = renderUnlit(modelScene, T_O_C, K, modelAt, &hitModel);
    for (size_t i = 0; i < hitTruth.size(); ++i) {
      if (!hitTruth[i] && !hitModel[i]) continue;
      for (int k = 0; k < 3; ++k) {
        const double e = double(a.rgb[3 * i + size_t(k)]) - double(b.rgb[3 * i + size_t(k)]);
        sse += e * e;
      }
      count += 3;
    }
    if (images) {
      images->push_back(a);
      images->push_back(b);
    }
  }
  if (count == 0) return 0;
  const double mse = sse / double(count);
  return mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : 99.0;
}

}  // namespace inhand
