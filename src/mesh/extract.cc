#include "inhand/mesh/extract.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "inhand/core/internal/parallel.h"
#include "inhand/geometry/internal/contour.h"

namespace inhand {

std::string MeshOptions::validate() const { return checkOptionRanges(*this); }

std::string surfaceMethodName(SurfaceMethod m) { return enumName(kSurfaceMethodNames, m); }

bool parseSurfaceMethod(const std::string& s, SurfaceMethod* out) {
  return enumFromName(kSurfaceMethodNames, s, out);
}

double gaussianEntropy(double variance) { return 0.5 * std::log(2.0 * M_PI * M_E * variance); }

namespace {
// Σ f(i) over i in [0, n) (f returns a fixed-size array of terms), in fixed chunks on both
// cores, the chunks' sums added in chunk order: the same value for any thread count.
template <size_t N, typename F>
std::array<double, N> chunkedSums(int n, F&& f) {
  constexpr int kChunk = 8192;
  const int chunks = (n + kChunk - 1) / kChunk;
  std::vector<std::array<double, N>> part(static_cast<size_t>(chunks));
  parallelFor(0, chunks, [&](int c) {
    std::array<double, N> sum{};
    for (int i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const std::array<double, N> term = f(i);
      for (size_t k = 0; k < N; ++k) sum[k] += term[k];
    }
    part[size_t(c)] = sum;
  });
  std::array<double, N> total{};
  for (const std::array<double, N>& p : part)
    for (size_t k = 0; k < N; ++k) total[k] += p[k];
  return total;
}
}  // namespace

double ObjectModel::meanEntropy() const {
  if (variance.empty()) return 0.0;
  const double sum = chunkedSums<1>(int(variance.size()), [&](int i) {
    return std::array<double, 1>{gaussianEntropy(variance[size_t(i)])};
  })[0];
  return sum / double(variance.size());
}

double ObjectModel::observedAreaFraction() const {
  const auto [total, seen] = chunkedSums<2>(int(mesh.triangles.size()), [&](int t) {
    const double a = mesh.triangleArea(t);
    const Tri& f = mesh.triangles[size_t(t)];
    return std::array<double, 2>{a, observed[f[0]] && observed[f[1]] && observed[f[2]] ? a : 0.0};
  });
  return total > 0 ? seen / total : 0.0;
}

double ObjectModel::unresolvedInformation(double sigma_ref_m) const {
  const double ref = sigma_ref_m * sigma_ref_m;
  return chunkedSums<1>(int(mesh.triangles.size()), [&](int t) {
    const Tri& f = mesh.triangles[size_t(t)];
    double h = 0;
    for (int k = 0; k < 3; ++k) h += std::max(0.0, 0.5 * std::log(double(variance[f[k]]) / ref));
    return std::array<double, 1>{mesh.triangleArea(t) * h / 3};
  })[0];
}

double ObjectModel::holeArea() const {
  return chunkedSums<1>(int(mesh.triangles.size()), [&](int t) {
    const Tri& f = mesh.triangles[size_t(t)];
    return std::array<double, 1>{
        observed[f[0]] && observed[f[1]] && observed[f[2]] ? 0.0 : mesh.triangleArea(t)};
  })[0];
}

ObjectModel ObjectModel::observedSurface() const {
  ObjectModel out;
  std::vector<int> index(mesh.vertices.size(), -1);
  for (const Tri& f : mesh.triangles) {
    if (!(observed[f[0]] && observed[f[1]] && observed[f[2]])) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      int& i = index[f[k]];
      if (i < 0) {
        i = int(out.mesh.vertices.size());
        out.mesh.vertices.push_back(mesh.vertices[f[k]]);
        out.variance.push_back(variance[f[k]]);
        out.observed.push_back(1);
        if (rgba.size() == mesh.vertices.size()) out.rgba.push_back(rgba[f[k]]);
      }
      g[k] = i;
    }
    out.mesh.triangles.push_back(g);
  }
  return out;
}

