#include "inhand/sim/sim_world.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"
#include "inhand/core/pose.h"
#include "inhand/core/random.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/ik.h"
#include "inhand/robot/wrench.h"

namespace inhand {

std::string SimFaults::validate() const { return checkOptionRanges(*this); }

std::string SimColourOptions::validate() const { return checkOptionRanges(*this); }

std::string SimOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (!R_B_O_rest.allFinite() || std::abs(R_B_O_rest.determinant() - 1) > 1e-6)
    return "the rest orientation must be a rotation";
  if (std::string p = physics.validate(); !p.empty()) return "physics." + p;
  return {};
}

namespace {
// A unit direction in arm joint space drawn from the seed (uniform on the sphere).
JointVector armDirection(const RobotModel& m, uint64_t seed) {
  JointVector e = JointVector::Zero(m.variableCount());
  Rng rng = makeRng(mixSeed(seed, 0xa4e));
  std::normal_distribution<double> N(0, 1);
  for (int v : m.armVariables()) e[v] = N(rng);
  return e.norm() > 0 ? JointVector(e / e.norm()) : e;
}

// The gravity torques on the arm's joints at q (zero elsewhere).
JointVector armGravity(const RobotModel& m, const JointVector& q) {
  const JointVector tau = m.gravityTorques(q);
  JointVector out = JointVector::Zero(m.variableCount());
  for (int v : m.armVariables()) out[v] = tau[v];
  return out;
}

// How far short of T_O_palm along its palm axis a guarded approach starts: `back`, or where the
// hand (joints q) is not clear of `closer`'s obstacles there, the farthest point of that line
// (5 mm steps) where it is; 0 when none is.
double clearStart(const FingerCloser& closer, const JointVector& q, const Iso3& T_O_palm,
                  double back) {
  auto touches = [&](double s) {
    Iso3 T = T_O_palm;
    T.translation() -= s * T_O_palm.linear().col(2);
    return closer.handTouches(q, T);
  };
  while (back > 0 && touches(back)) back -= 0.005;
  return std::max(back, 0.0);
}

}  // namespace

std::vector<JointVector> presentationConfigurations(const RobotModel& m) {
  const Vec3 centre = m.camera().lookAt_B;
  std::vector<Iso3> targets;
  for (const Vec3& d : fibonacciSphere(24)) {
    Iso3 T = Iso3::Identity();
    T.linear() = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), d).toRotationMatrix();
    T.translation() = centre - m.graspOffset() * d;
    targets.push_back(T);
  }
  const JointVector home = m.home();
  std::vector<JointVector> out;
  for (const auto& arm : solveIkBatch(m, targets, m.arm(home), 0x5eed))
    if (arm) out.push_back(m.withArm(home, *arm));
  return out;
}

SimWorld::SimWorld(const RobotModel& model, const TriangleMesh& object_O, const Iso3& grasp,
                   const DepthCameraOptions& camera, const NoiseModelOptions& noise,
                   const SimOptions& options)
    : q(model.home()),
      T_B_C(Iso3::Identity()),
      T_O_palm(grasp),
      model_(&model),
      camera_(camera),
      noise_(noise),
      options_(options),
      robot_(model) {
  std::string p = options.validate();
  if (!p.empty()) throw Error("simulation options: " + p);
  jointError = JointVector::Zero(model.variableCount());
  if (options.arm_error_m > 0) {
    const JointVector e = armDirection(model, options.seed);
    std::vector<JointVector> configs = presentationConfigurations(model);
    if (configs.empty()) configs.push_back(model.home());
    // Gravity's torques relative to their RMS where objects are presented.
    double sq = 0;
    for (const JointVector& q : configs) sq += armGravity(model, q).squaredNorm();
    gravityTypical_ = std::sqrt(sq / double(configs.size()));
    const double g = gravityTypical_ > 0 ? options.arm_error_gravity / gravityTypical_ : 0.0;
    // The fixed offsets' scale for which the palm's error (with gravity's part) has the
    // median arm_error_m over those configurations: nearly linear in the scale for small
    // angles, a few secant steps make it exact to a micrometre.
    auto median = [&](double scale) {
      std::vector<double> d;
      for (const JointVector& q : configs)
        d.push_back((model.tipPose(q + scale * (e + g * armGravity(model, q))).translation() -
                     model.tipPose(q).translation())
                        .norm());
      std::nth_element(d.begin(), d.begin() + long(d.size() / 2), d.end());
      return d[d.size() / 2];
    };
    armScale_ = 0.01;
    for (int it = 0; it < 20; ++it) {
      const double d = median(armScale_);
      if (std::abs(d - options.arm_error_m) < 1e-7 || d <= 0) break;
      armScale_ *= options.arm_error_m / d;
    }
    jointError = armScale_ * e;
    Rng rng = makeRng(mixSeed(options.seed, 0xd81f7));
    std::uniform_real_distribution<double> U(0, 1);
    driftPeriod_.resize(model.variableCount(), 2);
    driftPhase_.resize(model.variableCount(), 2);
    for (int v = 0; v < model.variableCount(); ++v)
      for (int k = 0; k < 2; ++k) {
        driftPeriod_(v, k) = 20 + 100 * U(rng);
        driftPhase_(v, k) = 2 * M_PI * U(rng);
      }
  }
  objectMesh_ = object_O;
  objectSolid_ = massProperties(object_O);
  tablePose = restPose();
  if (options.physics.enabled)
    physics_ = std::make_unique<PhysicsWorld>(model, object_O, options.friction, options.physics);
  objectSamples_ = surfaceSamples(object_O, 0.003);
  object_.addMesh(object_O);
  object_.commit();
}

