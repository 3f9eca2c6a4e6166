// libFuzzer target: importMesh (assimp) on OBJ, STL and PLY: the first byte picks the format.
#include "fuzz_util.h"
#include "inhand/geometry/mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* const names[] = {"mesh.obj", "mesh.stl", "mesh.ply"};
  const auto file = inhand::fuzz::writeInput(names[data[0] % 3], data + 1, size - 1);
  inhand::fuzz::expectCleanResult(file, [&] { (void)inhand::importMesh(file); });
  return 0;
}