std::vector<uint8_t> unknownAttachedToObservedReference(const TsdfVolume& volume) {
  const Vec3i d = volume.dims();
  const size_t n = volume.voxelCount();
  std::vector<uint8_t> keep(n, 0);
  // The fill's stack holds coordinates with the index: no division per visit.
  struct Item {
    int x, y, z;
  };
  std::vector<Item> stack;
  const size_t sy = size_t(d.x()), sz = size_t(d.x()) * d.y();
  auto push = [&](int x, int y, int z) {
    const size_t j = size_t(z) * sz + size_t(y) * sy + size_t(x);
    if (volume.state(j) == VoxelState::kUnknown && !keep[j]) {
      keep[j] = 1;
      stack.push_back({x, y, z});
    }
  };
  auto visitNeighbours = [&](int x, int y, int z) {
    if (x > 0) push(x - 1, y, z);
    if (x + 1 < d.x()) push(x + 1, y, z);
    if (y > 0) push(x, y - 1, z);
    if (y + 1 < d.y()) push(x, y + 1, z);
    if (z > 0) push(x, y, z - 1);
    if (z + 1 < d.z()) push(x, y, z + 1);
  };
  for (int z = 0; z < d.z(); ++z)
    for (int y = 0; y < d.y(); ++y)
      for (int x = 0; x < d.x(); ++x)
        if (volume.state(size_t(z) * sz + size_t(y) * sy + size_t(x)) == VoxelState::kObserved)
          visitNeighbours(x, y, z);
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    visitNeighbours(it.x, it.y, it.z);
  }
  return keep;
}

std::vector<uint8_t> unknownAttachedToObserved(const TsdfVolume& volume) {
  const Vec3i d = volume.dims();
  const int nx = d.x(), ny = d.y(), nz = d.z();
  const size_t n = volume.voxelCount();
  std::vector<uint8_t> keep(n, 0);
  if (n == 0) return keep;
  const uint8_t* state = volume.states();
  const uint8_t kUnknown = uint8_t(VoxelState::kUnknown),
                kObserved = uint8_t(VoxelState::kObserved);
  const size_t sy = size_t(nx), sz = size_t(nx) * ny;
  // The unknown voxels as runs along x, row by row (row = y + ny·z), found slice by slice on both
  // cores. A run is a seed when a voxel 6-adjacent to one of its voxels is observed: its ends'
  // x neighbours, or any voxel of the four neighbouring rows over its span (memchr).
  struct Run {
    int x0, x1;  // [x0, x1)
  };
  std::vector<std::vector<Run>> sliceRuns(static_cast<size_t>(nz));
  std::vector<std::vector<uint8_t>> sliceSeed(static_cast<size_t>(nz));
  std::vector<uint32_t> rowRuns(size_t(ny) * nz + 1, 0);  // runs per row, then prefix sums
  parallelFor(0, nz, [&](int z) {
    std::vector<Run>& runs = sliceRuns[size_t(z)];
    std::vector<uint8_t>& seeds = sliceSeed[size_t(z)];
    for (int y = 0; y < ny; ++y) {
      const uint8_t* row = state + size_t(z) * sz + size_t(y) * sy;
      const uint8_t* near[4] = {y > 0 ? row - sy : nullptr, y + 1 < ny ? row + sy : nullptr,
                                z > 0 ? row - sz : nullptr, z + 1 < nz ? row + sz : nullptr};
      uint32_t count = 0;
      int x = 0;
      while (x < nx) {
        const void* u = std::memchr(row + x, kUnknown, size_t(nx - x));
        if (!u) break;
        const int x0 = int(static_cast<const uint8_t*>(u) - row);
        int x1 = x0 + 1;
        while (x1 < nx && row[x1] == kUnknown) ++x1;
        bool seed = (x0 > 0 && row[x0 - 1] == kObserved) || (x1 < nx && row[x1] == kObserved);
        for (int k = 0; k < 4 && !seed; ++k)
          seed = near[k] && std::memchr(near[k] + x0, kObserved, size_t(x1 - x0));
        runs.push_back({x0, x1});
        seeds.push_back(uint8_t(seed));
        ++count;
        x = x1 + 1;
      }
      rowRuns[size_t(z) * ny + y + 1] = count;
    }
  });
  for (size_t r = 0; r + 1 < rowRuns.size(); ++r) rowRuns[r + 1] += rowRuns[r];
  std::vector<Run> runs;
  std::vector<uint8_t> marked;
  runs.reserve(rowRuns.back());
  marked.reserve(rowRuns.back());
  for (int z = 0; z < nz; ++z) {
    runs.insert(runs.end(), sliceRuns[size_t(z)].begin(), sliceRuns[size_t(z)].end());
    marked.insert(marked.end(), sliceSeed[size_t(z)].begin(), sliceSeed[size_t(z)].end());
  }
  sliceRuns = {};
  sliceSeed = {};
  // Flood from the seeds through runs that overlap in x in the four neighbouring rows.
  std::vector<uint32_t> stack;
  for (uint32_t i = 0; i < uint32_t(runs.size()); ++i)
    if (marked[i]) stack.push_back(i);
  std::vector<uint32_t> rowOf(runs.size());
  for (size_t r = 0; r + 1 < rowRuns.size(); ++r)
    std::fill(rowOf.begin() + rowRuns[r], rowOf.begin() + rowRuns[r + 1], uint32_t(r));
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    const Run run = runs[i];
    const int y = int(rowOf[i] % uint32_t(ny)), z = int(rowOf[i] / uint32_t(ny));
    const int rows[4][2] = {{y - 1, z}, {y + 1, z}, {y, z - 1}, {y, z + 1}};
    for (const auto& yz : rows) {
      if (yz[0] < 0 || yz[0] >= ny || yz[1] < 0 || yz[1] >= nz) continue;
      const size_t r = size_t(yz[1]) * ny + size_t(yz[0]);
      // The row's runs are in x order: the first that ends after run.x0, on while they start
      // before run.x1.
      auto first = std::partition_point(runs.begin() + rowRuns[r], runs.begin() + rowRuns[r + 1],
                                        [&](const Run& o) { return o.x1 <= run.x0; });
      for (auto it = first; it != runs.begin() + rowRuns[r + 1] && it->x0 < run.x1; ++it) {
        const uint32_t j = uint32_t(it - runs.begin());
        if (!marked[j]) {
          marked[j] = 1;
          stack.push_back(j);
        }
      }
    }
  }
  parallelFor(0, nz, [&](int z) {
    for (int y = 0; y < ny; ++y) {
      const size_t r = size_t(z) * ny + size_t(y);
      uint8_t* row = keep.data() + size_t(z) * sz + size_t(y) * sy;
      for (uint32_t i = rowRuns[r]; i < rowRuns[r + 1]; ++i)
        if (marked[i]) std::memset(row + runs[i].x0, 1, size_t(runs[i].x1 - runs[i].x0));
    }
  });
  return keep;
}

