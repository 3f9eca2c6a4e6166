#include "inhand/sim/physics.h"

#include <mujoco/mujoco.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <sstream>

#include "inhand/core/error.h"

namespace inhand {

std::string PhysicsOptions::validate() const {
  if (!(density_kg_m3 > 0 && density_kg_m3 <= 30000)) return "density_kg_m3 must be in (0, 30000]";
  if (!(mass_kg >= 0 && mass_kg <= 100)) return "mass_kg must be in [0, 100]";
  if (!(timestep_s >= 1e-4 && timestep_s <= 0.01)) return "timestep_s must be in [1e-4, 0.01]";
  if (!(finger_force_n > 0 && finger_force_n <= 1000)) return "finger_force_n must be in (0, 1000]";
  if (!(finger_close_time_s > 0.05 && finger_close_time_s <= 10))
    return "finger_close_time_s must be in (0.05, 10]";
  if (!(hold_force_factor >= 1 && hold_force_factor <= 1000))
    return "hold_force_factor must be in [1, 1000]";
  if (!(breakaway_rate >= 0 && breakaway_rate <= 10)) return "breakaway_rate must be in [0, 10]";
  if (!(ramp_s >= 0 && ramp_s <= 2)) return "ramp_s must be in [0, 2]";
  if (!(settle_s >= 0 && settle_s <= 20)) return "settle_s must be in [0, 20]";
  if (std::string p = decomposition.validate(); !p.empty()) return "decomposition." + p;
  return {};
}

namespace {
constexpr double kArmature = 0.01;  // kg·m²: a worm drive's rotor inertia seen at the joint

std::string num(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%.9g", x);
  return b;
}
// prefix followed by n (GCC 12 warns falsely of overlapping copies on "literal" + to_string).
std::string named(const char* prefix, long n) {
  char b[48];
  std::snprintf(b, sizeof b, "%s%ld", prefix, n);
  return b;
}
std::string vec(const Vec3& v) { return num(v.x()) + " " + num(v.y()) + " " + num(v.z()); }
std::string quat(const Mat3& R) {
  const Eigen::Quaterniond q(R);
  return num(q.w()) + " " + num(q.x()) + " " + num(q.y()) + " " + num(q.z());
}
std::string posQuat(const Iso3& T) {
  return "pos=\"" + vec(T.translation()) + "\" quat=\"" + quat(T.linear()) + "\"";
}
// An inertial element for a body of mass m with inertia I about com (body frame).
std::string inertial(double m, const Vec3& com, const Mat3& I) {
  Eigen::SelfAdjointEigenSolver<Mat3> es(0.5 * (I + I.transpose()));
  Mat3 R = es.eigenvectors();
  if (R.determinant() < 0) R.col(2) = -R.col(2);
  const Vec3 d = es.eigenvalues().cwiseMax(1e-9);
  return "<inertial pos=\"" + vec(com) + "\" quat=\"" + quat(R) + "\" mass=\"" + num(m) +
         "\" diaginertia=\"" + vec(d) + "\"/>";
}
}  // namespace

struct PhysicsWorld::Impl {
  const RobotModel* robot = nullptr;
  PhysicsOptions options;
  std::vector<ConvexPiece> pieces;
  double mass = 0, piecesVolume = 0;
  mjModel* m = nullptr;
  mjData* d = nullptr;
  int objectBody = -1, palmBody = -1, targetBody = -1, tableGeom = -1;
  int objectQpos = -1, objectDof = -1, palmQpos = -1, palmDof = -1;
  struct HandJoint {
    int variable = -1;  // robot variable
    int qpos = -1, dof = -1, actuator = -1;
    double force = 0;  // driving limit, N·m
    int finger = -1;   // index in fingers(), or -1 (spread and the like)
    bool driver = false;
    double mult = 1, offset = 0;  // follower: q = mult·q_driver + offset
  };
  std::vector<HandJoint> joints;
  std::vector<uint8_t> handBody;  // per MuJoCo body: part of the hand
  double simulated = 0, wall = 0;

  ~Impl() {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
  }

