// libFuzzer target: readScanConfigFile (the scan's JSON options).
#include "fuzz_util.h"
#include "inhand/config/scan_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto file = inhand::fuzz::writeInput("scan.json", data, size);
  inhand::fuzz::expectCleanResult(file, [&] {
    inhand::ScanConfig config;
    inhand::readScanConfigFile(file, &config);
  });
  return 0;
}
