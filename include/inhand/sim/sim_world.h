#pragma once
#include <array>
// The simulator: a table, an object held rigidly in the robot's hand, the robot, a depth camera on
// its pan-tilt unit and a room around them. SimRobot and SimSensor implement the interfaces the
// scan uses; only they see the true object.
#include <memory>

#include "inhand/core/json_util.h"
#include "inhand/core/options.h"
#include "inhand/geometry/ray_scene.h"
#include "inhand/physics/physics.h"
#include "inhand/robot/robot_interface.h"
#include "inhand/robot/robot_scenes.h"
#include "inhand/sensor/depth_sensor.h"
#include "inhand/sensor/noise_model.h"
#include "inhand/sensor/render.h"

namespace inhand {

// Faults the simulator injects (all off by default; each drawn from the seed, so a run
// repeats): what real sensors, arms and grasps do now and then.
struct SimFaults {
  double dropped_frames = 0;  // fraction of frames that never arrive (an empty image)
  // Fraction that arrive corrupted, in turn: all zeros, NaN in a fifth of the pixels, a stripe
  // of 40 rows at a constant wrong depth (0.4 m).
  double corrupted_frames = 0;
  double pose_jumps = 0;     // fraction of reported joint states with one arm joint 0.3 rad off
  double stopped_short = 0;  // fraction of motions the arm stops part-way (20–80 %)
  // Fraction of motions the arm's controller refuses (a planning or IK failure on the robot's
  // side: it stays where it is), and of pick-ups that fail (the hand reaches nothing).
  double refused_motions = 0;
  double failed_pickups = 0;
  // The object slips in the hand this far (m, a random direction), once, halfway through motion
  // `slip_in_motion` with it in the hand of every grasp (0-based; 1, the default: the second;
  // slip_m 0: never).
  double slip_m = 0;
  int slip_in_motion = 1;
  // The object falls out of the hand halfway through this motion with it in the hand (0-based,
  // counting every motion of the scan; -1: never). It lands where it rested.
  int drop_in_motion = -1;

  template <class V, class S>
  static void fields(V& v, S& o) {
    const Range rate = Range::closed(0, 1);
    v.num("dropped_frames", o.dropped_frames, "fraction of frames that never arrive", rate);
    v.num("corrupted_frames", o.corrupted_frames,
          "fraction corrupted: zeros, NaNs, a stripe of wrong depth (in turn)", rate);
    v.num("pose_jumps", o.pose_jumps, "fraction of joint states with an arm joint 0.3 rad off",
          rate);
    v.num("stopped_short", o.stopped_short, "fraction of motions stopped part-way", rate);
    v.num("refused_motions", o.refused_motions,
          "fraction of motions the arm refuses (it stays where it is)", rate);
    v.num("failed_pickups", o.failed_pickups, "fraction of pick-ups that reach nothing", rate);
    v.num("slip_m", o.slip_m, "the object slips this far in the hand once per grasp, m",
          Range::closed(0, 0.05));
    v.integer("slip_in_motion", o.slip_in_motion,
              "… halfway through this motion with it in the hand of each grasp (0-based)",
              Range::atLeast(0));
    v.integer("drop_in_motion", o.drop_in_motion,
              "the object falls out of the hand during this motion (0-based; -1: never)",
              Range::atLeast(-1));
  }
  std::string validate() const;
};

// What the simulator injected (SimFaults).
struct SimFaultLog {
  int dropped_frames = 0, corrupted_frames = 0, pose_jumps = 0, stopped_short = 0, slips = 0,
      object_drops = 0, refused_motions = 0, failed_pickups = 0;
};

// The simulated colour camera (DepthCameraOptions::colour): what it sees is the surfaces'
// albedo (the object's SurfaceColours; the robot and the table in colours of their own) lit by
// ambient light plus a lamp at the camera (Lambertian), times an exposure that changes a little
// from frame to frame, plus per-pixel Gaussian noise, in 8-bit sRGB.
struct SimColourOptions {
  bool enabled = false;          // a colour camera beside the depth camera
  double ambient = 0.4;          // the lit fraction where the lamp's light grazes the surface
  double noise_sigma = 2.0;      // per-pixel noise, 8-bit levels
  double exposure_sigma = 0.02;  // per-frame exposure change, relative
  std::array<uint8_t, 3> robot{40, 60, 190};    // the arm and hand
  std::array<uint8_t, 3> table{205, 185, 150};  // the table top
  std::array<uint8_t, 3> room{128, 128, 128};   // the background

