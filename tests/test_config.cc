// The scan options tables: every key read into the member it is written from, errors that name
// the key, and docs/config.md generated from the same tables.
#include <gtest/gtest.h>

#include <functional>

#include "inhand/config/scan_config.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"

using namespace inhand;

namespace {
std::string errorOf(const std::string& json) {
  ScanConfig c;
  try {
    readScanConfig(Json::parse(json), "cfg", &c);
  } catch (const Error& e) {
    return e.what();
  }
  return "no error";
}
}  // namespace

// Every leaf of the written options changed (numbers moved, booleans flipped, arrays grown),
// read over the defaults and written again: the same JSON. A key read into another member than
// the one it is written from, or not read at all, breaks this.
TEST(Config, EveryOptionReadsBackIntoTheMemberItWasWrittenFrom) {
  const ScanConfig initial;
  const Json defaults = scanConfigJson(initial);
  Json changed = defaults;
  int leaves = 0;
  std::function<void(Json&)> change = [&](Json& j) {
    if (j.is_object()) {
      for (auto& [key, value] : j.items()) change(value);
    } else if (j.is_number_integer()) {
      j = j.get<int>() + 1;
      ++leaves;
    } else if (j.is_number()) {
      j = j.get<double>() * 1.5 + 0.25;
      ++leaves;
    } else if (j.is_boolean()) {
      j = !j.get<bool>();
      ++leaves;
    } else if (j.is_array()) {
      j.push_back(0.125);
      ++leaves;
    }
  };
  change(changed);
  EXPECT_GT(leaves, 80);
  ScanConfig c;
  readScanConfig(changed, "changed", &c);
  EXPECT_EQ(scanConfigJson(c), changed);
  // Spot checks on the structs themselves.
  EXPECT_DOUBLE_EQ(c.scan.planner.t_q, defaults["planner"]["t_q"].get<double>() * 1.5 + 0.25);
  EXPECT_EQ(c.multi.ranking.directions, MultiGraspOptions::defaultRankingPlanner().directions + 1);
  EXPECT_EQ(c.multi.grasp.preshapes.size(), GraspOptions{}.preshapes.size() + 1);
  EXPECT_EQ(c.sim.check_hold, !SimOptions{}.check_hold);
  // Choices by name.
  readScanConfig(Json::parse(R"({"hand_mode": "naive", "sim": {"pick_up": "palm"},
                                 "planner": {"ik_solver": "kdl_lma"}, "start": "held"})"),
                 "cfg", &c);
  EXPECT_EQ(c.scan.hand_mode, HandMode::kNaive);
  EXPECT_FALSE(c.sim.pick_up_first_contact);
  EXPECT_EQ(c.scan.planner.ik_solver, IkMethod::kKdlLma);
  EXPECT_EQ(c.start, "held");
}

TEST(Config, ErrorsNameTheKey) {
  EXPECT_EQ(errorOf(R"({"grasp": {"ranking": {"quality": {"pixel_strid": 2}}}})"),
            "cfg.grasp.ranking.quality: unknown option \"pixel_strid\"");
  EXPECT_EQ(errorOf(R"({"planner": {"t_q": "0.01"}})"), "cfg.planner.t_q: expected a number");
  EXPECT_EQ(errorOf(R"({"max_views": 2.5})"), "cfg.max_views: expected an integer");
  EXPECT_EQ(errorOf(R"({"fit_volume": 1})"), "cfg.fit_volume: expected true or false");
  EXPECT_EQ(errorOf(R"({"eval": {"fscore_m": [0.01, "x"]}})"),
            "cfg.eval.fscore_m: expected an array of numbers");
  EXPECT_EQ(errorOf(R"({"hand_mode": "ignore"})"),
            "cfg.hand_mode: must be naive, carve or carve-empty");
  EXPECT_EQ(errorOf(R"({"sim": 3})"), "cfg.sim: expected an object");
  EXPECT_EQ(errorOf("[1]"), "cfg: expected an object");
  EXPECT_EQ(errorOf(R"({"voxel_m": 0.004, "max_views": 3})"), "no error");
  // Values in range are the structs' own validate()'s business, through ScanConfig::validate.
  ScanConfig c;
  readScanConfig(Json::parse(R"({"voxel_m": -1})"), "cfg", &c);
  EXPECT_NE(c.validate().find("voxel_m must be in"), std::string::npos);
}

// docs/config.md is what `inhand config --reference` prints, below its introduction.
TEST(Config, TheReferenceInDocsIsGeneratedFromTheTables) {
  const std::string doc = readTextFile(std::string(INHAND_SOURCE_DIR) + "/docs/config.md");
  const std::string reference = scanConfigReference();
  ASSERT_GE(doc.size(), reference.size());
  EXPECT_EQ(doc.substr(doc.size() - reference.size()), reference)
      << "docs/config.md is stale: regenerate it with inhand config --reference";
  for (const char* key : {"`planner.quality.t_hand_m`", "`grasp.ranking.directions`",
                          "`sim.pick_up`", "`table_top.plane_max_tilt_deg`"})
    EXPECT_NE(reference.find(key), std::string::npos) << key;
}
