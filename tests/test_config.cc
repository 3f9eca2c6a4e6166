// The scan options tables: every key read into the member it is written from, errors that name
// the key, and docs/config.md generated from the same tables.
#include <gtest/gtest.h>

#include <cmath>
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
  EXPECT_EQ(c.validate(), "option voxel_m must be in (0, 0.05) (is -1)");
  // A contact time constant under MuJoCo's floor (twice the step) would be raised silently.
  ScanConfig p;
  readScanConfig(
      Json::parse(R"({"sim": {"physics": {"timestep_s": 0.002, "contact_timeconst_s": 0.003}}})"),
      "cfg", &p);
  EXPECT_NE(p.validate().find("contact_timeconst_s must be at least twice timestep_s"),
            std::string::npos)
      << p.validate();
  p.sim.physics.contact_timeconst_s = 0.004;
  EXPECT_NE(p.validate().find("table_contact_timeconst_s must be at least twice timestep_s"),
            std::string::npos)
      << p.validate();
  p.sim.physics.table_contact_timeconst_s = 0.004;
  EXPECT_EQ(p.validate(), "");
}

TEST(Config, RangesHaveOpenAndClosedEnds) {
  EXPECT_TRUE(Range::closed(0, 1).contains(0));
  EXPECT_TRUE(Range::closed(0, 1).contains(1));
  EXPECT_FALSE(Range::open(0, 1).contains(0));
  EXPECT_FALSE(Range::open(0, 1).contains(1));
  EXPECT_TRUE(Range::closedOpen(0, 1).contains(0));
  EXPECT_FALSE(Range::closedOpen(0, 1).contains(1));
  EXPECT_FALSE(Range::openClosed(0, 1).contains(0));
  EXPECT_FALSE(Range::atLeast(0).contains(-1e-12));
  EXPECT_FALSE(Range::above(0).contains(0));
  EXPECT_FALSE(Range::any().contains(std::nan("")));
  EXPECT_TRUE(Range::any().contains(-1e300));
  EXPECT_EQ(Range::open(0, 90).text(), "in (0, 90)");
  EXPECT_EQ(Range::closedOpen(0, 0.05).text(), "in [0, 0.05)");
  EXPECT_EQ(Range::atLeast(1).text(true), ">= 1");
  EXPECT_EQ(Range::above(0).text(), "> 0");
  EXPECT_EQ(Range::closed(1, 16).text(true), "in 1..16");
  EXPECT_EQ(Range::open(0, 10).text(true), "in 1..9");
}

// A value just outside an end of its range, for that row's type.
double justOutside(const ScanConfigRow& row, bool below) {
  const Range& r = row.range;
  const double end = below ? r.lo : r.hi;
  const bool open = below ? r.lo_open : r.hi_open;
  if (row.type == "integer")
    return below ? std::ceil(end) - (open ? 0 : 1) : std::floor(end) + (open ? 0 : 1);
  if (open) return end;
  const double step = std::max(1e-9, std::abs(end) * 1e-6);
  return below ? end - step : end + step;
}

// validate() of the default options with `row` set to x.
std::string validateWith(const ScanConfigRow& row, double x) {
  Json j = row.type == "numbers"   ? Json::array({x})
           : row.type == "integer" ? Json(int(x))
                                   : Json(x);
  // {"a": {"b": {"c": x}}} from "a.b.c".
  std::string key = row.key;
  for (size_t dot; (dot = key.rfind('.')) != std::string::npos; key = key.substr(0, dot))
    j = Json{{key.substr(dot + 1), j}};
  ScanConfig c;
  readScanConfig(Json{{key, j}}, "cfg", &c);
  return c.validate();
}

