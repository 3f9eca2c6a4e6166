#pragma once
// Every option of a scan, from the rows each options struct lists beside its defaults (its static
// fields(): key, meaning, range; core/options.h): the same rows read JSON (config files, Python
// dicts; unknown keys and values of the wrong type are rejected, naming the key), write it
// (summary.json "options"), check the values' ranges (validate()) and generate the reference in
// docs/config.md (`inhand config --reference`).
#include <string>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/eval/metrics.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/sim/sim_world.h"

namespace inhand {

struct ScanConfig {
  // Physics on (sim.physics.enabled) with what it implies (setPhysics).
  ScanConfig();
  std::string robot;            // robot config JSON; empty: the WAM with BarrettHand in data/
  std::string start = "table";  // table: the whole scan from the table top; held: given grasp
  ScanOptions scan;
  MultiGraspOptions multi;
  SimOptions sim;
  EvalOptions eval;
  // Every option's range, then every struct's validate(); empty when valid. An option out of its
  // range is named by its key ("option planner.t_q must be >= 0 (is -1)").
  std::string validate() const;
};

// One option: its dotted key as in a config file, its type and range.
struct ScanConfigRow {
  std::string key;
  std::string type;  // number, integer, true/false, numbers, string, choice
  Range range;       // of the value (of each, for numbers)
};

// Reads the keys present in `j` over `config` (the others keep their values). `where` names the
// source in errors ("FILE.planner.t_q: expected a number"). Throws Error. A `j` that sets
// sim.physics.enabled also sets what that implies (setPhysics).
void readScanConfig(const Json& j, const std::string& where, ScanConfig* config);
// Physics on or off, with the options that follow from it unless the config `j` (an object, or
// null: none) sets them. With physics on, what a hand that moves the object needs:
// tracking.in_hand, grasp.settle_s (GraspOptions::kSettleSeconds), grasp.lift_straight and
// grasp.lift_in_view, each on. With physics off (the kinematic simulator: the object moves rigidly
// with the hand) each keeps the default of its own struct (off, 0).
void setPhysics(bool on, const Json& j, ScanConfig* config);
// The same from a JSON file (the error names the file).
void readScanConfigFile(const std::filesystem::path& file, ScanConfig* config);
// Every option with its value.
Json scanConfigJson(const ScanConfig& config);
// The reference (Markdown): every key, its type, default and meaning.
std::string scanConfigReference();
// Every option, in the reference's order.
std::vector<ScanConfigRow> scanConfigRows();

}  // namespace inhand
