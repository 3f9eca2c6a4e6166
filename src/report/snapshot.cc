#include "inhand/report/snapshot.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/ray_scene.h"

namespace inhand {

RgbImage renderSnapshot(const TriangleMesh& mesh, const std::vector<std::array<uint8_t, 3>>& colors,
                        const SnapshotOptions& o) {
  RayScene scene;
  scene.addMesh(mesh);
  scene.commit();
  const Aabb box = mesh.bounds();
  const Vec3 centre = box.center();
  const double radius = 0.5 * box.size().norm();
  const int n = std::max(1, o.views);
  const int cols = std::max(1, std::min(o.columns, n)), rows = (n + cols - 1) / cols;
  const int T = o.tile_px;
  RgbImage img;
  img.width = cols * T;
  img.height = rows * T;
  img.rgb.assign(size_t(img.width) * img.height * 3, 255);
  const double f = 0.5 * T / std::tan(20.0 * M_PI / 180.0);  // 40° field of view
  const double dist = radius / std::sin(18.0 * M_PI / 180.0);
  for (int k = 0; k < n; ++k) {
    Vec3 dir;
    if (n > 4 && k == n - 1) {
      dir = Vec3(0.3, 0.2, -1).normalized();  // from below
    } else {
      int ring = (n > 4) ? n - 1 : n;
      double az = 2 * M_PI * k / ring + 0.5, el = o.elevation_deg * M_PI / 180;
      dir = Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
    }
    Iso3 T_W_C = lookAt(centre + dist * dir, centre, Vec3::UnitZ());
    std::vector<Ray> rays(size_t(T) * T);
    for (int v = 0; v < T; ++v)
      for (int u = 0; u < T; ++u) {
        Ray& r = rays[size_t(v) * T + u];
        r.origin = T_W_C.translation().cast<float>();
        r.dir = (T_W_C.linear() * Vec3((u - 0.5 * T) / f, (v - 0.5 * T) / f, 1.0)).cast<float>();
      }
    std::vector<Hit> hits(rays.size());
    scene.intersect(rays.data(), hits.data(), rays.size());
    const int ox = (k % cols) * T, oy = (k / cols) * T;
    for (int v = 0; v < T; ++v)
      for (int u = 0; u < T; ++u) {
        const Hit& h = hits[size_t(v) * T + u];
        if (!h.valid()) continue;
        const Tri& tri = mesh.triangles[h.triangle];
        double c[3] = {170, 170, 170};
        if (!colors.empty()) {
          double w[3] = {1.0 - h.u - h.v, h.u, h.v};
          for (int ch = 0; ch < 3; ++ch)
            c[ch] =
                w[0] * colors[tri[0]][ch] + w[1] * colors[tri[1]][ch] + w[2] * colors[tri[2]][ch];
        }
        Vec3 nrm = h.normal.cast<double>().normalized();
        double lambert = std::abs(nrm.dot(rays[size_t(v) * T + u].dir.cast<double>().normalized()));
        double shade = 0.25 + 0.75 * lambert;
        uint8_t* px = &img.rgb[(size_t(oy + v) * img.width + ox + u) * 3];
        for (int ch = 0; ch < 3; ++ch) px[ch] = uint8_t(std::clamp(c[ch] * shade, 0.0, 255.0));
      }
  }
  return img;
}

}  // namespace inhand
