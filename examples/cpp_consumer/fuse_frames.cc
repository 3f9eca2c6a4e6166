// Fuses recorded depth frames (frames.json + 16-bit PNGs, as `inhand render` writes and as one
// records from a real robot) into a model with per-vertex variance, through an installed inhand.
//   fuse_frames FRAMES_DIR OUT.ply
#include <inhand/inhand.h>

#include <cstdio>

int main(int argc, char** argv) {
  using namespace inhand;
  if (argc != 3) {
    std::fprintf(stderr, "usage: fuse_frames FRAMES_DIR OUT.ply\n");
    return 2;
  }
  try {
    const FrameSet frames = readFrameSet(argv[1]);
    Aabb box;  // bounds_O from frames.json, else a 30 cm cube around the origin of frame O
    if (frames.bounds_O) {
      box = *frames.bounds_O;
    } else {
      box.extend(Vec3::Constant(-0.15));
      box.extend(Vec3::Constant(0.15));
    }
    VolumeOptions vo;
    vo.voxel_size_m = 0.002;
    TsdfVolume volume(box, vo);
    const NoiseModelOptions noise;
    for (size_t i = 0; i < frames.frames.size(); ++i) {
      const DepthImage depth = loadFrameDepth(argv[1], frames, i);
      integrate(depth, frames.frames[i].T_O_C, frames.intrinsics,
                measurementSigma(depth, frames.intrinsics, noise), &volume);
    }
    const ObjectModel model = extractModel(volume);  // closed; observedSurface(): measured only
    writePly(argv[2], model.mesh, &model.variance);
    std::printf("%zu frames -> %s: %zu vertices, observed %.1f%% of the surface\n",
                frames.frames.size(), argv[2], model.mesh.vertices.size(),
                100 * model.observedAreaFraction());
  } catch (const Error& e) {
    std::fprintf(stderr, "fuse_frames: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
