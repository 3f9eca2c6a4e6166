#include "inhand/geometry/internal/contour.h"

#include <array>
#include <bit>
#include <memory>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"

namespace inhand {

namespace {

// The 6 tetrahedra of the Kuhn split: corner codes (bit 0 = +x, bit 1 = +y, bit 2 = +z) along the
// monotone paths 0 → 7. Along each path the corners only gain bits, so every tetrahedron edge
// runs from a corner c to a superset corner c' and is owned by corner c with direction c' ^ c.
constexpr int kTets[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                             {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};

inline bool inside(float f) { return f < 0.f; }

// Set bits of a 7-bit edge mask, by table: the baseline x86-64 has no popcount instruction, and
// std::popcount became a library call per sample.
constexpr std::array<uint8_t, 128> kBitCount = [] {
  std::array<uint8_t, 128> t{};
  for (int m = 0; m < 128; ++m) t[size_t(m)] = uint8_t(std::popcount(unsigned(m)));
  return t;
}();

}  // namespace

namespace {
// Pass 1 of contour: which of the 7 edges leaving each sample (towards +x,+y,+z combinations)
// cross 0 (bit dir − 1 of its mask), which rows (y, z) have any, how many crossings each slice
// has. Every sample's mask is written, so the mask is not zeroed first.
struct CrossingMasks {
  std::unique_ptr<uint8_t[]> mask;
  std::vector<uint8_t> rowAny;
  std::vector<uint32_t> sliceCount;
};

// Each sample's side as a byte (0 or 1), then each row's masks from the four rows (y, z),
// (y+1, z), (y, z+1), (y+1, z+1) in straight loops the compiler vectorises: bit dir − 1 is the
// sample's side XOR its neighbour's along dir. A neighbour off the grid reads a row of the grid
// instead and its bit is cleared.
void crossingMasksVectorised(const ScalarGrid& grid, CrossingMasks* out) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  const size_t n = grid.values.size();
  const size_t sy = size_t(nx), sz = size_t(nx) * ny;
  const float* f = grid.values.data();
  uint8_t* mask = out->mask.get();
  std::vector<uint8_t>& rowAny = out->rowAny;
  std::vector<uint32_t>& sliceCount = out->sliceCount;
  const std::unique_ptr<uint8_t[]> side = std::make_unique_for_overwrite<uint8_t[]>(n);
  parallelFor(0, nz, [&](int z) {
    const size_t i0 = size_t(z) * sz;
    for (size_t i = i0; i < i0 + sz; ++i) side[i] = uint8_t(inside(f[i]));
  });
  parallelFor(0, nz, [&](int z) {
    uint32_t count = 0;
    for (int y = 0; y < ny; ++y) {
      const bool upY = y + 1 < ny, upZ = z + 1 < nz;
      const size_t row = grid.index(0, y, z);
      const uint8_t* a = side.get() + row;
      const uint8_t* b = upY ? a + sy : a;
      const uint8_t* c = upZ ? a + sz : a;
      const uint8_t* d = upY && upZ ? a + sy + sz : a;
      // Bits (dir − 1) of the directions with dy (dirs 2, 3, 6, 7) and with dz (4 … 7).
      uint8_t allowed = 0x7f;
      if (!upY) allowed &= uint8_t(~0x66);
      if (!upZ) allowed &= uint8_t(~0x78);
      uint8_t* m = mask + row;
      uint8_t any = 0;
      for (int x = 0; x + 1 < nx; ++x) {
        const uint8_t s = a[x];
        const uint8_t bits =
            uint8_t((s ^ a[x + 1]) | (s ^ b[x]) << 1 | (s ^ b[x + 1]) << 2 | (s ^ c[x]) << 3 |
                    (s ^ c[x + 1]) << 4 | (s ^ d[x]) << 5 | (s ^ d[x + 1]) << 6) &
            allowed;
        m[x] = bits;
        any |= bits;
      }
      // The last sample of the row has no +x neighbour (dirs 1, 3, 5, 7).
      const int x = nx - 1;
      const uint8_t s = a[x];
      m[x] = uint8_t((s ^ b[x]) << 1 | (s ^ c[x]) << 3 | (s ^ d[x]) << 5) & allowed;
      any |= m[x];
      rowAny[size_t(z) * ny + y] = any != 0;
      if (any)
        for (int k = 0; k < nx; ++k) count += kBitCount[m[k]];
    }
    sliceCount[z] = count;
  });
}

// The same masks, sample by sample and edge by edge (the reference the vectorised pass is
// tested against).
void crossingMasksPlain(const ScalarGrid& grid, CrossingMasks* out) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  const size_t sx = 1, sy = size_t(nx), sz = size_t(nx) * ny;
  const float* f = grid.values.data();
  uint8_t* mask = out->mask.get();
  std::vector<uint8_t>& rowAny = out->rowAny;
  std::vector<uint32_t>& sliceCount = out->sliceCount;
  parallelFor(0, nz, [&](int z) {
    uint32_t count = 0;
    for (int y = 0; y < ny; ++y) {
      uint8_t any = 0;
      for (int x = 0; x < nx; ++x) {
        size_t i = grid.index(x, y, z);
        bool in = inside(f[i]);
        uint8_t m = 0;
        for (int dir = 1; dir < 8; ++dir) {
          int dx = dir & 1, dy = (dir >> 1) & 1, dz = (dir >> 2) & 1;
          if (x + dx >= nx || y + dy >= ny || z + dz >= nz) continue;
          if (inside(f[i + dx * sx + dy * sy + dz * sz]) != in) m |= uint8_t(1u << (dir - 1));
        }
        mask[i] = m;
        any |= m;
        count += kBitCount[m];
      }
      rowAny[size_t(z) * ny + y] = any != 0;
    }
    sliceCount[z] = count;
  });
}

// Pass 2 of contour: the crossings' vertices and their sources, numbered slice by slice (each
// sample's first at offset[sample]: an exclusive prefix sum); returns how many. Rows without a
// crossing add no vertex, and their offsets are never read.
uint32_t crossingVertices(const ScalarGrid& grid, const CrossingMasks& masks, uint32_t* offset,
                          ContourResult* result) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  const size_t sx = 1, sy = size_t(nx), sz = size_t(nx) * ny;
  const float* f = grid.values.data();
  const uint8_t* mask = masks.mask.get();
  std::vector<uint32_t> sliceBase(nz + 1, 0);
  for (int z = 0; z < nz; ++z) sliceBase[z + 1] = sliceBase[z] + masks.sliceCount[z];
  const uint32_t vertexCount = sliceBase[nz];
  result->mesh.vertices.resize(vertexCount);
  result->sources.resize(vertexCount);
  parallelFor(0, nz, [&](int z) {
    uint32_t next = sliceBase[z];
    for (int y = 0; y < ny; ++y) {
      if (!masks.rowAny[size_t(z) * ny + y]) continue;
      for (int x = 0; x < nx; ++x) {
        size_t i = grid.index(x, y, z);
        offset[i] = next;
        uint8_t m = mask[i];
        if (!m) continue;
        Vec3 p = grid.point(x, y, z);
        for (int dir = 1; dir < 8; ++dir) {
          if (!(m & (1u << (dir - 1)))) continue;
          int dx = dir & 1, dy = (dir >> 1) & 1, dz = (dir >> 2) & 1;
          size_t j = i + dx * sx + dy * sy + dz * sz;
          float t = f[i] / (f[i] - f[j]);
          Vec3 q = p + grid.spacing * t * Vec3(dx, dy, dz);
          result->mesh.vertices[next] = q.cast<float>();
          result->sources[next] = {uint32_t(i), uint32_t(j), t};
          ++next;
        }
      }
    }
  });
  return vertexCount;
}

