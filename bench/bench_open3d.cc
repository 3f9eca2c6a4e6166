// inhand's integration against Open3D's dense UniformTSDFVolume on the same frames, volume and
// truncation, in one run (built only where Open3D is found: Debian's libopen3d-dev).
//
//   ./build/bench/bench_open3d [OBJECT] [FRAMES]     (default builtin:cracker_box, 40)
//
// The frames: OBJECT rendered with the sensor's noise from FRAMES views all around at 0.7 m
// (as `inhand render` does). Two volumes, each a cube at 2 mm voxels with μ = 8 mm: the scan's
// 0.34 m cube, and a tight cube around the object (its largest side + 2 cm). For each, every
// frame is integrated in turn into a fresh volume, three rounds; printed: milliseconds per frame
// (median round) for Open3D's Integrate, inhand's integrate with σ per pixel computed as in
// `inhand fuse` and a scan (the whole fusion of a frame: σ only for the pixels the volume's
// voxels can project to), and inhand's integrate alone (σ precomputed), all three with the
// paper's band (the update Open3D makes); then inhand's whole fusion of a frame with the scans'
// and `inhand fuse`'s defaults (band_sigmas 2, smooth_depth: a plane fitted per pixel).
// Open3D's voxels hold a truncated distance and a weight; inhand's Σw·d, Σw and a state
// (unknown / empty / observed) and weights 1/σ², so the work per voxel is alike.
//
// Then the same with colour: each frame also has a registered colour image (the object's 2 cm
// checkerboard, rendered unlit from the depth camera's pose), integrated by Open3D's RGB8 volume
// (a weighted mean colour in every voxel of the band) and by inhand as a scan fuses a frame's
// colour: integrate + integrateColour (a weighted mean colour in the voxels beside the measured
// surface, σ and viewing-angle weights, edge and occlusion tests) + ColourFrames::add (the
// frame's colour kept for the model's vertices).
#include <open3d/Open3D.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/eval/metrics.h"
#include "inhand/geometry/appearance.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/sensor/render.h"
#include "inhand/volume/colour_volume.h"
#include "inhand/volume/integrate.h"

using namespace inhand;
using Clock = std::chrono::steady_clock;

