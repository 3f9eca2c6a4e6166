#include "inhand/core/json_util.h"

#include <cmath>
#include <limits>
#include <vector>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"

namespace inhand {

Json readJsonFile(const std::filesystem::path& path) {
  std::string text = readTextFile(path);
  try {
    return Json::parse(text);
  } catch (const Json::exception& e) {  // syntax, or a number beyond double (out_of_range)
    throw Error(path.string() + ": malformed JSON (" + e.what() + ")");
  }
}

const Json& requireField(const Json& obj, const std::string& key, const std::string& where) {
  if (!obj.is_object()) throw Error(where + ": expected a JSON object");
  auto it = obj.find(key);
  if (it == obj.end()) throw Error(where + ": missing field \"" + key + "\"");
  return *it;
}

double requireNumber(const Json& obj, const std::string& key, const std::string& where) {
  const Json& v = requireField(obj, key, where);
  if (!v.is_number()) throw Error(where + "." + key + ": expected a number, got " + v.dump());
  double d = v.get<double>();
  if (!std::isfinite(d)) throw Error(where + "." + key + ": not a finite number");
  return d;
}

int requireInt(const Json& obj, const std::string& key, const std::string& where) {
  const Json& v = requireField(obj, key, where);
  if (!v.is_number_integer())
    throw Error(where + "." + key + ": expected an integer, got " + v.dump());
  return v.get<int>();
}

std::string requireString(const Json& obj, const std::string& key, const std::string& where) {
  const Json& v = requireField(obj, key, where);
  if (!v.is_string()) throw Error(where + "." + key + ": expected a string, got " + v.dump());
  return v.get<std::string>();
}

Json isoJson(const Iso3& T) {
  Json j = Json::array();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) j.push_back(T.matrix()(r, c));
  return j;
}

Iso3 isoFrom(const Json& j) {
  Iso3 T = Iso3::Identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) T.matrix()(r, c) = j.at(r * 4 + c).get<double>();
  return T;
}

Json vecJson(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

Vec3 vecFrom(const Json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

Json vectorJson(const Eigen::VectorXd& v) {
  Json j = Json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) j.push_back(v[i]);
  return j;
}

Eigen::VectorXd vectorFrom(const Json& j) {
  const std::vector<double> v = j.get<std::vector<double>>();
  return Eigen::Map<const Eigen::VectorXd>(v.data(), Eigen::Index(v.size()));
}

double numberOrNan(const Json& j) {
  return j.is_null() ? std::numeric_limits<double>::quiet_NaN() : j.get<double>();
}

}  // namespace inhand
