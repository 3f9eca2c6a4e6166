#include "inhand/scan/checkpoint.h"

#include <fstream>
#include <limits>

#include "inhand/core/error.h"
#include "inhand/scan/records.h"

namespace inhand {

namespace {

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

// The table-top anchor: its depths (floats round-trip exactly) and its hidden pixels as run
// lengths, alternating from a run of pixels not hidden.
Json anchorJson(const TableAnchor& a) {
  Json runs = Json::array();
  uint8_t state = 0;
  size_t run = 0;
  for (uint8_t h : a.hidden) {
    if (uint8_t(h != 0) != state) {
      runs.push_back(run);
      state ^= 1;
      run = 0;
    }
    ++run;
  }
  runs.push_back(run);
  return {{"width", a.depth.width}, {"height", a.depth.height},  {"depth_m", a.depth.depth_m},
          {"hidden_runs", runs},    {"T_B_C", isoJson(a.T_B_C)}, {"T_B_O", isoJson(a.T_B_O)}};
}
TableAnchor anchorFrom(const Json& j) {
  TableAnchor a;
  a.depth.width = j.at("width").get<int>();
  a.depth.height = j.at("height").get<int>();
  a.depth.depth_m = j.at("depth_m").get<std::vector<float>>();
  const size_t n = a.depth.depth_m.size();
  if (a.depth.width <= 0 || a.depth.height <= 0 || n != size_t(a.depth.width) * a.depth.height)
    throw Error("table anchor: depth size differs from width × height");
  uint8_t state = 0;
  for (const Json& r : j.at("hidden_runs")) {
    const size_t run = r.get<size_t>();
    if (run > n - a.hidden.size()) throw Error("table anchor: hidden runs exceed the image");
    a.hidden.insert(a.hidden.end(), run, state);
    state ^= 1;
  }
  if (a.hidden.size() != n) throw Error("table anchor: hidden runs fall short of the image");
  a.T_B_C = isoFrom(j.at("T_B_C"));
  a.T_B_O = isoFrom(j.at("T_B_O"));
  return a;
}

// A grasp's record and its model.
Json graspJson(const GraspRecord& g) {
  Json j = graspRecordJson(g);
  j["model"] = modelJson(g.model);
  return j;
}
GraspRecord graspFrom(const Json& j) {
  GraspRecord g = graspRecordFrom(j);
  g.model = modelFrom(j.at("model"));
  return g;
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
  if (c.sofar->table_top) scan["table_top"] = tableTopRecordJson(*c.sofar->table_top);
  if (c.anchor) scan["table_anchor"] = anchorJson(*c.anchor);
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
    if (scan.contains("table_top")) out.sofar.table_top = tableTopRecordFrom(scan["table_top"]);
    if (scan.contains("table_anchor")) out.anchor = anchorFrom(scan["table_anchor"]);
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