  void step(int n) {
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) mj_step(m, d);
    simulated += n * m->opt.timestep;
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  void setMocap(const Iso3& T) {
    for (int k = 0; k < 3; ++k) d->mocap_pos[k] = T.translation()[k];
    const Eigen::Quaterniond q(T.linear());
    d->mocap_quat[0] = q.w();
    d->mocap_quat[1] = q.x();
    d->mocap_quat[2] = q.y();
    d->mocap_quat[3] = q.z();
  }
  Iso3 bodyPose(int b) const {
    Iso3 T = Iso3::Identity();
    T.translation() = Vec3(d->xpos[3 * b], d->xpos[3 * b + 1], d->xpos[3 * b + 2]);
    T.linear() = Eigen::Quaterniond(d->xquat[4 * b], d->xquat[4 * b + 1], d->xquat[4 * b + 2],
                                    d->xquat[4 * b + 3])
                     .toRotationMatrix();
    return T;
  }
  Iso3 mocapPose() const {
    Iso3 T = Iso3::Identity();
    T.translation() = Vec3(d->mocap_pos[0], d->mocap_pos[1], d->mocap_pos[2]);
    T.linear() =
        Eigen::Quaterniond(d->mocap_quat[0], d->mocap_quat[1], d->mocap_quat[2], d->mocap_quat[3])
            .toRotationMatrix();
    return T;
  }
  void setFree(int qpos, int dof, const Iso3& T) {
    for (int k = 0; k < 3; ++k) d->qpos[qpos + k] = T.translation()[k];
    const Eigen::Quaterniond q(T.linear());
    d->qpos[qpos + 3] = q.w();
    d->qpos[qpos + 4] = q.x();
    d->qpos[qpos + 5] = q.y();
    d->qpos[qpos + 6] = q.z();
    for (int k = 0; k < 6; ++k) d->qvel[dof + k] = 0;
  }
};

namespace {

// The hand's part of the model: the tip link and the links below it, as MJCF bodies.
struct HandXml {
  std::string assets, bodies, actuators;
};

void geomsXml(const LinkInfo& link, const std::string& prefix, int* meshCount, HandXml* out,
              std::string* body) {
  for (const Primitive& p : link.collision) {
    const std::string pq = posQuat(p.T_link_geom);
    const std::string cls = " contype=\"2\" conaffinity=\"1\"";
    switch (p.type) {
      case Primitive::Type::kBox:
        *body += "<geom type=\"box\" size=\"" + vec(0.5 * p.size) + "\" " + pq + cls + "/>";
        break;
      case Primitive::Type::kCylinder:
        *body += "<geom type=\"cylinder\" size=\"" + num(p.size.x()) + " " + num(0.5 * p.size.z()) +
                 "\" " + pq + cls + "/>";
        break;
      case Primitive::Type::kSphere:
        *body += "<geom type=\"sphere\" size=\"" + num(p.size.x()) + "\" " + pq + cls + "/>";
        break;
      case Primitive::Type::kMesh: {
        if (!p.mesh || p.mesh->vertices.size() < 4) break;
        const std::string name = prefix + named("_m", (*meshCount)++);
        out->assets += "<mesh name=\"" + name + "\" vertex=\"";
        for (const Vec3f& v : p.mesh->vertices) out->assets += vec(v.cast<double>()) + " ";
        out->assets += "\"/>";
        *body += "<geom type=\"mesh\" mesh=\"" + name + "\" " + pq + cls + "/>";
        break;
      }
    }
  }
}

}  // namespace

PhysicsWorld::PhysicsWorld(const RobotModel& model, const TriangleMesh& object_O, double friction,
                           const PhysicsOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (std::string p = options.validate(); !p.empty()) throw Error("physics options: " + p);
  Impl& I = *impl_;
  I.robot = &model;
  I.options = options;
  // The object: mass and inertia of the solid its mesh encloses, collision through its pieces.
  const MassProperties mp = massProperties(object_O);
  if (!(mp.volume_m3 > 0))
    throw Error("physics: the object's mesh encloses no volume (it must be closed and outward)");
  I.mass = options.mass_kg > 0 ? options.mass_kg : options.density_kg_m3 * mp.volume_m3;
  const double density = I.mass / mp.volume_m3;
  I.pieces = convexDecomposition(object_O, options.decomposition);
  if (I.pieces.empty()) throw Error("physics: the object's convex decomposition is empty");
  for (const ConvexPiece& p : I.pieces) I.piecesVolume += p.volume_m3;

  std::ostringstream x;
  const std::string mu = num(friction) + " 0.002 0.0001";
  x << "<mujoco model=\"inhand\"><compiler angle=\"radian\"/>"
    << "<option timestep=\"" << num(options.timestep_s)
    << "\" gravity=\"0 0 -9.81\" cone=\"elliptic\" impratio=\"10\"/>"
    << "<default><geom friction=\"" << mu << "\" condim=\"4\" solref=\"0.005 1\"/></default>";
  std::string assets;
  for (size_t i = 0; i < I.pieces.size(); ++i) {
    assets += "<mesh name=\"" + named("obj", long(i)) + "\" vertex=\"";
    for (const Vec3& v : I.pieces[i].hull.vertices) assets += vec(v) + " ";
    assets += "\"/>";
  }
  // The hand: bodies along the URDF joints below the tip link.
  HandXml hand;
  int meshCount = 0;
  const std::vector<LinkInfo>& links = model.links();
  const std::vector<JointInfo>& js = model.joints();
  // Levers for the force limits: the farthest collision vertex of the links a joint carries.
  const JointVector q0 = model.openHand(0.0);
  const std::vector<Iso3> poses = model.linkPoses(q0);
  std::function<void(int, std::vector<int>*)> below = [&](int link, std::vector<int>* out) {
    out->push_back(link);
    for (const JointInfo& j : js)
      if (j.parentLink == link) below(j.childLink, out);
  };
  auto lever = [&](const JointInfo& j) {
    std::vector<int> carried;
    below(j.childLink, &carried);
    const Vec3 origin = (poses[size_t(j.parentLink)] * j.T_parent_joint).translation();
    double r = 0.02;
    for (int l : carried)
      for (const Primitive& p : links[size_t(l)].collision)
        for (const Vec3f& v : p.toMesh().vertices)
          r = std::max(r, (poses[size_t(l)] * v.cast<double>() - origin).norm());
    return r;
  };
  auto linkInertial = [&](const LinkInfo& l) {
    const double m = l.mass > 0 ? l.mass : 0.05;
    return inertial(m, l.com, Mat3::Identity() * m * 1e-4);
  };
  std::function<std::string(int)> bodyXml = [&](int link) {
    std::string b;
    geomsXml(links[size_t(link)], named("l", link), &meshCount, &hand, &b);
    for (size_t ji = 0; ji < js.size(); ++ji) {
      const JointInfo& j = js[ji];
      if (j.parentLink != link) continue;
      b += "<body name=\"" + named("link", j.childLink) + "\" " + posQuat(j.T_parent_joint) + ">" +
           linkInertial(links[size_t(j.childLink)]);
      if (j.type == JointInfo::Type::kRevolute || j.type == JointInfo::Type::kContinuous) {
        Impl::HandJoint hj;
        hj.variable = j.variable;
        const std::string name = named("j", long(ji));
        b += "<joint name=\"" + name + "\" type=\"hinge\" axis=\"" + vec(j.axis) + "\"";
        if (j.type == JointInfo::Type::kRevolute)
          b += " limited=\"true\" range=\"" + num(j.lower) + " " + num(j.upper) + "\"";
        hj.force = options.finger_force_n * lever(j);
        const double kp = hj.force / 0.02;
        b += " armature=\"" + num(kArmature) + "\" damping=\"" +
             num(2 * std::sqrt(kp * kArmature)) + "\"/>";
        hand.actuators += "<position name=\"a" + name + "\" joint=\"" + name + "\" kp=\"" +
                          num(kp) + "\" forcelimited=\"true\" forcerange=\"" + num(-hj.force) +
                          " " + num(hj.force) + "\"/>";
        for (size_t f = 0; f < model.fingers().size(); ++f) {
          const FingerInfo& fi = model.fingers()[f];
          if (fi.variable == j.variable) {
            hj.finger = int(f);
            hj.driver = true;
          } else if (j.mimicOf == fi.variable) {
            hj.finger = int(f);
            hj.mult = j.mimicMultiplier;
            hj.offset = j.mimicOffset;
          }
        }
        I.joints.push_back(hj);
      } else if (j.type == JointInfo::Type::kPrismatic) {
        throw Error("physics: prismatic hand joints are not supported (" + j.name + ")");
      }
      b += bodyXml(j.childLink) + "</body>";
    }
    return b;
  };
  const int tip = model.tipLink();
  const std::string handBodies = bodyXml(tip);
  std::string palmGeoms;
  geomsXml(links[size_t(tip)], "tip", &meshCount, &hand, &palmGeoms);
  const LinkInfo& palmLink = links[size_t(tip)];
  const double palmMass = palmLink.mass > 0 ? palmLink.mass : 1.0;

  const TableInfo& table = model.table();
  x << "<asset>" << assets << hand.assets << "</asset><worldbody>";
  x << "<geom name=\"table\" type=\"box\" pos=\"" << vec(table.center_B) << "\" size=\""
    << vec(0.5 * table.size) << "\" contype=\"1\" conaffinity=\"1\"/>";
  x << "<body name=\"object\">"
    << "<freejoint name=\"object\"/>" << inertial(I.mass, mp.com, density * mp.inertia_com);
  for (size_t i = 0; i < I.pieces.size(); ++i)
    x << "<geom type=\"mesh\" mesh=\"obj" << i << "\" contype=\"1\" conaffinity=\"1\"/>";
  x << "</body>";
  x << "<body name=\"target\" mocap=\"true\"/>";
  x << "<body name=\"palm\"><freejoint name=\"palm\"/>"
    << inertial(palmMass, palmLink.com, Mat3::Identity() * palmMass * 2e-3) << palmGeoms
    << handBodies << "</body>";
  x << "</worldbody><equality><weld body1=\"palm\" body2=\"target\" solref=\"0.004 1\"/></equality>"
    << "<actuator>" << hand.actuators << "</actuator></mujoco>";
  const std::string xml = x.str();

  // MuJoCo's virtual file system is megabytes of fixed arrays: on the heap, not the stack.
  const auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), "inhand.xml", int(xml.size())) != 0)
    throw Error("physics: MuJoCo could not take the model");
  std::memcpy(vfs->filedata[vfs->nfile - 1], xml.data(), xml.size());
  char error[1000] = "";
  I.m = mj_loadXML("inhand.xml", vfs.get(), error, sizeof error);
  mj_deleteVFS(vfs.get());
  if (!I.m) throw Error(std::string("physics: MuJoCo refused the model: ") + error);
  I.d = mj_makeData(I.m);
  I.objectBody = mj_name2id(I.m, mjOBJ_BODY, "object");
  I.palmBody = mj_name2id(I.m, mjOBJ_BODY, "palm");
  I.targetBody = mj_name2id(I.m, mjOBJ_BODY, "target");
  I.tableGeom = mj_name2id(I.m, mjOBJ_GEOM, "table");
  const int oj = mj_name2id(I.m, mjOBJ_JOINT, "object"), pj = mj_name2id(I.m, mjOBJ_JOINT, "palm");
  I.objectQpos = I.m->jnt_qposadr[oj];
  I.objectDof = I.m->jnt_dofadr[oj];
  I.palmQpos = I.m->jnt_qposadr[pj];
  I.palmDof = I.m->jnt_dofadr[pj];
  for (Impl::HandJoint& hj : I.joints) {
    const JointInfo& j = model.variable(hj.variable);
    const int ji = model.jointIndex(j.name);
    char name[32];
    std::snprintf(name, sizeof name, "j%d", ji);
    const int id = mj_name2id(I.m, mjOBJ_JOINT, name);
    hj.qpos = I.m->jnt_qposadr[id];
    hj.dof = I.m->jnt_dofadr[id];
    std::snprintf(name, sizeof name, "aj%d", ji);
    hj.actuator = mj_name2id(I.m, mjOBJ_ACTUATOR, name);
  }
  I.handBody.assign(size_t(I.m->nbody), 0);
  for (int b = 0; b < I.m->nbody; ++b)
    for (int a = b; a > 0; a = I.m->body_parentid[a])
      if (a == I.palmBody) I.handBody[size_t(b)] = 1;
}