namespace {

struct Frame {
  DepthImage depth;
  Iso3 T_O_C;
  std::vector<float> sigma;
  open3d::geometry::RGBDImage rgbd;
  RgbImage colour;                          // registered to the depth image
  open3d::geometry::RGBDImage rgbd_colour;  // the same with the colour image
};

double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Row {
  double open3d_ms, inhand_fuse_ms, inhand_integrate_ms, inhand_defaults_ms;
};

// One cube of `edge` around `centre` for both libraries: Open3D's resolution and origin, the
// camera, and inhand's volume options and box (inhand samples at origin + i·voxel, i = 0..n-1:
// the same n as Open3D's voxel centres).
struct Setup {
  Setup(const DepthCameraOptions& cam, const Vec3& centre, double edge, double voxel, double mu)
      : resolution(int(std::lround(edge / voxel))),
        origin(centre - Vec3::Constant(0.5 * edge)),
        intr(cam.intrinsics.width, cam.intrinsics.height, cam.intrinsics.fx, cam.intrinsics.fy,
             cam.intrinsics.cx, cam.intrinsics.cy),
        box{origin + Vec3::Constant(0.5 * voxel),
            origin + Vec3::Constant(0.5 * voxel + (resolution - 1) * voxel)} {
    vo.voxel_size_m = voxel;
    vo.truncation_m = mu;
  }
  int resolution;
  Vec3 origin;
  open3d::camera::PinholeCameraIntrinsic intr;
  Aabb box;
  VolumeOptions vo;
};

Row compare(const std::vector<Frame>& frames, const DepthCameraOptions& cam,
            const NoiseModelOptions& noise, const Vec3& centre, double edge, double voxel,
            double mu) {
  const Setup g(cam, centre, edge, voxel, mu);
  const int resolution = g.resolution;
  const Vec3& origin = g.origin;
  const CameraIntrinsics& K = cam.intrinsics;
  const auto& intr = g.intr;
  const VolumeOptions& vo = g.vo;
  const Aabb& box = g.box;
  std::vector<double> o3d, fuse, integ, defaults;
  VolumeOptions vd = vo;
  vd.band_sigmas = 2.0;
  vd.smooth_depth = true;
  for (int round = 0; round < 3; ++round) {
    open3d::pipelines::integration::UniformTSDFVolume v(
        edge, resolution, mu, open3d::pipelines::integration::TSDFVolumeColorType::NoColor, origin);
    auto t = Clock::now();
    for (const Frame& f : frames) v.Integrate(f.rgbd, intr, f.T_O_C.inverse().matrix());
    o3d.push_back(msSince(t) / double(frames.size()));

    TsdfVolume a(box, vo);
    t = Clock::now();
    for (const Frame& f : frames) {
      const PixelRect rect = volumeImageRect(a, f.T_O_C, K);  // as a scan and `inhand fuse` do
      integrate(f.depth, f.T_O_C, K, measurementSigma(f.depth, K, noise, &rect), &a);
    }
    fuse.push_back(msSince(t) / double(frames.size()));

    TsdfVolume b(box, vo);
    t = Clock::now();
    for (const Frame& f : frames) integrate(f.depth, f.T_O_C, K, f.sigma, &b);
    integ.push_back(msSince(t) / double(frames.size()));

    TsdfVolume c(box, vd);
    t = Clock::now();
    for (const Frame& f : frames) {
      const PixelRect rect = volumeImageRect(c, f.T_O_C, K);
      integrate(f.depth, f.T_O_C, K, measurementSigma(f.depth, K, noise, &rect), &c);
    }
    defaults.push_back(msSince(t) / double(frames.size()));
  }
  return {median(o3d), median(fuse), median(integ), median(defaults)};
}

struct ColourRow {
  double open3d_ms, inhand_ms, inhand_frames_ms;
};

// Depth and colour per frame: Open3D's RGB8 volume against inhand's integrate + integrateColour
// (+ ColourFrames::add, as a scan), σ per pixel computed in the timed loop as a scan does.
ColourRow compareColour(const std::vector<Frame>& frames, const DepthCameraOptions& cam,
                        const NoiseModelOptions& noise, const Vec3& centre, double edge,
                        double voxel, double mu) {
  const Setup g(cam, centre, edge, voxel, mu);
  const CameraIntrinsics& K = cam.intrinsics;
  std::vector<double> o3d, ours, withFrames;
  for (int round = 0; round < 3; ++round) {
    open3d::pipelines::integration::UniformTSDFVolume v(
        edge, g.resolution, mu, open3d::pipelines::integration::TSDFVolumeColorType::RGB8,
        g.origin);
    auto t = Clock::now();
    for (const Frame& f : frames) v.Integrate(f.rgbd_colour, g.intr, f.T_O_C.inverse().matrix());
    o3d.push_back(msSince(t) / double(frames.size()));
    for (const bool keep : {false, true}) {
      TsdfVolume a(g.box, g.vo);
      ColourVolume colour(a);
      ColourFrames kept(64u << 20);
      t = Clock::now();
      for (const Frame& f : frames) {
        const PixelRect rect = volumeImageRect(a, f.T_O_C, K);
        const std::vector<float> sigma = measurementSigma(f.depth, K, noise, &rect);
        integrate(f.depth, f.T_O_C, K, sigma, &a);
        integrateColour(f.depth, f.colour, f.T_O_C, cam, sigma, &colour);
        if (keep) kept.add(f.depth, f.colour, f.T_O_C, cam, sigma);
      }
      (keep ? withFrames : ours).push_back(msSince(t) / double(frames.size()));
    }
  }
  return {median(o3d), median(ours), median(withFrames)};
}

}  // namespace