  // The options' rows (core/options.h); the robot's, table's and room's colours are the scene's.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.boolean("enabled", o.enabled, "render colour images and fuse their colours");
    v.num("ambient", o.ambient,
          "lit fraction where the lamp at the camera grazes a surface (Lambertian)",
          Range::closed(0, 1));
    v.num("noise_sigma", o.noise_sigma, "per-pixel Gaussian noise, 8-bit levels",
          Range::closed(0, 100));
    v.num("exposure_sigma", o.exposure_sigma, "per-frame exposure change, relative (Gaussian σ)",
          Range::closed(0, 0.5));
  }
  std::string validate() const;
};

// How the simulated pick-up comes in (SimOptions::pick_up_first_contact).
inline constexpr EnumNames<bool, 2> kPickUpNames = {{false, "palm"}, {true, "first_contact"}};

struct SimOptions {
  double frame_rate_hz = 30.0;  // sensor frame rate along trajectories
  SimColourOptions colour;
  int frame_subsample = 1;     // deliver every n-th frame to the scan (1: every frame, 30 Hz)
  bool noise = true;           // sensor noise
  uint64_t seed = 1;           // noise seed
  double room_radius_m = 2.5;  // background: a room around the camera (0: none)
  // Pick-up: false backs the palm off until it is clear of the true object (the fingers may end
  // inside it); true stops the open hand at the first contact of any link (physically valid).
  bool pick_up_first_contact = true;
  // Whether a grasp holds: the closed hand's contacts on the true object (its surface samples
  // within 3 mm of the hand, pooled per 1 cm) with Coulomb friction `friction` must be force
  // closure with ε ≥ `hold_min_epsilon` (robot/wrench.h): the scan turns the object to every
  // side, so the grasp must resist gravity in every direction. One that does not lets the
  // object fall back onto the table, where it rested, at the first motion after the pick-up.
  bool check_hold = true;
  double friction = 0.5;
  double hold_min_epsilon = 1e-4;
  // The object's orientation on the table (rotation from its mesh frame O to the base frame).
  Mat3 R_B_O_rest = Mat3::Identity();
  // Arm error (paper §II: cable stretch puts the WAM's hand centimetres from where its motor
  // encoders say): offsets of the arm's joints from the angles the robot reports, fixed ones
  // drawn from the seed plus the parts below, scaled so that where objects are presented to the
  // camera the palm is at the median this far (m) from where forward kinematics of the reported
  // joints puts it. The world (the rendered robot, the held object) moves with the true joints;
  // the robot reports the others. 0: an exact arm.
  double arm_error_m = 0.0;
  // The error's parts that change, each as a fraction of the fixed offsets' size (so that
  // arm_error_m scales them all; 0 turns a part off):
  // - gravity: joint compliance (cable stretch under load), offsets proportional to the torque
  //   the links' weights put on each joint at the reported configuration (URDF masses;
  //   RobotModel::gravityTorques), this fraction of the fixed offsets' norm at a typical
  //   configuration (the torques' RMS over presentationConfigurations);
  // - drift: a slow wander of every joint (two sines each, periods 20-120 s of sensor time),
  //   this fraction in RMS;
  // - noise: per-frame joint noise (independent per frame), this fraction in RMS.
  // With the fixed offsets and gravity's part, the palm's error has the median arm_error_m over
  // the configurations that present an object to the camera (presentationConfigurations).
  double arm_error_gravity = 0.5;
  double arm_error_drift = 0.2;
  double arm_error_noise = 0.02;
  // The arm's error also at the pick-up: the palm comes in from where the true joints put it, so
  // the object sits in the hand off where the reported joints say (a real arm's case). false: the
  // hand grasps the object exactly as planned (the error shows only while it is held).
  bool grasp_error = false;
  // The joint torques the simulated arm reports at rest: gravity's on its links (URDF masses)
  // and on the object it holds (its true mass at its true centre of mass), plus Gaussian noise
  // of this standard deviation per joint (N·m).
  double torque_noise_nm = 0.1;
  // Rigid-body physics (MuJoCo) for every pick-up, motion with the object in the hand and
  // put-down; off: the kinematic simulator (check_hold decides at the pick-up).
  PhysicsOptions physics;
  SimFaults faults;

