#include "inhand/scan/table_top.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/robot/collision.h"

namespace inhand {

namespace {

// The smallest extent of the object: of its upright principal axes', the one along the table
// normal measured from the table to its top (the 99th percentile of the points' heights, as the
// axes' extents are 1 % trimmed: stray returns at depth edges).
double smallestExtent(const TableTopObject& o) {
  std::vector<double> heights;
  for (const Vec3& p : o.points_O) heights.push_back(o.table_O.distance(p));
  std::nth_element(heights.begin(), heights.begin() + heights.size() * 99 / 100, heights.end());
  const double height = heights[heights.size() * 99 / 100];
  double smallest = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3; ++k)
    smallest = std::min(smallest, std::abs(o.axes.axes.col(k).dot(o.table_O.n)) > 0.9
                                      ? height
                                      : o.axes.max[k] - o.axes.min[k]);
  return smallest;
}

}  // namespace

namespace {
// The frames' points (not the robot's) within search_radius_m across and 0.5 m up or down of the
// rest pose's origin, frame O.
std::vector<Vec3> pointsNear(const std::vector<DepthImage>& frames,
                             const std::vector<std::vector<uint8_t>>& robotMask, const Iso3& T_B_C,
                             const CameraIntrinsics& K, const Iso3& T_B_O_rest,
                             double search_radius_m) {
  const Vec3 rest_B = T_B_O_rest.translation();
  const Iso3 T_O_B = T_B_O_rest.inverse();
  std::vector<Vec3> near;
  for (size_t f = 0; f < frames.size(); ++f) {
    const DepthImage& d = frames[f];
    for (int v = 0; v < d.height; ++v)
      for (int u = 0; u < d.width; ++u) {
        const size_t i = size_t(v) * d.width + u;
        const float z = d.depth_m[i];
        if (!(z > 0) || robotMask[f][i]) continue;
        const Vec3 p_B = T_B_C * (double(z) * K.rayZ1(u, v));
        if ((p_B - rest_B).head<2>().norm() > search_radius_m ||
            std::abs(p_B.z() - rest_B.z()) > 0.5)
          continue;
        near.push_back(T_O_B * p_B);
      }
  }
  return near;
}

// Where the object may be: the points' box mirrored through the centre (the far side unseen),
// from the table (onTable) up to its top (onTable + up), 5 mm more each way.
Aabb believedBox(const Aabb& box, const Vec3& centre, const Vec3& onTable, const Vec3& up) {
  Aabb out;
  for (int c = 0; c < 8; ++c) {
    const Vec3 p = box.corner(c);
    out.extend(p);
    out.extend(2 * centre - p);
  }
  out.extend(onTable);
  out.extend(onTable + up);
  out.min.array() -= 0.005;
  out.max.array() += 0.005;
  return out;
}

// TableTopObject::region_O: box_O's faces and, with `footprint`, the sides of the points'
// upright rectangle (their trimmed extents along `axes`), 5 mm out.
std::vector<Plane> regionPlanes(const TableTopObject& o, const Vec3& up, bool footprint) {
  std::vector<Plane> region;
  for (int k = 0; k < 3; ++k) {
    region.push_back(Plane{Vec3::Unit(k), -o.box_O.min[k]});
    region.push_back(Plane{-Vec3::Unit(k), o.box_O.max[k]});
    const Vec3 a = o.axes.axes.col(k);
    // The upright axis: box_O's faces bound it.
    if (!footprint || std::abs(a.dot(up)) > 0.5) continue;
    const double c = o.axes.centroid.dot(a);
    region.push_back(Plane{a, -(c + o.axes.min[k] - 0.005)});
    region.push_back(Plane{-a, c + o.axes.max[k] + 0.005});
  }
  return region;
}
}  // namespace

