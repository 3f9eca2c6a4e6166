#include "inhand/scan/checkpoint.h"

#include <fstream>
#include <limits>

#include "inhand/core/error.h"

namespace inhand {

namespace {

Json jointsJson(const JointVector& q) {
  Json j = Json::array();
  for (int i = 0; i < q.size(); ++i) j.push_back(q[i]);
  return j;
}
JointVector jointsFrom(const Json& j) {
  JointVector q = JointVector::Zero(Eigen::Index(j.size()));
  for (size_t i = 0; i < j.size(); ++i) q[Eigen::Index(i)] = j.at(i).get<double>();
  return q;
}

// A model as flat arrays (floats round-trip exactly through JSON's shortest representation).
Json modelJson(const ObjectModel& m) {
  Json v = Json::array(), t = Json::array();
  for (const auto& p : m.mesh.vertices) {
    v.push_back(p.x());
    v.push_back(p.y());
    v.push_back(p.z());
  }
  for (const auto& f : m.mesh.triangles) {
    t.push_back(f[0]);
    t.push_back(f[1]);
    t.push_back(f[2]);
  }
  return {{"vertices", v}, {"triangles", t}, {"variance", m.variance}, {"observed", m.observed}};
}
ObjectModel modelFrom(const Json& j) {
  ObjectModel m;
  const Json& v = j.at("vertices");
  const Json& t = j.at("triangles");
  if (v.size() % 3 || t.size() % 3) throw Error("model arrays are not triples");
  const size_t n = v.size() / 3;
  m.mesh.vertices.resize(n);
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) m.mesh.vertices[i][k] = v.at(3 * i + k).get<float>();
  m.mesh.triangles.resize(t.size() / 3);
  for (size_t i = 0; i < m.mesh.triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const int idx = t.at(3 * i + k).get<int>();
      if (idx < 0 || size_t(idx) >= n) throw Error("model triangle index out of range");
      m.mesh.triangles[i][k] = idx;
    }
  m.variance = j.at("variance").get<std::vector<float>>();
  m.observed = j.at("observed").get<std::vector<uint8_t>>();
  if (m.variance.size() != n || m.observed.size() != n)
    throw Error("model variance/observed sizes differ from its vertices");
  return m;
}

Json graspJson(const GraspRecord& g) {
  Json ranked = Json::array();
  for (const RankedGrasp& r : g.ranked)
    ranked.push_back({{"T_O_palm", isoJson(r.T_O_palm)},
                      {"q", jointsJson(r.q)},
                      {"quality", r.quality},
                      {"epsilon", r.epsilon}});
  return {{"T_O_palm", isoJson(g.T_O_palm)},
          {"q", jointsJson(g.q)},
          {"candidates", g.candidates},
          {"tried", g.tried},
          {"quality", g.quality},
          {"t_q", g.t_q},
          {"model_area_m2", g.model_area_m2},
          {"epsilon", std::isfinite(g.epsilon) ? Json(g.epsilon) : Json()},
          {"views", g.views},
          {"termination", terminationName(g.termination)},
          {"hole_area_m2", g.hole_area_m2},
          {"mean_entropy", g.mean_entropy},
          {"generation_s", g.generation_s},
          {"ranking_s", g.ranking_s},
          {"ranked", ranked},
          {"attempts", attemptsJson(g.attempts)},
          {"model", modelJson(g.model)}};
}
GraspRecord graspFrom(const Json& j) {
  GraspRecord g;
  g.T_O_palm = isoFrom(j.at("T_O_palm"));
  g.q = jointsFrom(j.at("q"));
  g.candidates = j.at("candidates").get<int>();
  g.tried = j.at("tried").get<int>();
  g.quality = j.at("quality").get<double>();
  g.t_q = j.value("t_q", 0.0);
  g.model_area_m2 = j.value("model_area_m2", 0.0);
  g.epsilon = j.at("epsilon").is_null() ? std::numeric_limits<double>::quiet_NaN()
                                        : j.at("epsilon").get<double>();
  g.views = j.at("views").get<int>();
  if (!parseTermination(j.at("termination").get<std::string>(), &g.termination))
    throw Error("unknown termination " + j.at("termination").get<std::string>());
  g.hole_area_m2 = j.at("hole_area_m2").get<double>();
  g.mean_entropy = j.at("mean_entropy").get<double>();
  g.generation_s = j.at("generation_s").get<double>();
  g.ranking_s = j.at("ranking_s").get<double>();
  for (const Json& r : j.at("ranked"))
    g.ranked.push_back({isoFrom(r.at("T_O_palm")), jointsFrom(r.at("q")),
                        r.at("quality").get<double>(), r.at("epsilon").get<double>()});
  g.attempts = attemptsFrom(j.at("attempts"));
  g.model = modelFrom(j.at("model"));
  return g;
}

Json tableTopJson(const TableTopRecord& t) {
  Json poses = Json::array();
  for (const GraspPoseRecord& p : t.poses)
    poses.push_back({{"approach_O", vecJson(p.approach_O)},
                     {"roll_rad", p.roll_rad},
                     {"spread", p.spread},
                     {"preshape", p.preshape},
                     {"edge", p.edge},
                     {"pinch", p.pinch},
                     {"two_finger", p.two_finger},
                     {"epsilon", p.epsilon},
                     {"result", p.result}});
  Json axes = Json::array();
  for (int k = 0; k < 3; ++k) axes.push_back(vecJson(t.axes.axes.col(k)));
  return {{"frames", t.frames},
          {"points", t.points},
          {"table_inliers", t.table_inliers},
          {"object_points", t.object_points},
          {"table_n", vecJson(t.table_O.n)},
          {"table_d", t.table_O.d},
          {"centroid", vecJson(t.axes.centroid)},
          {"axes", axes},
          {"variances", vecJson(t.axes.variances)},
          {"min", vecJson(t.axes.min)},
          {"max", vecJson(t.axes.max)},
          {"tried", t.tried},
          {"touching", t.touching},
          {"stable", t.stable},
          {"table_free", t.table_free},
          {"reachable", t.reachable},
          {"poses", poses},
          {"volume_size_m", t.volume_size_m},
          {"voxel_m", t.voxel_m},
          {"attempts", attemptsJson(t.attempts)},
          {"seconds", t.seconds}};
}
TableTopRecord tableTopFrom(const Json& j) {
  TableTopRecord t;
  t.frames = j.at("frames").get<int>();
  t.points = j.at("points").get<int>();
  t.table_inliers = j.at("table_inliers").get<int>();
  t.object_points = j.at("object_points").get<int>();
  t.table_O.n = vecFrom(j.at("table_n"));
  t.table_O.d = j.at("table_d").get<double>();
  t.axes.centroid = vecFrom(j.at("centroid"));
  for (int k = 0; k < 3; ++k) t.axes.axes.col(k) = vecFrom(j.at("axes").at(k));
  t.axes.variances = vecFrom(j.at("variances"));
  t.axes.min = vecFrom(j.at("min"));
  t.axes.max = vecFrom(j.at("max"));
  t.tried = j.at("tried").get<int>();
  t.touching = j.at("touching").get<int>();
  t.stable = j.at("stable").get<int>();
  t.table_free = j.at("table_free").get<int>();
  t.reachable = j.at("reachable").get<int>();
  for (const Json& p : j.at("poses")) {
    GraspPoseRecord r;
    r.approach_O = vecFrom(p.at("approach_O"));
    r.roll_rad = p.at("roll_rad").get<double>();
    r.spread = p.at("spread").get<double>();
    r.preshape = p.at("preshape").get<double>();
    r.edge = p.at("edge").get<bool>();
    r.pinch = p.value("pinch", false);  // (checkpoints written before pinch poses)
    r.two_finger = p.value("two_finger", false);
    r.epsilon = p.at("epsilon").get<double>();
    r.result = p.at("result").get<std::string>();
    t.poses.push_back(r);
  }
  t.volume_size_m = j.at("volume_size_m").get<double>();
  t.voxel_m = j.at("voxel_m").get<double>();
  t.attempts = attemptsFrom(j.at("attempts"));
  t.seconds = j.at("seconds").get<double>();
  return t;
}

// The scan's state in a checkpoint's header (the session's "extra"), without the volume.
Json readScanState(const std::filesystem::path& path) {
  auto bad = [&](const std::string& what) {
    return Error(path.string() + ": not a scan checkpoint (" + what + ")");
  };
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(path.string() + ": cannot open the checkpoint");
  std::string magic;
  size_t bytes = 0;
  if (!std::getline(f, magic) || magic != "INHAND-SESSION 1" || !(f >> bytes) || f.get() != '\n' ||
      bytes > (64u << 20))
    throw bad("no INHAND-SESSION 1 header");
  std::string text(bytes, '\0');
  if (!f.read(text.data(), std::streamsize(bytes))) throw bad("header cut short");
  try {
    Json state = Json::parse(text).at("extra");
    if (!state.is_object() || !state.contains("version")) throw bad("no scan state");
    return state;
  } catch (const Json::exception& e) {
    throw bad(e.what());
  }
}

}  // namespace

