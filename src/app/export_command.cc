// `inhand export`: a scanned model as an asset for simulators and planners (docs/asset.md).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "commands.h"
#include "inhand/asset/asset.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/grasp/grasp.h"
#include "inhand/grasp/hold_test.h"

namespace inhand::app {

namespace {

// The grasps a scan tried (summary.json), each with what became of it: held (it was lifted and
// the scan went on with it), lost_in_hand (lifted, then lost during the scan), dropped (it fell in
// the lift), slid (it moved in the hand while the hand held still after the lift), empty_hand (the
// fingers closed on nothing), no_contact (the hand met nothing).
// Attempts recorded without their pose (older scans) are left out.
Json triedGrasps(const Json& summary, const std::string& where) {
  Json out = Json::array();
  auto add = [&](const Json& attempts, const std::string& stage, bool lost) {
    if (!attempts.is_array()) throw Error(where + ": pick_up_attempts is not a list");
    for (const Json& a : attempts) {
      if (!a.is_object() || !a.contains("T_O_palm")) continue;
      std::string outcome = a.value("outcome", "");
      if (outcome == "picked") outcome = lost ? "lost_in_hand" : "held";
      out.push_back({{"source", "tried"},
                     {"stage", stage},
                     {"outcome", outcome},
                     {"T_O_palm", a.at("T_O_palm")},
                     {"preshape", a.at("preshape")},
                     {"closed", a.at("closed")},
                     {"kind", a.value("kind", "")},
                     {"epsilon", a.value("epsilon", 0.0)}});
    }
  };
  const Json grasps = summary.value("grasps", Json::array());
  for (size_t i = 0; i < grasps.size(); ++i)
    add(grasps[i].value("pick_up_attempts", Json::array()), "grasp " + std::to_string(i + 1),
        grasps[i].value("termination", "") == "object_lost");
  add(summary.value("failed_regrasp_attempts", Json::array()), "failed re-grasp", false);
  return out;
}

// Candidates on the finished model, chosen as the scan chooses them, in each of its most probable
// stable poses (those of probability 5 % or more, at most 4, the most probable first): the model
// resting in that pose on the robot's table under the presentation point, candidates generated
// there (generateGrasps) and closed, lifted and turned on the model in physics at the asset's mass
// (the hold test); those that held, in the hold test's order (those that held with its margin
// first), at most `max` per pose, none within 5 mm and 5° of one taken before. In O, like the
// tried ones.
Json rankedGrasps(const ObjectAsset& asset, const RobotModel& robot, int max, std::string* line) {
  Json out = Json::array();
  const std::vector<StablePose> poses = stablePoses(asset.model_O);
  if (max <= 0 || poses.empty()) return out;
  GraspOptions go;
  go.hold.density_kg_m3 = asset.density_kg_m3;
  go.hold.max_candidates = 16;  // more than a scan tests: the set offers several that held
  std::vector<Vec3> footprint;
  for (const Vec3f& v : asset.model_O.vertices) footprint.push_back(v.cast<double>());
  auto hand = [&](const JointVector& q) {
    Json j = Json::object();
    for (const auto& [name, value] : robot.handJointValues(q)) j[name] = value;
    return j;
  };
  std::vector<Iso3> taken;
  for (size_t k = 0; k < poses.size() && k < 4; ++k) {
    if (k > 0 && poses[k].probability < 0.05) break;
    Iso3 T_B_O = Iso3::Identity();
    T_B_O.linear() = poses[k].R_B_O;
    Aabb b;
    for (const Vec3f& v : asset.model_O.vertices) b.extend(poses[k].R_B_O * v.cast<double>());
    const Vec3 at = robot.camera().lookAt_B;
    T_B_O.translation() =
        Vec3(at.x() - b.center().x(), at.y() - b.center().y(), robot.table().topZ() - b.min.z());
    GraspGeneration gen = generateGrasps(robot, asset.model_O, T_B_O, robot.home(), go, &footprint);
    const double seconds =
        rankByHold(robot, asset.model_O, T_B_O, nullptr, go.friction, go.hold, &gen.candidates);
    *line += (line->empty() ? "" : "; ") + std::string("rest pose ") + std::to_string(k) + ": " +
             holdLine(gen.candidates, seconds);
    int added = 0;
    for (const GraspCandidate& c : gen.candidates) {
      if (c.hold != 1 || added >= max) continue;
      const bool near = std::any_of(taken.begin(), taken.end(), [&](const Iso3& T) {
        return (T.translation() - c.T_O_palm.translation()).norm() < 0.005 &&
               rotationBetween(T, c.T_O_palm) < 5 * M_PI / 180;
      });
      if (near) continue;
      taken.push_back(c.T_O_palm);
      ++added;
      out.push_back({{"source", "ranked"},
                     {"stage", "hold test on the model, rest pose " + std::to_string(k)},
                     {"outcome", c.hold_margin == 1 ? "held_with_margin" : "held"},
                     {"T_O_palm", isoJson(c.T_O_palm)},
                     {"preshape", hand(c.q_open)},
                     {"closed", hand(c.q)},
                     {"kind", c.palm_contact ? "enveloping" : "fingertips"},
                     {"epsilon", c.epsilon}});
    }
  }
  return out;
}

}  // namespace

std::vector<AssetFormat> parseAssetFormats(const std::string& list) {
  std::vector<AssetFormat> out;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t comma = std::min(list.find(',', start), list.size());
    const std::string name = list.substr(start, comma - start);
    const auto f = assetFormatFromName(name);
    if (!f) throw Error("--format: '" + name + "' is not one of mjcf, urdf, sdf");
    if (std::find(out.begin(), out.end(), *f) == out.end()) out.push_back(*f);
    start = comma + 1;
  }
  return out;
}