TableTopObject findObjectOnTable(const std::vector<DepthImage>& frames,
                                 const std::vector<std::vector<uint8_t>>& robotMask,
                                 const Iso3& T_B_C, const CameraIntrinsics& K,
                                 const Iso3& T_B_O_rest, const RobotModel& m,
                                 const ScanOptions& options, const TableTopOptions& to,
                                 TableTopRecord* record,
                                 const std::function<void(const std::string&)>& log) {
  TableTopRecord local;
  TableTopRecord& tt = record ? *record : local;
  TableTopObject out;
  const Vec3 rest_B = T_B_O_rest.translation();
  const Iso3 T_O_B = T_B_O_rest.inverse();
  tt.frames = int(frames.size());
  const std::vector<Vec3> near =
      pointsNear(frames, robotMask, T_B_C, K, T_B_O_rest, to.search_radius_m);
  tt.points = int(near.size());
  PlaneFitOptions po = to.plane;
  po.expected_normal = T_O_B.linear() * Vec3::UnitZ();
  // The table the robot's config declares, in O (the fit finds where it really is).
  const Vec3 onTable_O = T_O_B * Vec3(rest_B.x(), rest_B.y(), m.table().topZ());
  po.expected_plane = Plane{po.expected_normal, -po.expected_normal.dot(onTable_O)};
  const std::optional<PlaneFit> fit = fitPlaneRansac(near, po);
  if (!fit) {
    out.problem = Termination::kObjectNotFound;
    return out;
  }
  out.table_O = fit->plane;
  tt.table_O = fit->plane;
  tt.table_inliers = fit->inliers;
  std::vector<Vec3> above;
  for (const Vec3& p : near)
    if (fit->plane.distance(p) > to.above_table_m) above.push_back(p);
  // The object: the largest cluster above the table (stray returns dropped).
  out.points_O = above.empty() ? above : largestCluster(above, to.cluster_cell_m);
  tt.object_points = int(out.points_O.size());
  if (log) {
    char line[240];
    std::snprintf(line, sizeof(line),
                  "table top: %d frames, %d points near the rest pose, %d on the table plane, %zu "
                  "above it, %d in the object's cluster",
                  tt.frames, tt.points, tt.table_inliers, above.size(), tt.object_points);
    log(line);
  }
  if (tt.object_points < to.min_points) {
    out.problem = Termination::kObjectNotFound;
    return out;
  }
  // Too large for the hand: the open hand spans none of its extents (85 % of the open hand's
  // extent along palm x; flat fingers: 328 mm for the BarrettHand).
  out.axes = principalAxesUpright(out.points_O, fit->plane.n);
  tt.axes = out.axes;
  const Aabb hb = HandGeometry(m, m.openHand(0.0), Iso3::Identity()).mesh().bounds();
  if (smallestExtent(out) > 0.85 * (hb.max.x() - hb.min.x())) {
    out.problem = Termination::kObjectTooLargeForHand;
    return out;
  }
  // The volume: centred on the points' box, from the table plane to their top.
  const Vec3 n = fit->plane.n;
  Aabb box;
  for (const Vec3& p : out.points_O) {
    box.extend(p);
    out.height_m = std::max(out.height_m, fit->plane.distance(p));
  }
  const Vec3 onTable = box.center() - n * fit->plane.distance(box.center());
  out.centre_O = onTable + 0.5 * out.height_m * n;
  if (std::max(box.size().maxCoeff(), out.height_m) > options.volume_size_m - 0.02) {
    out.problem = Termination::kObjectTooLargeForVolume;
    return out;
  }
  out.box_O = believedBox(box, out.centre_O, onTable, out.height_m * n);
  out.region_O = regionPlanes(out, n, to.footprint_region);
  return out;
}

bool insideRegion(const std::vector<Plane>& region, const Vec3& p) {
  return std::all_of(region.begin(), region.end(),
                     [&](const Plane& h) { return h.distance(p) >= 0; });
}

ScanOptions fitScanVolume(const ScanOptions& options, const TableTopObject& object) {
  ScanOptions fitted = options;
  if (options.fit_volume) {
    const double extent =
        std::max((object.box_O.max - object.box_O.min).maxCoeff(), object.height_m);
    const double size = std::min(options.volume_size_m, 1.5 * extent + 0.04);
    fitted.voxel_m = options.voxel_m * size / options.volume_size_m;
    fitted.volume_size_m = size;
  }
  return fitted;
}

std::vector<uint8_t> tablePixels(const DepthImage& d, const Iso3& T_O_C, const CameraIntrinsics& K,
                                 const Plane& table_O, double above_m) {
  std::vector<uint8_t> table(d.depth_m.size(), 0);
  for (int v = 0; v < d.height; ++v)
    for (int u = 0; u < d.width; ++u) {
      const size_t i = size_t(v) * d.width + u;
      const float z = d.depth_m[i];
      if (z > 0 && table_O.distance(T_O_C * (double(z) * K.rayZ1(u, v))) < above_m) table[i] = 1;
    }
  return table;
}

std::vector<uint8_t> unknownUnderMeasuredReference(const TsdfVolume& volume, const Vec3& up_O) {
  const Vec3i n = volume.dims();
  std::vector<uint8_t> keep(size_t(n.prod()), 0);
  // In voxel units, steps of at most half a voxel along each axis: no voxel is stepped over.
  const Vec3 step = up_O.normalized() * 0.5;
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x) {
        const size_t i = volume.index(x, y, z);
        if (volume.state(i) != VoxelState::kUnknown) continue;
        Vec3 p(x, y, z);
        for (;;) {
          p += step;
          const int px = int(std::lround(p.x())), py = int(std::lround(p.y())),
                    pz = int(std::lround(p.z()));
          if (px < 0 || py < 0 || pz < 0 || px >= n.x() || py >= n.y() || pz >= n.z()) break;
          if (volume.state(volume.index(px, py, pz)) == VoxelState::kObserved) {
            keep[i] = 1;
            break;
          }
        }
      }
  return keep;
}