PhysicsWorld::~PhysicsWorld() = default;

double PhysicsWorld::mass_kg() const { return impl_->mass; }
int PhysicsWorld::pieces() const { return int(impl_->pieces.size()); }
double PhysicsWorld::piecesVolume_m3() const { return impl_->piecesVolume; }
const std::vector<ConvexPiece>& PhysicsWorld::decomposition() const { return impl_->pieces; }
double PhysicsWorld::simulated_s() const { return impl_->simulated; }
double PhysicsWorld::wall_s() const { return impl_->wall; }

void PhysicsWorld::reset(const Iso3& T_B_O, const Iso3& T_B_palm, const JointVector& q) {
  Impl& I = *impl_;
  mj_resetData(I.m, I.d);
  I.setFree(I.objectQpos, I.objectDof, T_B_O);
  I.setFree(I.palmQpos, I.palmDof, T_B_palm);
  I.setMocap(T_B_palm);
  for (const Impl::HandJoint& hj : I.joints) {
    I.d->qpos[hj.qpos] = q[hj.variable];
    I.d->ctrl[hj.actuator] = q[hj.variable];
    // Spread and the like hold where they are, stiffly; fingers drive with their limit.
    const double limit = hj.finger < 0 ? I.options.hold_force_factor * hj.force : hj.force;
    I.m->actuator_forcerange[2 * hj.actuator] = -limit;
    I.m->actuator_forcerange[2 * hj.actuator + 1] = limit;
  }
  mj_forward(I.m, I.d);
}

