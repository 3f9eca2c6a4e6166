#pragma once
// The HTML reports: one self-contained file that opens offline in any browser. The front-end
// libraries (three.js for the 3-D viewer, Chart.js for the curves) come from npm (web/,
// installed by scripts/install_deps.sh) and are inlined when the report is written; the page's
// own code is web/report.js and web/index.js.
#include <filesystem>
#include <string>

namespace inhand {

// Where the web assets are: $INHAND_WEB_DIR when set, else share/inhand/web beside an installed
// executable, else the source tree's web/. Throws Error
// (saying how to install them) when the npm packages are missing.
std::filesystem::path webDirectory();

// DIR/report.html from a scan's files in DIR: summary.json, model.ply, and where present
// truth.ply and grasps/ (grasp_K_model.ply, grasp_K_hand.ply, grasp_K_candidate_J.ply).
// Written atomically; throws Error naming a missing or malformed file.
void writeScanReport(const std::filesystem::path& scan_dir, const std::filesystem::path& web_dir);

// DIR/index.html from an eval's files: results.md, curves.json (links to each run's report).
void writeEvalIndex(const std::filesystem::path& eval_dir, const std::filesystem::path& web_dir);

}  // namespace inhand
