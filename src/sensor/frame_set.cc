#include "inhand/sensor/frame_set.h"

#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"

namespace inhand {

namespace fs = std::filesystem;

namespace {

// A rigid transform from 16 row-major numbers; counts re-orthonormalised ones in `set`.
Json intrinsicsJson(const CameraIntrinsics& c) {
  return {{"width", c.width}, {"height", c.height}, {"fx", c.fx},
          {"fy", c.fy},       {"cx", c.cx},         {"cy", c.cy}};
}

Iso3 readPose(const Json& T, const std::string& where, FrameSet* set) {
  double deviation = 0;
  const Iso3 pose = readRowMajorPose(T, where, 1e-2, &deviation);
  if (deviation > 1e-9) {
    ++set->reorthonormalised;
    set->max_rotation_deviation = std::max(set->max_rotation_deviation, deviation);
  }
  return pose;
}

}  // namespace

Iso3 readRowMajorPose(const Json& T, const std::string& where, double tol, double* deviation) {
  if (!T.is_array() || T.size() != 16)
    throw Error(where + ": expected an array of 16 numbers (row-major 4x4)");
  std::array<double, 16> m{};
  for (size_t k = 0; k < 16; ++k) {
    if (!T[k].is_number()) throw Error(where + "[" + std::to_string(k) + "]: not a number");
    m[k] = T[k].get<double>();
  }
  std::string why;
  const std::optional<Iso3> pose = poseFromRowMajor(m, &why, tol, deviation);
  if (!pose) throw Error(where + ": not a rigid transform: " + why);
  return *pose;
}

CameraIntrinsics readIntrinsics(const Json& K, const std::string& where) {
  CameraIntrinsics c;
  c.width = requireInt(K, "width", where);
  c.height = requireInt(K, "height", where);
  c.fx = requireNumber(K, "fx", where);
  c.fy = requireNumber(K, "fy", where);
  c.cx = requireNumber(K, "cx", where);
  c.cy = requireNumber(K, "cy", where);
  if (std::string problem = c.validate(); !problem.empty()) throw Error(where + "." + problem);
  return c;
}

namespace {
// frames.json's colour camera: its intrinsics (default the depth camera's), its pose in the
// depth camera's frame (default the identity: a registered image) and whether a lamp at the
// camera lit the frames.
void readColourCamera(const Json& j, const std::string& name, FrameSet* set) {
  set->colour.intrinsics = set->intrinsics;
  set->colour.T_D_RGB = Iso3::Identity();
  if (j.contains("colour_intrinsics"))
    set->colour.intrinsics = readIntrinsics(j["colour_intrinsics"], name + ": colour_intrinsics");
  if (j.contains("T_D_RGB")) set->colour.T_D_RGB = readPose(j["T_D_RGB"], name + ": T_D_RGB", set);
  if (j.contains("colour_light_at_camera")) {
    if (!j["colour_light_at_camera"].is_boolean())
      throw Error(name + ": colour_light_at_camera: expected true or false");
    set->colour.light_at_camera = j["colour_light_at_camera"].get<bool>();
  }
}
}  // namespace

FrameSet readFrameSet(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(dir.string() + ": no such frames directory");
  const fs::path path = dir / "frames.json";
  const std::string name = path.string();
  Json j = readJsonFile(path);
  if (!j.is_object()) throw Error(name + ": expected a JSON object at the top level");
  FrameSet set;
  if (j.contains("depth_scale_m")) {
    set.depth_scale_m = requireNumber(j, "depth_scale_m", name);
    if (!(set.depth_scale_m > 0)) throw Error(name + ": depth_scale_m must be > 0");
  }
  set.intrinsics = readIntrinsics(requireField(j, "intrinsics", name), name + ": intrinsics");
  if (j.contains("bounds_O")) {
    const Json& b = j["bounds_O"];
    const std::string bw = name + ": bounds_O";
    Aabb box;
    for (const char* key : {"min", "max"}) {
      const Json& v = requireField(b, key, bw);
      if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() ||
          !v[2].is_number())
        throw Error(bw + "." + key + ": expected an array of 3 numbers");
      box.extend(Vec3(v[0].get<double>(), v[1].get<double>(), v[2].get<double>()));
    }
    if (!(Vec3(b["min"][0], b["min"][1], b["min"][2]).array() <
          Vec3(b["max"][0], b["max"][1], b["max"][2]).array())
             .all())
      throw Error(bw + ": each min must be below its max");
    set.bounds_O = box;
  }
  if (j.contains("T_O_palm")) set.T_O_palm = readPose(j["T_O_palm"], name + ": T_O_palm", &set);
  readColourCamera(j, name, &set);
  const Json& frames = requireField(j, "frames", name);
  if (!frames.is_array()) throw Error(name + ": frames: expected an array");
  if (frames.empty()) throw Error(name + ": frames: the array is empty");
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string where = name + ": frames[" + std::to_string(i) + "]";
    FrameRecord rec;
    rec.file = requireString(frames[i], "file", where);
    if (rec.file.empty()) throw Error(where + ".file: empty file name");
    if (!fs::is_regular_file(dir / rec.file, ec))
      throw Error(where + ".file: " + (dir / rec.file).string() + " does not exist");
    if (frames[i].contains("q")) {
      const Json& q = frames[i]["q"];
      if (!q.is_object() || q.empty())
        throw Error(where + ".q: expected an object of joint names and values");
      for (auto it = q.begin(); it != q.end(); ++it) {
        if (!it.value().is_number() || !std::isfinite(it.value().get<double>()))
          throw Error(where + ".q." + it.key() + ": not a number");
        rec.q.emplace_back(it.key(), it.value().get<double>());
      }
    }
    if (frames[i].contains("T_B_C"))
      rec.T_B_C = readPose(frames[i]["T_B_C"], where + ".T_B_C", &set);
    if (frames[i].contains("T_O_palm"))
      rec.T_O_palm = readPose(frames[i]["T_O_palm"], where + ".T_O_palm", &set);
    if (frames[i].contains("colour")) {
      rec.colour_file = requireString(frames[i], "colour", where);
      if (!fs::is_regular_file(dir / rec.colour_file, ec))
        throw Error(where + ".colour: " + (dir / rec.colour_file).string() + " does not exist");
      set.colour.enabled = true;
    }
    if (frames[i].contains("T_O_C")) {
      rec.T_O_C = readPose(frames[i]["T_O_C"], where + ".T_O_C", &set);
    } else if (!rec.q.empty() && rec.T_B_C) {
      rec.has_T_O_C = false;
    } else {
      throw Error(where + ": no T_O_C (give T_O_C, or q and T_B_C for fuse --robot)");
    }
    set.frames.push_back(rec);
  }
  return set;
}

