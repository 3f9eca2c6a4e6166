#include "inhand/config/scan_config.h"

#include <cstdio>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

#include "inhand/core/error.h"

namespace inhand {

namespace {

template <class T>
using Names = std::vector<std::pair<T, const char*>>;

// "a, b or c"
template <class T>
std::string alternatives(const Names<T>& names) {
  std::string s;
  for (size_t i = 0; i < names.size(); ++i)
    s += (i == 0 ? "" : i + 1 == names.size() ? " or " : ", ") + std::string(names[i].second);
  return s;
}

const Names<HandMode> kHandModes = {{HandMode::kNaive, "naive"},
                                    {HandMode::kCarveOnly, "carve"},
                                    {HandMode::kCarveAndEmpty, "carve-empty"}};
const Names<SurfaceMethod> kSurfaceMethods = {{SurfaceMethod::kSurfaceNets, "surface_nets"},
                                              {SurfaceMethod::kTetrahedra, "tetrahedra"}};
const Names<IkMethod> kIkMethods = {{IkMethod::kDampedLeastSquares, "dls"},
                                    {IkMethod::kKdlLma, "kdl_lma"}};
const Names<StopRule> kStopRules = {{StopRule::kRelative, "relative"},
                                    {StopRule::kAbsolute, "absolute"}};
const Names<PrimaryVisibility> kVisibilities = {{PrimaryVisibility::kAuto, "auto"},
                                                {PrimaryVisibility::kRaster, "raster"},
                                                {PrimaryVisibility::kRayCast, "ray_cast"}};
const Names<GraspApproach> kApproaches = {{GraspApproach::kPalm, "palm"},
                                          {GraspApproach::kFirstContact, "first_contact"}};
const Names<bool> kPickUps = {{false, "palm"}, {true, "first_contact"}};
const Names<std::string> kStarts = {{"table", "table"}, {"held", "held"}};

// The tables. Each visits every option of its struct with its key and meaning; the visitor
// reads, writes or documents it.

template <class V>
void visitQuality(V& v, ViewQualityOptions& o) {
  v.num("t_hand_m", o.t_hand_m, "hits this close to the hand are skipped (eq. 9), m");
  v.num("max_incidence_deg", o.max_incidence_deg, "camera ray vs surface normal at most, degrees");
  v.num("max_projector_incidence_deg", o.max_projector_incidence_deg,
        "projector ray vs surface normal at most, degrees");
  v.num("near_hand_cell_m", o.near_hand_cell_m, "resolution of the near-hand grid, m");
  v.integer("pixel_stride", o.pixel_stride, "eq. 9 over every n-th pixel in u and v");
  v.choice("visibility", o.visibility, kVisibilities,
           "primary visibility: rasterised or ray cast (auto: raster where it is faster)");
}

template <class V>
void visitVolumetric(V& v, VolumetricOptions& o) {
  v.integer("ray_stride", o.ray_stride, "volumetric baselines: every n-th pixel in u and v");
  v.num("p_unknown", o.p_unknown, "occupancy of an unknown voxel");
  v.num("p_free", o.p_free, "occupancy of a voxel in front of the surface");
  v.num("p_occupied", o.p_occupied, "occupancy of a voxel on or just behind the surface");
  v.num("min_visibility", o.min_visibility, "a ray stops when its visibility falls below this");
}

template <class V>
void visitPlanner(V& v, ViewPlannerOptions& o) {
  v.integer("directions", o.directions, "candidate directions on the unit sphere (Alg. 1)");
  v.num("min_angle_deg", o.min_angle_deg, "t_θ: minimum angle to every used view, degrees");
  v.num("range_m", o.range_m, "preferred camera-to-object-centre distance, m");
  v.numbers("fallback_ranges_m", o.fallback_ranges_m,
            "ranges tried only where range_m has no IK solution, m");
  v.integer("rolls", o.rolls, "rolls swept about each viewing direction");
  v.num("alpha_cost", o.alpha_cost,
        "α_cost: score = quality − α_cost · trajectory seconds (absolute rule)");
  v.choice("stop", o.stop, kStopRules,
           "relative: t_q and α_cost scale with S_obj's surface area, every planner stops when no "
           "view's eq. 9 gain reaches t_q; absolute: the paper's t_q and α_cost, each planner on "
           "its own threshold");
  v.num("t_q", o.t_q, "t_q: minimum quality of a view that counts (absolute rule)");
  v.num("t_q_relative", o.t_q_relative,
        "relative rule: t_q = this · S_obj's area, nats per m² (0.036: 1% of the surface seen "
        "for the first time)");
  v.num("alpha_cost_relative", o.alpha_cost_relative,
        "relative rule: α_cost = this · S_obj's area, per second");
  v.boolean("use_cost", o.use_cost, "false: score = quality (ablation)");
  v.boolean("hand_occlusion", o.hand_occlusion,
            "false: no robot occluders, no t_hand rule (ablation)");
  v.boolean("check_collisions", o.check_collisions,
            "reject candidates whose arm, hand or object hit the table or base");
  v.integer("ik_restarts", o.ik_restarts, "random IK restarts after the seeded attempt");
  v.choice("ik_solver", o.ik_solver, kIkMethods, "IK: damped least squares or KDL's LMA");
  v.integer("prescreen_stride", o.prescreen_stride,
            "coarse pass: every n-th pixel for every reachable candidate");
  v.integer("refine", o.refine, "the best this many by the coarse pass are scored in full");
  v.object("quality", "eq. 9", [&](V& s) { visitQuality(s, o.quality); });
  v.object("volumetric", "the volumetric baselines (Isler et al. 2016)",
           [&](V& s) { visitVolumetric(s, o.volumetric); });
}

template <class V>
void visitConfig(V& v, ScanConfig& c) {
  ScanOptions& s = c.scan;
  MultiGraspOptions& m = c.multi;
  v.string("robot", c.robot, "robot config JSON (empty: data/robots/wam_barretthand.json)");
  v.num("voxel_m", s.voxel_m, "volume voxel size, m");
  v.num("volume_size_m", s.volume_size_m, "edge of the cubic volume, m");
  v.num("truncation_m", s.volume_budget.truncation_m,
        "half-width μ of the signed-distance band, m (0: 4 voxels)");
  v.num("band_sigmas", s.volume_budget.band_sigmas,
        "a measurement reaches this many of its σ behind its smoothed surface (at least a voxel "
        "across the surface, at most μ), so that both sides of a thin wall are kept; 0: μ behind "
        "its depth");
  v.boolean("smooth_depth", s.volume_budget.smooth_depth,
            "update the voxels from each pixel's surface smoothed over its 5×5 neighbourhood "
            "(a fitted plane) rather than from its raw depth");
  v.boolean("fit_volume", s.fit_volume,
            "from the table: a cube of 1.5 × the object's extent + 4 cm, as many voxels across");
  v.integer("torque_readings", s.torque_readings,
            "joint-torque readings at rest after each view that weigh the object (noise 1/√N)");
  v.num("t_hand_m", s.t_hand_m, "measurements this close to the robot only carve (§IV), m");
  v.integer("carve_radius_px", s.carve_radius_px, "… or this close to it in the image, pixels");
  v.num("edge_jump_m", s.edge_jump_m,
        "in the hand, a pixel next to one farther by more than this is not fused (a "
        "silhouette); 0: off, m");
  v.choice("hand_mode", s.hand_mode, kHandModes, "the robot's own measurements (Fig. 3 a, b, c)");
  v.integer("initial_views", s.initial_views, "directions of the initial trajectory");
  v.integer("max_views", s.max_views, "Alg. 1 views per grasp at most");
  v.integer("planning_stride", s.planning_stride, "S_obj for planning from every n-th voxel");
  v.choice("planning_mesh", s.planning_method, kSurfaceMethods, "S_obj for planning");
  v.object("planner", "the view planner (Alg. 1)", [&](V& p) { visitPlanner(p, s.planner); });
  v.object(
      "tracking", "in-hand frames aligned with the hand and the model (arm error, §II)", [&](V& t) {
        TrackingOptions& o = s.tracking;
        t.boolean("enabled", o.enabled, "off: frames fused with the poses the robot reports");
        t.integer("iterations", o.iterations, "ICP iterations per frame");
        t.num("gate_m", o.gate_m, "depth gate of the first iteration, m");
        t.num("final_gate_m", o.final_gate_m, "… shrinking to this, m");
        t.integer("min_inliers", o.min_inliers, "fewer aligned points: the frame is not fused");
        t.num("max_rms_ratio", o.max_rms_ratio,
              "a final residual above this many sensor σ: the frame is not fused");
        t.num("max_correction_m", o.max_correction_m,
              "a correction moving the palm farther: the frame is not fused, m");
        t.num("hand_spacing_m", o.hand_spacing_m, "spacing of the hand's surface samples, m");
        t.integer("max_object_points", o.max_object_points,
                  "the model's observed surface, subsampled to this many points");
        t.boolean("filter", o.filter,
                  "corrections Kalman-filtered over frames (a random walk); off: each frame's own");
        t.num("drift_m", o.drift_m, "the correction's drift per radian of joint motion, m");
        t.num("drift_rad", o.drift_rad, "… and of its rotation, rad");
        t.num("frame_drift_m", o.frame_drift_m, "the correction's drift per frame, m");
        t.num("frame_drift_rad", o.frame_drift_rad, "… and of its rotation, rad");
        t.num("pair_information", o.pair_information,
              "each aligned point pair counts as this fraction of an independent measurement");
        t.boolean("in_hand", o.in_hand,
                  "after each pick-up the object's pose in the hand from a frame (the model "
                  "aligned with it); off: as the robot reports it");
        t.num("in_hand_significance", o.in_hand_significance,
              "a pick-up's palm error is carried to the grasp only when its squared "
              "Mahalanobis distance exceeds this (χ²(6) at 99 %)");
        t.boolean("slip_check", o.slip_check,
                  "each in-hand frame, the model alone aligned with it: the object's slip in the "
                  "hand found, the grasp corrected, frames not fused while it moves");
        t.num("slip_m", o.slip_m,
              "a significant correction moving the model's surface farther (RMS along its normals) "
              "is a slip, m");
        t.integer("slip_points", o.slip_points,
                  "the model's observed surface, subsampled to this many points for it");
        t.num("slip_gate_m", o.slip_gate_m, "its first iteration's depth gate, m");
      });
  v.object("checks", "in-hand frames that are not fused (docs/reliability.md)", [&](V& k) {
    FrameChecks& o = s.checks;
    k.num("min_valid_fraction", o.min_valid_fraction,
          "fewer valid depth pixels than this fraction: an empty frame");
    k.num("max_path_deviation_rad", o.max_path_deviation_rad,
          "joints farther from the planned path: a jump, not fused (0: no check), rad");
    k.num("min_support", o.min_support,
          "the model's points in view the frame must bear out, or the object is not in the hand "
          "(0: no check)");
    k.integer("min_points", o.min_points, "… when at least this many are in view");
    k.integer("lost_after", o.lost_after, "that many such frames in a row: object_lost");
    k.num("max_free_space_fraction", o.max_free_space_fraction,
          "at most this fraction of a frame's depth in the volume where the model knows space is "
          "empty (1: no check)");
  });
  v.integer("max_grasps", m.max_grasps, "grasps in all (1: no re-grasping)");
  v.choice("start", c.start, kStarts, "table: from the table top (§V); held: at a given grasp");
  v.object("table_top", "the table-top stage", [&](V& t) {
    TableTopOptions& o = m.table_top;
    t.integer("frames", o.frames, "depth frames of the object where it rests");
    t.num("aim_height_m", o.aim_height_m, "the camera aims this far above the rest pose, m");
    t.num("search_radius_m", o.search_radius_m, "object points within this of the rest pose, m");
    t.num("above_table_m", o.above_table_m, "… and this far above the fitted table plane, m");
    t.num("cluster_cell_m", o.cluster_cell_m, "the object: the largest cluster at this cell, m");
    t.integer("min_points", o.min_points, "fewer object points: object_not_found");
    t.num("plane_inlier_m", o.plane.inlier_m, "RANSAC: a point this close supports a plane, m");
    t.integer("plane_iterations", o.plane.iterations, "RANSAC hypotheses");
    t.num("plane_max_tilt_deg", o.plane.max_tilt_deg,
          "RANSAC: planes tilted more from the table's normal lose, degrees");
  });
  v.object("grasp", "grasp candidates and their ranking", [&](V& g) {
    GraspOptions& o = m.grasp;
    g.choice("approach", o.approach, kApproaches,
             "how the open hand comes in: palm slides to contact, or the whole hand to first "
             "contact");
    g.integer("approaches", o.approaches, "approach directions over the sphere");
    g.integer("max_failed_pick_ups", o.max_failed_pick_ups,
              "failed pick-ups per grasp before the scan gives up on it");
    g.integer("rolls", o.rolls, "palm rolls about each approach (over 180°)");
    g.numbers("spreads", o.spreads, "spread joint values tried");
    g.numbers("preshapes", o.preshapes,
              "fingers this fraction of the way closed as the hand comes in");
    g.numbers("edge_spreads", o.edge_spreads, "edge poses at each of these spreads");
    g.num("edge_inset_m", o.edge_inset_m, "edge poses: the model ends this far beyond the palm, m");
    g.boolean("pinch_poses", o.pinch_poses,
              "pinch poses: straight down, fingertips straddling the model's footprint");
    g.boolean("two_finger_pinch", o.two_finger_pinch,
              "two-finger pinch poses: the first two fingers facing, the others left open");
    g.num("two_finger_spread", o.two_finger_spread,
          "the spread at which the first two fingers face each other, rad");
    g.num("friction", o.friction, "μ at each contact (stability)");
    g.integer("cone_edges", o.cone_edges, "friction-cone linearisation");
    g.integer("wrench_directions", o.wrench_directions, "directions sampled for ε");
    g.num("contact_m", o.contact_m, "model points this close to the hand are in contact, m");
    g.num("contact_cell_m", o.contact_cell_m, "contact pooling cell, m");
    g.num("min_epsilon", o.min_epsilon, "ε below this: not a stable grasp");
    g.num("stability_weight", o.stability_weight, "ranking score = quality + weight · ε");
    g.integer("max_candidates", o.max_candidates, "ranked at most (the most stable first)");
    g.num("lift_m", o.lift_m, "the object is lifted this far after the pick, m");
    g.object("hold", "the hold test: candidates closed, lifted and turned on the model in physics",
             [&](V& h) {
               HoldTestOptions& x = o.hold;
               h.boolean("enabled", x.enabled, "test the candidates; those that hold go first");
               h.integer("max_candidates", x.max_candidates, "the first this many are tested");
               h.integer("max_tested", x.max_tested,
                         "… and when none holds the model, the next as many, up to this many");
               h.num("density_kg_m3", x.density_kg_m3,
                     "assumed: the model's mass is its volume times this, kg/m³");
               h.num("lift_m", x.lift_m, "lifted this far straight up, m");
               h.num("lift_s", x.lift_s, "… over this long, s");
               h.num("turn_rad", x.turn_rad, "then turned this far about a horizontal axis, rad");
               h.num("turn_s", x.turn_s, "… over this long, s");
               h.num("max_slip_m", x.max_slip_m, "moved farther in the hand: it did not hold, m");
               h.num("margin_mass", x.margin_mass,
                     "those that held, tried this many times as heavy: those that hold go first");
               h.num("margin_friction", x.margin_friction, "… with this fraction of the friction");
               h.num("pose_tolerance_m", x.pose_tolerance_m,
                     "those that held, tried with the model moved this far each way across the "
                     "table: the first that holds in all goes first (0: not tried), m");
               h.integer("robust_checked", x.robust_checked,
                         "… at most this many of them, in their order");
             });
    g.object("ranking", "Alg. 1 as used to rank grasp candidates",
             [&](V& p) { visitPlanner(p, m.ranking); });
  });
  v.object("mesh", "the model's surface", [&](V& o) {
    o.num("hole_sigma_m", s.mesh.hole_sigma_m, "σ of never-observed (hole-filled) surface, m");
    o.boolean("drop_floating_unknown", s.mesh.drop_floating_unknown,
              "drop components with no observed vertex");
    o.num("min_component_fraction", s.mesh.min_component_fraction,
          "drop components smaller than this fraction of the largest");
  });
  v.object("eval", "scoring against the true mesh (simulation)", [&](V& o) {
    o.integer("samples", c.eval.samples, "points drawn on each surface");
    o.num("tau_m", c.eval.tau_m, "coverage radius τ, m");
    o.numbers("fscore_m", c.eval.fscore_m, "F-score thresholds, m");
    o.num("detached_m", c.eval.detached_m,
          "a model piece none of whose vertices lies this near the true surface is detached "
          "(summary detached_area_m2), m");
  });
  v.object("sim", "the simulator", [&](V& o) {
    o.num("frame_rate_hz", c.sim.frame_rate_hz, "sensor frame rate along trajectories, Hz");
    o.integer("frame_subsample", c.sim.frame_subsample,
              "deliver every n-th sensor frame to the scan (1: all)");
    o.boolean("noise", c.sim.noise, "sensor noise");
    o.object("colour", "a colour camera beside the depth camera (Kinect-class, 640x480)",
             [&](V& k) {
               SimColourOptions& x = c.sim.colour;
               k.boolean("enabled", x.enabled, "render colour images and fuse their colours");
               k.num("ambient", x.ambient,
                     "lit fraction where the lamp at the camera grazes a surface (Lambertian)");
               k.num("noise_sigma", x.noise_sigma, "per-pixel Gaussian noise, 8-bit levels");
               k.num("exposure_sigma", x.exposure_sigma,
                     "per-frame exposure change, relative (Gaussian σ)");
             });
    o.num("room_radius_m", c.sim.room_radius_m, "a room around the camera (0: none), m");
    o.boolean("check_hold", c.sim.check_hold, "grasps must be force closure on the true object");
    o.num("friction", c.sim.friction, "μ of the true contacts");
    o.num("hold_min_epsilon", c.sim.hold_min_epsilon, "ε a grasp needs to hold");
    o.num("arm_error_m", c.sim.arm_error_m,
          "the arm's error: the palm's median distance from the reported joints' FK where "
          "objects are presented (fixed offsets and gravity's sag), m");
    o.num("arm_error_gravity", c.sim.arm_error_gravity,
          "joint sag proportional to gravity's torque at the configuration (URDF masses), as a "
          "fraction of the fixed offsets at a typical configuration");
    o.num("arm_error_drift", c.sim.arm_error_drift,
          "slow drift of every joint (periods 20-120 s), RMS as a fraction of the fixed offsets");
    o.num("arm_error_noise", c.sim.arm_error_noise,
          "per-frame joint noise, RMS as a fraction of the fixed offsets");
    o.num("torque_noise_nm", c.sim.torque_noise_nm,
          "noise (standard deviation, N·m) of the joint torques the arm reports at rest, from "
          "which the scan weighs the object");
    o.boolean("grasp_error", c.sim.grasp_error,
              "the arm's error also at pick-ups: the object sits in the hand off where the "
              "reported joints say");
    o.choice("pick_up", c.sim.pick_up_first_contact, kPickUps,
             "the simulated pick-up: palm backed off, or a guarded move to first contact");
    o.object(
        "physics",
        "MuJoCo rigid-body physics for pick-ups, held motions and put-downs "
        "(docs/physics.md)",
        [&](V& p) {
          PhysicsOptions& x = c.sim.physics;
          p.boolean("enabled", x.enabled,
                    "simulate every manipulation (off: the object moves rigidly with the hand)");
          p.num("density_kg_m3", x.density_kg_m3, "the object's density, kg/m³");
          p.num("mass_kg", x.mass_kg, "the object's mass (0: from the density), kg");
          p.num("timestep_s", x.timestep_s, "MuJoCo's time step, s");
          p.num("finger_force_n", x.finger_force_n, "each finger's force limit at its tip, N");
          p.num("touch_force_n", x.touch_force_n,
                "fingers close with this force until each meets something, then squeeze, N");
          p.num("finger_close_time_s", x.finger_close_time_s, "fingers open to closed, s");
          p.num("hold_force_factor", x.hold_force_factor,
                "a closed finger resists this multiple of its drive force (worm drive)");
          p.num("breakaway_rate", x.breakaway_rate,
                "TorqueSwitch: coupled joints' rate after the driven joint stalls, relative to it");
          p.num("table_sweep_m", x.table_sweep_m,
                "a hand closing this near the table top is lowered as its fingertips rise, m");
          p.num("ramp_s", x.ramp_s,
                "each motion segment speeds up and slows down over this long, s");
          p.num("settle_s", x.settle_s, "longest wait for the object to come to rest, s");
          p.integer("decomposition_resolution", x.decomposition.resolution,
                    "voxels along the object's longest side for its convex decomposition");
          p.integer("decomposition_max_pieces", x.decomposition.max_pieces,
                    "at most this many convex pieces");
          p.num("decomposition_max_excess", x.decomposition.max_excess,
                "the pieces' hulls exceed the solid by at most this fraction of its volume");
        });
    o.object("faults", "faults injected (all off by default; docs/reliability.md)", [&](V& f) {
      SimFaults& x = c.sim.faults;
      f.num("dropped_frames", x.dropped_frames, "fraction of frames that never arrive");
      f.num("corrupted_frames", x.corrupted_frames,
            "fraction corrupted: zeros, NaNs, a stripe of wrong depth (in turn)");
      f.num("pose_jumps", x.pose_jumps, "fraction of joint states with an arm joint 0.3 rad off");
      f.num("stopped_short", x.stopped_short, "fraction of motions stopped part-way");
      f.num("refused_motions", x.refused_motions,
            "fraction of motions the arm refuses (it stays where it is)");
      f.num("failed_pickups", x.failed_pickups, "fraction of pick-ups that reach nothing");
      f.num("slip_m", x.slip_m, "the object slips this far in the hand once per grasp, m");
      f.integer("slip_in_motion", x.slip_in_motion,
                "… halfway through this motion with it in the hand of each grasp (0-based)");
      f.integer("drop_in_motion", x.drop_in_motion,
                "the object falls out of the hand during this motion (0-based; -1: never)");
    });
  });
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
  void num(const char* key, double& v, const char*) {
    if (!take(key)) return;
    if (!j_[key].is_number()) throw Error(at(key) + ": expected a number");
    v = j_[key].get<double>();
  }
  void integer(const char* key, int& v, const char*) {
    if (!take(key)) return;
    if (!j_[key].is_number_integer()) throw Error(at(key) + ": expected an integer");
    v = j_[key].get<int>();
  }
  void boolean(const char* key, bool& v, const char*) {
    if (!take(key)) return;
    if (!j_[key].is_boolean()) throw Error(at(key) + ": expected true or false");
    v = j_[key].get<bool>();
  }
  void numbers(const char* key, std::vector<double>& v, const char*) {
    if (!take(key)) return;
    const Json& a = j_[key];
    if (!a.is_array()) throw Error(at(key) + ": expected an array of numbers");
    v.clear();
    for (const Json& x : a) {
      if (!x.is_number()) throw Error(at(key) + ": expected an array of numbers");
      v.push_back(x.get<double>());
    }
  }
  void string(const char* key, std::string& v, const char*) {
    if (!take(key)) return;
    if (!j_[key].is_string()) throw Error(at(key) + ": expected a string");
    v = j_[key].get<std::string>();
  }
  template <class T>
  void choice(const char* key, T& v, const Names<T>& names, const char*) {
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
  void object(const char* key, const char*, F visit) {
    if (!take(key)) return;
    Reader sub(j_[key], at(key));
    visit(sub);
    sub.finish();
  }

 private:
  bool take(const char* key) {
    seen_.insert(key);
    return j_.contains(key);
  }
  std::string at(const char* key) const { return where_ + "." + key; }
  const Json& j_;
  std::string where_;
  std::set<std::string> seen_;
};

class Writer {
 public:
  Json j = Json::object();
  void num(const char* key, double& v, const char*) { j[key] = v; }
  void integer(const char* key, int& v, const char*) { j[key] = v; }
  void boolean(const char* key, bool& v, const char*) { j[key] = v; }
  void numbers(const char* key, std::vector<double>& v, const char*) { j[key] = v; }
  void string(const char* key, std::string& v, const char*) { j[key] = v; }
  template <class T>
  void choice(const char* key, T& v, const Names<T>& names, const char*) {
    for (const auto& [value, name] : names)
      if (value == v) j[key] = name;
  }
  template <class F>
  void object(const char* key, const char*, F visit) {
    Writer sub;
    visit(sub);
    j[key] = sub.j;
  }
};

class Documenter {
 public:
  explicit Documenter(std::string prefix = "") : prefix_(std::move(prefix)) {}
  std::ostringstream rows, sections;
  void num(const char* key, double& v, const char* doc) { row(key, "number", Json(v).dump(), doc); }
  void integer(const char* key, int& v, const char* doc) {
    row(key, "integer", std::to_string(v), doc);
  }
  void boolean(const char* key, bool& v, const char* doc) {
    row(key, "true/false", v ? "true" : "false", doc);
  }
  void numbers(const char* key, std::vector<double>& v, const char* doc) {
    row(key, "numbers", Json(v).dump(), doc);
  }
  void string(const char* key, std::string& v, const char* doc) {
    row(key, "string", v.empty() ? "(empty)" : "\"" + v + "\"", doc);
  }
  template <class T>
  void choice(const char* key, T& v, const Names<T>& names, const char* doc) {
    std::string def, all;
    for (const auto& [value, name] : names) {
      if (value == v) def = std::string("\"") + name + "\"";
      all += (all.empty() ? "" : " \\| ") + std::string(name);
    }
    row(key, all, def, doc);
  }
  template <class F>
  void object(const char* key, const char* doc, F visit) {
    Documenter sub(prefix_ + key + ".");
    visit(sub);
    sections << "\n### `" << prefix_ << key << "`: " << doc << "\n\n"
             << "| key | type | default | meaning |\n|---|---|---|---|\n"
             << sub.rows.str() << sub.sections.str();
  }

 private:
  void row(const char* key, const std::string& type, const std::string& def, const char* doc) {
    rows << "| `" << prefix_ << key << "` | " << type << " | " << def << " | " << doc << " |\n";
  }
  std::string prefix_;
};

}  // namespace

std::string ScanConfig::validate() const {
  if (std::string p = scan.validate(); !p.empty()) return "scan options: " + p;
  if (std::string p = multi.validate(); !p.empty()) return "scan options: " + p;
  if (std::string p = sim.validate(); !p.empty()) return "simulation options: " + p;
  if (std::string p = eval.validate(); !p.empty()) return "eval options: " + p;
  return {};
}

void readScanConfig(const Json& j, const std::string& where, ScanConfig* config) {
  Reader r(j, where);
  visitConfig(r, *config);
  r.finish();
}

void readScanConfigFile(const std::filesystem::path& file, ScanConfig* config) {
  readScanConfig(readJsonFile(file), file.string(), config);
}

Json scanConfigJson(const ScanConfig& config) {
  ScanConfig c = config;
  Writer w;
  visitConfig(w, c);
  return w.j;
}

std::string scanConfigReference() {
  ScanConfig defaults;
  Documenter d;
  visitConfig(d, defaults);
  return "## Top level\n\n| key | type | default | meaning |\n|---|---|---|---|\n" + d.rows.str() +
         d.sections.str();
}

}  // namespace inhand
