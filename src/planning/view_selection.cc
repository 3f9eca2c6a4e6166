#include "inhand/planning/view_selection.h"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/geometry/primitives.h"

namespace inhand {

namespace {
// Collision checker with the held object as its current bounding box (the model changes every
// pass, so a BVH of the model itself would be rebuilt each time).
CollisionChecker heldObjectChecker(const RobotModel& model, const Aabb& box_O, const Iso3& T_O_palm,
                                   bool enabled) {
  CollisionChecker checker(model);
  // An empty box (no model yet) holds nothing to check: its size would be −∞ and FCL's bounding
  // volumes NaN.
  if (enabled && !box_O.empty())
    checker.setHeldObject(
        transformed(makeBox(box_O.size()), Iso3(Eigen::Translation3d(box_O.center()))),
        T_O_palm.inverse());
  return checker;
}
}  // namespace

std::string ViewPlannerOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (std::string p = volumetric.validate(); !p.empty()) return "volumetric." + p;
  return {};
}

double viewThreshold(const ViewPlannerOptions& o, double area_m2) {
  return o.stop == StopRule::kRelative ? o.t_q_relative * area_m2 : o.t_q;
}

double costWeight(const ViewPlannerOptions& o, double area_m2) {
  return o.stop == StopRule::kRelative ? o.alpha_cost_relative * area_m2 : o.alpha_cost;
}

std::vector<std::string> plannerNames() {
  return {"ig",   "ig-no-hand",        "ig-no-cost",       "random",
          "area", "unobserved-voxels", "rear-side-entropy"};
}

bool applyPlannerName(const std::string& name, ViewPlannerOptions* o) {
  o->metric = ViewMetric::kInformationGain;
  o->quality.integrand = QualityIntegrand::kInformationGain;
  o->use_cost = true;
  o->hand_occlusion = true;
  o->t_q = 0.005;
  if (name == "ig") return true;
  if (name == "ig-no-hand") {
    o->hand_occlusion = false;
    return true;
  }
  if (name == "ig-no-cost") {
    o->use_cost = false;
    return true;
  }
  // The baselines rank by their own metric alone (its units are not eq. 9's, so α_cost does not
  // apply); ties go to the cheaper view.
  o->use_cost = false;
  if (name == "random") {
    o->metric = ViewMetric::kRandom;
    o->t_q = 0;
    return true;
  }
  if (name == "area") {
    o->quality.integrand = QualityIntegrand::kUnknownArea;
    o->t_q = 2e-4;
    return true;
  }
  if (name == "unobserved-voxels") {
    o->metric = ViewMetric::kUnobservedVoxels;
    o->t_q = 300;
    return true;
  }
  if (name == "rear-side-entropy") {
    o->metric = ViewMetric::kRearSideEntropy;
    o->t_q = 5000;
    return true;
  }
  return false;
}

ViewPlanner::ViewPlanner(const RobotModel& model, const DepthCameraOptions& camera,
                         const NoiseModelOptions& noise, const ViewPlannerOptions& options)
    : model_(&model), camera_(camera), noise_(noise), options_(options), occluders_(model) {
  std::string p = options.validate();
  if (!p.empty()) throw Error("view planner options: " + p);
}

Iso3 ViewPlanner::cameraPose(double range) const {
  const CameraMount& cam = model_->camera();
  Vec3 target = cam.panTilt_B + range * (cam.lookAt_B - cam.panTilt_B).normalized();
  auto T = cam.aimAt(target);
  INHAND_CHECK(T.has_value(), "presentation point outside pan/tilt range (checked at load)");
  return *T;
}

Iso3 ViewPlanner::objectPoseFor(const Iso3& T_O_C, double range) const {
  return cameraPose(range) * T_O_C.inverse();
}