void exportAsset(const fs::path& in, const fs::path& out, const std::vector<AssetFormat>& formats,
                 AssetOptions options, const RobotModel* robot, int ranked,
                 const std::string& shown_out) {
  if (std::string p = options.validate(); !p.empty()) throw Error("export: " + p);
  std::string massFrom = options.mass_kg > 0 ? "given" : "density";
  std::error_code ec;
  fs::path model = in;
  Json grasps = Json::array();
  if (fs::is_directory(in, ec)) {
    model = in / "model.ply";
    if (!fs::exists(model, ec))
      throw Error(in.string() + ": no model.ply (not a scan's output directory?)");
    if (fs::exists(in / "summary.json", ec)) {
      const Json summary = readJsonFile(in / "summary.json");
      grasps = triedGrasps(summary, (in / "summary.json").string());
      // The weight the arm measured, unless a mass was given: when three readings or more
      // determine it to 10 % (lighter objects' weight is lost in the torques' noise).
      const Json payload = summary.value("payload", Json());
      if (options.mass_kg == 0 && payload.is_object()) {
        const double m = payload.value("mass_kg", 0.0), s = payload.value("sigma_kg", 0.0);
        if (payload.value("readings", 0) >= 3 && m > 0 && s < 0.1 * m) {
          options.mass_kg = m;
          massFrom = "weighed by the arm, ±" + std::to_string(int(std::lround(1000 * s))) + " g";
        }
      }
    }
  }
  // The model as written: the closed (hole-filled) surface, its triangles kept as they are.
  TriangleMesh mesh = model.extension() == ".ply" ? readPly(model).mesh : importMesh(model);
  ObjectAsset asset = makeAsset(mesh, options);
  asset.grasps = std::move(grasps);
  std::string holdSummary;
  if (robot && ranked > 0)
    for (Json& g : rankedGrasps(asset, *robot, ranked, &holdSummary))
      asset.grasps.push_back(std::move(g));
  if (!holdSummary.empty()) std::printf("export: %s\n", holdSummary.c_str());
  std::optional<fs::path> ply;
  if (model.extension() == ".ply") ply = model;
  writeAsset(asset, out, formats, ply);
  int held = 0;
  for (const Json& g : asset.grasps)
    held += g.value("source", "") == "tried" && g.value("outcome", "") == "held";
  std::printf(
      "export: %.1f cm³, %.3f kg (%s; %.0f kg/m³), centre of mass %.1f %.1f %.1f mm; %zu convex "
      "pieces (+%.1f %% volume); visual %zu triangles; %zu grasps (%d tried and held) -> %s\n",
      1e6 * asset.volume_m3, asset.mass_kg, massFrom.c_str(), asset.density_kg_m3,
      1000 * asset.com_O.x(), 1000 * asset.com_O.y(), 1000 * asset.com_O.z(), asset.pieces.size(),
      100 * (asset.pieces_volume_m3 / asset.volume_m3 - 1), asset.visual_O.triangles.size(),
      asset.grasps.size(), held, shown_out.empty() ? out.string().c_str() : shown_out.c_str());
}

int runExport(const ExportArgs& args) {
  AssetOptions options;
  options.name = args.name;
  options.density_kg_m3 = args.density_kg_m3;
  options.mass_kg = args.mass_kg;
  const std::vector<AssetFormat> formats = parseAssetFormats(args.formats);
  if (args.ranked < 0 || args.ranked > 100) throw Error("--ranked must be in 0..100");
  std::optional<RobotModel> robot;
  if (args.ranked > 0)
    robot = RobotModel::load(args.robot.empty() ? defaultRobotConfig() : args.robot);
  exportAsset(args.input, args.out, formats, options, robot ? &*robot : nullptr, args.ranked);
  return 0;
}

}  // namespace inhand::app