JointVector SimWorld::jointErrorAt(const JointVector& qr) const {
  JointVector e = jointError;
  if (armScale_ <= 0) return e;
  const RobotModel& m = *model_;
  const double n = std::sqrt(double(std::max(1, m.armDof())));
  const uint64_t f = frame_ > 0 ? frame_ - 1 : 0;  // the last frame rendered
  if (options_.arm_error_drift > 0) {
    const double t = double(f) * options_.frame_subsample / options_.frame_rate_hz;
    for (int v : m.armVariables())
      e[v] += armScale_ * options_.arm_error_drift / n *
              (std::sin(2 * M_PI * t / driftPeriod_(v, 0) + driftPhase_(v, 0)) +
               std::sin(2 * M_PI * t / driftPeriod_(v, 1) + driftPhase_(v, 1)));
  }
  if (options_.arm_error_noise > 0) {
    Rng rng = makeRng(mixSeed(mixSeed(options_.seed, 0x6e01), f));
    std::normal_distribution<double> N(0, 1);
    for (int v : m.armVariables()) e[v] += armScale_ * options_.arm_error_noise / n * N(rng);
  }
  // Gravity's torques at the reported configuration (those at the true one differ by a second-
  // order amount: a hundredth of the sag at 2 cm).
  if (options_.arm_error_gravity > 0 && gravityTypical_ > 0)
    e += armScale_ * options_.arm_error_gravity / gravityTypical_ * armGravity(m, qr);
  return e;
}

Iso3 SimWorld::objectPose() const {
  return held ? model_->tipPose(trueJoints()) * T_O_palm.inverse() : tablePose;
}

void SimWorld::syncFromPhysics() {
  if (!physics_) return;
  T_O_palm = physics_->objectPose().inverse() * physics_->palmPose() * T_tip_palm.inverse();
  q = physics_->handJoints(q);
}

void SimWorld::holdAt(const JointVector& qHeld) {
  q = qHeld;
  held = true;
  if (!physics_) return;
  // The fingers start where they touch the object (an open hand would let it fall while they
  // close).
  const Iso3 T_B_tip = model_->tipPose(trueJoints());
  physics_->reset(T_B_tip * T_O_palm.inverse(), T_B_tip * T_tip_palm, q);
  q = physics_->closeHand(q);
  syncFromPhysics();
}

void SimWorld::stepPhysics(double dt_s, double* untouched_s) {
  // The palm follows the arm; the object moves as physics moves it. It has fallen when it has
  // touched no part of the hand for a tenth of a second, and then settles where it lands.
  physics_->movePalm(model_->tipPose(trueJoints()) * T_tip_palm, dt_s);
  syncFromPhysics();
  *untouched_s = physics_->objectTouchesHand() ? 0.0 : *untouched_s + dt_s;
  if (*untouched_s >= 0.1 - 1e-9) {
    physics_->settle(options_.physics.settle_s);
    tablePose = physics_->objectPose();
    held = false;
    ++drops;
  }
}

Iso3 SimWorld::restPose() const {
  const Vec3 at = model_->camera().lookAt_B;
  Iso3 T = Iso3::Identity();
  T.linear() = options_.R_B_O_rest;
  Aabb b;
  for (const Vec3f& v : objectMesh_.vertices) b.extend(options_.R_B_O_rest * v.cast<double>());
  T.translation() =
      Vec3(at.x() - b.center().x(), at.y() - b.center().y(), model_->table().topZ() - b.min.z());
  return T;
}

