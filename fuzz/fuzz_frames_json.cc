// libFuzzer target: readFrameSet (frames.json: intrinsics, depth scale, per-frame poses).
#include "fuzz_util.h"
#include "inhand/sensor/frame_set.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const bool pngs = [] {  // the frames the seed names exist (readFrameSet checks)
    const uint8_t none[1] = {0};
    inhand::fuzz::writeInput("depth_000.png", none, 1);
    inhand::fuzz::writeInput("depth_001.png", none, 1);
    return true;
  }();
  (void)pngs;
  const auto file = inhand::fuzz::writeInput("frames.json", data, size);
  inhand::fuzz::expectCleanResult(file, [&] { (void)inhand::readFrameSet(file.parent_path()); });
  return 0;
}
