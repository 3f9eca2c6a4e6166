#include "inhand/config/scan_config.h"

#include <cstdio>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

#include "inhand/core/error.h"

namespace inhand {

namespace {

// "a, b or c"
template <class T, size_t N>
std::string alternatives(const EnumNames<T, N>& names) {
  std::string s;
  for (size_t i = 0; i < N; ++i)
    s += (i == 0 ? "" : i + 1 == N ? " or " : ", ") + std::string(names[i].second);
  return s;
}

const EnumNames<std::string, 2> kStarts = {{"table", "table"}, {"held", "held"}};

// Every option of a scan: the options structs' own rows (their static fields(), beside each
// struct's defaults), in the layout of the JSON options.
template <class V, class C>
void visitConfig(V& v, C& c) {
  v.string("robot", c.robot, "robot config JSON (empty: data/robots/wam_barretthand.json)");
  v.choice("start", c.start, kStarts, "table: from the table top (§V); held: at a given grasp");
  ScanOptions::fields(v, c.scan);
  MultiGraspOptions::fields(v, c.multi);
  v.object("eval", "scoring against the true mesh (simulation)",
           [&](auto& o) { EvalOptions::fields(o, c.eval); });
  v.object("sim", "the simulator", [&](auto& o) { SimOptions::fields(o, c.sim); });
}

class Reader {
 public:
  Reader(const Json& j, std::string where) : j_(j), where_(std::move(where)) {
    if (!j.is_object()) throw Error(where_ + ": expected an object");
  }
  // After every known key: any other key is an error that names it.
  void finish() const {
    for (const auto& [key, value] : j_.items())
      if (!seen_.count(key)) throw Error(where_ + ": unknown option \"" + key + "\"");
  }
  void num(const std::string& key, double& v, const char*, Range = {}) {
    if (!take(key)) return;
    if (!j_[key].is_number()) throw Error(at(key) + ": expected a number");
    v = j_[key].get<double>();
  }
  void integer(const std::string& key, int& v, const char*, Range = {}) {
    if (!take(key)) return;
    if (!j_[key].is_number_integer()) throw Error(at(key) + ": expected an integer");
    v = j_[key].get<int>();
  }
  void boolean(const std::string& key, bool& v, const char*) {
    if (!take(key)) return;
    if (!j_[key].is_boolean()) throw Error(at(key) + ": expected true or false");
    v = j_[key].get<bool>();
  }
  void numbers(const std::string& key, std::vector<double>& v, const char*, Range = {}) {
    if (!take(key)) return;
    const Json& a = j_[key];
    if (!a.is_array()) throw Error(at(key) + ": expected an array of numbers");
    v.clear();
    for (const Json& x : a) {
      if (!x.is_number()) throw Error(at(key) + ": expected an array of numbers");
      v.push_back(x.get<double>());
    }
  }
  void string(const std::string& key, std::string& v, const char*) {
    if (!take(key)) return;
    if (!j_[key].is_string()) throw Error(at(key) + ": expected a string");
    v = j_[key].get<std::string>();
  }
  template <class T, size_t N>
  void choice(const std::string& key, T& v, const EnumNames<T, N>& names, const char*) {
    if (!take(key)) return;
    if (j_[key].is_string())
      for (const auto& [value, name] : names)
        if (j_[key].get<std::string>() == name) {
          v = value;
          return;
        }
    throw Error(at(key) + ": must be " + alternatives(names));
  }
  template <class F>
  void object(const std::string& key, const char*, F visit) {
    if (!take(key)) return;
    Reader sub(j_[key], at(key));
    visit(sub);
    sub.finish();
  }

 private:
  bool take(const std::string& key) {
    seen_.insert(key);
    return j_.contains(key);
  }
  std::string at(const std::string& key) const { return where_ + "." + key; }
  const Json& j_;
  std::string where_;
  std::set<std::string> seen_;
};

class Writer {
 public:
  Json j = Json::object();
  void num(const std::string& key, double v, const char*, Range = {}) { j[key] = v; }
  void integer(const std::string& key, int v, const char*, Range = {}) { j[key] = v; }
  void boolean(const std::string& key, bool v, const char*) { j[key] = v; }
  void numbers(const std::string& key, const std::vector<double>& v, const char*, Range = {}) {
    j[key] = v;
  }
  void string(const std::string& key, const std::string& v, const char*) { j[key] = v; }
  template <class T, size_t N>
  void choice(const std::string& key, const T& v, const EnumNames<T, N>& names, const char*) {
    j[key] = enumName(names, v);
  }
  template <class F>
  void object(const std::string& key, const char*, F visit) {
    Writer sub;
    visit(sub);
    j[key] = sub.j;
  }
};

// The reference's tables (docs/config.md) and the list of rows (scanConfigRows).
class Documenter {
 public:
  explicit Documenter(std::string prefix = "") : prefix_(std::move(prefix)) {}
  std::ostringstream rows, sections;
  std::vector<ScanConfigRow> list;