  // The options' rows (core/options.h); seed and R_B_O_rest are set by the caller.
  template <class V, class S>
  static void fields(V& v, S& o) {
    v.num("frame_rate_hz", o.frame_rate_hz, "sensor frame rate along trajectories, Hz",
          Range::above(0));
    v.integer("frame_subsample", o.frame_subsample,
              "deliver every n-th sensor frame to the scan (1: all)", Range::atLeast(1));
    v.boolean("noise", o.noise, "sensor noise");
    v.object("colour", "a colour camera beside the depth camera (Kinect-class, 640x480)",
             [&](auto& c) { SimColourOptions::fields(c, o.colour); });
    v.num("room_radius_m", o.room_radius_m, "a room around the camera (0: none), m",
          Range::atLeast(0));
    v.boolean("check_hold", o.check_hold, "grasps must be force closure on the true object");
    v.num("friction", o.friction, "μ of the true contacts", Range::openClosed(0, 2));
    v.num("hold_min_epsilon", o.hold_min_epsilon, "ε a grasp needs to hold", Range::atLeast(0));
    v.num("arm_error_m", o.arm_error_m,
          "the arm's error: the palm's median distance from the reported joints' FK where "
          "objects are presented (fixed offsets and gravity's sag), m",
          Range::closed(0, 0.2));
    v.num("arm_error_gravity", o.arm_error_gravity,
          "joint sag proportional to gravity's torque at the configuration (URDF masses), as a "
          "fraction of the fixed offsets at a typical configuration",
          Range::closed(0, 5));
    v.num("arm_error_drift", o.arm_error_drift,
          "slow drift of every joint (periods 20-120 s), RMS as a fraction of the fixed offsets",
          Range::closed(0, 5));
    v.num("arm_error_noise", o.arm_error_noise,
          "per-frame joint noise, RMS as a fraction of the fixed offsets", Range::closed(0, 5));
    v.num("torque_noise_nm", o.torque_noise_nm,
          "noise (standard deviation, N·m) of the joint torques the arm reports at rest, from "
          "which the scan weighs the object",
          Range::closed(0, 10));
    v.boolean("grasp_error", o.grasp_error,
              "the arm's error also at pick-ups: the object sits in the hand off where the "
              "reported joints say");
    v.choice("pick_up", o.pick_up_first_contact, kPickUpNames,
             "the simulated pick-up: palm backed off, or a guarded move to first contact");
    v.object("physics",
             "MuJoCo rigid-body physics for pick-ups, held motions and put-downs "
             "(docs/physics.md)",
             [&](auto& p) { PhysicsOptions::fields(p, o.physics); });
    v.object("faults", "faults injected (all off by default; docs/reliability.md)",
             [&](auto& f) { SimFaults::fields(f, o.faults); });
  }
  std::string validate() const;
};

// How far along a motion segment the simulated arm is at time t (0 at the start, 1 at its end,
// T + ramp seconds in): T seconds at its speed limits, speeding up over `ramp` at the start and
// slowing down over it at the end (a trapezoidal speed profile; with PhysicsOptions::ramp_s).
double rampedFraction(double t, double T, double ramp);

// Arm configurations presenting an object at the camera's nominal point (CameraMount::lookAt_B):
// the palm graspOffset() short of it along its axis, from 24 directions around it; those IK
// reaches from home. SimOptions::arm_error_m is the palm's median error over these.
std::vector<JointVector> presentationConfigurations(const RobotModel& model);