std::vector<uint8_t> unknownUnderMeasured(const TsdfVolume& volume, const Vec3& up_O) {
  const Vec3i n = volume.dims();
  std::vector<uint8_t> keep(size_t(n.prod()), 0);
  // The observed voxels' bounds, widened by the half voxel that rounding reaches and a margin:
  // a ray that misses them reaches no observed voxel, and one is followed only across them.
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int z = 0; z < n.z(); ++z)
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x)
        if (volume.state(volume.index(x, y, z)) == VoxelState::kObserved) {
          lo = lo.cwiseMin(Vec3(x, y, z));
          hi = hi.cwiseMax(Vec3(x, y, z));
        }
  if (!(lo.x() <= hi.x())) return keep;
  lo.array() -= 0.51;
  hi.array() += 0.51;
  // In voxel units, steps of at most half a voxel along each axis: no voxel is stepped over.
  const Vec3 step = up_O.normalized() * 0.5;
  parallelFor(0, n.z(), [&](int z) {
    for (int y = 0; y < n.y(); ++y)
      for (int x = 0; x < n.x(); ++x) {
        const size_t i = volume.index(x, y, z);
        if (volume.state(i) != VoxelState::kUnknown) continue;
        // The steps k in [k0, k1] at which the ray is within the bounds (slabs).
        const Vec3 start(x, y, z);
        double k0 = 0, k1 = std::numeric_limits<double>::infinity();
        for (int a = 0; a < 3 && k0 <= k1; ++a) {
          if (std::abs(step[a]) < 1e-12) {
            if (start[a] < lo[a] || start[a] > hi[a]) k1 = -1;
            continue;
          }
          double ka = (lo[a] - start[a]) / step[a], kb = (hi[a] - start[a]) / step[a];
          if (ka > kb) std::swap(ka, kb);
          k0 = std::max(k0, ka);
          k1 = std::min(k1, kb);
        }
        if (k0 > k1) continue;
        // The same half-voxel steps as the reference (the same sums, rounded alike: lround of a
        // value above −½ is floor(v + ½)), rounded only within the bounds.
        Vec3 p = start;
        for (int k = 1; double(k) <= k1 + 1; ++k) {
          p += step;
          if (double(k) < k0 - 1) continue;
          if (p.x() <= -0.5 || p.y() <= -0.5 || p.z() <= -0.5 || p.x() >= n.x() - 0.5 ||
              p.y() >= n.y() - 0.5 || p.z() >= n.z() - 0.5)
            break;
          const int px = int(p.x() + 0.5), py = int(p.y() + 0.5), pz = int(p.z() + 0.5);
          if (volume.state(volume.index(px, py, pz)) == VoxelState::kObserved) {
            keep[i] = 1;
            break;
          }
        }
      }
  });
  return keep;
}

namespace {
// The first grasp's model at the planning stride: from the table-top frames with their
// silhouettes (ScanSession::tableTopVolume), with `under_measured_only` the unknown space that
// is not beneath measured surface counted as empty (TableTopOptions::under_measured_only).
ObjectModel tableTopModel(const ScanSession& session, const Plane& table_O,
                          bool under_measured_only) {
  TsdfVolume volume = session.tableTopVolume();
  if (under_measured_only) {
    const std::vector<uint8_t> keep = unknownUnderMeasured(volume, table_O.n);
    for (size_t i = 0; i < keep.size(); ++i)
      if (volume.state(i) == VoxelState::kUnknown && !keep[i])
        volume.states()[i] = uint8_t(VoxelState::kEmpty);
  }
  MeshOptions mesh = session.options().mesh;
  mesh.stride = session.options().planning_stride;
  mesh.method = session.options().planning_method;
  return extractModel(volume, mesh);
}
}  // namespace