JointVector PhysicsWorld::closeHand(const JointVector& q) {
  Impl& I = *impl_;
  const RobotModel& model = *I.robot;
  const double dt = I.m->opt.timestep;
  struct State {
    double dir = 1, limit = 0;
    bool done = false;
    double stalled_s = 0;
  };
  std::vector<State> st(I.joints.size());
  for (size_t k = 0; k < I.joints.size(); ++k) {
    const Impl::HandJoint& hj = I.joints[k];
    const JointInfo& j = model.variable(hj.variable);
    if (hj.finger < 0) {
      st[k].done = true;
      continue;
    }
    const FingerInfo& f = model.fingers()[size_t(hj.finger)];
    const double dirDriver = f.closed >= f.open ? 1.0 : -1.0;
    st[k].dir = hj.driver ? dirDriver : dirDriver * (hj.mult >= 0 ? 1.0 : -1.0);
    st[k].limit = hj.driver ? f.closed : (st[k].dir > 0 ? j.upper : j.lower);
  }
  std::vector<int> driverOf(model.fingers().size(), -1);
  for (size_t k = 0; k < I.joints.size(); ++k)
    if (I.joints[k].driver) driverOf[size_t(I.joints[k].finger)] = int(k);
  const double t_max = 2 * I.options.finger_close_time_s;
  for (double t = 0; t < t_max; t += dt) {
    bool all = true;
    for (size_t k = 0; k < I.joints.size(); ++k) {
      if (st[k].done) continue;
      all = false;
      const Impl::HandJoint& hj = I.joints[k];
      const FingerInfo& f = model.fingers()[size_t(hj.finger)];
      const double rate = std::abs(f.closed - f.open) / I.options.finger_close_time_s;
      double& target = I.d->ctrl[hj.actuator];
      const double qj = I.d->qpos[hj.qpos];
      if (hj.driver) {
        target = st[k].dir > 0 ? std::min(st[k].limit, target + rate * dt)
                               : std::max(st[k].limit, target - rate * dt);
      } else {
        const int drv = driverOf[size_t(hj.finger)];
        if (drv >= 0 && !st[size_t(drv)].done) {  // coupled to the driven joint's command
          target = hj.mult * I.d->ctrl[I.joints[size_t(drv)].actuator] + hj.offset;
        } else {  // TorqueSwitch: the driven joint stopped, this one closes on
          const double r = I.options.breakaway_rate * rate;
          target = st[k].dir > 0 ? std::min(st[k].limit, target + r * dt)
                                 : std::max(st[k].limit, target - r * dt);
        }
      }
      // Stalled: held back by a contact (the servo's error grows, the joint does not move).
      const double lag = st[k].dir * (target - qj);
      const double speed = std::abs(I.d->qvel[hj.dof]);
      st[k].stalled_s = (lag > 0.05 && speed < 0.05) ? st[k].stalled_s + dt : 0;
      const bool atLimit = std::abs(qj - st[k].limit) < 0.01;
      if (st[k].stalled_s > 0.05 || atLimit) st[k].done = true;
    }
    if (all) break;
    I.step(1);
  }
  // Lock: each finger joint holds where it is, pressing with the force it had reached, and
  // resists being pushed back (the worm drive) up to hold_force_factor times its drive.
  for (const Impl::HandJoint& hj : I.joints) {
    if (hj.finger < 0) continue;
    const int a = hj.actuator;
    const double kp = I.m->actuator_gainprm[size_t(a) * mjNGAIN];
    const double qj = I.d->qpos[hj.qpos];
    const double force = std::clamp(kp * (I.d->ctrl[a] - qj), -hj.force, hj.force);
    I.d->ctrl[a] = qj + force / kp;
    I.m->actuator_forcerange[2 * a] = -I.options.hold_force_factor * hj.force;
    I.m->actuator_forcerange[2 * a + 1] = I.options.hold_force_factor * hj.force;
  }
  return handJoints(q);
}