namespace {

// Keeps the triangles of connected pieces with at least `fraction` of the largest piece's
// triangles, and the vertices they use (with their per-vertex data).
void dropSmallComponents(ObjectModel* m, double fraction) {
  const size_t nv = m->mesh.vertices.size();
  std::vector<uint32_t> parent(nv);
  for (size_t i = 0; i < nv; ++i) parent[i] = uint32_t(i);
  auto find = [&](uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const Tri& f : m->mesh.triangles) {
    uint32_t a = find(uint32_t(f[0]));
    for (int k = 1; k < 3; ++k) {
      uint32_t b = find(uint32_t(f[k]));
      if (a != b) parent[b] = a;
    }
  }
  std::vector<uint32_t> count(nv, 0);
  for (const Tri& f : m->mesh.triangles) ++count[find(uint32_t(f[0]))];
  uint32_t largest = count.empty() ? 0 : *std::max_element(count.begin(), count.end());
  const double keepFrom = fraction * largest;
  std::vector<int> remap(nv, -1);
  ObjectModel out;
  for (const Tri& f : m->mesh.triangles) {
    if (count[find(uint32_t(f[0]))] < keepFrom) continue;
    Tri g;
    for (int k = 0; k < 3; ++k) {
      int& r = remap[f[k]];
      if (r < 0) {
        r = int(out.mesh.vertices.size());
        out.mesh.vertices.push_back(m->mesh.vertices[f[k]]);
        out.variance.push_back(m->variance[f[k]]);
        out.observed.push_back(m->observed[f[k]]);
      }
      g[k] = r;
    }
    out.mesh.triangles.push_back(g);
  }
  *m = std::move(out);
}

}  // namespace