std::vector<std::optional<ViewCandidate>> ViewPlanner::reach(const std::vector<Vec3>& dirs,
                                                             const Vec3& centre, const Aabb& box,
                                                             const GraspState& grasp,
                                                             bool path_free) const {
  const ViewPlannerOptions& o = options_;
  // IK for every (direction, roll) at the preferred range, then the fallback ranges for the
  // directions with no solution; keep the cheapest collision-free roll.
  const Eigen::VectorXd current = model_->arm(grasp.q);
  IkOptions ik;
  ik.random_restarts = o.ik_restarts;
  ik.method = o.ik_solver;
  CollisionChecker checker = heldObjectChecker(*model_, box, grasp.T_O_palm, o.check_collisions);
  std::vector<std::optional<ViewCandidate>> chosen(dirs.size());
  std::vector<double> ranges{o.range_m};
  ranges.insert(ranges.end(), o.fallback_ranges_m.begin(), o.fallback_ranges_m.end());
  for (size_t ri = 0; ri < ranges.size(); ++ri) {
    std::vector<size_t> open;
    for (size_t k = 0; k < dirs.size(); ++k)
      if (!chosen[k]) open.push_back(k);
    if (open.empty()) break;
    std::vector<Iso3> targets;
    std::vector<ViewCandidate> cands;
    for (size_t k : open)
      for (int r = 0; r < o.rolls; ++r) {
        ViewCandidate c;
        c.dir_O = dirs[k];
        c.range_m = ranges[ri];
        c.roll_rad = 2 * M_PI * r / o.rolls;
        c.T_O_C = cameraPoseInObject(centre, dirs[k], c.range_m, c.roll_rad);
        c.T_B_O = objectPoseFor(c.T_O_C, c.range_m);
        targets.push_back(c.T_B_O * grasp.T_O_palm);
        cands.push_back(c);
      }
    auto sols = solveIkBatch(*model_, targets, current, mixSeed(o.seed, ri), ik);
    std::vector<uint8_t> free(sols.size(), 0);
    parallelFor(0, int(sols.size()), [&](int i) {
      if (!sols[i]) return;
      free[i] = !o.check_collisions || !checker.inCollision(model_->withArm(grasp.q, *sols[i]));
    });
    for (size_t j = 0; j < open.size(); ++j) {
      std::vector<ViewCandidate> rolls;
      for (int r = 0; r < o.rolls; ++r) {
        size_t i = j * o.rolls + r;
        if (!free[i]) continue;
        ViewCandidate c = cands[i];
        c.arm = *sols[i];
        c.cost_s = trajectoryTime(*model_, current, c.arm);
        rolls.push_back(c);
      }
      // The cheapest (stable order on ties); with path_free the cheapest whose move from
      // grasp.q is collision-free.
      std::stable_sort(
          rolls.begin(), rolls.end(),
          [](const ViewCandidate& a, const ViewCandidate& b) { return a.cost_s < b.cost_s; });
      for (const ViewCandidate& c : rolls)
        if (!path_free || !o.check_collisions ||
            checker.pathFree(grasp.q, model_->withArm(grasp.q, c.arm), 0.05)) {
          chosen[open[j]] = c;
          break;
        }
    }
  }
  return chosen;
}

ViewQualityScene ViewPlanner::qualityScene(const ObjectModel& S_obj) const {
  return ViewQualityScene(S_obj, camera_, noise_, options_.quality);
}

namespace {
// Whether select() may score some views at the prescreen stride (coarse to fine).
bool mayGoCoarse(const ViewPlannerOptions& o) {
  return o.refine > 0 && o.prescreen_stride > o.quality.pixel_stride;
}
bool isEq9(const ViewPlannerOptions& o) {
  return o.metric == ViewMetric::kInformationGain &&
         o.quality.integrand == QualityIntegrand::kInformationGain;
}
}  // namespace

std::vector<double> ViewPlanner::viewBoundsWithoutHand(ViewQualityScene& scene) const {
  const ViewPlannerOptions& o = options_;
  const ObjectModel& S_obj = scene.model();
  if (o.metric != ViewMetric::kInformationGain || S_obj.mesh.empty()) return {};
  scene.setNearHand(nullptr);
  const Vec3 centre = S_obj.mesh.bounds().center();
  std::vector<double> ranges{o.range_m};
  ranges.insert(ranges.end(), o.fallback_ranges_m.begin(), o.fallback_ranges_m.end());
  std::vector<Iso3> poses;
  for (const Vec3& d : fibonacciSphere(o.directions))
    for (double range : ranges)
      for (int r = 0; r < o.rolls; ++r)
        poses.push_back(cameraPoseInObject(centre, d, range, 2 * M_PI * r / o.rolls));
  // select() scores at the fine stride, and at the prescreen stride when it goes coarse to fine.
  std::vector<int> strides{o.quality.pixel_stride};
  if (mayGoCoarse(o)) strides.push_back(o.prescreen_stride);
  std::vector<double> bound(poses.size(), 0.0);
  parallelForThreads(0, int(poses.size()), [&](int i) {
    for (int stride : strides)
      bound[size_t(i)] =
          std::max(bound[size_t(i)], scene.quality(poses[size_t(i)], {}, nullptr, stride));
  });
  return bound;
}