class SimWorld {
 public:
  // `object_O`: the true object mesh; T_O_palm: the grasp (palm pose in the object frame).
  SimWorld(const RobotModel& model, const TriangleMesh& object_O, const Iso3& T_O_palm,
           const DepthCameraOptions& camera, const NoiseModelOptions& noise,
           const SimOptions& options);

  const RobotModel& model() const { return *model_; }
  const SimOptions& options() const { return options_; }
  JointVector q;  // the robot's state, as it reports it (motor encoders)
  // The arm's fixed joint offsets (SimOptions::arm_error_m; arm joints, zero elsewhere).
  JointVector jointError;
  // The arm's whole error with the robot reporting q, at the last frame rendered (the fixed
  // offsets, gravity's part at q, drift at that frame's time, that frame's noise): the arm is truly
  // at q + jointErrorAt(q).
  JointVector jointErrorAt(const JointVector& q) const;
  JointVector trueJoints() const { return q + jointErrorAt(q); }
  Iso3 T_B_C;     // the camera's pose
  Iso3 T_O_palm;  // the grasp
  // Depth image at the current state, seeded by the frame counter (with SimOptions::faults: at
  // times empty or corrupted).
  DepthImage render();
  // The colour camera's image (DepthCameraOptions::colour) of the state the last render() saw,
  // seeded by its frame; empty when the camera has none.
  RgbImage renderColour();
  // The true object's colours (flat grey until set; its triangles as objectMesh()'s).
  void setObjectColours(SurfaceColours colours) { colours_ = std::move(colours); }
  // A uniform number in [0, 1) for fault `kind`, from the seed and a counter (part of state()).
  double faultDraw(int kind);
  int motions = 0;          // arm motions with the object in the hand so far
  int graspMotions = 0;     // … since the object was last picked up
  Iso3 objectPose() const;  // T_B_O at the current state
  bool held = true;         // false: the object rests on the table at restPose()
  bool slipping = false;    // held by a grasp that does not hold: falls at the next motion
  int drops = 0;            // how often the object fell
  SimFaultLog faults;       // what SimOptions::faults injected so far
  double render_s = 0;      // time spent rendering the simulated sensor's images
  int renders = 0;          // … how many
  const TriangleMesh& objectMesh() const { return objectMesh_; }
  const std::vector<SurfacePoint>& objectSamples() const { return objectSamples_; }
  // Where the object rests on the table: turned by SimOptions::R_B_O_rest, its lowest point on
  // the table top, its box's centre under the presentation point.
  Iso3 restPose() const;
  // Where the object lies when not in the hand: restPose() at the start; with physics where it
  // settled after a put-down or a fall.
  Iso3 tablePose;
  // Whether the hand at q, T_O_palm holds the object (SimOptions::check_hold; the kinematic
  // simulator's verdict).
  bool graspHolds() const;
  // The arm's joint torques now, at rest (SimOptions::torque_noise_nm; a counter seeds the noise).
  JointVector jointTorques();
  double objectMass_kg() const;  // the true object's mass (physics', or the density's)
  // The physics (SimOptions::physics; null when off).
  PhysicsWorld* physics() { return physics_.get(); }
  const PhysicsWorld* physics() const { return physics_.get(); }
  // With physics: the object's grasp (T_O_palm) and the hand's joints as physics has them.
  void syncFromPhysics();
  // The robot holds the object (a scan's start "held"): the joints at q, the object at T_O_palm;
  // with physics the fingers, touching it at q's hand joints, squeeze it under their force
  // limits (PhysicsWorld::closeHand) and physics has it where they leave it.
  void holdAt(const JointVector& q);
  // With physics and the object in the hand: dt_s of the palm following the arm at q;
  // `untouched_s` counts how long the object has touched no hand link (a tenth of a second: it
  // fell, and is left on the table where it settles).
  void stepPhysics(double dt_s, double* untouched_s);
  // The physics palm's pose relative to the arm's tip as the joints put it (the guarded move
  // and the fingers' give move the hand from where the arm's joints say).
  Iso3 T_tip_palm = Iso3::Identity();
  int slips = 0;         // motions in which the object moved in the hand (physics), > 2 mm
  double slipMax_m = 0;  // the largest such movement, m
  // The world's changing state (joints, arm error, camera, grasp, held, slipping, drops, the
  // frame counter that seeds the noise), for checkpoints: setState(state()) continues exactly.
  Json state() const;
  void setState(const Json& state);  // throws Error on a state of another robot or malformed

