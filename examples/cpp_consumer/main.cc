// Uses an installed inhand: fuses simulated depth frames of a sphere into the paper's volume,
// extracts the closed model, checks it against the sphere, and drives the simulated scan's
// building blocks (robot model, stable poses). Exits non-zero when a figure is off.
#include <inhand/inhand.h>

#include <cmath>
#include <cstdio>

int main(int argc, char** argv) {
  using namespace inhand;
  try {
    // A sphere of 5 cm seen from 8 directions at 0.7 m.
    const double r = 0.05;
    RayScene scene;
    scene.addMesh(makeSphere(r, 5));
    scene.addMesh(makeSphere(2.0, 3));  // a room around it: rays that miss the sphere carve
    scene.commit();
    const DepthCameraOptions camera;
    const NoiseModelOptions noise;
    VolumeOptions vo;
    vo.voxel_size_m = 0.002;
    Aabb box;
    box.extend(Vec3::Constant(-0.08));
    box.extend(Vec3::Constant(0.08));
    TsdfVolume volume(box, vo);
    for (int k = 0; k < 8; ++k) {  // from the 8 corner directions
      const Vec3 eye(k & 1 ? 1 : -1, k & 2 ? 1 : -1, k & 4 ? 1 : -1);
      const Iso3 T_O_C = lookAt(0.7 * eye.normalized(), Vec3::Zero());
      RenderOptions ro;
      ro.seed = uint64_t(k);
      const DepthImage d = renderDepth(scene, T_O_C, camera, noise, ro);
      integrate(d, T_O_C, camera.intrinsics, measurementSigma(d, camera.intrinsics, noise),
                &volume);
    }
    const ObjectModel model = extractModel(volume);
    double worst = 0;
    for (size_t i = 0; i < model.mesh.vertices.size(); ++i)
      if (model.observed[i])
        worst = std::max(worst, std::abs(model.mesh.vertices[i].cast<double>().norm() - r));
    std::printf("consumer: %zu vertices, observed %.1f %%, worst radius error %.2f mm\n",
                model.mesh.vertices.size(), 100 * model.observedAreaFraction(), 1000 * worst);
    if (model.observedAreaFraction() < 0.95 || worst > 0.006) return 1;
    // A box rests on its largest face most often.
    const std::vector<StablePose> poses = stablePoses(makeBox(Vec3(0.06, 0.158, 0.21)));
    std::printf("consumer: %zu stable poses of the box, the most probable %.3f\n", poses.size(),
                poses.front().probability);
    if (poses.size() != 6) return 1;
    // The robot shipped with inhand, from the installed data folder when given.
    if (argc > 1) {
      const RobotModel robot = RobotModel::load(argv[1]);
      std::printf("consumer: %s with %d arm joints\n", argv[1], robot.armDof());
      if (robot.armDof() != 7) return 1;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "consumer: %s\n", e.what());
    return 1;
  }
  return 0;
}
