#include "inhand/core/json_util.h"

#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"

namespace inhand {

Json readJsonFile(const std::filesystem::path& path) {
  std::string text = readTextFile(path);
  try {
    return Json::parse(text);
  } catch (const Json::parse_error& e) {
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

}  // namespace inhand
