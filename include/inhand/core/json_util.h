#pragma once
// Reading JSON input with errors that name the file and the field ("frames.json: frames[3].T_O_C:
// expected 16 numbers").
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "inhand/core/types.h"

namespace inhand {

using Json = nlohmann::json;

// Parses a JSON file; throws Error naming the file (and line/column for syntax errors).
Json readJsonFile(const std::filesystem::path& path);

// `where` is the context for messages, e.g. "frames.json: frames[3]".
const Json& requireField(const Json& obj, const std::string& key, const std::string& where);
double requireNumber(const Json& obj, const std::string& key, const std::string& where);
int requireInt(const Json& obj, const std::string& key, const std::string& where);
std::string requireString(const Json& obj, const std::string& key, const std::string& where);

// Exact round trips (summary.json, checkpoints, frames.json): a pose as its 16 row-major
// numbers, a vector as 3, a joint vector as its values.
Json isoJson(const Iso3& T);
Iso3 isoFrom(const Json& j);  // throws Json::exception on a malformed value
Json vecJson(const Vec3& v);
// A number, or NaN for null (nlohmann writes NaN as null); throws on anything else.
double numberOrNan(const Json& j);
Vec3 vecFrom(const Json& j);
Json vectorJson(const Eigen::VectorXd& v);
Eigen::VectorXd vectorFrom(const Json& j);  // throws Json::exception on a malformed value

}  // namespace inhand