double ViewPlanner::graspQualityBound(ViewQualityScene& scene,
                                      std::vector<double>* view_bounds) const {
  if (view_bounds) view_bounds->clear();
  if (options_.metric != ViewMetric::kInformationGain)
    return std::numeric_limits<double>::infinity();
  std::vector<double> bound = viewBoundsWithoutHand(scene);
  const double best = bound.empty() ? 0.0 : *std::max_element(bound.begin(), bound.end());
  if (view_bounds) *view_bounds = std::move(bound);
  return best;
}

std::optional<double> ViewPlanner::bestViewQuality(ViewQualityScene& scene, const GraspState& grasp,
                                                   std::shared_ptr<const NearHandGrid> nearHand,
                                                   const std::vector<double>& bounds,
                                                   int* reachable) const {
  const ViewPlannerOptions& o = options_;
  const ObjectModel& S_obj = scene.model();
  const std::vector<Vec3> dirs = fibonacciSphere(o.directions);
  const size_t nRanges = 1 + o.fallback_ranges_m.size();
  if (!isEq9(o) || mayGoCoarse(o) || S_obj.mesh.empty() ||
      bounds.size() != dirs.size() * nRanges * size_t(o.rolls))
    return std::nullopt;
  const Vec3 centre = S_obj.mesh.bounds().center();
  std::vector<std::optional<ViewCandidate>> chosen =
      reach(dirs, centre, S_obj.mesh.bounds(), grasp);
  scene.setNearHand(o.hand_occlusion ? std::move(nearHand) : nullptr);
  // Each reachable direction's view with its bound: the (range, roll) reach() chose.
  std::vector<std::pair<double, size_t>> order;
  for (size_t k = 0; k < chosen.size(); ++k) {
    if (!chosen[k]) continue;
    size_t ri = nRanges;
    if (chosen[k]->range_m == o.range_m) {
      ri = 0;
    } else {
      for (size_t j = 0; j < o.fallback_ranges_m.size() && ri == nRanges; ++j)
        if (o.fallback_ranges_m[j] == chosen[k]->range_m) ri = j + 1;
    }
    const long roll = std::lround(chosen[k]->roll_rad * o.rolls / (2 * M_PI));
    INHAND_CHECK(ri < nRanges && roll >= 0 && roll < o.rolls, "view outside the bounds' table");
    order.emplace_back(bounds[(k * nRanges + ri) * size_t(o.rolls) + size_t(roll)], k);
  }
  *reachable = int(order.size());
  std::stable_sort(order.begin(), order.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  // Best bound first, a view per thread at a time, until no view left can beat the best found.
  const int threads = std::max(1, threadCount());
  double best = 0;
  std::vector<double> q(static_cast<size_t>(threads));
  for (size_t next = 0; next < order.size() && order[next].first > best;) {
    const int batch = int(std::min(order.size() - next, size_t(threads)));
    parallelForThreads(0, batch, [&](int b) {
      const ViewCandidate& c = *chosen[order[next + size_t(b)].second];
      std::vector<Occluder> occ;
      if (o.hand_occlusion) occ = occluders_.at(model_->withArm(grasp.q, c.arm), c.T_B_O.inverse());
      q[size_t(b)] = scene.quality(c.T_O_C, occ, nullptr, o.quality.pixel_stride);
    });
    for (int b = 0; b < batch; ++b) best = std::max(best, q[size_t(b)]);
    next += size_t(batch);
  }
  return best;
}

ViewSelection ViewPlanner::select(const ObjectModel& S_obj, const GraspState& grasp,
                                  const std::vector<Vec3>& used,
                                  std::shared_ptr<const NearHandGrid> nearHand,
                                  const TsdfVolume* volume) const {
  if (S_obj.mesh.empty()) return ViewSelection{};
  ViewQualityScene scene = qualityScene(S_obj);
  return select(scene, grasp, used, std::move(nearHand), volume);
}

namespace {
// Line 5 of Alg. 1: of `n` directions over the sphere, those at least min_angle_deg from every
// used view.
std::vector<Vec3> directionsAwayFrom(const std::vector<Vec3>& used, int n, double min_angle_deg) {
  const double cosMin = std::cos(min_angle_deg * M_PI / 180);
  std::vector<Vec3> dirs;
  for (const Vec3& d : fibonacciSphere(n)) {
    bool far = true;
    for (const Vec3& u : used)
      if (d.dot(u.normalized()) > cosMin) {
        far = false;
        break;
      }
    if (far) dirs.push_back(d);
  }
  return dirs;
}

// Best score first; ties to the cheaper view, then by direction (deterministic).
bool betterView(const ViewCandidate& a, const ViewCandidate& b) {
  if (a.score != b.score) return a.score > b.score;
  if (a.cost_s != b.cost_s) return a.cost_s < b.cost_s;
  return a.dir_O.x() < b.dir_O.x();
}

// Lines 11–14 for one candidate at a pixel stride: its quality by the planner's metric (eq. 9,
// a volumetric one, or a random draw per (seed, pass, direction), independent of threads and of
// the other candidates' reachability), its eq. 9 gain when that is the metric at full
// resolution, its score (less α·cost).
struct CandidateScoring {
  const ViewPlannerOptions& o;
  const RobotModel& model;
  const RobotOccluders& occluders;
  const GraspState& grasp;
  ViewQualityScene& scene;
  const VolumetricScorer* voxels;
  uint64_t passSeed;
  double alpha;
  bool eq9;

  // The robot where the candidate puts it, as occluders in the object frame (none without
  // hand reasoning).
  std::vector<Occluder> occludersOf(const ViewCandidate& c) const {
    if (!o.hand_occlusion) return {};
    return occluders.at(model.withArm(grasp.q, c.arm), c.T_B_O.inverse());
  }
  void operator()(size_t k, ViewCandidate& c, int stride) const {
    if (o.metric == ViewMetric::kRandom) {
      Rng rng = makeRng(passSeed, k);
      c.quality = std::uniform_real_distribution<double>(0.0, 1.0)(rng);
    } else if (o.metric == ViewMetric::kInformationGain) {
      c.quality = scene.quality(c.T_O_C, occludersOf(c), nullptr, stride);
    } else {
      c.quality = voxels->score(c.T_O_C,
                                o.metric == ViewMetric::kUnobservedVoxels
                                    ? VolumetricMetric::kUnobservedVoxels
                                    : VolumetricMetric::kRearSideEntropy,
                                occludersOf(c));
    }
    c.pixel_stride = stride;
    if (eq9) c.gain = stride == o.quality.pixel_stride ? c.quality : NAN;
    c.score = c.quality - (o.use_cost ? alpha * c.cost_s : 0.0);
  }
};

// Line 15: the best of `pool` (betterView) whose joint-space path from q is collision-free
// (checker null: not checked).
std::optional<ViewCandidate> bestWithFreePath(std::vector<const ViewCandidate*> pool,
                                              const CollisionChecker* checker,
                                              const RobotModel& model, const JointVector& q) {
  std::sort(pool.begin(), pool.end(),
            [](const ViewCandidate* a, const ViewCandidate* b) { return betterView(*a, *b); });
  for (const ViewCandidate* c : pool)
    if (!checker || checker->pathFree(q, model.withArm(q, c->arm), 0.05)) return *c;
  return std::nullopt;
}

// Under the relative rule a baseline stops as ig does: eq. 9 (`gainOf` at a pixel stride) of
// every reachable candidate, coarse to fine as ig's own pass (the `refine` largest at the
// prescreen stride, then at full resolution); their gains set, the largest returned.
double largestGain(std::vector<std::optional<ViewCandidate>>& chosen,
                   const std::vector<size_t>& reachable, const ViewPlannerOptions& o,
                   const std::function<double(const ViewCandidate&, int)>& gainOf, int* refined) {
  const int fine = o.quality.pixel_stride;
  const int coarseStride = o.refine > 0 && o.prescreen_stride > fine ? o.prescreen_stride : fine;
  std::vector<double> coarseGain(chosen.size(), 0.0);
  parallelForThreads(0, int(reachable.size()), [&](int i) {
    coarseGain[reachable[size_t(i)]] = gainOf(*chosen[reachable[size_t(i)]], coarseStride);
  });
  std::vector<size_t> order = reachable;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return coarseGain[a] > coarseGain[b]; });
  if (coarseStride != fine && o.refine > 0 && order.size() > size_t(o.refine))
    order.resize(size_t(o.refine));
  if (coarseStride != fine) {
    parallelForThreads(0, int(order.size()), [&](int i) {
      chosen[order[size_t(i)]]->gain = gainOf(*chosen[order[size_t(i)]], fine);
    });
  } else {
    for (size_t k : order) chosen[k]->gain = coarseGain[k];
  }
  double maxGain = 0;
  for (size_t k : order) maxGain = std::max(maxGain, chosen[k]->gain);
  *refined = int(order.size());
  return maxGain;
}

