// libFuzzer target: readPly (inhand's own PLY reader: ASCII and binary little-endian).
#include "fuzz_util.h"
#include "inhand/geometry/mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = inhand::fuzz::writeInput("mesh.ply", data, size);
  inhand::fuzz::expectCleanResult(file, [&] { (void)inhand::readPly(file); });
  return 0;
}
