#include "inhand/physics/physics.h"

#include <mujoco/mujoco.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <sstream>

#include "inhand/core/error.h"
#include "inhand/core/pose.h"
#include "inhand/robot/collision.h"

namespace inhand {

std::string PhysicsOptions::validate() const {
  if (std::string p = checkOptionRanges(*this); !p.empty()) return p;
  if (!(touch_force_n <= finger_force_n)) return "touch_force_n must be at most finger_force_n";
  if (!(contact_timeconst_s >= 2 * timestep_s - 1e-12))
    return "contact_timeconst_s must be at least twice timestep_s (MuJoCo's floor)";
  if (!(table_contact_timeconst_s >= 2 * timestep_s - 1e-12))
    return "table_contact_timeconst_s must be at least twice timestep_s (MuJoCo's floor)";
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

// A hand joint in the MuJoCo model, driven by a position servo.
struct HandJoint {
  int variable = -1;  // robot variable
  int joint = -1;     // robot joint (index into RobotModel::joints())
  int qpos = -1, dof = -1, actuator = -1;
  double force = 0;       // driving limit, N·m
  double kp = 0, kv = 0;  // servo gains: kp (target − q) + kv (commanded speed − q̇)
  int finger = -1;        // index in fingers(), or -1 (spread and the like)
  bool driver = false;
  double mult = 1, offset = 0;  // follower: q = mult·q_driver + offset
};
}  // namespace

struct PhysicsWorld::Impl {
  const RobotModel* robot = nullptr;
  PhysicsOptions options;
  std::vector<ConvexPiece> pieces;
  double mass = 0, piecesVolume = 0;
  mjModel* m = nullptr;
  mjData* d = nullptr;
  int objectBody = -1, palmBody = -1, tableGeom = -1;
  int objectQpos = -1, objectDof = -1, palmQpos = -1, palmDof = -1;
  std::vector<HandJoint> joints;
  std::vector<uint8_t> handBody;  // per MuJoCo body: part of the hand
  double simulated = 0, wall = 0;

  // The ids and addresses of the named parts in the compiled model.
  void bind() {
    objectBody = mj_name2id(m, mjOBJ_BODY, "object");
    palmBody = mj_name2id(m, mjOBJ_BODY, "palm");
    tableGeom = mj_name2id(m, mjOBJ_GEOM, "table");
    const int oj = mj_name2id(m, mjOBJ_JOINT, "object"), pj = mj_name2id(m, mjOBJ_JOINT, "palm");
    objectQpos = m->jnt_qposadr[oj];
    objectDof = m->jnt_dofadr[oj];
    palmQpos = m->jnt_qposadr[pj];
    palmDof = m->jnt_dofadr[pj];
    for (HandJoint& hj : joints) {
      char name[32];
      std::snprintf(name, sizeof name, "j%d", hj.joint);
      const int id = mj_name2id(m, mjOBJ_JOINT, name);
      hj.qpos = m->jnt_qposadr[id];
      hj.dof = m->jnt_dofadr[id];
      std::snprintf(name, sizeof name, "aj%d", hj.joint);
      hj.actuator = mj_name2id(m, mjOBJ_ACTUATOR, name);
    }
    handBody.assign(size_t(m->nbody), 0);
    for (int b = 0; b < m->nbody; ++b)
      for (int a = b; a > 0; a = m->body_parentid[a])
        if (a == palmBody) handBody[size_t(b)] = 1;
  }

  ~Impl() {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
  }

