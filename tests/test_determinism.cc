// The same inputs and seed give the same model byte for byte, whatever the number of threads
// (setThreadCount; INHAND_THREADS for the command line).
#include <gtest/gtest.h>

#include "inhand/core/file_util.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/driver/simulated_scan.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/mesh_io.h"
#include "test_util.h"

using namespace inhand;

namespace {

// A short two-grasp scan from the table, tracking on with arm error: every parallel stage runs
// (fusion, Alg. 1, grasp generation and ranking, tracking's pair sums).
std::string scanBytes(int threads, const test::TempDir& dir) {
  setThreadCount(threads);
  ScanConfig c = test::quickScanConfig();
  c.sim.arm_error_m = 0.01;
  c.scan.tracking.enabled = true;
  const SimulatedScan s = runSimulatedScan(test::wam(), loadObject("builtin:cracker_box"), c);
  setThreadCount(0);
  EXPECT_EQ(s.result.grasps.size(), 2u);
  const fs::path file = dir.path() / ("model_" + std::to_string(threads) + ".ply");
  writePly(file, s.result.scan.model.mesh, &s.result.scan.model.variance);
  std::string views;
  for (const ViewRecord& v : s.result.scan.views)
    views += std::to_string(v.dir_O.x()) + std::to_string(v.frames) + ";";
  return views + "|" + readTextFile(file);
}

}  // namespace

TEST(Determinism, TheScanIsTheSameByteForByteOnOneTwoAndThreeThreads) {
  test::TempDir dir;
  const std::string one = scanBytes(1, dir);
  EXPECT_EQ(scanBytes(2, dir), one);
  EXPECT_EQ(scanBytes(3, dir), one);
}
