// libFuzzer target: TsdfVolume::readData (the volume in a scan checkpoint) into an 8³ volume. It
// returns what is wrong rather than throwing; a crash, a hang or an unbounded allocation is a
// finding, and so is a read that succeeds but writes back a volume that reads differently.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>

#include "inhand/volume/tsdf_volume.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  inhand::Aabb box;
  box.extend(inhand::Vec3::Zero());
  box.extend(inhand::Vec3::Constant(0.028));
  inhand::VolumeOptions o;
  o.voxel_size_m = 0.004;
  inhand::TsdfVolume v(box, o);  // 8 x 8 x 8
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  if (!v.readData(in).empty()) return 0;
  std::stringstream again;
  v.writeData(again);
  inhand::TsdfVolume w(box, o);
  if (!w.readData(again).empty() || std::memcmp(w.states(), v.states(), v.voxelCount()) != 0 ||
      std::memcmp(w.sumWD(), v.sumWD(), v.voxelCount() * sizeof(float)) != 0 ||
      std::memcmp(w.sumW(), v.sumW(), v.voxelCount() * sizeof(float)) != 0)
    std::abort();
  return 0;
}