// Pass 3 of contour for one cube (corner samples `corner`, `in`: which are inside): the
// triangles of its six Kuhn tetrahedra, their vertices the crossings of pass 2 (a sample's
// first at offset[sample], then one per set bit of its mask below the edge's).
void cubeTriangles(uint8_t in, const size_t corner[8], const uint32_t* offset, const uint8_t* mask,
                   std::vector<Tri>& out) {
  auto edgeVertex = [&](size_t owner, int dir) {
    return int(offset[owner] + uint32_t(kBitCount[mask[owner] & ((1u << (dir - 1)) - 1)]));
  };
  for (const auto& tet : kTets) {
    int insideList[4], outsideList[4], ni = 0, no = 0;
    for (int k = 0; k < 4; ++k) {
      if (in & (1u << tet[k]))
        insideList[ni++] = tet[k];
      else
        outsideList[no++] = tet[k];
    }
    if (ni == 0 || no == 0) continue;
    auto vid = [&](int ca, int cb) {
      int lo = ca < cb ? ca : cb, hi = ca < cb ? cb : ca;  // lo ⊂ hi along the Kuhn path
      return edgeVertex(corner[lo], hi ^ lo);
    };
    // Orientation is decided combinatorially (exactly), not from the interpolated vertex
    // positions: within a tetrahedron the linear iso-surface is a planar, convex polygon
    // whose facing follows from the orientation of the corners.
    auto corner3 = [](int c) { return Vec3(c & 1, (c >> 1) & 1, (c >> 2) & 1); };
    auto det = [&](int o, int p, int q, int r) {
      Vec3 base = corner3(o);
      Mat3 m;
      m.col(0) = corner3(p) - base;
      m.col(1) = corner3(q) - base;
      m.col(2) = corner3(r) - base;
      return m.determinant();
    };
    if (ni == 1 || no == 1) {
      int lone = ni == 1 ? insideList[0] : outsideList[0];
      const int* others = ni == 1 ? outsideList : insideList;
      int a = vid(lone, others[0]), b = vid(lone, others[1]), c = vid(lone, others[2]);
      // The triangle's normal points away from `lone` iff det(e_j, e_k, e_l) > 0; it must
      // point away from an inside lone corner and towards an outside one.
      double s = det(lone, others[0], others[1], others[2]);
      if ((ni == 1) != (s > 0)) std::swap(b, c);
      out.emplace_back(a, b, c);
    } else {
      int a = vid(insideList[0], outsideList[0]), b = vid(insideList[0], outsideList[1]);
      int c = vid(insideList[1], outsideList[1]), d = vid(insideList[1], outsideList[0]);
      if (det(insideList[0], insideList[1], outsideList[0], outsideList[1]) > 0) {
        out.emplace_back(a, b, c);
        out.emplace_back(a, c, d);
      } else {
        out.emplace_back(a, c, b);
        out.emplace_back(a, d, c);
      }
    }
  }
}