void PhysicsWorld::openHand() {
  Impl& I = *impl_;
  const RobotModel& model = *I.robot;
  std::vector<double> from(I.joints.size()), to(I.joints.size());
  for (size_t k = 0; k < I.joints.size(); ++k) {
    const Impl::HandJoint& hj = I.joints[k];
    from[k] = I.d->qpos[hj.qpos];
    to[k] = from[k];
    if (hj.finger < 0) continue;
    const FingerInfo& f = model.fingers()[size_t(hj.finger)];
    to[k] = hj.driver ? f.open : hj.mult * f.open + hj.offset;
  }
  const int n = std::max(1, int(std::ceil(I.options.finger_close_time_s / I.m->opt.timestep)));
  for (int s = 1; s <= n; ++s) {
    for (size_t k = 0; k < I.joints.size(); ++k)
      I.d->ctrl[I.joints[k].actuator] = from[k] + (to[k] - from[k]) * double(s) / n;
    I.step(1);
  }
}

void PhysicsWorld::movePalm(const Iso3& T_B_palm, double duration_s) {
  Impl& I = *impl_;
  const Iso3 from = I.mocapPose();
  const Eigen::Quaterniond qa(from.linear()), qb(T_B_palm.linear());
  const int n = std::max(1, int(std::lround(duration_s / I.m->opt.timestep)));
  for (int s = 1; s <= n; ++s) {
    const double f = double(s) / n;
    Iso3 T = Iso3::Identity();
    T.translation() = from.translation() + f * (T_B_palm.translation() - from.translation());
    T.linear() = qa.slerp(f, qb).toRotationMatrix();
    I.setMocap(T);
    I.step(1);
  }
}

