#include "inhand/report/html_report.h"

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/json_util.h"
#include "inhand/geometry/mesh_io.h"

namespace inhand {

namespace fs = std::filesystem;

namespace {

std::string readText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw Error(p.string() + ": cannot read");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string base64(const void* data, size_t n) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const auto* b = static_cast<const unsigned char*>(data);
  std::string out((n + 2) / 3 * 4, '=');
  char* o = out.data();
  size_t i = 0;
  for (; i + 2 < n; i += 3, o += 4) {
    const uint32_t v = (uint32_t(b[i]) << 16) | (uint32_t(b[i + 1]) << 8) | b[i + 2];
    o[0] = k[(v >> 18) & 63];
    o[1] = k[(v >> 12) & 63];
    o[2] = k[(v >> 6) & 63];
    o[3] = k[v & 63];
  }
  if (i < n) {  // one or two bytes left: the rest of the four characters stay '='
    uint32_t v = uint32_t(b[i]) << 16;
    if (i + 1 < n) v |= uint32_t(b[i + 1]) << 8;
    o[0] = k[(v >> 18) & 63];
    o[1] = k[(v >> 12) & 63];
    if (i + 1 < n) o[2] = k[(v >> 6) & 63];
  }
  return out;
}

// A mesh as base64 little-endian arrays: float32 positions, uint32 indices, and uint8 RGB
// colours when the PLY has them (and the confidence colours of a model scanned with colour).
Json meshJson(const fs::path& ply) {
  const PlyData d = readPly(ply);
  std::vector<float> pos;
  pos.reserve(d.mesh.vertices.size() * 3);
  for (const Vec3f& v : d.mesh.vertices) pos.insert(pos.end(), {v.x(), v.y(), v.z()});
  std::vector<uint32_t> idx;
  idx.reserve(d.mesh.triangles.size() * 3);
  for (const Tri& t : d.mesh.triangles)
    idx.insert(idx.end(), {uint32_t(t[0]), uint32_t(t[1]), uint32_t(t[2])});
  Json j = {{"positions", base64(pos.data(), pos.size() * 4)},
            {"indices", base64(idx.data(), idx.size() * 4)},
            {"vertices", d.mesh.vertices.size()},
            {"triangles", d.mesh.triangles.size()}};
  auto r = d.vertexProperties.find("red"), g = d.vertexProperties.find("green"),
       b = d.vertexProperties.find("blue");
  if (r != d.vertexProperties.end() && g != d.vertexProperties.end() &&
      b != d.vertexProperties.end()) {
    std::vector<uint8_t> rgb(d.mesh.vertices.size() * 3);
    for (size_t i = 0; i < d.mesh.vertices.size(); ++i) {
      rgb[3 * i] = uint8_t(r->second[i]);
      rgb[3 * i + 1] = uint8_t(g->second[i]);
      rgb[3 * i + 2] = uint8_t(b->second[i]);
    }
    j["colors"] = base64(rgb.data(), rgb.size());
  }
  // A model scanned with colour (alpha): its confidence colours too, for the report's switch.
  auto a = d.vertexProperties.find("alpha"), var = d.vertexProperties.find("variance");
  if (a != d.vertexProperties.end() && var != d.vertexProperties.end()) {
    std::vector<uint8_t> rgb(d.mesh.vertices.size() * 3);
    for (size_t i = 0; i < d.mesh.vertices.size(); ++i) {
      const auto c = confidenceColor(var->second[i]);
      std::copy(c.begin(), c.end(), &rgb[3 * i]);
    }
    j["confidence_colors"] = base64(rgb.data(), rgb.size());
  }
  return j;
}

void replaceOnce(std::string* s, const std::string& key, const std::string& value) {
  const size_t at = s->find(key);
  if (at == std::string::npos) throw Error("report template lacks " + key);
  s->replace(at, key.size(), value);
}

// Inside <script>, "</" must not appear (it could close the element).
std::string scriptSafe(std::string s) {
  for (size_t at = s.find("</"); at != std::string::npos; at = s.find("</", at + 3))
    s.replace(at, 2, "<\\/");
  return s;
}

std::string dataUrl(const std::string& js) {
  return "data:text/javascript;base64," + base64(js.data(), js.size());
}

// The page: template, libraries, data and app code put together.
std::string buildPage(const fs::path& web, const std::string& title, const Json& data,
                      const std::string& appFile) {
  std::string page = readText(web / "template.html");
  const fs::path nm = web / "node_modules";
  std::string core = readText(nm / "three/build/three.core.min.js");
  std::string three = readText(nm / "three/build/three.module.min.js");
  // three.module imports its core by a relative path, which a data: URL cannot resolve: point it
  // at a bare specifier the import map resolves.
  for (size_t at = three.find("\"./three.core.min.js\""); at != std::string::npos;
       at = three.find("\"./three.core.min.js\"", at))
    three.replace(at, 21, "\"three/core\"");
  const std::string orbit = readText(nm / "three/examples/jsm/controls/OrbitControls.js");
  // The glTF loader imports a helper by a relative path: a bare specifier here too.
  std::string gltf = readText(nm / "three/examples/jsm/loaders/GLTFLoader.js");
  replaceOnce(&gltf, "'../utils/BufferGeometryUtils.js'", "'three/addons/BufferGeometryUtils.js'");
  const std::string utils = readText(nm / "three/examples/jsm/utils/BufferGeometryUtils.js");
  const Json importMap = {{"imports",
                           {{"three", dataUrl(three)},
                            {"three/core", dataUrl(core)},
                            {"three/addons/OrbitControls.js", dataUrl(orbit)},
                            {"three/addons/GLTFLoader.js", dataUrl(gltf)},
                            {"three/addons/BufferGeometryUtils.js", dataUrl(utils)}}}};
  replaceOnce(&page, "{{TITLE}}", title);
  replaceOnce(&page, "/*{{IMPORTMAP}}*/", importMap.dump());
  replaceOnce(&page, "/*{{CHARTJS}}*/",
              scriptSafe(readText(nm / "chart.js/dist/chart.umd.min.js")));
  replaceOnce(&page, "/*{{DATA}}*/", scriptSafe(data.dump()));
  replaceOnce(&page, "/*{{APP}}*/", scriptSafe(readText(web / appFile)));
  return page;
}

}  // namespace