bool SimWorld::graspHolds() const {
  if (!options_.check_hold) return true;
  const HandContacts hc = handContacts(*model_, q, T_O_palm, objectSamples_, 0.003, 0.01);
  if (hc.fingers_touching + int(hc.palm_touching) < 2) return false;
  Vec3 centre = Vec3::Zero();
  for (const SurfacePoint& s : objectSamples_) centre += s.p;
  centre /= double(std::max<size_t>(1, objectSamples_.size()));
  double rho = 1e-3;
  for (const SurfacePoint& s : objectSamples_) rho = std::max(rho, (s.p - centre).norm());
  return forceClosureEpsilon(hc.contacts, centre, rho, options_.friction, 8, 1000) >=
         options_.hold_min_epsilon;
}

bool SimRobot::putDown() {
  SimWorld& w = *world_;
  PhysicsWorld* ph = w.physics();
  if (ph && w.held) {
    // The hand carries the object (as it holds it now) to 10 cm above where it rested when this
    // grasp picked it up, lowers it to 5 mm above that in 5 mm steps, stopping where the object
    // or the hand touches the table (a grasp that moved in the hand may put the fingers lower
    // than the object), opens, backs off 10 cm along its axis; the object settles.
    const Iso3 T_O_palmPhys = ph->objectPose().inverse() * ph->palmPose();
    Iso3 place = w.tablePose;
    place.translation().z() += 0.005;
    Iso3 down = place * T_O_palmPhys;
    Iso3 above = down;
    above.translation().z() += 0.10;
    const PhysicsOptions& po = w.options().physics;
    // On the way there the palm first rises, then moves and turns at a height where no point of
    // the object or the hand can reach the table, whatever the turn (the motion is the hand's
    // alone, in straight lines).
    double reach = 0.25;  // the hand's own, about its palm
    for (const Vec3f& v : w.objectMesh().vertices)
      reach = std::max(reach, (T_O_palmPhys.inverse() * v.cast<double>()).norm());
    const double safeZ = std::max({ph->palmPose().translation().z(), above.translation().z(),
                                   w.model().table().topZ() + reach + 0.02});
    Iso3 up = ph->palmPose(), over = above;
    up.translation().z() = safeZ;
    over.translation().z() = safeZ;
    ph->movePalm(up, 0.5);
    ph->movePalm(over, 1.5);
    ph->movePalm(above, 0.5);
    for (int k = 1; k <= 20; ++k) {
      Iso3 T = above;
      T.translation().z() -= 0.005 * k;
      ph->movePalm(T, 0.025);
      down = T;
      if (ph->objectTouchesTable() || ph->handTouchesTable()) break;
    }
    ph->openHand();
    Iso3 away = down;
    away.translation() -= 0.10 * down.linear().col(2);
    ph->movePalm(away, 0.5);
    ph->settle(po.settle_s);
    w.tablePose = ph->objectPose();
    w.q = w.model().withFingersOpen(w.q);
  }
  w.held = false;
  w.slipping = false;
  return true;
}

std::optional<Iso3> SimRobot::pickUp(const Iso3& T_O_palm, const JointVector& q) {
  world_->graspMotions = 0;
  const double failed = world_->options().faults.failed_pickups;
  if (failed > 0 && world_->faultDraw(9) < failed) {
    ++world_->faults.failed_pickups;
    return std::nullopt;
  }
  std::optional<Iso3> T = grasp(T_O_palm, q);
  // With physics the lift shows whether it holds; the kinematic simulator decides here.
  world_->slipping = T && !world_->physics() && !world_->graspHolds();
  return T;
}