  void num(const std::string& key, double v, const char* doc, Range r = {}) {
    row(key, "number", Json(v).dump(), r, r.bounded() ? r.text() : "", doc);
  }
  void integer(const std::string& key, int v, const char* doc, Range r = {}) {
    row(key, "integer", std::to_string(v), r, r.bounded() ? r.text(true) : "", doc);
  }
  void boolean(const std::string& key, bool v, const char* doc) {
    row(key, "true/false", v ? "true" : "false", {}, "", doc);
  }
  void numbers(const std::string& key, const std::vector<double>& v, const char* doc,
               Range r = {}) {
    row(key, "numbers", Json(v).dump(), r, r.bounded() ? "each " + r.text() : "", doc);
  }
  void string(const std::string& key, const std::string& v, const char* doc) {
    row(key, "string", v.empty() ? "(empty)" : "\"" + v + "\"", {}, "", doc);
  }
  template <class T, size_t N>
  void choice(const std::string& key, const T& v, const EnumNames<T, N>& names, const char* doc) {
    std::string all;
    for (const auto& [value, name] : names) all += (all.empty() ? "" : " \\| ") + std::string(name);
    row(key, "choice", std::string("\"") + enumName(names, v) + "\"", {}, all, doc);
  }
  template <class F>
  void object(const std::string& key, const char* doc, F visit) {
    Documenter sub(prefix_ + key + ".");
    visit(sub);
    sections << "\n### `" << prefix_ << key << "`: " << doc << "\n\n"
             << kHeader << sub.rows.str() << sub.sections.str();
    list.insert(list.end(), sub.list.begin(), sub.list.end());
  }
  static constexpr const char* kHeader =
      "| key | type | default | allowed | meaning |\n|---|---|---|---|---|\n";

 private:
  void row(const std::string& key, const char* type, const std::string& def, Range r,
           const std::string& allowed, const char* doc) {
    rows << "| `" << prefix_ << key << "` | " << type << " | " << def << " | " << allowed << " | "
         << doc << " |\n";
    list.push_back({prefix_ + key, type, r});
  }
  std::string prefix_;
};

}  // namespace

std::string ScanConfig::validate() const {
  // Every row against its range first (the error names the option's key as in a config file),
  // then the relations between options in each struct's validate().
  OptionChecker rows;
  visitConfig(rows, *this);
  if (!rows.error.empty()) return "option " + rows.error;
  if (std::string p = scan.validate(); !p.empty()) return "scan options: " + p;
  if (std::string p = multi.validate(); !p.empty()) return "scan options: " + p;
  if (std::string p = sim.validate(); !p.empty()) return "simulation options: sim." + p;
  if (std::string p = eval.validate(); !p.empty()) return "eval options: eval." + p;
  return {};
}

ScanConfig::ScanConfig() { setPhysics(true, Json(), this); }

void readScanConfig(const Json& j, const std::string& where, ScanConfig* config) {
  Reader r(j, where);
  visitConfig(r, *config);
  r.finish();
  const bool physicsGiven = j.contains("sim") && j["sim"].is_object() &&
                            j["sim"].contains("physics") && j["sim"]["physics"].is_object() &&
                            j["sim"]["physics"].contains("enabled");
  if (physicsGiven) setPhysics(config->sim.physics.enabled, j, config);
}

void setPhysics(bool on, const Json& j, ScanConfig* config) {
  auto given = [&](const char* a, const char* b) {
    return j.is_object() && j.contains(a) && j[a].is_object() && j[a].contains(b);
  };
  config->sim.physics.enabled = on;
  const TrackingOptions tracking;
  const GraspOptions grasp;
  // Closing the fingers moves the object in the hand (millimetres to centimetres), so the
  // object's pose in the hand comes from the lift's frame (tracking.in_hand). The kinematic
  // simulator's hand grasps exactly as planned, where a registration with one frame would only
  // add the model's error.
  if (!given("tracking", "in_hand")) config->scan.tracking.in_hand = on || tracking.in_hand;
  // … and an object may slide out of the hand after the lift: the hand holds still and the
  // camera looks again (grasp.settle_s).
  if (!given("grasp", "settle_s"))
    config->multi.grasp.settle_s = on ? GraspOptions::kSettleSeconds : grasp.settle_s;
  // … and the held object feels the arm's move from the pick to the lift: the lift rises
  // straight (grasp.lift_straight) and keeps the object in the camera's view (lift_in_view).
  if (!given("grasp", "lift_straight"))
    config->multi.grasp.lift_straight = on || grasp.lift_straight;
  if (!given("grasp", "lift_in_view")) config->multi.grasp.lift_in_view = on || grasp.lift_in_view;
}

void readScanConfigFile(const std::filesystem::path& file, ScanConfig* config) {
  readScanConfig(readJsonFile(file), file.string(), config);
}

Json scanConfigJson(const ScanConfig& config) {
  Writer w;
  visitConfig(w, config);
  return w.j;
}

std::string scanConfigReference() {
  const ScanConfig defaults;
  Documenter d;
  visitConfig(d, defaults);
  return std::string("## Top level\n\n") + Documenter::kHeader + d.rows.str() + d.sections.str();
}

std::vector<ScanConfigRow> scanConfigRows() {
  const ScanConfig defaults;
  Documenter d;
  visitConfig(d, defaults);
  return d.list;
}

}  // namespace inhand
