#include "inhand/scan/multi_grasp.h"

#include <chrono>
#include <cstdio>

#include "inhand/core/error.h"

namespace inhand {

ViewPlannerOptions MultiGraspOptions::defaultRankingPlanner() {
  ViewPlannerOptions o;
  o.directions = 48;
  o.rolls = 4;
  o.fallback_ranges_m = {};
  o.ik_restarts = 0;
  o.quality.pixel_stride = 4;
  o.quality.near_hand_cell_m = 0.005;
  return o;
}

std::string MultiGraspOptions::validate() const {
  if (max_grasps < 1 || max_grasps > 50) return "max_grasps must be in 1..50";
  if (keep_ranked < 0) return "keep_ranked must be >= 0";
  std::string p = grasp.validate();
  if (!p.empty()) return "grasp." + p;
  p = ranking.validate();
  return p.empty() ? "" : "ranking." + p;
}

MultiGraspResult scanMultiGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm0,
                                const Vec3& centre_O, const Iso3& T_B_O_rest,
                                const ScanOptions& options, const MultiGraspOptions& multi,
                                const NoiseModelOptions& noise, const ScanProgress& progress) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  std::string problem = options.validate();
  if (problem.empty()) problem = multi.validate();
  if (!problem.empty()) throw Error("scan options: " + problem);
  auto log = [&](const std::string& s) {
    if (progress.log) progress.log(s);
  };
  const RobotModel& m = robot.model();
  TsdfVolume volume = makeScanVolume(centre_O, options);
  MultiGraspResult out;
  ScanResult& all = out.scan;
  const ViewPlanner ranker(m, sensor.camera(), noise, multi.ranking);

  Iso3 T_O_palm = T_O_palm0;
  GraspRecord next;
  next.T_O_palm = T_O_palm;
  for (int g = 0;; ++g) {
    log("grasp " + std::to_string(g + 1));
    ScanOptions o = options;
    if (g > 0) o.initial_views = 0;  // the model exists; Alg. 1 from the start
    next.q = robot.joints();
    ScanResult r = scanSingleGrasp(robot, sensor, T_O_palm, centre_O, o, noise, progress, &volume);
    GraspRecord rec = next;
    rec.model = r.planning_model;  // at the planning stride: a quarter of the triangles
    rec.views = int(r.views.size());
    rec.termination = r.termination;
    rec.hole_area_m2 = r.model.holeArea();
    rec.mean_entropy = r.model.meanEntropy();
    for (ViewRecord& v : r.views) all.views.push_back(v);
    all.view_evaluations += r.view_evaluations;
    all.planning_s += r.planning_s;
    all.fusion_s += r.fusion_s;
    all.frames += r.frames;
    all.model = std::move(r.model);
    all.planning_model = std::move(r.planning_model);
    out.grasps.push_back(rec);
    char line[200];
    std::snprintf(line, sizeof(line),
                  "grasp %d: %d views (%s), unknown area %.4f m², mean entropy %.3f", g + 1,
                  rec.views, rec.termination.c_str(), rec.hole_area_m2, rec.mean_entropy);
    log(line);
    if (r.termination == "no_reachable_view" && g == 0) {
      all.termination = "no_reachable_view";
      break;
    }
    if (g + 1 >= multi.max_grasps) {
      // One grasp only: the scan ends as that grasp's views did.
      all.termination = multi.max_grasps == 1 ? r.termination : "max_grasps";
      break;
    }
    // Put down, then candidates on the model so far.
    if (!robot.putDown()) {
      all.termination = "regrasp_unsupported";
      break;
    }
    GraspGeneration gen =
        generateGrasps(m, all.planning_model.mesh, T_B_O_rest, robot.joints(), multi.grasp);
    std::snprintf(line, sizeof(line),
                  "grasp candidates: %d poses, %d touching, %d stable, %d clear of the table, %zu "
                  "reachable (%.2f s)",
                  gen.tried, gen.touching, gen.stable, gen.table_free, gen.candidates.size(),
                  gen.seconds);
    log(line);
    if (gen.candidates.empty()) {
      all.termination = "no_reachable_grasp";
      break;
    }
    const double rankS = rankGrasps(ranker, all.planning_model, multi.grasp, &gen.candidates);
    const GraspCandidate& best = gen.candidates.front();
    std::snprintf(line, sizeof(line), "ranked %zu grasps in %.2f s: best quality %.4f, ε %.4f",
                  gen.candidates.size(), rankS, best.quality, best.epsilon);
    log(line);
    // Candidates are ranked by eq. 9 (the ranking planner) whatever the view planner is, so its
    // own t_q decides; a baseline view planner's threshold is in other units.
    if (best.quality < multi.ranking.t_q) {
      all.termination = "no_grasp_above_threshold";
      break;
    }
    const std::optional<Iso3> achieved = robot.pickUp(best.T_O_palm, best.q);
    if (!achieved) {
      all.termination = "pick_up_failed";
      break;
    }
    // Lift (not fused): the fingers as the robot closed them, the arm to the lift configuration.
    robot.execute({robot.joints(), m.withArm(robot.joints(), m.arm(best.q_lift))},
                  [](const JointVector&) {});
    T_O_palm = *achieved;
    next = GraspRecord{};
    next.T_O_palm = *achieved;
    next.candidates = int(gen.candidates.size());
    next.tried = gen.tried;
    next.quality = best.quality;
    next.epsilon = best.epsilon;
    next.generation_s = gen.seconds;
    next.ranking_s = rankS;
    for (const GraspCandidate& c : gen.candidates) {
      if (int(next.ranked.size()) >= multi.keep_ranked) break;
      next.ranked.push_back({c.T_O_palm, c.q, c.quality, c.epsilon});
    }
  }
  all.total_s = std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

}  // namespace inhand