// The 12 axis edges of a cube: (corner code, axis), corner bits as in contour().
constexpr int kEdges[12][2] = {{0, 0}, {2, 0}, {4, 0}, {6, 0}, {0, 1}, {1, 1},
                               {4, 1}, {5, 1}, {0, 2}, {1, 2}, {2, 2}, {3, 2}};

// The slices' triangles, in slice order, appended to `mesh`.
void appendSliceTriangles(const std::vector<std::vector<Tri>>& slices, TriangleMesh* mesh) {
  size_t total = 0;
  for (const auto& t : slices) total += t.size();
  mesh->triangles.reserve(mesh->triangles.size() + total);
  for (const auto& t : slices) mesh->triangles.insert(mesh->triangles.end(), t.begin(), t.end());
}

// Surface nets' pass 3: a quad per crossing axis edge, around the 4 cubes sharing it
// (`vertexOf`: each cube's vertex, cubes x fastest); it faces from the inside end of the edge to
// the outside end. With axes (a, b, c) cyclic, the cubes at (b−1, c−1), (b, c−1), (b, c),
// (b−1, c) in that order make a quad whose normal is +a. Per z slice of grid points.
std::vector<std::vector<Tri>> surfaceNetsQuads(const ScalarGrid& grid,
                                               const std::vector<uint32_t>& vertexOf) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  const int cx = nx - 1, cy = ny - 1;
  const size_t step[3] = {1, size_t(nx), size_t(nx) * ny};
  const float* f = grid.values.data();
  std::vector<std::vector<Tri>> sliceTris(nz);
  parallelFor(0, nz, [&](int z) {
    std::vector<Tri>& out = sliceTris[z];
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const int p[3] = {x, y, z};
        const size_t i = grid.index(x, y, z);
        for (int a = 0; a < 3; ++a) {
          const int b = (a + 1) % 3, c = (a + 2) % 3;
          if (p[a] + 1 >= grid.dims[a] || p[b] < 1 || p[c] < 1 || p[b] >= grid.dims[b] - 1 ||
              p[c] >= grid.dims[c] - 1)
            continue;
          const bool inLow = inside(f[i]);
          if (inLow == inside(f[i + step[a]])) continue;
          uint32_t v[4];
          const int db[4] = {-1, 0, 0, -1}, dc[4] = {-1, -1, 0, 0};
          for (int k = 0; k < 4; ++k) {
            int q[3] = {p[0], p[1], p[2]};
            q[b] += db[k];
            q[c] += dc[k];
            v[k] = vertexOf[(size_t(q[2]) * size_t(cy) + size_t(q[1])) * size_t(cx) + size_t(q[0])];
          }
          if (inLow) {
            out.emplace_back(int(v[0]), int(v[1]), int(v[2]));
            out.emplace_back(int(v[0]), int(v[2]), int(v[3]));
          } else {
            out.emplace_back(int(v[0]), int(v[2]), int(v[1]));
            out.emplace_back(int(v[0]), int(v[3]), int(v[2]));
          }
        }
      }
  });
  return sliceTris;
}
}  // namespace