GraspGeneration firstGrasps(const ScanSession& session, const TableTopObject& object,
                            const Iso3& T_B_O_rest, const JointVector& q_now) {
  const RobotModel& m = session.robot();
  const TableTopOptions& to = session.multiOptions().table_top;
  const ObjectModel seen = to.under_measured_only || &session.tableTopVolume() != &session.volume()
                               ? tableTopModel(session, object.table_O, to.under_measured_only)
                               : session.planningModel();
  // The model where the object may lie (region_O; without the footprint's rectangle, 2 cm out):
  // what the camera did not see is closed up to the volume's bounds.
  std::vector<Plane> region = object.region_O;
  if (!session.multiOptions().table_top.footprint_region)
    for (Plane& h : region) h.d += 0.02;
  auto clipped = [&](const TriangleMesh& mesh) {
    TriangleMesh out;
    out.vertices = mesh.vertices;
    for (const Tri& t : mesh.triangles) {
      bool inside = true;
      for (int k = 0; k < 3 && inside; ++k) {
        const Vec3 p = mesh.vertices[t[k]].cast<double>();
        inside = object.table_O.distance(p) > 0.003 && insideRegion(region, p);
      }
      if (inside) out.triangles.push_back(t);
    }
    return out;
  };
  const TriangleMesh model = clipped(seen.mesh);
  GraspGeneration first =
      generateGrasps(m, model, T_B_O_rest, q_now, session.multiOptions().grasp, &object.points_O);
  // Most stable first; among equally stable (to 10 %), the cheaper arm motion.
  for (GraspCandidate& c : first.candidates) c.score = trajectoryTime(m, m.arm(q_now), m.arm(c.q));
  std::stable_sort(first.candidates.begin(), first.candidates.end(),
                   [](const GraspCandidate& a, const GraspCandidate& b) {
                     const double ea = std::floor(std::log(std::max(a.epsilon, 1e-9)) / 0.1);
                     const double eb = std::floor(std::log(std::max(b.epsilon, 1e-9)) / 0.1);
                     return ea != eb ? ea > eb : a.score < b.score;
                   });
  // Those that hold the model in physics first (grasp/hold_test.h), the model clipped to region_O
  // or, with footprint_hold_test, to the points' rectangle.
  const std::vector<Plane> holdRegion = to.footprint_hold_test && !to.footprint_region
                                            ? regionPlanes(object, object.table_O.n, true)
                                            : object.region_O;
  const GraspOptions& go = session.multiOptions().grasp;
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<ConvexPiece> pieces =
      go.hold.enabled && !first.candidates.empty() && !seen.mesh.empty()
          ? modelPiecesAboveTable(seen.mesh, T_B_O_rest, m, &holdRegion, go.hold.decomposition)
          : std::vector<ConvexPiece>();
  // A lift that shows the hand first, among those that held alike: else the lift's frame may
  // not tell whether the object is held.
  double holdS = rankByHold(m, pieces, T_B_O_rest, go.friction, go.hold, &first.candidates, true);
  if (holdS > 0)
    holdS = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  session.log(holdLine(first.candidates, holdS));
  // The hands the unseen space would stop short of their plan, tried from there.
  if (to.under_measured_only && to.unseen_hold_checked > 0 && holdS > 0) {
    const TriangleMesh unseen = clipped(tableTopModel(session, object.table_O, false).mesh);
    const double s = preferHoldingUnseen(m, pieces, unseen, T_B_O_rest, go.friction, go.hold,
                                         to.unseen_hold_checked, &first.candidates);
    if (std::string line = unseenHoldLine(first.candidates, s); !line.empty()) session.log(line);
  }
  return first;
}

std::vector<Iso3> restingStarts(const TriangleMesh& model_O, const Vec3& seen_B,
                                const Vec3& camera_B, double table_top_z, int orientations,
                                int headings) {
  std::vector<StablePose> rests;
  try {
    rests = stablePoses(model_O);
  } catch (const Error&) {
    return {};
  }
  if (int(rests.size()) > orientations) rests.resize(size_t(std::max(0, orientations)));
  std::vector<Iso3> starts;
  for (const StablePose& rest : rests)
    for (int k = 0; k < headings; ++k) {
      Iso3 T = Iso3::Identity();
      T.linear() =
          Eigen::AngleAxisd(2 * M_PI * k / headings, Vec3::UnitZ()).toRotationMatrix() * rest.R_B_O;
      double low = std::numeric_limits<double>::infinity();
      for (const Vec3f& v : model_O.vertices)
        low = std::min(low, (T.linear() * v.cast<double>()).z());
      T.translation() = Vec3(0, 0, table_top_z - low);
      // The centroid (by area) of the triangles facing the camera with the model there.
      Vec3 near = Vec3::Zero();
      double area = 0;
      for (const Tri& t : model_O.triangles) {
        const Vec3 a = T * model_O.vertices[size_t(t[0])].cast<double>();
        const Vec3 b = T * model_O.vertices[size_t(t[1])].cast<double>();
        const Vec3 c = T * model_O.vertices[size_t(t[2])].cast<double>();
        const Vec3 n = (b - a).cross(c - a);
        const Vec3 mid = (a + b + c) / 3;
        if (n.dot(camera_B - mid) <= 0 || mid.z() < table_top_z + 0.005) continue;
        near += 0.5 * n.norm() * mid;
        area += 0.5 * n.norm();
      }
      if (!(area > 0)) continue;
      near /= area;
      T.translation().x() += seen_B.x() - near.x();
      T.translation().y() += seen_B.y() - near.y();
      starts.push_back(T);
    }
  return starts;
}

}  // namespace inhand
