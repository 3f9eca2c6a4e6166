#include "inhand/sim/sim_world.h"

#include <algorithm>
#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/random.h"
#include "inhand/geometry/primitives.h"
#include "inhand/robot/collision.h"
#include "inhand/robot/wrench.h"

namespace inhand {

std::string SimOptions::validate() const {
  if (!(frame_rate_hz > 0)) return "frame_rate_hz must be > 0";
  if (frame_subsample < 1) return "frame_subsample must be >= 1";
  if (!(room_radius_m >= 0)) return "room_radius_m must be >= 0";
  if (!(friction > 0 && friction <= 2)) return "friction must be in (0, 2]";
  if (!(hold_min_epsilon >= 0)) return "hold_min_epsilon must be >= 0";
  if (!R_B_O_rest.allFinite() || std::abs(R_B_O_rest.determinant() - 1) > 1e-6)
    return "the rest orientation must be a rotation";
  if (!(arm_error_m >= 0 && arm_error_m <= 0.2)) return "arm_error_m must be in [0, 0.2] m";
  return {};
}

namespace {
// Arm joint offsets in a direction drawn from the seed (uniform on the sphere of arm joint
// space), scaled so that the palm moves error_m at the home configuration.
JointVector armJointError(const RobotModel& m, double error_m, uint64_t seed) {
  JointVector e = JointVector::Zero(m.variableCount());
  if (error_m <= 0) return e;
  Rng rng = makeRng(mixSeed(seed, 0xa4e));
  std::normal_distribution<double> N(0, 1);
  for (int v : m.armVariables()) e[v] = N(rng);
  e /= e.norm();
  const JointVector home = m.home();
  const Vec3 p0 = m.tipPose(home).translation();
  // The palm's displacement is nearly linear in the offsets' scale for small angles; two
  // secant steps make it exact to a micrometre.
  double s = 0.01;
  for (int it = 0; it < 20; ++it) {
    const double d = (m.tipPose(home + s * e).translation() - p0).norm();
    if (std::abs(d - error_m) < 1e-6 || d <= 0) break;
    s *= error_m / d;
  }
  return s * e;
}
}  // namespace

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
  jointError = armJointError(model, options.arm_error_m, options.seed);
  objectMesh_ = object_O;
  objectSamples_ = surfaceSamples(object_O, 0.003);
  object_.addMesh(object_O);
  object_.commit();
  if (options.room_radius_m > 0) room_.addMesh(makeSphere(options.room_radius_m, 3));
  room_.commit();
}

Iso3 SimWorld::objectPose() const {
  return held ? model_->tipPose(trueJoints()) * T_O_palm.inverse() : restPose();
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
  world_->held = false;
  world_->slipping = false;
  return true;
}

std::optional<Iso3> SimRobot::pickUp(const Iso3& T_O_palm, const JointVector& q) {
  std::optional<Iso3> T = grasp(T_O_palm, q);
  world_->slipping = T && !world_->graspHolds();
  return T;
}

std::optional<Iso3> SimRobot::grasp(const Iso3& T_O_palm, const JointVector& q) {
  const RobotModel& m = world_->model();
  const JointVector open = q;  // the preshape the hand comes in with
  if (world_->options().pick_up_first_contact) {
    // A guarded move along the planned palm axis, from 25 cm short of the planned pose (more
    // than the open hand's reach: a plan made with the palm may have its fingers in the object)
    // to at most 10 cm past it (the plan was made on the model, whose hole-filled parts can lie
    // well outside the true surface).
    TriangleMesh obstacles = world_->objectMesh();
    obstacles.append(tableMeshInObject(m, world_->restPose()));
    const FingerCloser closer(m, obstacles), objectOnly(m, world_->objectMesh());
    const Vec3 in = T_O_palm.linear().col(2);  // palm z points into the object
    Iso3 T = T_O_palm;
    T.translation() -= 0.25 * in;
    const std::optional<double> travel = closer.freeTravel(open, T, in, 0.35);
    if (!travel || *travel >= 0.35) return std::nullopt;  // blocked, or nothing to grasp there
    T.translation() += *travel * in;
    // The fingers close; one that meets the table short of the object lifts the hand off it.
    auto [closed, Tc] = closeOffTheTable(closer, objectOnly, open, T, 0.005, 0.03, 0.02);
    world_->T_O_palm = Tc;
    world_->q = closed.q;
    T = Tc;
    world_->held = true;
    return T;
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
  return T;
}

DepthImage SimWorld::render() {
  RayScene scene;
  scene.addInstance(object_, objectPose());
  for (const Occluder& o : robot_.at(trueJoints(), Iso3::Identity()))
    scene.addInstance(*o.scene, o.T_O_scene);
  if (options_.room_radius_m > 0)
    scene.addInstance(room_, Iso3(Eigen::Translation3d(model_->camera().panTilt_B)));
  scene.commit();
  RenderOptions ro;
  ro.noise = options_.noise;
  ro.seed = mixSeed(options_.seed, frame_++);
  return renderDepth(scene, T_B_C, camera_, noise_, ro);
}

void SimRobot::execute(const std::vector<JointVector>& waypoints,
                       const std::function<void(const JointVector&)>& on_state) {
  const RobotModel& m = world_->model();
  const SimOptions& o = world_->options();
  int tick = 0;
  for (size_t w = 1; w < waypoints.size(); ++w) {
    const JointVector& a = waypoints[w - 1];
    const JointVector& b = waypoints[w];
    double duration = trajectoryTime(m, m.arm(a), m.arm(b));
    int steps = std::max(1, int(std::ceil(duration * o.frame_rate_hz)));
    for (int s = 1; s <= steps; ++s) {
      world_->q = a + (b - a) * (double(s) / steps);
      if (world_->held && world_->slipping) {  // the grasp does not hold: the object falls
        world_->held = false;
        world_->slipping = false;
        ++world_->drops;
      }
      if (++tick % o.frame_subsample == 0 || (w + 1 == waypoints.size() && s == steps))
        on_state(world_->q);
    }
  }
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
Json jointsJson(const JointVector& q) {
  Json j = Json::array();
  for (int i = 0; i < q.size(); ++i) j.push_back(q[i]);
  return j;
}
JointVector jointsFrom(const Json& j, int n) {
  if (!j.is_array() || int(j.size()) != n)
    throw Error("simulator state: joint vector of " + std::to_string(j.size()) + " values, the " +
                "robot has " + std::to_string(n));
  JointVector q(n);
  for (int i = 0; i < n; ++i) q[i] = j.at(size_t(i)).get<double>();
  return q;
}
}  // namespace

Json SimWorld::state() const {
  return {{"q", jointsJson(q)},
          {"joint_error", jointsJson(jointError)},
          {"T_B_C", isoJson(T_B_C)},
          {"T_O_palm", isoJson(T_O_palm)},
          {"held", held},
          {"slipping", slipping},
          {"drops", drops},
          {"frame", frame_}};
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
  } catch (const Json::exception& e) {
    throw Error(std::string("simulator state: ") + e.what());
  }
}

}  // namespace inhand