namespace {
// The volume sampled at every `stride`-th voxel into a padded grid of signed distances (one
// extra sample on each side, treated as empty) for contouring: observed voxels their distance,
// empty ones +μ, unknown ones −μ (floating unknown pockets count as empty with
// MeshOptions::drop_floating_unknown).
class ModelGrid {
 public:
  ModelGrid(const TsdfVolume& volume, const MeshOptions& options)
      : volume_(volume),
        mu_(float(volume.truncation())),
        k_(std::max(1, options.stride)),
        n_((volume.dims().x() + k_ - 1) / k_, (volume.dims().y() + k_ - 1) / k_,
           (volume.dims().z() + k_ - 1) / k_),
        holeVar_(float(options.hole_sigma_m * options.hole_sigma_m)) {
    if (options.drop_floating_unknown) attached_ = unknownAttachedToObserved(volume);
    grid_.dims = n_ + Vec3i::Constant(2);
    grid_.spacing = k_ * volume.voxelSize();
    grid_.origin = volume.origin() - Vec3::Constant(grid_.spacing);
    grid_.values.assign(size_t(grid_.dims.prod()), mu_);
    behindMeasured_.assign(grid_.values.size(), 0);
  }

  // Samples of empty voxels keep the +μ the grid was filled with: rows of samples with none but
  // empty voxels are passed over. Which rows have an unknown sample is noted for the next pass.
  void sample() {
    constexpr uint8_t kEmptyState = uint8_t(VoxelState::kEmpty);
    rowUnknown_.assign(size_t(n_.y()) * n_.z(), 0);
    const uint8_t* states = volume_.states();
    parallelFor(0, n_.z(), [&](int zs) {
      for (int ys = 0; ys < n_.y(); ++ys) {
        const size_t i0 = volume_.index(0, ys * k_, zs * k_);
        if (k_ == 1) {
          bool allEmpty = true;
          for (int xs = 0; xs < n_.x(); ++xs) allEmpty &= states[i0 + size_t(xs)] == kEmptyState;
          if (allEmpty) continue;
        }
        bool unknown = false;
        for (int xs = 0; xs < n_.x(); ++xs) {
          const size_t i = i0 + size_t(xs) * size_t(k_);
          const size_t g = grid_.index(xs + 1, ys + 1, zs + 1);
          switch (stateOf(uint32_t(i))) {
            case VoxelState::kObserved: {
              const float s = volume_.distance(i);
              grid_.values[g] = s == 0.f ? 1e-7f : s;  // exact zeros off the surface's corners
              break;
            }
            case VoxelState::kEmpty:
              grid_.values[g] = mu_;
              break;
            case VoxelState::kUnknown:
              grid_.values[g] = -mu_;
              unknown = true;
              break;
          }
        }
        rowUnknown_[size_t(zs) * n_.y() + size_t(ys)] = unknown;
      }
    });
  }

  // An unknown sample next to an observed one that lies less than their distance in front of
  // the surface is behind that measured surface: its signed distance is at least the
  // neighbour's less their distance (a distance changes by at most that much), the tightest
  // such bound over its 26 neighbours (the contouring's edges include the cubes' diagonals). The
  // crossing then sits where the measurement puts it and counts as observed (the measured end's
  // variance) instead of a hole vertex pulled towards the measured voxel by −μ: a reach behind
  // the surface narrower than μ (VolumeOptions::band_sigmas) leaves voxels a little behind some
  // measured surfaces unknown. Only unknown samples are written and only observed ones read: no
  // sample read changes.
  void boundBehindMeasured() {
    const float h = float(grid_.spacing);
    const std::array<float, 4> stepLength{0.f, h, std::sqrt(2.f) * h, std::sqrt(3.f) * h};
    parallelFor(1, grid_.dims.z() - 1, [&](int z) {
      for (int y = 1; y < grid_.dims.y() - 1; ++y) {
        if (!rowUnknown_[size_t(z - 1) * n_.y() + size_t(y - 1)]) continue;
        for (int x = 1; x < grid_.dims.x() - 1; ++x) {
          const uint32_t v = voxelAt(x, y, z);
          if (v == UINT32_MAX || !isUnknown(v)) continue;
          float best = -mu_;
          for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) {
                const int steps = std::abs(dx) + std::abs(dy) + std::abs(dz);
                if (steps == 0) continue;
                const uint32_t vn = voxelAt(x + dx, y + dy, z + dz);
                if (vn == UINT32_MAX || volume_.state(vn) != VoxelState::kObserved) continue;
                const float dn = grid_.values[grid_.index(x + dx, y + dy, z + dz)],
                            len = stepLength[size_t(steps)];
                if (dn > 0.f && dn < len) best = std::max(best, dn - len);
              }
          if (best > -mu_) {
            const size_t g = grid_.index(x, y, z);
            grid_.values[g] = best;
            behindMeasured_[g] = 1;
          }
        }
      }
    });
  }