 private:
  const RobotModel* model_;
  DepthCameraOptions camera_;
  NoiseModelOptions noise_;
  SimOptions options_;
  RayScene object_;
  RobotOccluders robot_;
  std::unique_ptr<PhysicsWorld> physics_;
  TriangleMesh objectMesh_;
  SurfaceColours colours_;
  std::vector<SurfacePoint> objectSamples_;  // for the pick-up clearance test
  uint64_t frame_ = 0;
  uint64_t faultDraws_ = 0;
  uint64_t torqueReads_ = 0;
  MassProperties objectSolid_;  // of the true mesh (unit density)
  // The arm error's changing parts (from the options and seed): the scale of its unit parts,
  // gravity's typical torque norm (RMS over configurations), each arm joint's drift periods (s)
  // and phases.
  double armScale_ = 0, gravityTypical_ = 0;
  Eigen::MatrixXd driftPeriod_, driftPhase_;
};

class SimRobot : public RobotInterface {
 public:
  explicit SimRobot(SimWorld* world) : world_(world) {}
  const RobotModel& model() const override { return world_->model(); }
  JointVector joints() const override { return world_->q; }
  // Synchronous joint-space motion at the joint speed limits (the trajectory-time model).
  void execute(const std::vector<JointVector>& waypoints,
               const std::function<void(const JointVector&)>& on_state) override;
  // Put-down and pick-up are instantaneous state changes in the simulator (no trajectories).
  bool putDown() override;
  // With SimOptions::pick_up_first_contact (the default) a guarded move: the open hand comes in
  // along its axis, from 25 cm short of the planned pose to at most 10 cm past it, until any link
  // touches the true object (nullopt when it is blocked at the start or touches nothing).
  // Without, the palm is backed off (2 mm steps, up to 5 cm) until it is clear of the true
  // object. The guarded move and the fingers stop at the table too. Then the fingers close on
  // the true object from the preshape in q (its finger values; an open hand when they are open),
  // and SimOptions::check_hold decides whether the grasp holds. With SimOptions::grasp_error
  // the palm starts from where the true joints put it, off the plan, and the grasp returned is
  // what the reported joints say (the plan, moved as the palm moved): the object sits in the
  // hand that far from where the robot believes.
  std::optional<Iso3> pickUp(const Iso3& T_O_palm, const JointVector& q) override;
  std::optional<JointVector> jointTorques() override { return world_->jointTorques(); }
  // With physics and the object in the hand, `seconds` of physics with the arm still (the object
  // may slide or fall meanwhile); otherwise nothing changes and no time passes.
  void holdStill(double seconds) override;

 private:
  std::optional<Iso3> grasp(const Iso3& T_O_palm, const JointVector& q);
  SimWorld* world_;
};

class SimSensor : public DepthSensor {
 public:
  SimSensor(SimWorld* world, const DepthCameraOptions& camera) : world_(world), camera_(camera) {}
  RgbImage captureColour() override { return world_->renderColour(); }
  const DepthCameraOptions& camera() const override { return camera_; }
  void setPose(const Iso3& T_B_C) override { world_->T_B_C = T_B_C; }
  Iso3 pose() const override { return world_->T_B_C; }
  DepthImage capture() override { return world_->render(); }

 private:
  SimWorld* world_;
  DepthCameraOptions camera_;
};

// A default side grasp for simulation: the open hand comes at the face across the object's
// middle-length axis until it first touches it, fingers closing across its shortest axis, then
// closed to contact.
// Returns T_O_palm and the joint vector (home arm, fingers at contact).
std::pair<Iso3, JointVector> defaultGrasp(const RobotModel& model, const TriangleMesh& object_O);

}  // namespace inhand