// Coarse to fine: the candidates (scored at the prescreen stride) in order of score, in batches
// of `refine` evaluated at full resolution (after the first batch only those within half the
// threshold) until `pick` finds the best among those refined.
std::optional<ViewCandidate> refineInBatches(
    const std::vector<std::optional<ViewCandidate>>& chosen, const std::vector<size_t>& reachable,
    int refine, double threshold,
    const std::function<void(const std::vector<size_t>&)>& evaluateFine,
    const std::function<std::optional<ViewCandidate>(const std::vector<size_t>&)>& pick,
    int* refinedCount) {
  std::vector<size_t> coarse = reachable;
  std::sort(coarse.begin(), coarse.end(),
            [&](size_t a, size_t b) { return betterView(*chosen[a], *chosen[b]); });
  std::vector<size_t> refined;
  std::optional<ViewCandidate> best;
  for (size_t next = 0; next < coarse.size() && !best;) {
    std::vector<size_t> batch;
    for (; next < coarse.size() && batch.size() < size_t(refine); ++next)
      if (refined.empty() || chosen[coarse[next]]->quality >= 0.5 * threshold)
        batch.push_back(coarse[next]);
    if (batch.empty()) break;
    evaluateFine(batch);
    refined.insert(refined.end(), batch.begin(), batch.end());
    best = pick(refined);
  }
  *refinedCount = int(refined.size());
  return best;
}
}  // namespace