  int unstable = 0;  // steps MuJoCo found unstable (bad accelerations), undone
  std::vector<mjtNum> saved;
  // MuJoCo 2.2 sizes its buffers once, from the model's nconmax and njmax (its A·R matrix alone
  // holds njmax² numbers). They begin at PhysicsOptions::constraint_rows and double whenever a
  // step fills them (grow): the step is taken again with room, so a full buffer never drops a
  // contact.
  std::string xml;                  // the model's MJCF with "@SIZE@" for its size element
  int rows = 0;                     // njmax (nconmax: a quarter)
  int grown = 0;                    // times the buffers doubled
  std::vector<mjtNum> savedMotion;  // qvel, qacc_warmstart and act before the step
  void grow();
  // The positions, servo commands and the palm's target saved before the step, into `to`.
  void restoreSaved(mjData* to) const {
    const size_t nq = size_t(m->nq), nu = size_t(m->nu), nm = size_t(m->nmocap);
    std::copy(saved.begin(), saved.begin() + long(nq), to->qpos);
    std::copy(saved.begin() + long(nq), saved.begin() + long(nq + nu), to->ctrl);
    std::copy(saved.begin() + long(nq + nu), saved.begin() + long(nq + nu + 3 * nm), to->mocap_pos);
    std::copy(saved.begin() + long(nq + nu + 3 * nm), saved.end(), to->mocap_quat);
  }
  // Steps n times. A step MuJoCo finds unstable resets its whole state (the object at the
  // world's origin, the servos' commands and the palm's target zeroed): it is undone, the
  // positions, commands and target as before it, at rest.
  void step(int n) {
    const auto t0 = std::chrono::steady_clock::now();
    const size_t nq = size_t(m->nq), nu = size_t(m->nu), nm = size_t(m->nmocap);
    saved.resize(nq + nu + 7 * nm);
    for (int i = 0; i < n; ++i) {
      std::copy(d->qpos, d->qpos + nq, saved.begin());
      std::copy(d->ctrl, d->ctrl + nu, saved.begin() + long(nq));
      std::copy(d->mocap_pos, d->mocap_pos + 3 * nm, saved.begin() + long(nq + nu));
      std::copy(d->mocap_quat, d->mocap_quat + 4 * nm, saved.begin() + long(nq + nu + 3 * nm));
      const int bad = d->warning[mjWARN_BADQACC].number;
      const int full = d->warning[mjWARN_CONTACTFULL].number + d->warning[mjWARN_CNSTRFULL].number;
      const double time = d->time;
      const size_t nv = size_t(m->nv), na = size_t(m->na);
      savedMotion.resize(2 * nv + na);
      std::copy(d->qvel, d->qvel + nv, savedMotion.begin());
      std::copy(d->qacc_warmstart, d->qacc_warmstart + nv, savedMotion.begin() + long(nv));
      std::copy(d->act, d->act + na, savedMotion.begin() + long(2 * nv));
      mj_step(m, d);
      if (d->warning[mjWARN_CONTACTFULL].number + d->warning[mjWARN_CNSTRFULL].number > full) {
        grow();  // the state as before the step, with room: the step again
        d->time = time;
        --i;
        continue;
      }
      if (d->warning[mjWARN_BADQACC].number == bad && d->time > time) continue;
      restoreSaved(d);
      std::fill(d->qvel, d->qvel + m->nv, 0.0);
      std::fill(d->qacc_warmstart, d->qacc_warmstart + m->nv, 0.0);
      d->time = time + m->opt.timestep;
      mj_forward(m, d);
      ++unstable;
    }
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
  // The body contact c touches the table with; -1 when it is not a contact with the table.
  int tableContactBody(int c) const {
    const mjContact& k = d->contact[c];
    if (k.geom1 == tableGeom) return m->geom_bodyid[k.geom2];
    if (k.geom2 == tableGeom) return m->geom_bodyid[k.geom1];
    return -1;
  }
  // Contact c is between the object and a hand link.
  bool handObjectContact(int c) const {
    const int b1 = m->geom_bodyid[d->contact[c].geom1], b2 = m->geom_bodyid[d->contact[c].geom2];
    return (b1 == objectBody && handBody[size_t(b2)]) || (b2 == objectBody && handBody[size_t(b1)]);
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

// The hand as MJCF: the tip link's bodies and joints below it (URDF tree), each hinge with a
// force-limited position servo.
class HandXmlBuilder {
 public:
  HandXmlBuilder(const RobotModel& model, const PhysicsOptions& options)
      : model_(model), options_(options), poses_(model.linkPoses(model.openHand(0.0))) {}
  // The palm's geoms and the bodies below it; the joints go to `joints`.
  std::string palmContents(std::vector<HandJoint>* joints) {
    const int tip = model_.tipLink();
    std::string palm;
    geomsXml(model_.links()[size_t(tip)], "tip", &meshCount_, &xml_, &palm);
    return palm + bodies(tip, joints);
  }
  const std::string& assets() const { return xml_.assets; }
  const std::string& actuators() const { return xml_.actuators; }

 private:
  // The links `link` carries, itself included.
  void below(int link, std::vector<int>* out) const {
    out->push_back(link);
    for (const JointInfo& j : model_.joints())
      if (j.parentLink == link) below(j.childLink, out);
  }
  // The force limit's lever: the farthest collision vertex of the links the joint carries.
  double lever(const JointInfo& j) const {
    std::vector<int> carried;
    below(j.childLink, &carried);
    const Vec3 origin = (poses_[size_t(j.parentLink)] * j.T_parent_joint).translation();
    double r = 0.02;
    for (int l : carried)
      for (const Primitive& p : model_.links()[size_t(l)].collision)
        for (const Vec3f& v : p.toMesh().vertices)
          r = std::max(r, (poses_[size_t(l)] * v.cast<double>() - origin).norm());
    return r;
  }
  std::string hinge(int ji, std::vector<HandJoint>* joints) {
    const JointInfo& j = model_.joints()[size_t(ji)];
    HandJoint hj;
    hj.variable = j.variable;
    hj.joint = ji;
    const std::string name = named("j", ji);
    std::string b = "<joint name=\"" + name + "\" type=\"hinge\" axis=\"" + vec(j.axis) + "\"";
    if (j.type == JointInfo::Type::kRevolute)
      b += " limited=\"true\" range=\"" + num(j.lower) + " " + num(j.upper) + "\"";
    hj.force = options_.finger_force_n * lever(j);
    // The full force at 0.02 rad behind the target, critically damped; the damping is the
    // servo's (relative to the commanded speed, within the force limit), not the joint's.
    hj.kp = hj.force / 0.02;
    hj.kv = 2 * std::sqrt(hj.kp * kArmature);
    b += " armature=\"" + num(kArmature) + "\" damping=\"" + num(0.01 * hj.kv) + "\"/>";
    xml_.actuators += "<general name=\"a" + name + "\" joint=\"" + name + "\" gainprm=\"" +
                      num(hj.kp) + "\" biastype=\"affine\" biasprm=\"0 " + num(-hj.kp) + " " +
                      num(-hj.kv) + "\" forcelimited=\"true\" forcerange=\"" + num(-hj.force) +
                      " " + num(hj.force) + "\"/>";
    for (size_t f = 0; f < model_.fingers().size(); ++f) {
      const FingerInfo& fi = model_.fingers()[f];
      if (fi.variable == j.variable) {
        hj.finger = int(f);
        hj.driver = true;
      } else if (j.mimicOf == fi.variable) {
        hj.finger = int(f);
        hj.mult = j.mimicMultiplier;
        hj.offset = j.mimicOffset;
      }
    }
    joints->push_back(hj);
    return b;
  }
  std::string bodies(int link, std::vector<HandJoint>* joints) {
    std::string b;
    const std::vector<JointInfo>& js = model_.joints();
    for (size_t ji = 0; ji < js.size(); ++ji) {
      const JointInfo& j = js[ji];
      if (j.parentLink != link) continue;
      const LinkInfo& child = model_.links()[size_t(j.childLink)];
      const double m = child.mass > 0 ? child.mass : 0.05;
      b += "<body name=\"" + named("link", j.childLink) + "\" " + posQuat(j.T_parent_joint) + ">" +
           inertial(m, child.com, Mat3::Identity() * m * 1e-4);
      if (j.type == JointInfo::Type::kRevolute || j.type == JointInfo::Type::kContinuous)
        b += hinge(int(ji), joints);
      else if (j.type == JointInfo::Type::kPrismatic)
        throw Error("physics: prismatic hand joints are not supported (" + j.name + ")");
      geomsXml(child, named("l", j.childLink), &meshCount_, &xml_, &b);
      b += bodies(j.childLink, joints) + "</body>";
    }
    return b;
  }

  const RobotModel& model_;
  const PhysicsOptions& options_;
  std::vector<Iso3> poses_;  // link poses with the hand open
  HandXml xml_;
  int meshCount_ = 0;
};

// The object as MJCF: a free body with the solid's inertia, one mesh geom per convex piece.
std::string objectXml(const std::vector<ConvexPiece>& pieces, double mass, const MassProperties& mp,
                      std::string* assets) {
  std::string body = "<body name=\"object\"><freejoint name=\"object\"/>" +
                     inertial(mass, mp.com, mass / mp.volume_m3 * mp.inertia_com);
  for (size_t i = 0; i < pieces.size(); ++i) {
    const std::string name = named("obj", long(i));
    *assets += "<mesh name=\"" + name + "\" vertex=\"";
    for (const Vec3& v : pieces[i].hull.vertices) *assets += vec(v) + " ";
    *assets += "\"/>";
    body += "<geom type=\"mesh\" mesh=\"" + name + "\" contype=\"1\" conaffinity=\"1\"/>";
  }
  return body + "</body>";
}

// Compiles MJCF text (MuJoCo's virtual file system is megabytes of fixed arrays: on the heap).
mjModel* compileXml(const std::string& xml) {
  const auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  if (mj_makeEmptyFileVFS(vfs.get(), "inhand.xml", int(xml.size())) != 0)
    throw Error("physics: MuJoCo could not take the model");
  std::memcpy(vfs->filedata[vfs->nfile - 1], xml.data(), xml.size());
  char error[1000] = "";
  mjModel* m = mj_loadXML("inhand.xml", vfs.get(), error, sizeof error);
  mj_deleteVFS(vfs.get());
  if (!m) throw Error(std::string("physics: MuJoCo refused the model: ") + error);
  return m;
}

// The model's MJCF with buffers for `rows` constraint rows and a quarter as many contacts.
std::string sizedXml(const std::string& xml, int rows) {
  std::string text = xml;
  text.replace(text.find("@SIZE@"), 6,
               "<size nconmax=\"" + std::to_string(std::max(1, rows / 4)) + "\" njmax=\"" +
                   std::to_string(rows) + "\"/>");
  return text;
}

}  // namespace

void PhysicsWorld::Impl::grow() {
  rows *= 2;
  mjModel* bigger = compileXml(sizedXml(xml, rows));
  mjData* fresh = mj_makeData(bigger);
  // The state as it was before the step (saved by step()): positions, servo commands, the
  // palm's target, velocities, warm start, activations (step() sets the time).
  const size_t nv = size_t(m->nv);
  restoreSaved(fresh);
  std::copy(savedMotion.begin(), savedMotion.begin() + long(nv), fresh->qvel);
  std::copy(savedMotion.begin() + long(nv), savedMotion.begin() + long(2 * nv),
            fresh->qacc_warmstart);
  std::copy(savedMotion.begin() + long(2 * nv), savedMotion.end(), fresh->act);
  // The warnings carry over, so that a step compares with the counts before it.
  std::copy(d->warning, d->warning + mjNWARNING, fresh->warning);
  mj_deleteData(d);
  mj_deleteModel(m);
  m = bigger;
  d = fresh;
  mj_forward(m, d);
  ++grown;
}

PhysicsWorld::PhysicsWorld(const RobotModel& model, const TriangleMesh& object_O, double friction,
                           const PhysicsOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (std::string p = options.validate(); !p.empty()) throw Error("physics options: " + p);
  // The object: mass and inertia of the solid its mesh encloses, collision through its pieces.
  // A mesh whose triangles all face inwards (a negative enclosed volume) is the same solid.
  MassProperties mp = massProperties(object_O);
  if (mp.volume_m3 < 0) {
    TriangleMesh outward = object_O;
    for (Tri& t : outward.triangles) std::swap(t[1], t[2]);
    mp = massProperties(outward);
  }
  if (!(mp.volume_m3 > 0))
    throw Error("physics: the object's mesh encloses no volume (it must be a closed surface)");
  std::vector<ConvexPiece> pieces = convexDecomposition(object_O, options.decomposition);
  if (pieces.empty()) throw Error("physics: the object's convex decomposition is empty");
  build(model, std::move(pieces), mp, friction, options);
}

PhysicsWorld::PhysicsWorld(const RobotModel& model, std::vector<ConvexPiece> pieces,
                           double friction, const PhysicsOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (std::string p = options.validate(); !p.empty()) throw Error("physics options: " + p);
  if (pieces.empty()) throw Error("physics: the object has no convex pieces");
  const MassProperties mp = massProperties(pieces);  // their union (they do not overlap)
  if (!(mp.volume_m3 > 0)) throw Error("physics: the object's pieces enclose no volume");
  build(model, std::move(pieces), mp, friction, options);
}

namespace {
// MuJoCo's warnings (a full contact buffer, an unstable step) are counted, not written to a log
// file in the working folder: the stepping undoes unstable steps and counts them itself.
std::atomic<long> mujocoWarnings{0};
void countWarning(const char*) { ++mujocoWarnings; }
}  // namespace

void PhysicsWorld::build(const RobotModel& model, std::vector<ConvexPiece> pieces,
                         const MassProperties& mp, double friction, const PhysicsOptions& options) {
  mju_user_warning = countWarning;
  Impl& I = *impl_;
  I.robot = &model;
  I.options = options;
  I.mass = options.mass_kg > 0 ? options.mass_kg : options.density_kg_m3 * mp.volume_m3;
  I.pieces = std::move(pieces);
  for (const ConvexPiece& p : I.pieces) I.piecesVolume += p.volume_m3;

  std::string assets;
  const std::string object = objectXml(I.pieces, I.mass, mp, &assets);
  HandXmlBuilder hand(model, options);
  const std::string palm = hand.palmContents(&I.joints);
  const LinkInfo& palmLink = model.links()[size_t(model.tipLink())];
  const double palmMass = palmLink.mass > 0 ? palmLink.mass : 1.0;
  const TableInfo& table = model.table();
  std::ostringstream x;
  // Contacts: every convex piece may touch the table plane at a few points (MuJoCo 2.2's default
  // buffer of 100 fills with a many-piece object on it): @SIZE@ is sizedXml's, which grows.
  x << "<mujoco model=\"inhand\"><compiler angle=\"radian\"/>@SIZE@"
    << "<option timestep=\"" << num(options.timestep_s)
    << "\" gravity=\"0 0 -9.81\" cone=\"elliptic\" impratio=\"10\" noslip_iterations=\""
    << options.noslip_iterations << "\"/>"
    << "<default><geom friction=\"" << num(friction) << " 0.002 0.0001\" condim=\"4\" solref=\""
    << num(options.contact_timeconst_s) << " 1\"/></default>"
    << "<asset>" << assets << hand.assets()
    << "</asset><worldbody>"
    // The table top as a plane (MuJoCo 2.2 gives a convex mesh one contact against a box, several
    // against a plane: an object rests on a plane without rocking).
    << "<geom name=\"table\" type=\"plane\" pos=\""
    << vec(Vec3(table.center_B.x(), table.center_B.y(), table.topZ())) << "\" size=\""
    << vec(Vec3(0.5 * table.size.x(), 0.5 * table.size.y(), 0.01))
    // Its solmix outweighs every other geom's: a contact with the table takes the table's solref.
    << "\" contype=\"1\" conaffinity=\"1\" solmix=\"1000\" solref=\""
    << num(options.table_contact_timeconst_s) << " 1\"/>" << object
    << "<body name=\"target\" mocap=\"true\"/>"
    << "<body name=\"palm\"><freejoint name=\"palm\"/>"
    << inertial(palmMass, palmLink.com, Mat3::Identity() * palmMass * 2e-3) << palm << "</body>"
    << "</worldbody><equality><weld body1=\"palm\" body2=\"target\" solref=\"0.004 1\"/>"
    << "</equality><actuator>" << hand.actuators() << "</actuator></mujoco>";
  I.xml = x.str();
  I.rows = options.constraint_rows;
  I.m = compileXml(sizedXml(I.xml, I.rows));
  I.d = mj_makeData(I.m);
  I.bind();
}

PhysicsWorld::~PhysicsWorld() = default;

double PhysicsWorld::mass_kg() const { return impl_->mass; }
int PhysicsWorld::buffersGrown() const { return impl_->grown; }
int PhysicsWorld::pieces() const { return int(impl_->pieces.size()); }
double PhysicsWorld::piecesVolume_m3() const { return impl_->piecesVolume; }
const std::vector<ConvexPiece>& PhysicsWorld::decomposition() const { return impl_->pieces; }
double PhysicsWorld::simulated_s() const { return impl_->simulated; }
int PhysicsWorld::unstableSteps() const { return impl_->unstable; }
double PhysicsWorld::wall_s() const { return impl_->wall; }

void PhysicsWorld::reset(const Iso3& T_B_O, const Iso3& T_B_palm, const JointVector& q) {
  Impl& I = *impl_;
  mj_resetData(I.m, I.d);
  I.setFree(I.objectQpos, I.objectDof, T_B_O);
  I.setFree(I.palmQpos, I.palmDof, T_B_palm);
  I.setMocap(T_B_palm);
  for (const HandJoint& hj : I.joints) {
    I.d->qpos[hj.qpos] = q[hj.variable];
    I.d->ctrl[hj.actuator] = q[hj.variable];
    // Spread and the like hold where they are, stiffly; fingers drive with their limit.
    const double limit = hj.finger < 0 ? I.options.hold_force_factor * hj.force : hj.force;
    I.m->actuator_forcerange[2 * hj.actuator] = -limit;
    I.m->actuator_forcerange[2 * hj.actuator + 1] = limit;
  }
  mj_forward(I.m, I.d);
  // The hand was put where it touches the object's mesh; the object's pieces are hulls that may
  // stand a little proud of it (a coarse decomposition, a mesh not quite convex in a piece): the
  // palm backs off along its approach until the hand does not start inside a piece.
  const Vec3 back = -T_B_palm.linear().col(2);
  Iso3 T = T_B_palm;
  for (int k = 0; k < 8; ++k) {
    double depth = 0;
    for (int c = 0; c < I.d->ncon; ++c)
      if (I.handObjectContact(c)) depth = std::max(depth, -I.d->contact[c].dist);
    if (depth < 2e-4) break;
    T.translation() += (depth + 2e-4) * back;
    I.setFree(I.palmQpos, I.palmDof, T);
    I.setMocap(T);
    mj_forward(I.m, I.d);
  }
}

namespace {
// A finger joint while the hand closes: its closing direction and end, whether it has stopped.
struct Closing {
  double dir = 1, limit = 0, target = 0;  // target: the commanded position
  bool done = false, atLimit = false;
  double stalled_s = 0;
  double reached = -1e9;  // the farthest closed so far (along dir)
};
}  // namespace

// Every finger joint's servo force limited to `fraction` of its drive (spread joints untouched).
void setFingerForce(mjModel* m, const std::vector<HandJoint>& joints, double fraction) {
  for (const HandJoint& hj : joints) {
    if (hj.finger < 0) continue;
    m->actuator_forcerange[2 * hj.actuator] = -fraction * hj.force;
    m->actuator_forcerange[2 * hj.actuator + 1] = fraction * hj.force;
  }
}

// The worm drive does not backdrive: a finger joint pushed back (opened) from the farthest it
// has closed is held there with the gear's strength (hold_force_factor times the drive), else it
// drives with `fraction` of its force toward its command.
void holdBack(PhysicsWorld::Impl& I, const HandJoint& hj, double fraction, Closing* c) {
  const double q = I.d->qpos[hj.qpos];
  c->reached = std::max(c->reached, c->dir * q);
  double limit = fraction * hj.force;
  if (c->dir * q < c->reached - 0.002) {
    I.d->ctrl[hj.actuator] = c->dir * c->reached;
    limit = I.options.hold_force_factor * hj.force;
  }
  I.m->actuator_forcerange[2 * hj.actuator] = -limit;
  I.m->actuator_forcerange[2 * hj.actuator + 1] = limit;
}

// The fingers close at their speed until each joint stalls on something or reaches its end (at
// most twice finger_close_time_s): driven joints from their command, coupled ones with it until
// the driven joint stops, then on at breakaway_rate (TorqueSwitch).
void closeUntilStalled(PhysicsWorld::Impl& I, std::vector<Closing>& st, double fraction,
                       const std::function<void()>& eachStep) {
  const RobotModel& model = *I.robot;
  const double dt = I.m->opt.timestep;
  std::vector<int> driverOf(model.fingers().size(), -1);
  for (size_t k = 0; k < I.joints.size(); ++k)
    if (I.joints[k].driver) driverOf[size_t(I.joints[k].finger)] = int(k);
  for (double t = 0; t < 2 * I.options.finger_close_time_s; t += dt) {
    bool all = true;
    for (size_t k = 0; k < I.joints.size(); ++k) {
      if (st[k].done) {
        if (I.joints[k].finger >= 0) holdBack(I, I.joints[k], fraction, &st[k]);
        continue;
      }
      all = false;
      const HandJoint& hj = I.joints[k];
      const FingerInfo& f = model.fingers()[size_t(hj.finger)];
      double rate = std::abs(f.closed - f.open) / I.options.finger_close_time_s;
      double& target = st[k].target;
      const int drv = driverOf[size_t(hj.finger)];
      if (!hj.driver && drv >= 0 && !st[size_t(drv)].done) {  // coupled to the driven command
        target = hj.mult * st[size_t(drv)].target + hj.offset;
        rate *= std::abs(hj.mult);
      } else {
        if (!hj.driver) rate *= I.options.breakaway_rate;
        target = st[k].dir > 0 ? std::min(st[k].limit, target + rate * dt)
                               : std::max(st[k].limit, target - rate * dt);
      }
      const bool moving = std::abs(target - st[k].limit) > 1e-9;
      I.d->ctrl[hj.actuator] = target + (moving ? st[k].dir * rate * hj.kv / hj.kp : 0.0);
      holdBack(I, hj, fraction, &st[k]);
      // Stalled: held back by a contact (the servo's error grows, the joint does not move).
      const double qj = I.d->qpos[hj.qpos];
      const double lag = st[k].dir * (target - qj);
      const double speed = std::abs(I.d->qvel[hj.dof]);
      st[k].stalled_s = (lag > 0.02 && speed < 0.05) ? st[k].stalled_s + dt : 0;
      st[k].atLimit = std::abs(qj - st[k].limit) < 0.01;
      if (st[k].stalled_s > 0.05 || st[k].atLimit) st[k].done = true;
    }
    if (all) break;
    if (eachStep) eachStep();
    I.step(1);
  }
  for (size_t k = 0; k < I.joints.size(); ++k)
    if (I.joints[k].finger >= 0) I.d->ctrl[I.joints[k].actuator] = st[k].target;
}

// The table-level pinch (PhysicsOptions::table_sweep_m): a step function that lowers the palm's
// target from `start` as the hand's lowest point, with the hand joints as simulated, rises above
// where it was at the start; empty when the hand does not start near the table top.
std::function<void()> tableSweep(PhysicsWorld& world, PhysicsWorld::Impl& I, const JointVector& q,
                                 const Iso3& start) {
  if (I.options.table_sweep_m <= 0) return {};
  auto lowest = [&I, &world, q](const Iso3& T_B_palm) {
    return HandGeometry(*I.robot, world.handJoints(q), T_B_palm).bounds().min.z();
  };
  const double top = I.robot->table().topZ(), z0 = lowest(start);
  if (z0 - top > I.options.table_sweep_m || z0 < top - 0.002) return {};
  return [&I, start, z0, lowest] {
    const double rise = std::clamp(lowest(start) - z0, 0.0, 0.03);
    Iso3 T = start;
    T.translation().z() -= rise;
    I.setMocap(T);
  };
}

JointVector PhysicsWorld::closeHand(const JointVector& q) {
  Impl& I = *impl_;
  const RobotModel& model = *I.robot;
  std::vector<Closing> st(I.joints.size());
  // The fingers that close from the preshape the hand is in (RobotModel::closingFingers).
  const std::vector<bool> closing = model.closingFingers(handJoints(q));
  for (size_t k = 0; k < I.joints.size(); ++k) {
    const HandJoint& hj = I.joints[k];
    if (hj.finger < 0 || !closing[size_t(hj.finger)]) {
      st[k].done = true;
      st[k].atLimit = hj.finger >= 0;  // stays open: no squeeze
      st[k].target = I.d->qpos[hj.qpos];
      continue;
    }
    const JointInfo& j = model.variable(hj.variable);
    const FingerInfo& f = model.fingers()[size_t(hj.finger)];
    const double dirDriver = f.closed >= f.open ? 1.0 : -1.0;
    st[k].dir = hj.driver ? dirDriver : dirDriver * (hj.mult >= 0 ? 1.0 : -1.0);
    st[k].limit = hj.driver ? f.closed : (st[k].dir > 0 ? j.upper : j.lower);
    st[k].target = I.d->qpos[hj.qpos];
  }
  // Close with touch_force_n until every finger has met something (the first to arrive does not
  // push the object away from the others), then squeeze with the full force.
  const double touch = I.options.touch_force_n / I.options.finger_force_n;
  setFingerForce(I.m, I.joints, touch);
  closeUntilStalled(I, st, touch, tableSweep(*this, I, q, I.mocapPose()));
  setFingerForce(I.m, I.joints, 1.0);
  for (size_t k = 0; k < I.joints.size(); ++k) {
    const HandJoint& hj = I.joints[k];
    if (hj.finger < 0 || st[k].atLimit) continue;
    I.d->ctrl[hj.actuator] = I.d->qpos[hj.qpos] + st[k].dir * 1.5 * hj.force / hj.kp;
  }
  I.step(std::max(1, int(std::lround(0.2 / I.m->opt.timestep))));
  // Lock: each finger joint holds where it is, pressing with the force it had reached, and
  // resists being pushed back (the worm drive) up to hold_force_factor times its drive.
  for (const HandJoint& hj : I.joints) {
    if (hj.finger < 0) continue;
    const int a = hj.actuator;
    const double qj = I.d->qpos[hj.qpos];
    const double force = std::clamp(hj.kp * (I.d->ctrl[a] - qj), -hj.force, hj.force);
    I.d->ctrl[a] = qj + force / hj.kp;
  }
  setFingerForce(I.m, I.joints, I.options.hold_force_factor);
  return handJoints(q);
}

void PhysicsWorld::openHand() {
  Impl& I = *impl_;
  const RobotModel& model = *I.robot;
  std::vector<double> from(I.joints.size()), to(I.joints.size());
  for (size_t k = 0; k < I.joints.size(); ++k) {
    const HandJoint& hj = I.joints[k];
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
                       rotationBetween(start, now) < 0.005;
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
  for (int c = 0; c < I.d->ncon; ++c)
    if (I.handObjectContact(c)) return true;
  return false;
}

bool PhysicsWorld::objectTouchesTable() const {
  const Impl& I = *impl_;
  for (int c = 0; c < I.d->ncon; ++c)
    if (I.tableContactBody(c) == I.objectBody) return true;
  return false;
}

bool PhysicsWorld::handTouchesTable() const {
  const Impl& I = *impl_;
  for (int c = 0; c < I.d->ncon; ++c)
    if (const int b = I.tableContactBody(c); b >= 0 && I.handBody[size_t(b)]) return true;
  return false;
}

std::vector<PhysicsWorld::Contact> PhysicsWorld::objectContacts() const {
  const Impl& I = *impl_;
  std::vector<Contact> out;
  for (int c = 0; c < I.d->ncon; ++c) {
    const mjContact& k = I.d->contact[c];
    const int b1 = I.m->geom_bodyid[k.geom1], b2 = I.m->geom_bodyid[k.geom2];
    if (b1 != I.objectBody && b2 != I.objectBody) continue;
    // MuJoCo's normal (the frame's first row) points from geom1 to geom2.
    Vec3 n(k.frame[0], k.frame[1], k.frame[2]);
    const int other = b1 == I.objectBody ? b2 : b1;
    const int g = b1 == I.objectBody ? k.geom2 : k.geom1;
    if (b1 == I.objectBody) n = -n;
    int link = -2;
    if (g == I.tableGeom)
      link = -1;
    else if (other == I.palmBody)
      link = I.robot->tipLink();
    else if (const char* name = mj_id2name(I.m, mjOBJ_BODY, other);
             name && std::strncmp(name, "link", 4) == 0)
      link = std::atoi(name + 4);
    if (link == -2) continue;
    out.push_back({Vec3(k.pos[0], k.pos[1], k.pos[2]), n, link});
  }
  return out;
}

std::vector<std::pair<int, Iso3>> PhysicsWorld::handLinkPoses() const {
  const Impl& I = *impl_;
  std::vector<std::pair<int, Iso3>> out{{I.robot->tipLink(), I.bodyPose(I.palmBody)}};
  for (int b = 0; b < I.m->nbody; ++b) {
    const char* name = mj_id2name(I.m, mjOBJ_BODY, b);
    if (name && std::strncmp(name, "link", 4) == 0)
      out.emplace_back(std::atoi(name + 4), I.bodyPose(b));
  }
  return out;
}

JointVector PhysicsWorld::handJoints(const JointVector& q) const {
  const Impl& I = *impl_;
  JointVector out = q;
  for (const HandJoint& hj : I.joints) out[hj.variable] = I.d->qpos[hj.qpos];
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