DepthImage loadFrameDepth(const fs::path& dir, const FrameSet& set, size_t i) {
  return readDepthPng(dir / set.frames.at(i).file, set.depth_scale_m, set.intrinsics.width,
                      set.intrinsics.height);
}

RgbImage loadFrameColour(const fs::path& dir, const FrameSet& set, size_t i) {
  const FrameRecord& f = set.frames.at(i);
  if (f.colour_file.empty()) return {};
  RgbImage img = readRgbImage(dir / f.colour_file);
  const CameraIntrinsics& K = set.colour.intrinsics;
  if (img.width != K.width || img.height != K.height)
    throw Error((dir / f.colour_file).string() + ": colour image is " + std::to_string(img.width) +
                "x" + std::to_string(img.height) + ", expected " + std::to_string(K.width) + "x" +
                std::to_string(K.height) + " (from the colour intrinsics)");
  return img;
}

void writeFrameSet(const fs::path& dir, const FrameSet& set) {
  Json j;
  j["depth_scale_m"] = set.depth_scale_m;
  j["intrinsics"] = intrinsicsJson(set.intrinsics);
  Json frames = Json::array();
  for (const FrameRecord& f : set.frames) {
    Json r = {{"file", f.file}};
    if (f.has_T_O_C) r["T_O_C"] = isoJson(f.T_O_C);
    if (!f.q.empty()) {
      Json q = Json::object();
      for (const auto& [name, value] : f.q) q[name] = value;
      r["q"] = q;
    }
    if (f.T_B_C) r["T_B_C"] = isoJson(*f.T_B_C);
    if (f.T_O_palm) r["T_O_palm"] = isoJson(*f.T_O_palm);
    if (!f.colour_file.empty()) r["colour"] = f.colour_file;
    frames.push_back(r);
  }
  j["frames"] = frames;
  if (set.T_O_palm) j["T_O_palm"] = isoJson(*set.T_O_palm);
  if (set.colour.enabled) {
    j["colour_intrinsics"] = intrinsicsJson(set.colour.intrinsics);
    j["T_D_RGB"] = isoJson(set.colour.T_D_RGB);
    if (set.colour.light_at_camera) j["colour_light_at_camera"] = true;
  }
  if (set.bounds_O)
    j["bounds_O"] = {
        {"min", {set.bounds_O->min.x(), set.bounds_O->min.y(), set.bounds_O->min.z()}},
        {"max", {set.bounds_O->max.x(), set.bounds_O->max.y(), set.bounds_O->max.z()}}};
  writeTextAtomically(dir / "frames.json", j.dump(2) + "\n");
}

}  // namespace inhand