Json readScanCheckpointExtra(const std::filesystem::path& path) {
  return readScanState(path).value("extra", Json());
}

void saveScanCheckpoint(const std::filesystem::path& path, const ScanCheckpoint& c,
                        const Json& extra) {
  if (!c.session || !c.sofar || !c.current)
    throw Error(path.string() + ": incomplete scan checkpoint (no session, result or grasp)");
  Json grasps = Json::array();
  for (const GraspRecord& g : c.sofar->grasps) grasps.push_back(graspJson(g));
  Json scan = {{"version", 1},
               {"grasp", c.grasp},
               {"current", graspJson(*c.current)},
               {"grasps", grasps},
               {"T_B_O_rest", isoJson(c.T_B_O_rest)},
               {"total_s", c.sofar->scan.total_s},
               {"volume_size_m", c.session->options().volume_size_m},
               {"voxel_m", c.session->options().voxel_m},
               {"extra", extra}};
  if (!c.object_box_O.empty())
    scan["object_box_O"] = {vecJson(c.object_box_O.min), vecJson(c.object_box_O.max)};
  if (c.sofar->table_top) scan["table_top"] = tableTopJson(*c.sofar->table_top);
  c.session->save(path, scan);
}

LoadedCheckpoint loadScanCheckpoint(const std::filesystem::path& path, const RobotModel& robot,
                                    const DepthCameraOptions& camera,
                                    const NoiseModelOptions& noise, const ScanOptions& options,
                                    const MultiGraspOptions& multi) {
  // The volume's size and voxel come from the file (the table-top stage fits them).
  auto bad = [&](const std::string& what) {
    return Error(path.string() + ": not a scan checkpoint (" + what + ")");
  };
  ScanOptions fitted = options;
  try {
    const Json header = readScanState(path);
    fitted.volume_size_m = header.at("volume_size_m").get<double>();
    fitted.voxel_m = header.at("voxel_m").get<double>();
  } catch (const Json::exception& e) {
    throw bad(e.what());
  }
  LoadedCheckpoint out;
  Json scan;
  out.session = std::make_unique<ScanSession>(
      ScanSession::load(path, robot, camera, noise, fitted, multi, &scan));
  try {
    if (scan.at("version").get<int>() != 1) throw bad("unknown version");
    out.grasp = scan.at("grasp").get<int>();
    out.current = graspFrom(scan.at("current"));
    for (const Json& g : scan.at("grasps")) out.sofar.grasps.push_back(graspFrom(g));
    out.T_B_O_rest = isoFrom(scan.at("T_B_O_rest"));
    out.sofar.scan.total_s = scan.at("total_s").get<double>();
    if (scan.contains("object_box_O")) {
      out.object_box_O.extend(vecFrom(scan["object_box_O"].at(0)));
      out.object_box_O.extend(vecFrom(scan["object_box_O"].at(1)));
    }
    if (scan.contains("table_top")) out.sofar.table_top = tableTopFrom(scan["table_top"]);
    out.extra = scan.at("extra");
  } catch (const Json::exception& e) {
    throw bad(e.what());
  } catch (const Error& e) {
    throw bad(e.what());
  }
  if (out.grasp != int(out.sofar.grasps.size()) || out.grasp != out.session->graspIndex())
    throw bad("the grasp under way (" + std::to_string(out.grasp) + ") disagrees with the " +
              "grasps recorded (" + std::to_string(out.sofar.grasps.size()) + ")");
  return out;
}

}  // namespace inhand
