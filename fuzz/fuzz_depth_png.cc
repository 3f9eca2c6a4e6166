// libFuzzer target: readDepthPng (16-bit grey PNG depth images).
#include "fuzz_util.h"
#include "inhand/sensor/depth_image.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = inhand::fuzz::writeInput("depth.png", data, size);
  inhand::fuzz::expectCleanResult(file, [&] { (void)inhand::readDepthPng(file); });
  return 0;
}