fs::path webDirectory() {
  fs::path dir = resourceDirectory("web", INHAND_WEB_DIR);
  if (const char* env = std::getenv("INHAND_WEB_DIR"); env && *env) dir = env;
  for (const char* f : {"node_modules/three/build/three.module.min.js",
                        "node_modules/three/examples/jsm/loaders/GLTFLoader.js",
                        "node_modules/chart.js/dist/chart.umd.min.js", "template.html"})
    if (!fs::exists(dir / f))
      throw Error("report: " + (dir / f).string() +
                  " is missing; install the report libraries with scripts/install_deps.sh "
                  "(npm ci in web/) or point INHAND_WEB_DIR at such a folder");
  return dir;
}

void writeScanReport(const fs::path& dir, const fs::path& web) {
  const fs::path summaryFile = dir / "summary.json";
  if (!fs::exists(summaryFile)) throw Error(summaryFile.string() + ": not found (not a scan?)");
  const Json summary = readJsonFile(summaryFile);
  if (!summary.is_object() || !summary.contains("views") || !summary.contains("grasps"))
    throw Error(summaryFile.string() + ": not an inhand scan summary (no views or grasps)");
  // The PLYs the report shows, read and encoded on both cores.
  const fs::path gd = dir / "grasps";
  std::vector<fs::path> plys = {dir / "model.ply"};
  const bool truth = fs::exists(dir / "truth.ply");
  if (truth) plys.push_back(dir / "truth.ply");
  struct GraspPlys {
    int model = -1, hand = -1;
    std::vector<int> candidates;
  };
  std::vector<GraspPlys> graspPlys(summary["grasps"].size());
  for (size_t g = 0; g < graspPlys.size(); ++g) {
    const std::string k = std::to_string(g + 1);
    auto add = [&](const fs::path& f) {
      plys.push_back(f);
      return int(plys.size()) - 1;
    };
    if (fs::exists(gd / ("grasp_" + k + "_model.ply")))
      graspPlys[g].model = add(gd / ("grasp_" + k + "_model.ply"));
    if (fs::exists(gd / ("grasp_" + k + "_hand.ply")))
      graspPlys[g].hand = add(gd / ("grasp_" + k + "_hand.ply"));
    for (int c = 1;; ++c) {
      const fs::path f = gd / ("grasp_" + k + "_candidate_" + std::to_string(c) + ".ply");
      if (!fs::exists(f)) break;
      graspPlys[g].candidates.push_back(add(f));
    }
  }
  std::vector<Json> meshes(plys.size());
  parallelFor(0, int(plys.size()), [&](int i) { meshes[size_t(i)] = meshJson(plys[size_t(i)]); });
  Json data = {{"summary", summary}};
  data["model"] = std::move(meshes[0]);
  if (fs::exists(dir / "model.glb")) {  // a scan with colour: its textured model, as written
    const std::string glb = readText(dir / "model.glb");
    data["model_glb"] = base64(glb.data(), glb.size());
  }
  if (truth) data["truth"] = std::move(meshes[1]);
  Json grasps = Json::array();
  for (const GraspPlys& g : graspPlys) {
    Json gj = Json::object();
    if (g.model >= 0) gj["model"] = std::move(meshes[size_t(g.model)]);
    if (g.hand >= 0) gj["hand"] = std::move(meshes[size_t(g.hand)]);
    Json cands = Json::array();
    for (int c : g.candidates) cands.push_back(std::move(meshes[size_t(c)]));
    gj["candidates"] = cands;
    grasps.push_back(gj);
  }
  data["grasps"] = grasps;
  const std::string title = "inhand scan: " + summary.value("object", std::string("?"));
  writeTextAtomically(dir / "report.html", buildPage(web, title, data, "report.js"));
}

void writeEvalIndex(const fs::path& dir, const fs::path& web) {
  for (const char* f : {"results.md", "curves.json", "results.csv"})
    if (!fs::exists(dir / f)) throw Error((dir / f).string() + ": not found (not an eval?)");
  Json data = {{"results_md", readText(dir / "results.md")},
               {"results_csv", readText(dir / "results.csv")},
               {"curves", readJsonFile(dir / "curves.json")}};
  writeTextAtomically(dir / "index.html", buildPage(web, "inhand eval", data, "index.js"));
}

}  // namespace inhand