  // The zero set, each vertex's variance the mean over its crossings, observed only if every
  // crossing is; one crossing next to the unknown makes it a hole vertex (σ_hole), as for
  // marching tetrahedra.
  ObjectModel contourModel(SurfaceMethod method) const {
    ContourResult c = method == SurfaceMethod::kSurfaceNets ? surfaceNets(grid_) : contour(grid_);
    ObjectModel model;
    model.mesh = std::move(c.mesh);
    const size_t nv = model.mesh.vertices.size();
    model.variance.resize(nv);
    model.observed.resize(nv);
    parallelFor(
        0, int(nv),
        [&](int k) {
          double sum = 0;
          bool observed = true;
          for (uint32_t s = c.first[k]; s < c.first[k + 1]; ++s) {
            const float var = crossingVariance(c.sources[s]);
            sum += var;
            observed = observed && var < holeVar_;
          }
          model.variance[k] =
              observed ? float(sum / double(c.first[k + 1] - c.first[k])) : holeVar_;
          model.observed[k] = observed;
        },
        4096);
    return model;
  }

 private:
  bool isUnknown(uint32_t v) const {
    return volume_.state(v) == VoxelState::kUnknown && (attached_.empty() || attached_[v]);
  }
  // The voxel of padded sample (x, y, z) (UINT32_MAX on the padding), and of a sample's index.
  uint32_t voxelAt(int x, int y, int z) const {
    if (x < 1 || y < 1 || z < 1 || x > n_.x() || y > n_.y() || z > n_.z()) return UINT32_MAX;
    return uint32_t(volume_.index((x - 1) * k_, (y - 1) * k_, (z - 1) * k_));
  }
  uint32_t voxelOf(size_t g) const {
    const size_t gx = size_t(grid_.dims.x()), gxy = gx * size_t(grid_.dims.y());
    return voxelAt(int(g % gx), int(g / gx % size_t(grid_.dims.y())), int(g / gxy));
  }
  // A voxel's state as the surface sees it (a floating unknown one as empty; padding empty).
  VoxelState stateOf(uint32_t v) const {
    if (v == UINT32_MAX) return VoxelState::kEmpty;
    const VoxelState st = volume_.state(v);
    return (st == VoxelState::kUnknown && !isUnknown(v)) ? VoxelState::kEmpty : st;
  }
  // One crossing's variance: σ_hole² next to an unknown voxel, else 1/Σw interpolated between
  // observed voxels (or the observed end's, next to an empty voxel).
  float crossingVariance(const EdgeVertex& e) const {
    const uint32_t va = voxelOf(e.a), vb = voxelOf(e.b);
    const VoxelState sa = stateOf(va), sb = stateOf(vb);
    // Behind a measured surface (boundBehindMeasured): the crossing is that measurement's.
    if (behindMeasured_[e.a] && sb == VoxelState::kObserved)
      return std::min(volume_.variance(vb), holeVar_);
    if (behindMeasured_[e.b] && sa == VoxelState::kObserved)
      return std::min(volume_.variance(va), holeVar_);
    if (sa == VoxelState::kUnknown || sb == VoxelState::kUnknown) return holeVar_;
    float var;
    if (sa == VoxelState::kObserved && sb == VoxelState::kObserved)
      // The end in front of the surface: every measurement of the surface reaches it, while one
      // reaches only so far behind (VolumeOptions::band_sigmas).
      var = grid_.values[e.a] > 0 ? volume_.variance(va) : volume_.variance(vb);
    else if (sa == VoxelState::kObserved)
      var = volume_.variance(va);
    else if (sb == VoxelState::kObserved)
      var = volume_.variance(vb);
    else
      var = holeVar_;  // empty next to empty cannot cross zero; kept for safety
    return std::min(var, holeVar_);
  }

  const TsdfVolume& volume_;
  std::vector<uint8_t> attached_;
  float mu_;
  int k_;
  Vec3i n_;  // samples used
  float holeVar_;
  ScalarGrid grid_;
  std::vector<uint8_t> rowUnknown_, behindMeasured_;
};
}  // namespace

ObjectModel extractModel(const TsdfVolume& volume, const MeshOptions& options) {
  ModelGrid grid(volume, options);
  grid.sample();
  grid.boundBehindMeasured();
  ObjectModel model = grid.contourModel(options.method);
  if (options.min_component_fraction > 0)
    dropSmallComponents(&model, options.min_component_fraction);
  return model;
}

}  // namespace inhand
