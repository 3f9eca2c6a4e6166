#pragma once
// Every option of a scan, from one table per options struct (scan_config.cc): the same table reads
// JSON (config files, Python dicts; unknown keys and values of the wrong type are rejected,
// naming the key), writes it (summary.json "options") and generates the reference in
// docs/config.md (`inhand config --reference`).
#include <string>

#include "inhand/core/json_util.h"
#include "inhand/eval/metrics.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/sim/sim_world.h"

namespace inhand {

struct ScanConfig {
  std::string robot;            // robot config JSON; empty: the WAM with BarrettHand in data/
  std::string start = "table";  // table: the whole scan from the table top; held: given grasp
  ScanOptions scan;
  MultiGraspOptions multi;
  SimOptions sim;
  EvalOptions eval;
  std::string validate() const;  // every struct's validate(); empty when valid
};

// Reads the keys present in `j` over `config` (the others keep their values). `where` names the
// source in errors ("FILE.planner.t_q: expected a number"). Throws Error.
void readScanConfig(const Json& j, const std::string& where, ScanConfig* config);
// The same from a JSON file (the error names the file).
void readScanConfigFile(const std::filesystem::path& file, ScanConfig* config);
// Every option with its value.
Json scanConfigJson(const ScanConfig& config);
// The reference (Markdown): every key, its type, default and meaning.
std::string scanConfigReference();

}  // namespace inhand
