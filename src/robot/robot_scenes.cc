#include "inhand/robot/robot_scenes.h"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/geometry/internal/raster.h"
#include "inhand/geometry/primitives.h"

namespace inhand {

RobotOccluders::RobotOccluders(const RobotModel& model) : model_(&model) {
  for (int li = 0; li < int(model.links().size()); ++li) {
    const auto& col = model.links()[li].collision;
    if (col.empty()) continue;
    TriangleMesh m;
    for (const Primitive& p : col) m.append(p.toMesh());
    auto scene = std::make_unique<RayScene>();
    scene->addMesh(m);
    scene->commit();
    solid_.push_back(m.isWatertight() && m.signedVolume() > 0);
    links_.push_back(li);
    scenes_.push_back(std::move(scene));
  }
  table_ = std::make_unique<RayScene>();
  table_->addMesh(makeBox(model.table().size));
  table_->commit();
}

std::vector<Occluder> RobotOccluders::at(const JointVector& q, const Iso3& T_O_B,
                                         bool with_table) const {
  std::vector<Iso3> T = model_->linkPoses(q);
  std::vector<Occluder> out;
  for (size_t k = 0; k < links_.size(); ++k)
    out.push_back({scenes_[k].get(), T_O_B * T[links_[k]], solid_[k] != 0});
  if (with_table)
    out.push_back(
        {table_.get(), T_O_B * Iso3(Eigen::Translation3d(model_->table().center_B)), true});
  return out;
}

DepthImage robotDepthImage(const RobotOccluders& robotScenes, const JointVector& q,
                           const Iso3& T_B_C, const DepthCameraOptions& camera, bool with_table,
                           const PixelRect& region) {
  const CameraIntrinsics& K = camera.intrinsics;
  DepthImage out(K.width, K.height);
  const PixelRect window{std::max(0, region.u0), std::max(0, region.v0),
                         std::min(K.width, region.u1), std::min(K.height, region.v1)};
  if (window.empty()) return out;
  thread_local DepthRaster perThread;
  DepthRaster& raster = perThread;  // (inside the parallel loop below, the caller's)
  raster.reset(PinholeProjection{K.fx, K.fy, K.cx, K.cy},
               RasterWindow{window.u0, window.u1 - 1, window.v0, window.v1 - 1, 1});
  const Iso3 T_C_B = T_B_C.inverse();
  std::vector<RayScene::PlacedMesh> meshes;
  std::vector<uint8_t> solid;
  for (const Occluder& o : robotScenes.at(q, Iso3::Identity(), with_table)) {
    o.scene->collectMeshes(T_C_B * o.T_O_scene, &meshes);
    solid.resize(meshes.size(), o.solid);
  }
  // Triangle ids run on from mesh to mesh (the id is the index into `normal`); each triangle's
  // normal in the camera frame.
  std::vector<size_t> firstId(meshes.size() + 1, 0);
  for (size_t k = 0; k < meshes.size(); ++k)
    firstId[k + 1] = firstId[k] + meshes[k].mesh->triangles.size();
  std::vector<Vec3> normal(firstId.back());
  // The normals on the other core while this one rasterises.
  tbb::parallel_invoke(
      [&] {
        for (size_t k = 0; k < meshes.size(); ++k) {
          const RayScene::PlacedMesh& m = meshes[k];
          // Back faces of a closed link may go when the camera is outside its box.
          const bool inside = m.bounds->contains(m.T.inverse().translation());
          raster.draw(*m.mesh, m.T, int(firstId[k]), solid[k] && !inside, 0, m.bounds);
        }
      },
      [&] {
        for (size_t k = 0; k < meshes.size(); ++k) {
          const RayScene::PlacedMesh& m = meshes[k];
          Vec3* out = normal.data() + firstId[k];
          for (const Tri& t : m.mesh->triangles) {
            const Vec3 a = m.T * m.mesh->vertices[size_t(t[0])].cast<double>();
            const Vec3 b = m.T * m.mesh->vertices[size_t(t[1])].cast<double>();
            const Vec3 c = m.T * m.mesh->vertices[size_t(t[2])].cast<double>();
            *out++ = (b - a).cross(c - a);
          }
        }
      });
  const double cosLimit = std::cos(89 * M_PI / 180);
  parallelFor(window.v0, window.v1, [&](int v) {
    for (int u = window.u0; u < window.u1; ++u) {
      const int s = raster.index(u, v), id = raster.id(s);
      if (id < 0) continue;
      const double z = 1.0 / double(raster.inverseDepth(s));
      if (z < camera.min_range_m || z > camera.max_range_m) continue;
      const Vec3 dir = K.rayZ1(u, v);
      const Vec3& n = normal[size_t(id)];
      const double nn = n.squaredNorm() * dir.squaredNorm();
      if (!(nn > 0) || std::abs(n.dot(dir)) < cosLimit * std::sqrt(nn)) continue;
      out.depth_m[size_t(v) * K.width + size_t(u)] = float(z);
    }
  });
  return out;
}

std::vector<uint8_t> robotPixelMask(const DepthImage& depth, const Iso3& T_B_C,
                                    const JointVector& q, const RobotOccluders& robotScenes,
                                    const DepthCameraOptions& camera, double t_hand_m,
                                    int radius_px, bool with_table, const PixelRect* region) {
  const int W = depth.width, H = depth.height, R = radius_px;
  const PixelRect r = region ? PixelRect{std::max(0, region->u0), std::max(0, region->v0),
                                         std::min(W, region->u1), std::min(H, region->v1)}
                             : PixelRect{0, 0, W, H};
  std::vector<uint8_t> mask(depth.depth_m.size(), 0);
  if (r.empty()) return mask;
  const DepthImage robotDepth = robotDepthImage(robotScenes, q, T_B_C, camera, with_table,
                                                PixelRect{r.u0 - R, r.v0 - R, r.u1 + R, r.v1 + R});
  // A measurement is the robot's when the robot's rendered surface lies within t_hand of it at
  // that pixel or within radius_px of it: the sensor's lateral noise moves returns across the
  // robot's silhouette by a pixel or two. Pixels with no robot surface in the (2R + 1)² square
  // around them cannot be (a separable dilation of where the robot is, rows then columns).
  std::vector<uint8_t> rowNear(depth.depth_m.size(), 0), near(depth.depth_m.size(), 0);
  const int rv0 = std::max(0, r.v0 - R), rv1 = std::min(H, r.v1 + R);
  parallelFor(rv0, rv1, [&](int v) {
    const float* rd = &robotDepth.depth_m[size_t(v) * W];
    uint8_t* out = &rowNear[size_t(v) * W];
    // The last column up to u + R where the robot is: it is within R of u when not before u − R.
    int last = r.u0 - R - 1, next = std::max(0, r.u0 - R);
    for (int u = r.u0; u < r.u1; ++u) {
      for (const int end = std::min(W - 1, u + R); next <= end; ++next)
        if (rd[next] > 0) last = next;
      out[u] = last >= u - R;
    }
  });
  // (Raw row pointers: a store through a vector's uint8_t element may alias the vector itself,
  // which kept these loops from being vectorised.)
  parallelFor(r.v0, r.v1, [&](int v) {
    uint8_t* out = near.data() + size_t(v) * W;
    for (int vv = std::max(0, v - R); vv <= std::min(H - 1, v + R); ++vv) {
      const uint8_t* in = rowNear.data() + size_t(vv) * W;
      for (int u = r.u0; u < r.u1; ++u) out[u] |= in[u];
    }
  });
  const float* robotZ = robotDepth.depth_m.data();
  parallelFor(r.v0, r.v1, [&](int v) {
    const float* z = depth.depth_m.data() + size_t(v) * W;
    const uint8_t* isNear = near.data() + size_t(v) * W;
    uint8_t* out = mask.data() + size_t(v) * W;
    for (int u = r.u0; u < r.u1; ++u) {
      const float d = z[u];
      if (!(d > 0) || !isNear[u]) continue;
      // The pixel itself first (most pixels near the robot are on it), then the whole disk.
      const float rd0 = robotZ[size_t(v) * W + u];
      bool robot = rd0 > 0 && std::abs(d - rd0) < t_hand_m;
      for (int dv = -R; dv <= R && !robot; ++dv)
        for (int du = -R; du <= R && !robot; ++du) {
          const int uu = u + du, vv = v + dv;
          if (uu < 0 || vv < 0 || uu >= W || vv >= H || du * du + dv * dv > R * R) continue;
          const float rd = robotZ[size_t(vv) * W + uu];
          robot = rd > 0 && std::abs(d - rd) < t_hand_m;
        }
      out[u] = robot;
    }
  });
  return mask;
}

}  // namespace inhand