void PhysicsWorld::moveObject(const Iso3& T_B_O) {
  Impl& I = *impl_;
  I.setFree(I.objectQpos, I.objectDof, T_B_O);
  mj_forward(I.m, I.d);
}

void PhysicsWorld::settle(double max_s) {
  // At rest: the object moved less than 0.3 mm and 0.3° over the last tenth of a second (the
  // contact solver's velocities chatter at mm/s while the pose stays put).
  Impl& I = *impl_;
  const int window = std::max(1, int(std::lround(0.1 / I.m->opt.timestep)));
  Iso3 start = objectPose();
  for (int s = 1; s * I.m->opt.timestep <= max_s; ++s) {
    I.step(1);
    if (s % window) continue;
    const Iso3 now = objectPose();
    const bool still = (now.translation() - start.translation()).norm() < 3e-4 &&
                       Eigen::AngleAxisd(now.linear() * start.linear().transpose()).angle() < 0.005;
    if (still) break;
    start = now;
  }
}

Iso3 PhysicsWorld::objectPose() const { return impl_->bodyPose(impl_->objectBody); }
Iso3 PhysicsWorld::palmPose() const { return impl_->bodyPose(impl_->palmBody); }

double PhysicsWorld::objectSpeed() const {
  const Impl& I = *impl_;
  double s = 0;
  for (int k = 0; k < 3; ++k) s += I.d->qvel[I.objectDof + k] * I.d->qvel[I.objectDof + k];
  return std::sqrt(s);
}

