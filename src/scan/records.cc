#include "inhand/scan/records.h"

#include <cmath>
#include <limits>
#include <string>

#include "inhand/core/error.h"

namespace inhand {

namespace {
// The field `key`, or `older` (its name in checkpoints written before); throws like Json::at.
const Json& field(const Json& j, const char* key, const char* older) {
  if (!j.contains(key) && j.contains(older)) return j.at(older);
  return j.at(key);
}
Json finiteOrNull(double x) { return std::isfinite(x) ? Json(x) : Json(); }
}  // namespace

Json viewRecordJson(const ViewRecord& r) {
  return {{"initial", r.initial},
          {"direction_O", vecJson(r.dir_O)},
          {"T_O_C", isoJson(r.T_O_C)},
          {"quality", r.quality},
          {"predicted_gain", finiteOrNull(r.gain)},
          {"t_q", finiteOrNull(r.t_q)},
          {"unresolved", r.unresolved},
          {"cost_s", r.cost_s},
          {"score", r.score},
          {"mean_entropy", r.mean_entropy},
          {"observed_fraction", r.observed_fraction},
          {"coverage", r.coverage},
          {"frames", r.frames},
          {"candidates", r.candidates},
          {"planning_s", r.planning_s}};
}

ViewRecord viewRecordFrom(const Json& j) {
  ViewRecord r;
  r.initial = j.at("initial").get<bool>();
  r.dir_O = vecFrom(field(j, "direction_O", "dir_O"));
  r.T_O_C = isoFrom(j.at("T_O_C"));
  r.quality = j.at("quality").get<double>();
  r.gain = j.contains("predicted_gain") || j.contains("gain")
               ? numberOrNan(field(j, "predicted_gain", "gain"))
               : std::numeric_limits<double>::quiet_NaN();
  r.t_q = numberOrNan(j.value("t_q", Json()));
  r.unresolved = j.value("unresolved", 0.0);
  r.cost_s = j.at("cost_s").get<double>();
  r.score = j.at("score").get<double>();
  r.mean_entropy = j.at("mean_entropy").get<double>();
  r.observed_fraction = j.at("observed_fraction").get<double>();
  r.coverage = j.at("coverage").get<double>();
  r.frames = j.at("frames").get<int>();
  r.candidates = j.at("candidates").get<int>();
  r.planning_s = j.at("planning_s").get<double>();
  return r;
}

Json graspRecordJson(const GraspRecord& g) {
  Json ranked = Json::array();
  for (const RankedGrasp& r : g.ranked)
    ranked.push_back({{"T_O_palm", isoJson(r.T_O_palm)},
                      {"q", vectorJson(r.q)},
                      {"quality", r.quality},
                      {"stability_epsilon", r.epsilon}});
  return {{"T_O_palm", isoJson(g.T_O_palm)},
          {"q", vectorJson(g.q)},
          {"candidates", g.candidates},
          {"poses_tried", g.tried},
          {"quality", g.quality},
          {"t_q", g.t_q},
          {"model_area_m2", g.model_area_m2},
          {"stability_epsilon", finiteOrNull(g.epsilon)},
          {"views", g.views},
          {"termination", terminationName(g.termination)},
          {"views_ended_at_s", g.views_ended_at_s < 0 ? Json() : Json(g.views_ended_at_s)},
          {"unknown_area_m2", g.hole_area_m2},
          {"mean_entropy", g.mean_entropy},
          {"generation_s", g.generation_s},
          {"ranking_s", g.ranking_s},
          {"ranked", ranked},
          {"pick_up_attempts", attemptsJson(g.attempts)}};
}

GraspRecord graspRecordFrom(const Json& j) {
  GraspRecord g;
  g.T_O_palm = isoFrom(j.at("T_O_palm"));
  g.q = vectorFrom(j.at("q"));
  g.candidates = j.at("candidates").get<int>();
  g.tried = field(j, "poses_tried", "tried").get<int>();
  g.quality = j.at("quality").get<double>();
  g.t_q = j.value("t_q", 0.0);
  g.model_area_m2 = j.value("model_area_m2", 0.0);
  g.epsilon = numberOrNan(field(j, "stability_epsilon", "epsilon"));
  g.views = j.at("views").get<int>();
  const std::string termination = j.at("termination").get<std::string>();
  if (!parseTermination(termination, &g.termination))
    throw Error("unknown termination " + termination);
  g.hole_area_m2 = field(j, "unknown_area_m2", "hole_area_m2").get<double>();
  const Json ended = j.value("views_ended_at_s", Json());  // absent before it was recorded
  g.views_ended_at_s = ended.is_number() ? ended.get<double>() : -1;
  g.mean_entropy = j.at("mean_entropy").get<double>();
  g.generation_s = j.at("generation_s").get<double>();
  g.ranking_s = j.at("ranking_s").get<double>();
  for (const Json& r : j.at("ranked"))
    g.ranked.push_back({isoFrom(r.at("T_O_palm")), vectorFrom(r.at("q")),
                        r.at("quality").get<double>(),
                        field(r, "stability_epsilon", "epsilon").get<double>()});
  g.attempts = attemptsFrom(field(j, "pick_up_attempts", "attempts"));
  return g;
}

Json tableTopRecordJson(const TableTopRecord& t) {
  Json axes = Json::array();
  for (int k = 0; k < 3; ++k)
    axes.push_back({{"axis_O", vecJson(t.axes.axes.col(k))},
                    {"extent_m", t.axes.max[k] - t.axes.min[k]},
                    {"variance_m2", t.axes.variances[k]},
                    {"min_m", t.axes.min[k]},
                    {"max_m", t.axes.max[k]}});
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
  const Vec3& n = t.table_O.n;
  return {{"frames", t.frames},
          {"points", t.points},
          {"table_inliers", t.table_inliers},
          {"object_points", t.object_points},
          {"table_plane_O", {n.x(), n.y(), n.z(), t.table_O.d}},
          {"centroid_O", vecJson(t.axes.centroid)},
          {"principal_axes", axes},
          {"grasp_poses_tried", t.tried},
          {"grasp_poses_touching", t.touching},
          {"grasp_poses_stable", t.stable},
          {"grasp_poses_table_free", t.table_free},
          {"grasp_poses_reachable", t.reachable},
          {"grasp_rejected",
           {{"no_two_link_contact", t.tried - t.touching},
            {"not_force_closure", t.touching - t.stable},
            {"hand_in_table", t.stable - t.table_free},
            {"unreachable", t.table_free - t.reachable}}},
          {"pick_up_attempts", attemptsJson(t.attempts)},
          {"grasp_poses", poses},
          {"volume", {{"size_m", t.volume_size_m}, {"voxel_m", t.voxel_m}}},
          {"reanchor",
           {{"tried", t.reanchor.tried},
            {"found", t.reanchor.found},
            {"applied", t.reanchor.applied},
            {"gap_m", t.reanchor.gap_m},
            {"shift_m", t.reanchor.shift_m},
            {"turn_deg", t.reanchor.turn_rad * 180 / M_PI},
            {"reason", t.reanchor.reason}}},
          {"seconds", t.seconds}};
}

namespace {
// The principal axes of a record, or of a checkpoint written before (centroid, axes, variances,
// min, max).
PrincipalAxes axesFrom(const Json& j) {
  PrincipalAxes a;
  a.centroid = vecFrom(field(j, "centroid_O", "centroid"));
  if (j.contains("principal_axes")) {
    for (int k = 0; k < 3; ++k) {
      const Json& e = j.at("principal_axes").at(size_t(k));
      a.axes.col(k) = vecFrom(e.at("axis_O"));
      a.variances[k] = e.at("variance_m2").get<double>();
      a.min[k] = e.at("min_m").get<double>();
      a.max[k] = e.at("max_m").get<double>();
    }
    return a;
  }
  for (int k = 0; k < 3; ++k) a.axes.col(k) = vecFrom(j.at("axes").at(size_t(k)));
  a.variances = vecFrom(j.at("variances"));
  a.min = vecFrom(j.at("min"));
  a.max = vecFrom(j.at("max"));
  return a;
}
}  // namespace

TableTopRecord tableTopRecordFrom(const Json& j) {
  TableTopRecord t;
  t.frames = j.at("frames").get<int>();
  t.points = j.at("points").get<int>();
  t.table_inliers = j.at("table_inliers").get<int>();
  t.object_points = j.at("object_points").get<int>();
  if (j.contains("table_plane_O")) {
    const Json& p = j.at("table_plane_O");
    t.table_O.n = Vec3(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
    t.table_O.d = p.at(3).get<double>();
  } else {
    t.table_O.n = vecFrom(j.at("table_n"));
    t.table_O.d = j.at("table_d").get<double>();
  }
  t.axes = axesFrom(j);
  t.tried = field(j, "grasp_poses_tried", "tried").get<int>();
  t.touching = field(j, "grasp_poses_touching", "touching").get<int>();
  t.stable = field(j, "grasp_poses_stable", "stable").get<int>();
  t.table_free = field(j, "grasp_poses_table_free", "table_free").get<int>();
  t.reachable = field(j, "grasp_poses_reachable", "reachable").get<int>();
  for (const Json& p : field(j, "grasp_poses", "poses")) {
    GraspPoseRecord r;
    r.approach_O = vecFrom(p.at("approach_O"));
    r.roll_rad = p.at("roll_rad").get<double>();
    r.spread = p.at("spread").get<double>();
    r.preshape = p.at("preshape").get<double>();
    r.edge = p.at("edge").get<bool>();
    r.pinch = p.value("pinch", false);  // (records written before pinch poses)
    r.two_finger = p.value("two_finger", false);
    r.epsilon = p.at("epsilon").get<double>();
    r.result = p.at("result").get<std::string>();
    t.poses.push_back(r);
  }
  if (j.contains("volume")) {
    t.volume_size_m = j.at("volume").at("size_m").get<double>();
    t.voxel_m = j.at("volume").at("voxel_m").get<double>();
  } else {
    t.volume_size_m = j.at("volume_size_m").get<double>();
    t.voxel_m = j.at("voxel_m").get<double>();
  }
  t.attempts = attemptsFrom(field(j, "pick_up_attempts", "attempts"));
  t.seconds = j.at("seconds").get<double>();
  if (j.contains("reanchor")) {
    const Json& r = j["reanchor"];
    t.reanchor.tried = r.at("tried").get<bool>();
    t.reanchor.found = r.at("found").get<bool>();
    t.reanchor.applied = r.at("applied").get<bool>();
    t.reanchor.gap_m = r.at("gap_m").get<double>();
    t.reanchor.shift_m = r.at("shift_m").get<double>();
    t.reanchor.turn_rad = r.at("turn_deg").get<double>() * M_PI / 180;
    t.reanchor.reason = r.at("reason").get<std::string>();
  }
  return t;
}

}  // namespace inhand