// Every option with a range: set just outside either end (all else default), validate() refuses
// it and names that option's key, as a config file spells it; at the end itself (a closed end) it
// is accepted unless a relation to another option forbids it.
TEST(Config, EveryRangedOptionJustOutsideItsRangeIsRefusedByName) {
  int checked = 0;
  for (const ScanConfigRow& row : scanConfigRows()) {
    if (!row.range.bounded()) continue;
    for (bool below : {true, false}) {
      if (!std::isfinite(below ? row.range.lo : row.range.hi)) continue;
      const double x = justOutside(row, below);
      const std::string outside = validateWith(row, x);
      EXPECT_EQ(outside.rfind("option " + row.key + " must be ", 0), 0u)
          << row.key << " = " << x << ": " << outside;
      // The nearest value inside (a closed end itself, the next integer) passes its own row.
      const bool integer = row.type == "integer";
      if (integer || !(below ? row.range.lo_open : row.range.hi_open)) {
        const double inside =
            integer ? x + (below ? 1 : -1) : (below ? row.range.lo : row.range.hi);
        const std::string error = validateWith(row, inside);
        EXPECT_NE(error.rfind("option " + row.key + " must be ", 0), 0u)
            << row.key << " = " << inside << ": " << error;
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 150);
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

// Physics is on by default, and with it the in-hand registration after each pick-up (the
// closing fingers move the object); a config that turns physics off turns it off, unless it sets
// it.
TEST(Config, PhysicsTurnsTheInHandRegistrationOnUnlessTheConfigSetsIt) {
  auto inHand = [](const std::string& json) {
    ScanConfig c;
    readScanConfig(Json::parse(json), "cfg", &c);
    return c.scan.tracking.in_hand;
  };
  const ScanConfig defaults;
  EXPECT_TRUE(defaults.sim.physics.enabled);
  EXPECT_TRUE(defaults.scan.tracking.in_hand);
  EXPECT_FALSE(TrackingOptions().in_hand);  // the library's struct: the kinematic default
  EXPECT_TRUE(inHand("{}"));
  EXPECT_TRUE(inHand(R"({"sim": {"physics": {"enabled": true}}})"));
  EXPECT_FALSE(inHand(R"({"sim": {"physics": {"enabled": false}}})"));
  EXPECT_FALSE(
      inHand(R"({"sim": {"physics": {"enabled": true}}, "tracking": {"in_hand": false}})"));
  EXPECT_TRUE(inHand(R"({"sim": {"physics": {"enabled": false}}, "tracking": {"in_hand": true}})"));
  EXPECT_FALSE(inHand(R"({"tracking": {"in_hand": false}})"));
}

// … and the second look after the lift (an object may slide out of the hand): 0.5 s, unless the
// config sets it; none without physics.
TEST(Config, PhysicsTurnsTheSecondLookAfterTheLiftOnUnlessTheConfigSetsIt) {
  auto settle = [](const std::string& json) {
    ScanConfig c;
    readScanConfig(Json::parse(json), "cfg", &c);
    return c.multi.grasp.settle_s;
  };
  EXPECT_EQ(ScanConfig().multi.grasp.settle_s, GraspOptions::kSettleSeconds);
  EXPECT_EQ(GraspOptions().settle_s, 0.0);
  EXPECT_EQ(settle("{}"), GraspOptions::kSettleSeconds);
  EXPECT_EQ(settle(R"({"sim": {"physics": {"enabled": false}}})"), 0.0);
  EXPECT_EQ(settle(R"({"sim": {"physics": {"enabled": true}}, "grasp": {"settle_s": 0}})"), 0.0);
  EXPECT_EQ(settle(R"({"sim": {"physics": {"enabled": false}}, "grasp": {"settle_s": 1.5}})"), 1.5);
}

// … and the lift's rules (the held object feels the arm's move): straight and in view, unless
// the config sets them.
TEST(Config, PhysicsTurnsTheStraightLiftInViewOnUnlessTheConfigSetsIt) {
  auto lift = [](const std::string& json) {
    ScanConfig c;
    readScanConfig(Json::parse(json), "cfg", &c);
    return std::make_pair(c.multi.grasp.lift_straight, c.multi.grasp.lift_in_view);
  };
  const auto both = [](bool a, bool b) { return std::make_pair(a, b); };
  EXPECT_EQ(lift("{}"), both(true, true));
  EXPECT_EQ(lift(R"({"sim": {"physics": {"enabled": true}}})"), both(true, true));
  EXPECT_EQ(lift(R"({"sim": {"physics": {"enabled": false}}})"), both(false, false));
  EXPECT_EQ(lift(R"({"grasp": {"lift_in_view": false}})"), both(true, false));
  EXPECT_EQ(lift(R"({"sim": {"physics": {"enabled": true}}, "grasp": {"lift_straight": false}})"),
            both(false, true));
  EXPECT_EQ(lift(R"({"sim": {"physics": {"enabled": false}}, "grasp": {"lift_straight": true}})"),
            both(true, false));
}

// Physics set on or off by a command (`inhand scan --physics`, `inhand regrasp-test`): every
// implied option follows it; one the config sets keeps its value.
TEST(Config, PhysicsImpliedOptionsAreSetWhereTheConfigIsSilent) {
  ScanConfig off;
  setPhysics(false, Json(), &off);
  EXPECT_FALSE(off.sim.physics.enabled);
  EXPECT_FALSE(off.scan.tracking.in_hand);
  EXPECT_EQ(off.multi.grasp.settle_s, 0.0);
  EXPECT_FALSE(off.multi.grasp.lift_straight);
  EXPECT_FALSE(off.multi.grasp.lift_in_view);
  ScanConfig on = off;
  setPhysics(true, Json(), &on);
  EXPECT_TRUE(on.sim.physics.enabled);
  EXPECT_TRUE(on.scan.tracking.in_hand);
  EXPECT_EQ(on.multi.grasp.settle_s, GraspOptions::kSettleSeconds);
  EXPECT_TRUE(on.multi.grasp.lift_straight);
  EXPECT_TRUE(on.multi.grasp.lift_in_view);
  const Json j = Json::parse(R"({"tracking": {"in_hand": false}, "grasp": {"settle_s": 0}})");
  ScanConfig some;
  readScanConfig(j, "cfg", &some);
  setPhysics(true, j, &some);
  EXPECT_FALSE(some.scan.tracking.in_hand);
  EXPECT_EQ(some.multi.grasp.settle_s, 0.0);
  EXPECT_TRUE(some.multi.grasp.lift_straight);
  EXPECT_TRUE(some.multi.grasp.lift_in_view);
}