ContourResult contour(const ScalarGrid& grid, const ContourOptions& options) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  INHAND_CHECK(grid.values.size() == size_t(nx) * ny * nz, "grid value count mismatch");
  ContourResult result;
  if (nx < 2 || ny < 2 || nz < 2) return result;
  const size_t n = grid.values.size();
  const size_t sx = 1, sy = size_t(nx), sz = size_t(nx) * ny;
  const float* f = grid.values.data();

  // Pass 1 (CrossingMasks). The offsets of every sample in a row with a crossing (the only ones
  // read) are written in pass 2: neither they nor the masks are zeroed first (25 MB on one core
  // for a 172³ grid).
  const std::unique_ptr<uint32_t[]> offset = std::make_unique_for_overwrite<uint32_t[]>(n);
  CrossingMasks masks{std::make_unique_for_overwrite<uint8_t[]>(n),
                      std::vector<uint8_t>(size_t(ny) * nz, 0), std::vector<uint32_t>(nz, 0)};
  if (options.vectorised)
    crossingMasksVectorised(grid, &masks);
  else
    crossingMasksPlain(grid, &masks);
  const uint8_t* mask = masks.mask.get();
  const std::vector<uint8_t>& rowAny = masks.rowAny;

  // Pass 2 (crossingVertices).
  const uint32_t vertexCount = crossingVertices(grid, masks, offset.get(), &result);

  // Pass 3: triangles, per slice of cubes, concatenated in slice order (deterministic). Corner 0
  // of a cube is joined to each other corner by one of its edges (the Kuhn tetrahedra's), so a
  // cube with corners on both sides has a crossing in its corner 0's mask: cubes and rows of
  // cubes whose corner 0 has none are skipped.
  std::vector<std::vector<Tri>> sliceTris(nz - 1);
  parallelFor(0, nz - 1, [&](int z) {
    std::vector<Tri>& out = sliceTris[z];
    for (int y = 0; y + 1 < ny; ++y) {
      if (!rowAny[size_t(z) * ny + y]) continue;
      for (int x = 0; x + 1 < nx; ++x) {
        size_t base = grid.index(x, y, z);
        if (!mask[base]) continue;
        size_t corner[8];
        uint8_t in = 0;
        for (int c = 0; c < 8; ++c) {
          corner[c] = base + (c & 1) * sx + ((c >> 1) & 1) * sy + ((c >> 2) & 1) * sz;
          if (inside(f[corner[c]])) in |= uint8_t(1u << c);
        }
        if (in == 0 || in == 0xff) continue;
        cubeTriangles(in, corner, offset.get(), mask, out);
      }
    }
  });
  appendSliceTriangles(sliceTris, &result.mesh);
  result.first.resize(vertexCount + 1);
  for (uint32_t k = 0; k <= vertexCount; ++k) result.first[k] = k;
  return result;
}