int main(int argc, char** argv) {
  const std::string object = argc > 1 ? argv[1] : "builtin:cracker_box";
  const int count = argc > 2 ? std::max(1, std::atoi(argv[2])) : 40;
  const TriangleMesh mesh = loadObject(object);
  RayScene scene;
  scene.addMesh(mesh);
  scene.commit();
  DepthCameraOptions cam;
  NoiseModelOptions noise;
  // A colour camera registered to the depth camera (Open3D's RGBD images are registered).
  cam.colour.enabled = true;
  cam.colour.intrinsics = cam.intrinsics;
  cam.colour.T_D_RGB = Iso3::Identity();
  const SurfaceColours checker = checkerColours(mesh, kBuiltinCheckerSquare_m);
  const Vec3 centre = mesh.bounds().center();
  std::vector<Frame> frames;
  const std::vector<Vec3> dirs = fibonacciSphere(count);
  for (int i = 0; i < count; ++i) {
    Frame f;
    f.T_O_C = lookAt(centre + 0.7 * dirs[size_t(i)], centre, Vec3::UnitZ());
    RenderOptions ro;
    ro.seed = mixSeed(1, uint64_t(i));
    f.depth = renderDepth(scene, f.T_O_C, cam, noise, ro);
    f.sigma = measurementSigma(f.depth, cam.intrinsics, noise);
    open3d::geometry::Image depth, color;
    depth.Prepare(f.depth.width, f.depth.height, 1, 4);
    std::copy(f.depth.depth_m.begin(), f.depth.depth_m.end(), depth.PointerAs<float>());
    color.Prepare(f.depth.width, f.depth.height, 1, 4);  // NoColor volumes do not read it
    f.rgbd = open3d::geometry::RGBDImage(color, depth);
    f.colour = renderSurfaceColours(mesh, checker, f.T_O_C, cam.intrinsics);
    open3d::geometry::Image rgb;
    rgb.Prepare(f.colour.width, f.colour.height, 3, 1);
    std::copy(f.colour.rgb.begin(), f.colour.rgb.end(), rgb.data_.begin());
    f.rgbd_colour = open3d::geometry::RGBDImage(rgb, depth);
    frames.push_back(std::move(f));
  }
  const double voxel = 0.002, mu = 0.008;
  const double tight = mesh.bounds().size().maxCoeff() + 0.02;
  std::printf(
      "%d frames of %s (640x480, noisy, 0.7 m), voxels of %.0f mm, mu = %.0f mm, %d "
      "threads (Open3D: OpenMP)\n",
      count, object.c_str(), 1000 * voxel, 1000 * mu, threadCount());
  std::printf("%-26s %10s %14s %14s %10s %10s %16s %10s\n", "volume", "Open3D ms", "inhand fuse ms",
              "integrate ms", "x (fuse)", "x (integ.)", "defaults fuse ms", "x (def.)");
  for (const auto& [name, edge] : std::vector<std::pair<std::string, double>>{
           {"scan cube 0.34 m", 0.34},
           {"tight cube " + std::to_string(tight).substr(0, 5) + " m", tight}}) {
    const Row r = compare(frames, cam, noise, centre, edge, voxel, mu);
    std::printf("%-26s %10.2f %14.2f %14.2f %10.2f %10.2f %16.2f %10.2f\n", name.c_str(),
                r.open3d_ms, r.inhand_fuse_ms, r.inhand_integrate_ms,
                r.open3d_ms / r.inhand_fuse_ms, r.open3d_ms / r.inhand_integrate_ms,
                r.inhand_defaults_ms, r.open3d_ms / r.inhand_defaults_ms);
  }
  std::printf("\nwith colour (a registered 640x480 colour image per frame, 2 cm checkerboard)\n");
  std::printf("%-26s %14s %20s %10s %24s %10s\n", "volume", "Open3D RGB8 ms", "inhand +colour ms",
              "x", "inhand +colour frames ms", "x");
  for (const auto& [name, edge] : std::vector<std::pair<std::string, double>>{
           {"scan cube 0.34 m", 0.34},
           {"tight cube " + std::to_string(tight).substr(0, 5) + " m", tight}}) {
    const ColourRow r = compareColour(frames, cam, noise, centre, edge, voxel, mu);
    std::printf("%-26s %14.2f %20.2f %10.2f %24.2f %10.2f\n", name.c_str(), r.open3d_ms,
                r.inhand_ms, r.open3d_ms / r.inhand_ms, r.inhand_frames_ms,
                r.open3d_ms / r.inhand_frames_ms);
  }
  return 0;
}