bool PhysicsWorld::objectTouchesHand() const {
  const Impl& I = *impl_;
  for (int c = 0; c < I.d->ncon; ++c) {
    const int b1 = I.m->geom_bodyid[I.d->contact[c].geom1];
    const int b2 = I.m->geom_bodyid[I.d->contact[c].geom2];
    if ((b1 == I.objectBody && I.handBody[size_t(b2)]) ||
        (b2 == I.objectBody && I.handBody[size_t(b1)]))
      return true;
  }
  return false;
}

bool PhysicsWorld::objectTouchesTable() const {
  const Impl& I = *impl_;
  for (int c = 0; c < I.d->ncon; ++c) {
    const mjContact& k = I.d->contact[c];
    const int b1 = I.m->geom_bodyid[k.geom1], b2 = I.m->geom_bodyid[k.geom2];
    if ((k.geom1 == I.tableGeom && b2 == I.objectBody) ||
        (k.geom2 == I.tableGeom && b1 == I.objectBody))
      return true;
  }
  return false;
}

JointVector PhysicsWorld::handJoints(const JointVector& q) const {
  const Impl& I = *impl_;
  JointVector out = q;
  for (const Impl::HandJoint& hj : I.joints) out[hj.variable] = I.d->qpos[hj.qpos];
  return out;
}

Json PhysicsWorld::state() const {
  const Impl& I = *impl_;
  auto arr = [](const mjtNum* a, int n) { return std::vector<double>(a, a + n); };
  return {{"qpos", arr(I.d->qpos, I.m->nq)},
          {"qvel", arr(I.d->qvel, I.m->nv)},
          {"ctrl", arr(I.d->ctrl, I.m->nu)},
          {"warmstart", arr(I.d->qacc_warmstart, I.m->nv)},
          {"mocap_pos", arr(I.d->mocap_pos, 3 * I.m->nmocap)},
          {"mocap_quat", arr(I.d->mocap_quat, 4 * I.m->nmocap)},
          {"forcerange", arr(I.m->actuator_forcerange, 2 * I.m->nu)},
          {"time", I.d->time},
          {"simulated_s", I.simulated}};
}

void PhysicsWorld::setState(const Json& j) {
  Impl& I = *impl_;
  auto put = [&](const char* key, mjtNum* a, int n) {
    const std::vector<double> v = j.at(key).get<std::vector<double>>();
    if (int(v.size()) != n)
      throw Error(std::string("physics state: ") + key + " has " + std::to_string(v.size()) +
                  " values, the model " + std::to_string(n));
    std::copy(v.begin(), v.end(), a);
  };
  try {
    mj_resetData(I.m, I.d);
    put("qpos", I.d->qpos, I.m->nq);
    put("qvel", I.d->qvel, I.m->nv);
    put("ctrl", I.d->ctrl, I.m->nu);
    put("warmstart", I.d->qacc_warmstart, I.m->nv);
    put("mocap_pos", I.d->mocap_pos, 3 * I.m->nmocap);
    put("mocap_quat", I.d->mocap_quat, 4 * I.m->nmocap);
    put("forcerange", I.m->actuator_forcerange, 2 * I.m->nu);
    I.d->time = j.at("time").get<double>();
    I.simulated = j.at("simulated_s").get<double>();
  } catch (const Json::exception& e) {
    throw Error(std::string("physics state: ") + e.what());
  }
  mj_forward(I.m, I.d);
}

}  // namespace inhand