std::optional<Iso3> SimRobot::grasp(const Iso3& T_O_palm_planned, const JointVector& q) {
  const RobotModel& m = world_->model();
  // The arm's error at the pick configuration: the palm reaches delta (palm frame) from where the
  // plan put it, while the encoders report the plan. The hand moves and closes from there; the
  // robot reports the grasp as its joints see it: the plan moved as the palm moved relative to
  // its start.
  const JointVector error = world_->jointErrorAt(q);
  const Iso3 delta = m.tipPose(q).inverse() * m.tipPose(q + error);
  const bool exact = !world_->options().grasp_error || error.isZero(0);
  // With physics the hand goes where the arm's joints put it, and the object is where physics
  // left it: a scan that believes it elsewhere misses it. (Without, the grasp is taken relative
  // to the object.)
  const Iso3 T_O_palm = world_->physics() ? Iso3(world_->tablePose.inverse() * m.tipPose(q + error))
                        : exact           ? T_O_palm_planned
                                          : T_O_palm_planned * delta;
  auto reported = [&](const Iso3& T_true) -> Iso3 {
    if (exact) return T_true;
    return T_O_palm_planned * (T_O_palm.inverse() * T_true);
  };
  const JointVector open = q;  // the preshape the hand comes in with
  if (world_->options().pick_up_first_contact) {
    // A guarded move along the planned palm axis, from 25 cm short of the planned pose (more
    // than the open hand's reach: a plan made with the palm may have its fingers in the object)
    // to at most 10 cm past it (the plan was made on the model, whose hole-filled parts can lie
    // well outside the true surface). Where that line starts under the table (a side grasp low
    // over it, coming in slightly upwards), the hand starts from the farthest point of it that
    // is clear.
    TriangleMesh obstacles = world_->objectMesh();
    obstacles.append(tableMeshInObject(m, world_->tablePose));
    const FingerCloser closer(m, obstacles), objectOnly(m, world_->objectMesh());
    const Vec3 in = T_O_palm.linear().col(2);  // palm z points into the object
    const double back = clearStart(closer, open, T_O_palm, 0.25);
    Iso3 T = T_O_palm;
    T.translation() -= back * in;
    const double reach = back + 0.10;
    const std::optional<double> travel = closer.freeTravel(open, T, in, reach);
    if (!travel || *travel >= reach) return std::nullopt;  // blocked, or nothing to grasp there
    T.translation() += *travel * in;
    // The fingers close; one that meets the table short of the object lifts the hand off it.
    auto [closed, Tc] = closeOffTheTable(closer, objectOnly, open, T, 0.005, 0.03, 0.02);
    if (PhysicsWorld* ph = world_->physics()) {
      // The hand there, open as it came; the fingers close on the object under their force
      // limits (it may be pushed, or slip away); the grasp is where physics leaves it.
      const Iso3 T_B_palm = world_->tablePose * Tc;
      world_->q = closed.q;
      world_->T_tip_palm = m.tipPose(world_->trueJoints()).inverse() * T_B_palm;
      ph->reset(world_->tablePose, T_B_palm, open);
      world_->q = ph->closeHand(closed.q);
      world_->held = true;
      world_->syncFromPhysics();
      return reported(Tc);
    }
    world_->T_O_palm = Tc;
    world_->q = closed.q;
    world_->held = true;
    return reported(Tc);
  }
  Iso3 T = T_O_palm;
  const Vec3 back = -T_O_palm.linear().col(2);  // palm z points into the object
  const auto& palm = m.links()[m.tipLink()].collision;
  for (int k = 0;; ++k) {
    const Iso3 T_palm_O = T.inverse();
    bool clear = true;
    for (const SurfacePoint& s : world_->objectSamples()) {
      const Vec3 p = T_palm_O * s.p;
      for (const Primitive& prim : palm)
        if (prim.contains(p)) clear = false;
      if (!clear) break;
    }
    if (clear) break;
    if (k == 25) return std::nullopt;  // 5 cm back and still inside: no grasp here
    T.translation() += 0.002 * back;
  }
  // The real fingers close on the real object (the planner closed them on its model).
  world_->T_O_palm = T;
  world_->q = closeFingers(m, open, T, world_->objectMesh()).q;
  world_->held = true;
  return reported(T);
}