ContourResult surfaceNets(const ScalarGrid& grid) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  INHAND_CHECK(grid.values.size() == size_t(nx) * ny * nz, "grid value count mismatch");
  ContourResult result;
  if (nx < 2 || ny < 2 || nz < 2) return result;
  const int cx = nx - 1, cy = ny - 1, cz = nz - 1;  // cubes per axis
  const size_t step[3] = {1, size_t(nx), size_t(nx) * ny};
  const float* f = grid.values.data();
  auto cubeIndex = [&](int x, int y, int z) {
    return (size_t(z) * size_t(cy) + size_t(y)) * size_t(cx) + size_t(x);
  };

  // Pass 1: cubes with mixed corners, counted per slice.
  std::vector<uint32_t> sliceCount(cz, 0);
  std::vector<uint8_t> crossed(size_t(cx) * cy * cz, 0);
  parallelFor(0, cz, [&](int z) {
    uint32_t count = 0;
    for (int y = 0; y < cy; ++y)
      for (int x = 0; x < cx; ++x) {
        const size_t base = grid.index(x, y, z);
        int in = 0;
        for (int c = 0; c < 8; ++c)
          in += inside(
              f[base + (c & 1) * step[0] + ((c >> 1) & 1) * step[1] + ((c >> 2) & 1) * step[2]]);
        if (in != 0 && in != 8) {
          crossed[cubeIndex(x, y, z)] = 1;
          ++count;
        }
      }
    sliceCount[z] = count;
  });
  std::vector<uint32_t> sliceBase(cz + 1, 0);
  for (int z = 0; z < cz; ++z) sliceBase[z + 1] = sliceBase[z] + sliceCount[z];
  const uint32_t vertexCount = sliceBase[cz];

  // Pass 2: vertex ids, positions (mean crossing) and their crossings.
  std::vector<uint32_t> vertexOf(crossed.size(), UINT32_MAX);
  result.mesh.vertices.resize(vertexCount);
  std::vector<uint8_t> crossingCount(vertexCount, 0);
  std::vector<std::array<EdgeVertex, 12>> crossings(vertexCount);
  parallelFor(0, cz, [&](int z) {
    uint32_t next = sliceBase[z];
    for (int y = 0; y < cy; ++y)
      for (int x = 0; x < cx; ++x) {
        const size_t ci = cubeIndex(x, y, z);
        if (!crossed[ci]) continue;
        vertexOf[ci] = next;
        const size_t base = grid.index(x, y, z);
        Vec3 sum = Vec3::Zero();
        int n = 0;
        for (const auto& e : kEdges) {
          const int c = e[0], axis = e[1];
          const size_t a =
              base + (c & 1) * step[0] + ((c >> 1) & 1) * step[1] + ((c >> 2) & 1) * step[2];
          const size_t b = a + step[axis];
          if (inside(f[a]) == inside(f[b])) continue;
          const float t = f[a] / (f[a] - f[b]);
          Vec3 p = grid.point(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1));
          p[axis] += grid.spacing * t;
          sum += p;
          crossings[next][n++] = {uint32_t(a), uint32_t(b), t};
        }
        result.mesh.vertices[next] = (sum / n).cast<float>();
        crossingCount[next] = uint8_t(n);
        ++next;
      }
  });
  result.first.resize(vertexCount + 1, 0);
  for (uint32_t k = 0; k < vertexCount; ++k)
    result.first[k + 1] = result.first[k] + crossingCount[k];
  result.sources.resize(result.first[vertexCount]);
  parallelFor(0, int(vertexCount), [&](int k) {
    std::copy_n(crossings[k].begin(), crossingCount[k], result.sources.begin() + result.first[k]);
  });

  // Pass 3: a quad per crossing axis edge.
  appendSliceTriangles(surfaceNetsQuads(grid, vertexOf), &result.mesh);
  return result;
}

}  // namespace inhand
