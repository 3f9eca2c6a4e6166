// libFuzzer target: RobotModel::load with a fuzzed robot config (JSON) over the WAM's URDF.
#include "fuzz_util.h"
#include "inhand/robot/robot_model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = inhand::fuzz::writeInput("robot.json", data, size);
  const std::filesystem::path urdf =
      std::filesystem::path(INHAND_DATA_DIR) / "robots/wam_barretthand.urdf";
  inhand::fuzz::expectCleanResult(
      file, [&] { (void)inhand::RobotModel::load(file, urdf); }, urdf);
  return 0;
}
