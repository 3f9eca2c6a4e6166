// libFuzzer target: RobotModel::load with a fuzzed URDF (the WAM + BarrettHand robot config).
#include "fuzz_util.h"
#include "inhand/robot/robot_model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = inhand::fuzz::writeInput("robot.urdf", data, size);
  const std::filesystem::path config =
      std::filesystem::path(INHAND_DATA_DIR) / "robots/wam_barretthand.json";
  inhand::fuzz::expectCleanResult(
      file, [&] { (void)inhand::RobotModel::load(config, file); }, config);
  return 0;
}