DepthImage SimWorld::render() {
  const auto t0 = std::chrono::steady_clock::now();
  struct Timed {
    std::chrono::steady_clock::time_point t0;
    double* total;
    ~Timed() {
      *total += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  } timed{t0, &render_s};
  ++renders;
  const uint64_t frame = frame_++;  // the arm's error and the noise at this frame
  RayScene scene;
  scene.addInstance(object_, objectPose());
  for (const Occluder& o : robot_.at(trueJoints(), Iso3::Identity()))
    scene.addInstance(*o.scene, o.T_O_scene);
  scene.commit();
  RenderOptions ro;
  ro.background_centre = model_->camera().panTilt_B;  // the room
  ro.background_radius_m = options_.room_radius_m;
  ro.noise = options_.noise;
  ro.seed = mixSeed(options_.seed, frame);
  DepthImage d = renderDepth(scene, T_B_C, camera_, noise_, ro);
  const SimFaults& f = options_.faults;
  if (f.dropped_frames > 0 && faultDraw(0) < f.dropped_frames) {
    ++faults.dropped_frames;
    return DepthImage();
  }
  if (f.corrupted_frames > 0 && faultDraw(1) < f.corrupted_frames) {
    switch (faults.corrupted_frames++ % 3) {
      case 0:
        std::fill(d.depth_m.begin(), d.depth_m.end(), 0.f);
        break;
      case 1:
        for (size_t i = 0; i < d.depth_m.size(); i += 5)
          d.depth_m[i] = std::numeric_limits<float>::quiet_NaN();
        break;
      default:
        for (int v = d.height / 2 - 20; v < d.height / 2 + 20; ++v)
          for (int u = 0; u < d.width; ++u) d.at(u, v) = 0.4f;
    }
  }
  return d;
}

namespace {
// sRGB (0–255) to linear intensity and back through tables, linearly interpolated (the colour
// render's per-pixel loop; within 0.05 of a level of srgbToLinear / linearToSrgb).
struct SrgbTables {
  std::array<float, 1025> lin;  // srgbToLinear at 255 i / 1024
  std::array<float, 4097> enc;  // linearToSrgb at i / 4096
  SrgbTables() {
    for (size_t i = 0; i < lin.size(); ++i) lin[i] = float(srgbToLinear(255.0 * double(i) / 1024));
    for (size_t i = 0; i < enc.size(); ++i) enc[i] = float(linearToSrgb(double(i) / 4096));
  }
  static float lookup(const float* t, int n, float x) {
    x = std::clamp(x, 0.f, float(n));
    const int i = std::min(int(x), n - 1);
    return t[i] + (t[i + 1] - t[i]) * (x - float(i));
  }
  float toLinear(float c255) const { return lookup(lin.data(), 1024, c255 * (1024.f / 255)); }
  float toSrgb(float l) const { return lookup(enc.data(), 4096, l * 4096); }
};
const SrgbTables& srgbTables() {
  static const SrgbTables t;
  return t;
}
}  // namespace

RgbImage SimWorld::renderColour() {
  const ColourCameraOptions& cc = camera_.colour;
  if (!cc.enabled) return {};
  const auto t0 = std::chrono::steady_clock::now();
  // The scene render() saw (its frame counter has moved on by one).
  const uint64_t frame = frame_ - 1;
  RayScene scene;
  scene.addInstance(object_, objectPose());
  const std::vector<Occluder> robot = robot_.at(trueJoints(), Iso3::Identity());
  for (const Occluder& o : robot) scene.addInstance(*o.scene, o.T_O_scene);
  scene.commit();
  const CameraIntrinsics& K = cc.intrinsics;
  const Iso3 T_B_RGB = T_B_C * cc.T_D_RGB;
  const Vec3f eye = T_B_RGB.translation().cast<float>();
  const Eigen::Matrix3f R = T_B_RGB.linear().cast<float>();
  const size_t n = size_t(K.width) * size_t(K.height);
  std::vector<Ray> rays(n);
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      Ray& r = rays[size_t(v) * size_t(K.width) + size_t(u)];
      r.origin = eye;
      r.dir = R * K.rayZ1(u, v).cast<float>();
      r.tfar = float(options_.room_radius_m > 0 ? 2 * options_.room_radius_m : 100.0);
    }
  std::vector<Hit> hits(n);
  scene.intersect(rays.data(), hits.data(), n);
  const SimColourOptions& o = options_.colour;
  const uint64_t seed = mixSeed(options_.seed ^ 0xC0104Full, frame);
  const float exposure = float(1 + o.exposure_sigma * gaussianAt(seed, 0));
  const int tableScene = int(robot.size());  // the table is the last occluder (geometry id)
  RgbImage out(K.width, K.height);
  const SrgbTables& tables = srgbTables();
  parallelFor(0, K.height, [&](int v) {
    // The row's noise in one batch (gaussianPairsF: the bits gaussianAtF gives, eight at a time).
    const size_t W = size_t(K.width), row = size_t(v) * W;
    std::vector<uint64_t> index(3 * W);
    std::vector<float> noise(3 * W, 0.f);
    if (o.noise_sigma > 0) {
      for (size_t k = 0; k < 3 * W; ++k) index[k] = 3 * row + k + 1;
      gaussianPairsF(seed, index.data(), 3 * W, noise.data(), nullptr);
    }
    for (int u = 0; u < K.width; ++u) {
      const size_t i = row + size_t(u);
      const Hit& h = hits[i];
      Vec3f albedo;
      float shade = 1;
      if (!h.valid()) {
        albedo = Vec3f(o.room[0], o.room[1], o.room[2]);
      } else {
        if (h.geometry == 0)
          albedo = colours_.at(objectMesh_, h.triangle, h.u, h.v);
        else if (h.geometry == tableScene)
          albedo = Vec3f(o.table[0], o.table[1], o.table[2]);
        else
          albedo = Vec3f(o.robot[0], o.robot[1], o.robot[2]);
        // Lambertian: ambient plus the lamp at the camera.
        const Vec3f nrm = h.normal.normalized();
        const float cosine = std::abs(nrm.dot(rays[i].dir.normalized()));
        shade = float(o.ambient) + float(1 - o.ambient) * cosine;
      }
      uint8_t* px = out.at(u, v);
      for (int c = 0; c < 3; ++c) {
        const float n = float(o.noise_sigma) * noise[3 * size_t(u) + size_t(c)];
        // Light adds in linear intensity; the camera encodes it as sRGB.
        const float c255 = tables.toSrgb(tables.toLinear(albedo[c]) * shade * exposure);
        px[c] = uint8_t(std::clamp(std::lround(c255 + n), 0L, 255L));
      }
    }
  });
  render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

double SimWorld::objectMass_kg() const {
  if (physics_) return physics_->mass_kg();
  const PhysicsOptions& p = options_.physics;
  return p.mass_kg > 0 ? p.mass_kg : p.density_kg_m3 * std::abs(objectSolid_.volume_m3);
}

JointVector SimWorld::jointTorques() {
  const JointVector qt = trueJoints();
  JointVector tau = model_->gravityTorques(qt);
  if (held)
    tau += model_->pointForceTorques(qt, model_->tipLink(), objectPose() * objectSolid_.com,
                                     objectMass_kg() * Vec3(0, 0, -9.81));
  const uint64_t read = torqueReads_++;
  for (int v : model_->armVariables())
    tau[v] +=
        options_.torque_noise_nm * gaussianAt(options_.seed ^ 0x70C0E5ull, read * 64 + uint64_t(v));
  return tau;
}

double SimWorld::faultDraw(int kind) {
  const uint64_t h = mixSeed(options_.seed ^ 0x5EED0FFA17ull, faultDraws_++ * 8 + uint64_t(kind));
  return double(h >> 11) * 0x1.0p-53;
}

double rampedFraction(double t, double T, double ramp) {
  const double total = T + ramp;
  if (t >= total) return 1.0;
  if (ramp <= 0 || T <= 0) return t / total;
  const double v = 1 / T;
  if (t < ramp) return 0.5 * v * t * t / ramp;
  if (t > total - ramp) return 1 - 0.5 * v * (total - t) * (total - t) / ramp;
  return v * (t - 0.5 * ramp);
}

namespace {
// A motion through joint-space waypoints as the sensor's frames see it: each segment's steps at
// the frame rate, at the joints' speed limits (trajectoryTime). With `ramp_s` > 0 each segment
// speeds up and slows down over that long (at most its own duration), a trapezoidal profile that
// takes the ramp longer; 0 moves at the limits throughout (the kinematic simulator).
struct MotionSteps {
  std::vector<std::pair<size_t, int>> steps;  // (segment, step) per sensor frame time
  std::vector<int> segmentSteps;
  std::vector<double> segmentTime, segmentRamp;

  MotionSteps(const RobotModel& m, const std::vector<JointVector>& waypoints, double rate_hz,
              double ramp_s)
      : segmentSteps(waypoints.size(), 0),
        segmentTime(waypoints.size(), 0),
        segmentRamp(waypoints.size(), 0) {
    for (size_t k = 1; k < waypoints.size(); ++k) {
      segmentTime[k] = trajectoryTime(m, m.arm(waypoints[k - 1]), m.arm(waypoints[k]));
      segmentRamp[k] = std::min(ramp_s, segmentTime[k]);
      segmentSteps[k] = std::max(1, int(std::ceil((segmentTime[k] + segmentRamp[k]) * rate_hz)));
      for (int s = 1; s <= segmentSteps[k]; ++s) steps.emplace_back(k, s);
    }
  }
  // The fraction of segment k covered at its step s.
  double fraction(size_t k, int s) const {
    if (s >= segmentSteps[k]) return 1.0;
    const double ramp = segmentRamp[k], T = segmentTime[k];
    if (ramp <= 0 || T <= 0) return double(s) / segmentSteps[k];
    return rampedFraction((T + ramp) * double(s) / segmentSteps[k], T, ramp);
  }
};
}  // namespace

void SimRobot::execute(const std::vector<JointVector>& waypoints,
                       const std::function<void(const JointVector&)>& on_state) {
  const RobotModel& m = world_->model();
  const SimOptions& o = world_->options();
  const SimFaults& f = o.faults;
  SimWorld& w = *world_;
  // The motion's steps, and the faults that come during it.
  PhysicsWorld* ph = w.physics();
  const MotionSteps motion(m, waypoints, o.frame_rate_hz, ph ? o.physics.ramp_s : 0.0);
  const std::vector<std::pair<size_t, int>>& steps = motion.steps;
  if (steps.empty()) return;
  if (f.refused_motions > 0 && w.faultDraw(8) < f.refused_motions) {
    ++w.faults.refused_motions;
    on_state(w.q);  // it stays where it is
    return;
  }
  int tick = 0;
  size_t last = steps.size();  // steps taken
  if (f.stopped_short > 0 && w.faultDraw(2) < f.stopped_short) {
    last = std::max<size_t>(1, size_t(double(steps.size()) * (0.2 + 0.6 * w.faultDraw(3))));
    ++w.faults.stopped_short;
  }
  const bool inHand = w.held;
  size_t slipAt = steps.size(), dropAt = steps.size();
  if (inHand) {
    if (f.slip_m > 0 && w.graspMotions == f.slip_in_motion) slipAt = steps.size() / 2;
    if (f.drop_in_motion >= 0 && w.motions == f.drop_in_motion) dropAt = steps.size() / 2;
    ++w.motions;
    ++w.graspMotions;
  }
  double untouched_s = 0;  // since the object last touched the hand (physics)
  double motionSlip = 0;   // how far the object moved in the hand during this motion, m
  const Iso3 grip = w.T_O_palm;
  for (size_t i = 0; i < last; ++i) {
    const auto [k, s] = steps[i];
    const JointVector& a = waypoints[k - 1];
    const JointVector& b = waypoints[k];
    w.q = a + (b - a) * motion.fraction(k, s);
    if (ph && w.held) {
      w.stepPhysics(1.0 / o.frame_rate_hz, &untouched_s);
      motionSlip = std::max(motionSlip, (w.T_O_palm.translation() - grip.translation()).norm());
    }
    if (w.held && w.slipping) {  // the grasp does not hold: the object falls
      w.held = false;
      w.slipping = false;
      ++w.drops;
    }
    if (i == slipAt && w.held) {  // the object slips in the hand
      const Vec3 dir = Vec3(w.faultDraw(4) - 0.5, w.faultDraw(5) - 0.5, w.faultDraw(6) - 0.5);
      w.T_O_palm.translation() += f.slip_m * dir.normalized();
      if (ph) ph->moveObject(ph->palmPose() * w.T_tip_palm.inverse() * w.T_O_palm.inverse());
      ++w.faults.slips;
    }
    if (i == dropAt && w.held) {  // the object falls out of the hand
      if (ph) {
        // With physics it falls from where the hand holds it and settles on the table (the
        // fingers let go in the simulated world only: the robot reports them as they were).
        ph->openHand();
        ph->settle(o.physics.settle_s);
        w.tablePose = ph->objectPose();
      }
      w.held = false;
      ++w.drops;
      ++w.faults.object_drops;
    }
    if (++tick % o.frame_subsample == 0 || i + 1 == last) {
      JointVector reported = w.q;
      if (f.pose_jumps > 0 && w.faultDraw(7) < f.pose_jumps) {
        const std::vector<int>& arm = m.armVariables();
        reported[arm[size_t(w.faultDraw(7) * double(arm.size())) % arm.size()]] += 0.3;
        ++w.faults.pose_jumps;
      }
      on_state(reported);
    }
  }
  if (ph && inHand && motionSlip > 0.002) {
    ++w.slips;
    w.slipMax_m = std::max(w.slipMax_m, motionSlip);
  }
}

void SimRobot::holdStill(double seconds) {
  SimWorld& w = *world_;
  if (!w.physics() || !w.held || !(seconds > 0)) return;
  const double dt = 1.0 / w.options().frame_rate_hz;
  double untouched_s = 0;
  for (int i = 0, n = int(std::ceil(seconds / dt - 1e-9)); i < n && w.held; ++i)
    w.stepPhysics(dt, &untouched_s);
}

std::pair<Iso3, JointVector> defaultGrasp(const RobotModel& model, const TriangleMesh& object) {
  const Aabb b = object.bounds();
  const Vec3 size = b.size();
  int axes[3] = {0, 1, 2};
  std::sort(axes, axes + 3, [&](int i, int j) { return size[i] < size[j]; });
  const int shortest = axes[0], middle = axes[1];
  Vec3 approach = Vec3::Zero(), across = Vec3::Zero();
  approach[middle] = 1;  // palm comes from +middle, pointing −middle
  across[shortest] = 1;
  Iso3 T = Iso3::Identity();
  T.linear().col(2) = -approach;
  T.linear().col(0) = across;
  T.linear().col(1) = (-approach).cross(across);
  // The open hand comes in along −approach from well outside until any link first touches the
  // object (the knuckles stand proud of the palm face), then the fingers close.
  const JointVector open = model.openHand(0.0);
  T.translation() = b.center() + (0.5 * size.norm() + 0.3) * approach;
  const FingerCloser closer(model, object);
  const std::optional<double> travel = closer.freeTravel(open, T, -approach, 1.0);
  INHAND_CHECK(travel && *travel < 1.0, "the default grasp's approach meets the object");
  T.translation() -= *travel * approach;
  ClosingResult r = closer.close(open, T);
  return {T, r.q};
}

namespace {
JointVector jointsFrom(const Json& j, int n) {
  if (!j.is_array() || int(j.size()) != n)
    throw Error("simulator state: joint vector of " + std::to_string(j.size()) + " values, the " +
                "robot has " + std::to_string(n));
  return vectorFrom(j);
}
}  // namespace

Json SimWorld::state() const {
  return {{"q", vectorJson(q)},
          {"joint_error", vectorJson(jointError)},
          {"T_B_C", isoJson(T_B_C)},
          {"T_O_palm", isoJson(T_O_palm)},
          {"held", held},
          {"slipping", slipping},
          {"drops", drops},
          {"frame", frame_},
          {"fault_draws", faultDraws_},
          {"torque_reads", torqueReads_},
          {"motions", motions},
          {"grasp_motions", graspMotions},
          {"table_pose", isoJson(tablePose)},
          {"T_tip_palm", isoJson(T_tip_palm)},
          {"slips", slips},
          {"slip_max_m", slipMax_m},
          {"physics", physics_ ? physics_->state() : Json()},
          {"faults",
           {faults.dropped_frames, faults.corrupted_frames, faults.pose_jumps, faults.stopped_short,
            faults.slips, faults.object_drops, faults.refused_motions, faults.failed_pickups}}};
}

void SimWorld::setState(const Json& j) {
  try {
    const int n = model_->variableCount();
    q = jointsFrom(j.at("q"), n);
    jointError = jointsFrom(j.at("joint_error"), n);
    T_B_C = isoFrom(j.at("T_B_C"));
    T_O_palm = isoFrom(j.at("T_O_palm"));
    held = j.at("held").get<bool>();
    slipping = j.at("slipping").get<bool>();
    drops = j.at("drops").get<int>();
    frame_ = j.at("frame").get<uint64_t>();
    faultDraws_ = j.value("fault_draws", uint64_t(0));
    torqueReads_ = j.value("torque_reads", uint64_t(0));
    motions = j.value("motions", 0);
    graspMotions = j.value("grasp_motions", 0);
    if (j.contains("table_pose")) tablePose = isoFrom(j.at("table_pose"));
    if (j.contains("T_tip_palm")) T_tip_palm = isoFrom(j.at("T_tip_palm"));
    slips = j.value("slips", 0);
    slipMax_m = j.value("slip_max_m", 0.0);
    if (physics_ && j.contains("physics") && !j.at("physics").is_null())
      physics_->setState(j.at("physics"));
    if (j.contains("faults")) {
      const std::vector<int> f = j.at("faults").get<std::vector<int>>();
      if (f.size() != 8) throw Error("simulator state: faults: expected 8 counts");
      faults = {f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7]};
    }
  } catch (const Json::exception& e) {
    throw Error(std::string("simulator state: ") + e.what());
  }
}

}  // namespace inhand
