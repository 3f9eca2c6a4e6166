#include "inhand/asset/asset.h"

#include <mujoco/mujoco.h>
#include <urdf_parser/urdf_parser.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/geometry/mesh_io.h"

namespace inhand {

namespace {

std::string num(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%.9g", x);
  return b;
}
std::string vec(const Vec3& v) { return num(v.x()) + " " + num(v.y()) + " " + num(v.z()); }
std::string pieceName(size_t i) {
  char b[32];
  std::snprintf(b, sizeof b, "collision_%03zu", i);
  return b;
}
std::string pieceFile(size_t i) { return pieceName(i) + ".stl"; }
TriangleMesh hullMesh(const ConvexHull& hull) {
  TriangleMesh m;
  for (const Vec3& v : hull.vertices) m.vertices.push_back(v.cast<float>());
  for (const auto& t : hull.triangles) m.triangles.push_back(Tri(t[0], t[1], t[2]));
  return m;
}

}  // namespace

std::string AssetOptions::validate() const {
  if (name.empty() || name.size() > 64) return "name must have 1..64 characters";
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-'))
      return "name may hold only letters, digits, '_' and '-' (it is '" + name + "')";
  if (!(density_kg_m3 > 0 && density_kg_m3 <= 25000)) return "density_kg_m3 must be in (0, 25000]";
  if (!(mass_kg >= 0 && mass_kg <= 1000)) return "mass_kg must be in [0, 1000] (0: from density)";
  if (max_visual_triangles < 100 || max_visual_triangles > 200000)
    return "max_visual_triangles must be in 100..200000";
  if (std::string p = decomposition.validate(); !p.empty()) return "decomposition: " + p;
  return "";
}

ObjectAsset makeAsset(const TriangleMesh& closed_O, const AssetOptions& options) {
  if (std::string p = options.validate(); !p.empty()) throw Error("asset options: " + p);
  if (std::string p = validateMesh(closed_O); !p.empty()) throw Error("asset: the model: " + p);
  ObjectAsset a;
  a.name = options.name;
  a.model_O = closed_O;
  MassProperties mp = massProperties(a.model_O);
  if (mp.volume_m3 < 0) {  // inward triangles: the same solid
    for (Tri& t : a.model_O.triangles) std::swap(t[1], t[2]);
    mp = massProperties(a.model_O);
  }
  if (!(mp.volume_m3 > 1e-9))
    throw Error("asset: the model encloses no volume (it must be a closed surface)");
  a.volume_m3 = mp.volume_m3;
  a.mass_kg = options.mass_kg > 0 ? options.mass_kg : options.density_kg_m3 * mp.volume_m3;
  a.density_kg_m3 = a.mass_kg / mp.volume_m3;
  a.com_O = mp.com;
  a.inertia_kg_m2 = a.density_kg_m3 * mp.inertia_com;
  a.visual_O = simplifiedTo(a.model_O, size_t(options.max_visual_triangles));
  a.pieces = convexDecomposition(a.model_O, options.decomposition);
  if (a.pieces.empty()) throw Error("asset: the model's convex decomposition is empty");
  for (const ConvexPiece& p : a.pieces) a.pieces_volume_m3 += p.volume_m3;
  return a;
}

std::string mjcfText(const ObjectAsset& a) {
  const Mat3& I = a.inertia_kg_m2;
  std::string x = "<mujoco model=\"" + a.name + "\">\n";
  // The body's mass and inertia are the closed model's (not MuJoCo's from the geoms: the
  // pieces' hulls exceed the solid a little, the visual mesh is only for the eye).
  x += "  <compiler angle=\"radian\" inertiafromgeom=\"false\"/>\n  <asset>\n";
  x += "    <mesh name=\"" + a.name + "_visual\" file=\"visual.stl\"/>\n";
  for (size_t i = 0; i < a.pieces.size(); ++i)
    x += "    <mesh name=\"" + a.name + "_" + pieceName(i) + "\" file=\"" + pieceFile(i) + "\"/>\n";
  x += "  </asset>\n  <worldbody>\n    <body name=\"" + a.name + "\">\n";
  x += "      <freejoint name=\"" + a.name + "\"/>\n";
  x += "      <inertial pos=\"" + vec(a.com_O) + "\" mass=\"" + num(a.mass_kg) +
       "\" fullinertia=\"" + num(I(0, 0)) + " " + num(I(1, 1)) + " " + num(I(2, 2)) + " " +
       num(I(0, 1)) + " " + num(I(0, 2)) + " " + num(I(1, 2)) + "\"/>\n";
  x += "      <geom name=\"" + a.name + "_visual\" type=\"mesh\" mesh=\"" + a.name +
       "_visual\" contype=\"0\" conaffinity=\"0\" group=\"1\" rgba=\"0.75 0.75 0.75 1\"/>\n";
  for (size_t i = 0; i < a.pieces.size(); ++i) {
    const std::string n = a.name + "_" + pieceName(i);
    x += "      <geom name=\"" + n + "\" type=\"mesh\" mesh=\"" + n +
         "\" group=\"3\" rgba=\"0.3 0.6 0.9 0.5\"/>\n";
  }
  return x + "    </body>\n  </worldbody>\n</mujoco>\n";
}

std::string urdfText(const ObjectAsset& a) {
  const Mat3& I = a.inertia_kg_m2;
  std::string x = "<?xml version=\"1.0\"?>\n<robot name=\"" + a.name + "\">\n";
  // MuJoCo reads a URDF's mesh file names without their folder, relative to the URDF; without
  // fusestatic="false" it merges a link with no joint into the world and its name is gone.
  x += "  <mujoco><compiler fusestatic=\"false\"/></mujoco>\n";
  x += "  <link name=\"" + a.name + "\">\n    <inertial>\n      <origin xyz=\"" + vec(a.com_O) +
       "\" rpy=\"0 0 0\"/>\n      <mass value=\"" + num(a.mass_kg) + "\"/>\n";
  x += "      <inertia ixx=\"" + num(I(0, 0)) + "\" ixy=\"" + num(I(0, 1)) + "\" ixz=\"" +
       num(I(0, 2)) + "\" iyy=\"" + num(I(1, 1)) + "\" iyz=\"" + num(I(1, 2)) + "\" izz=\"" +
       num(I(2, 2)) + "\"/>\n    </inertial>\n";
  x += "    <visual>\n      <geometry><mesh filename=\"visual.stl\"/></geometry>\n    </visual>\n";
  for (size_t i = 0; i < a.pieces.size(); ++i)
    x += "    <collision name=\"" + pieceName(i) + "\">\n      <geometry><mesh filename=\"" +
         pieceFile(i) + "\"/></geometry>\n    </collision>\n";
  return x + "  </link>\n</robot>\n";
}

std::string sdfText(const ObjectAsset& a) {
  const Mat3& I = a.inertia_kg_m2;
  std::string x = "<?xml version=\"1.0\"?>\n<sdf version=\"1.7\">\n  <model name=\"" + a.name +
                  "\">\n    <link name=\"" + a.name + "\">\n      <inertial>\n        <pose>" +
                  vec(a.com_O) + " 0 0 0</pose>\n        <mass>" + num(a.mass_kg) +
                  "</mass>\n        <inertia><ixx>" + num(I(0, 0)) + "</ixx><ixy>" + num(I(0, 1)) +
                  "</ixy><ixz>" + num(I(0, 2)) + "</ixz><iyy>" + num(I(1, 1)) + "</iyy><iyz>" +
                  num(I(1, 2)) + "</iyz><izz>" + num(I(2, 2)) +
                  "</izz></inertia>\n      </inertial>\n";
  x += "      <visual name=\"visual\"><geometry><mesh><uri>visual.stl</uri></mesh></geometry>"
       "</visual>\n";
  for (size_t i = 0; i < a.pieces.size(); ++i)
    x += "      <collision name=\"" + pieceName(i) + "\"><geometry><mesh><uri>" + pieceFile(i) +
         "</uri></mesh></geometry></collision>\n";
  return x + "    </link>\n  </model>\n</sdf>\n";
}

namespace {
// Each format: its name, its file's extension, its text.
struct FormatInfo {
  AssetFormat format;
  const char* name;
  const char* extension;
  std::string (*text)(const ObjectAsset&);
};
const FormatInfo kFormats[] = {{AssetFormat::kMjcf, "mjcf", ".xml", mjcfText},
                               {AssetFormat::kUrdf, "urdf", ".urdf", urdfText},
                               {AssetFormat::kSdf, "sdf", ".sdf", sdfText}};
const FormatInfo& infoOf(AssetFormat format) {
  for (const FormatInfo& f : kFormats)
    if (f.format == format) return f;
  throw Error("asset: unknown format");
}
std::string fileOf(const ObjectAsset& a, AssetFormat format) {
  return a.name + infoOf(format).extension;
}
}  // namespace

std::optional<AssetFormat> assetFormatFromName(const std::string& name) {
  for (const FormatInfo& f : kFormats)
    if (name == f.name) return f.format;
  return std::nullopt;
}

const char* assetFormatName(AssetFormat format) { return infoOf(format).name; }

double mujocoBodyMass(const std::filesystem::path& model_file, const std::string& body) {
  char error[1000] = "";
  mjModel* m = mj_loadXML(model_file.string().c_str(), nullptr, error, sizeof error);
  if (!m) throw Error(model_file.string() + ": MuJoCo refused it: " + error);
  const int id = mj_name2id(m, mjOBJ_BODY, body.c_str());
  const double mass = id >= 0 ? m->body_mass[id] : -1;
  mj_deleteModel(m);
  if (id < 0) throw Error(model_file.string() + ": MuJoCo finds no body '" + body + "'");
  return mass;
}

namespace {

Json assetJson(const ObjectAsset& a, const std::vector<AssetFormat>& formats) {
  Json files = Json::object();
  for (AssetFormat f : formats) files[assetFormatName(f)] = fileOf(a, f);
  Json inertia = Json::array();
  for (int r = 0; r < 3; ++r)
    inertia.push_back({a.inertia_kg_m2(r, 0), a.inertia_kg_m2(r, 1), a.inertia_kg_m2(r, 2)});
  return {{"name", a.name},
          {"frame", "the scan's object frame O (model.ply's); metres, kilograms"},
          {"files", files},
          {"volume_m3", a.volume_m3},
          {"density_kg_m3", a.density_kg_m3},
          {"mass_kg", a.mass_kg},
          {"com_O", {a.com_O.x(), a.com_O.y(), a.com_O.z()}},
          {"inertia_kg_m2", inertia},
          {"model_triangles", a.model_O.triangles.size()},
          {"visual_triangles", a.visual_O.triangles.size()},
          {"collision_pieces", a.pieces.size()},
          {"collision_volume_m3", a.pieces_volume_m3},
          {"grasps", a.grasps.size()}};
}

// The written files checked as a simulator and a planner read them.
void checkWritten(const ObjectAsset& a, const fs::path& dir,
                  const std::vector<AssetFormat>& formats) {
  for (AssetFormat f : formats) {
    if (f == AssetFormat::kSdf) continue;
    const fs::path file = dir / fileOf(a, f);
    if (f == AssetFormat::kUrdf && !urdf::parseURDF(readTextFile(file)))
      throw Error("asset: urdfdom refused the URDF it wrote");
    const double mass = mujocoBodyMass(file, a.name);
    if (std::abs(mass - a.mass_kg) > 1e-6 * a.mass_kg)
      throw Error("asset: MuJoCo compiled " + file.filename().string() + " with mass " + num(mass) +
                  " kg, not " + num(a.mass_kg));
  }
}

}  // namespace

void writeAsset(const ObjectAsset& a, const fs::path& dir, const std::vector<AssetFormat>& formats,
                const std::optional<fs::path>& model_ply) {
  StagedDirectory staged(dir);
  const fs::path& s = staged.path();
  writeStl(s / "visual.stl", a.visual_O);
  for (size_t i = 0; i < a.pieces.size(); ++i)
    writeStl(s / pieceFile(i), hullMesh(a.pieces[i].hull));
  if (model_ply) {
    std::error_code ec;
    fs::copy_file(*model_ply, s / "model.ply", ec);
    if (ec) throw Error(model_ply->string() + ": cannot copy: " + ec.message());
  } else {
    writePly(s / "model.ply", a.model_O);
  }
  for (AssetFormat f : formats) writeTextAtomically(s / fileOf(a, f), infoOf(f).text(a));
  writeTextAtomically(s / "grasps.json", a.grasps.dump(1) + "\n");
  writeTextAtomically(s / "asset.json", assetJson(a, formats).dump(1) + "\n");
  checkWritten(a, s, formats);
  staged.commit();
}

LoadedAsset readAsset(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir.string() + ": not an asset directory");
  LoadedAsset out;
  const fs::path info = dir / "asset.json", grasps = dir / "grasps.json", model = dir / "model.ply";
  for (const fs::path& f : {info, grasps, model})
    if (!fs::exists(f, ec))
      throw Error(f.string() + ": missing (not an asset written by inhand export?)");
  const Json a = readJsonFile(info);
  try {
    out.name = a.at("name").get<std::string>();
    out.mass_kg = a.at("mass_kg").get<double>();
    const auto c = a.at("com_O").get<std::vector<double>>();
    if (c.size() != 3) throw Error(info.string() + ": com_O must have 3 numbers");
    out.com_O = Vec3(c[0], c[1], c[2]);
  } catch (const Json::exception& e) {
    throw Error(info.string() + ": " + e.what());
  }
  if (!(std::isfinite(out.mass_kg) && out.mass_kg > 0))
    throw Error(info.string() + ": mass_kg must be a positive number");
  out.grasps = readJsonFile(grasps);
  if (!out.grasps.is_array()) throw Error(grasps.string() + ": not a list of grasps");
  PlyData ply = readPly(model);
  out.model_O = std::move(ply.mesh);
  if (out.model_O.triangles.empty()) throw Error(model.string() + ": no triangles");
  out.observed.assign(out.model_O.vertices.size(), 1);
  if (const auto v = ply.vertexProperties.find("variance"); v != ply.vertexProperties.end())
    for (size_t k = 0; k < out.observed.size() && k < v->second.size(); ++k)
      out.observed[k] = v->second[k] < 0.99f * 0.05f * 0.05f;
  return out;
}

}  // namespace inhand