ViewSelection ViewPlanner::select(ViewQualityScene& scene, const GraspState& grasp,
                                  const std::vector<Vec3>& used,
                                  std::shared_ptr<const NearHandGrid> nearHand,
                                  const TsdfVolume* volume) const {
  const ObjectModel& S_obj = scene.model();
  const bool volumetric = options_.metric == ViewMetric::kUnobservedVoxels ||
                          options_.metric == ViewMetric::kRearSideEntropy;
  if (volumetric && !volume) throw Error("the volumetric view metrics need the volume");
  using Clock = std::chrono::steady_clock;
  auto secs = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  const auto t0 = Clock::now();
  const ViewPlannerOptions& o = options_;
  ViewSelection out;
  if (S_obj.mesh.empty()) return out;
  const Vec3 centre = S_obj.mesh.bounds().center();
  const double area = S_obj.mesh.area();
  const bool eq9 = o.metric == ViewMetric::kInformationGain &&
                   o.quality.integrand == QualityIntegrand::kInformationGain;
  // Under the relative rule every planner stops when no view's eq. 9 gain reaches t_q; a
  // baseline then picks by its own metric with no threshold of its own.
  const bool commonStop = o.stop == StopRule::kRelative && !eq9;
  out.t_q = viewThreshold(o, area);
  const double ownThreshold = commonStop ? -std::numeric_limits<double>::infinity() : out.t_q;
  const double alpha = costWeight(o, area);

  // Line 5: directions at least t_θ from every used view.
  const std::vector<Vec3> dirs = directionsAwayFrom(used, o.directions, o.min_angle_deg);
  out.directions = int(dirs.size());

  // Line 7: free DOFs.
  const auto tIk = Clock::now();
  std::vector<std::optional<ViewCandidate>> chosen =
      reach(dirs, centre, S_obj.mesh.bounds(), grasp);
  out.ik_s = secs(tIk);
  CollisionChecker checker =
      heldObjectChecker(*model_, S_obj.mesh.bounds(), grasp.T_O_palm, o.check_collisions);

  // Lines 11–14: quality and score of each reachable candidate, one candidate per core at a time.
  const auto tQ = Clock::now();
  // Without hand reasoning (ablation) neither the robot occludes nor the t_hand rule applies.
  scene.setNearHand(o.hand_occlusion ? std::move(nearHand) : nullptr);
  std::vector<size_t> reachable;
  for (size_t k = 0; k < chosen.size(); ++k)
    if (chosen[k]) reachable.push_back(k);
  out.reachable = int(reachable.size());
  std::optional<VolumetricScorer> voxels;
  if (volumetric) voxels.emplace(*volume, camera_, o.volumetric);
  // Random: one draw per (seed, pass, direction), independent of threads and of the other
  // candidates' reachability.
  const uint64_t passSeed = mixSeed(o.seed, 0x7a11 + used.size());
  const CandidateScoring scoring{
      o, *model_, occluders_, grasp, scene, voxels ? &*voxels : nullptr, passSeed, alpha, eq9};
  auto evaluateAll = [&](const std::vector<size_t>& ks, int stride) {
    parallelForThreads(0, int(ks.size()),
                       [&](int i) { scoring(ks[size_t(i)], *chosen[ks[size_t(i)]], stride); });
  };
  // Line 15: the best score among `pool` with q ≥ t_q whose joint-space path is collision-free.
  auto pick = [&](const std::vector<size_t>& pool) -> std::optional<ViewCandidate> {
    std::vector<const ViewCandidate*> order;
    for (size_t k : pool)
      if (chosen[k]->quality >= ownThreshold) order.push_back(&*chosen[k]);
    return bestWithFreePath(order, o.check_collisions ? &checker : nullptr, *model_, grasp.q);
  };
  const int fine = o.quality.pixel_stride;
  const bool coarseToFine = o.metric == ViewMetric::kInformationGain && o.refine > 0 &&
                            o.prescreen_stride > fine && reachable.size() > size_t(o.refine);
  out.evaluated = int(reachable.size());
  // eq. 9 for the baselines under the relative rule (on a scene of its own for `area`).
  std::optional<ViewQualityScene> own;
  ViewQualityScene* gainScene = &scene;
  if (commonStop && o.quality.integrand != QualityIntegrand::kInformationGain) {
    ViewQualityOptions q = o.quality;
    q.integrand = QualityIntegrand::kInformationGain;
    own.emplace(S_obj, camera_, noise_, q);
    own->setNearHand(o.hand_occlusion ? scene.nearHand() : nullptr);
    gainScene = &*own;
  }
  auto gainOf = [&](const ViewCandidate& c, int stride) {
    return gainScene->quality(c.T_O_C, scoring.occludersOf(c), nullptr, stride);
  };
  // eq. 9 of every reachable candidate, coarse to fine as ig's own pass: the largest decides.
  if (commonStop && largestGain(chosen, reachable, o, gainOf, &out.refined) < out.t_q) {
    out.quality_s = secs(tQ);
    for (size_t k : reachable) out.candidates.push_back(*chosen[k]);
    out.total_s = secs(t0);
    return out;
  }
  if (!coarseToFine) {
    evaluateAll(reachable, fine);
    if (!commonStop) out.refined = out.evaluated;
    out.best = pick(reachable);
  } else {
    evaluateAll(reachable, o.prescreen_stride);
    out.best = refineInBatches(
        chosen, reachable, o.refine, ownThreshold,
        [&](const std::vector<size_t>& batch) { evaluateAll(batch, fine); }, pick, &out.refined);
  }
  // The chosen baseline view's own eq. 9 gain at full resolution (the planner's prediction).
  if (commonStop && out.best && std::isnan(out.best->gain))
    out.best->gain = gainOf(*out.best, fine);
  out.quality_s = secs(tQ);
  for (size_t k : reachable) out.candidates.push_back(*chosen[k]);
  out.total_s = secs(t0);
  return out;
}

}  // namespace inhand
