#include "inhand/robot/robot_model.h"

#include <urdf_parser/urdf_parser.h>
#include <kdl/chain.hpp>
#include <kdl/frames.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <set>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/core/pose.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"
#include "inhand/sensor/frame_set.h"

namespace inhand {

namespace fs = std::filesystem;

// ---- primitives ---------------------------------------------------------------------------------

TriangleMesh Primitive::toMesh() const {
  TriangleMesh m;
  switch (type) {
    case Type::kBox:
      m = makeBox(size);
      break;
    case Type::kCylinder:
      m = makeCylinder(size.x(), size.z(), 32);
      break;
    case Type::kSphere:
      m = makeSphere(size.x(), 3);
      break;
    case Type::kMesh:
      m = *mesh;
      break;
  }
  return transformed(m, T_link_geom);
}

namespace {
// Ray-parity point-in-mesh test (brute force over all triangles; for closed meshes).
bool parityInside(const TriangleMesh& mesh, const Vec3& p) {
  const Vec3 dir = Vec3(0.5773, 0.5774, 0.5775).normalized();  // generic direction
  int crossings = 0;
  for (const Tri& f : mesh.triangles) {
    Vec3 a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
         c = mesh.vertices[f[2]].cast<double>();
    Vec3 e1 = b - a, e2 = c - a, h = dir.cross(e2);
    double det = e1.dot(h);
    if (std::abs(det) < 1e-15) continue;
    Vec3 s = p - a;
    double u = s.dot(h) / det;
    if (u < 0 || u > 1) continue;
    Vec3 q = s.cross(e1);
    double v = dir.dot(q) / det;
    if (v < 0 || u + v > 1) continue;
    if (e2.dot(q) / det > 0) ++crossings;
  }
  return crossings % 2 == 1;
}
}  // namespace

bool Primitive::contains(const Vec3& p_link) const {
  Vec3 p = T_link_geom.inverse() * p_link;
  switch (type) {
    case Type::kBox:
      return (p.cwiseAbs().array() <= 0.5 * size.array()).all();
    case Type::kCylinder:
      return std::hypot(p.x(), p.y()) <= size.x() && std::abs(p.z()) <= 0.5 * size.z();
    case Type::kSphere:
      return p.norm() <= size.x();
    case Type::kMesh:
      return parityInside(*mesh, p);
  }
  return false;
}

// ---- camera -------------------------------------------------------------------------------------

std::optional<Iso3> CameraMount::aimAt(const Vec3& target_B) const {
  Vec3 d = target_B - panTilt_B;
  if (d.norm() < 1e-6) return std::nullopt;
  double pan = std::atan2(d.y(), d.x());
  double tilt = std::atan2(-d.z(), std::hypot(d.x(), d.y()));  // positive looks down
  if (pan < panMin || pan > panMax || tilt < tiltMin || tilt > tiltMax) return std::nullopt;
  return lookAt(panTilt_B, target_B, Vec3::UnitZ());  // optical frame, image x level
}

// ---- loading ------------------------------------------------------------------------------------

namespace {

// The offset of the first byte that does not belong to a well-formed UTF-8 sequence (NUL
// included), or npos.
size_t invalidUtf8At(const std::string& text) {
  const auto* b = reinterpret_cast<const unsigned char*>(text.data());
  const size_t n = text.size();
  for (size_t i = 0; i < n;) {
    const unsigned c = b[i];
    const size_t len = c == 0             ? 0
                       : c < 0x80         ? 1
                       : (c >> 5) == 0x6  ? 2
                       : (c >> 4) == 0xE  ? 3
                       : (c >> 3) == 0x1E ? 4
                                          : 0;
    if (len == 0 || i + len > n) return i;
    for (size_t k = 1; k < len; ++k)
      if ((b[i + k] & 0xC0) != 0x80) return i;
    i += len;
  }
  return std::string::npos;
}

Iso3 toIso(const urdf::Pose& p) {
  double x, y, z, w;
  p.rotation.getQuaternion(x, y, z, w);
  Iso3 T = Iso3::Identity();
  T.linear() = Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
  T.translation() = Vec3(p.position.x, p.position.y, p.position.z);
  return T;
}

KDL::Frame toKdl(const Iso3& T) {
  const Mat3& R = T.linear();
  return KDL::Frame(KDL::Rotation(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0),
                                  R(2, 1), R(2, 2)),
                    KDL::Vector(T.translation().x(), T.translation().y(), T.translation().z()));
}

Vec3 readVec3(const Json& obj, const std::string& key, const std::string& where) {
  const Json& v = requireField(obj, key, where);
  if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() || !v[2].is_number())
    throw Error(where + "." + key + ": expected an array of 3 numbers");
  return Vec3(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
}

std::pair<double, double> readRangeDeg(const Json& obj, const std::string& key,
                                       const std::string& where, std::pair<double, double> dflt) {
  if (!obj.contains(key)) return dflt;
  const Json& v = obj[key];
  if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number() ||
      !(v[0].get<double>() < v[1].get<double>()))
    throw Error(where + "." + key + ": expected [min, max] in degrees with min < max");
  return {v[0].get<double>() * M_PI / 180, v[1].get<double>() * M_PI / 180};
}

}  // namespace

// Builds a RobotModel from a parsed URDF and the robot config, one part at a time (friend of
// RobotModel). Every error names the file and field.
struct RobotModelLoader {
  RobotModel& m;
  const Json& cfg;
  const std::string cfgName, urdfName;
  const fs::path urdfPath;

  static Primitive collisionPrimitive(const urdf::Collision& col, const fs::path& urdfPath,
                                      const std::string& where) {
    Primitive p;
    p.T_link_geom = toIso(col.origin);
    const auto& g = *col.geometry;
    switch (g.type) {
      case urdf::Geometry::BOX: {
        const auto& b = static_cast<const urdf::Box&>(g);
        p.type = Primitive::Type::kBox;
        p.size = Vec3(b.dim.x, b.dim.y, b.dim.z);
        break;
      }
      case urdf::Geometry::CYLINDER: {
        const auto& c = static_cast<const urdf::Cylinder&>(g);
        p.type = Primitive::Type::kCylinder;
        p.size = Vec3(c.radius, c.radius, c.length);
        break;
      }
      case urdf::Geometry::SPHERE: {
        const auto& s = static_cast<const urdf::Sphere&>(g);
        p.type = Primitive::Type::kSphere;
        p.size = Vec3::Constant(s.radius);
        break;
      }
      case urdf::Geometry::MESH: {
        const auto& mg = static_cast<const urdf::Mesh&>(g);
        std::string file = mg.filename;
        if (file.rfind("file://", 0) == 0) file = file.substr(7);
        if (file.rfind("package://", 0) == 0)
          throw Error(where + ": package:// mesh paths need ROS; use a path relative to the URDF");
        fs::path mp = fs::path(file).is_relative() ? urdfPath.parent_path() / file : fs::path(file);
        TriangleMesh mesh = importMesh(mp);
        for (Vec3f& v : mesh.vertices)
          v = v.cwiseProduct(Vec3f(float(mg.scale.x), float(mg.scale.y), float(mg.scale.z)));
        p.type = Primitive::Type::kMesh;
        p.mesh = std::make_shared<TriangleMesh>(std::move(mesh));
        break;
      }
    }
    if (p.type != Primitive::Type::kMesh && !(p.size.array() > 0).all())
      throw Error(where + ": sizes must be positive");
    return p;
  }

  // Links and joints of the URDF (name-sorted), the joint order, mimic tags.
  void urdfModel(const urdf::ModelInterface& urdf) {
    // Links and joints, in a deterministic (name-sorted) order.
    for (const auto& [name, link] : urdf.links_) {
      LinkInfo info;
      info.name = name;
      if (link->inertial) {
        info.mass = link->inertial->mass;
        const urdf::Vector3& c = link->inertial->origin.position;
        info.com = Vec3(c.x, c.y, c.z);
        if (!(info.mass >= 0) || !info.com.allFinite())
          throw Error(urdfName + ": link " + name +
                      ": inertial: mass must be >= 0 and the "
                      "origin finite");
      }
      for (const auto& col : link->collision_array) {
        if (!col || !col->geometry) continue;
        info.collision.push_back(collisionPrimitive(
            *col, urdfPath, urdfName + ": link " + name + ": collision geometry"));
      }
      m.links_.push_back(std::move(info));
    }
    for (const auto& [name, joint] : urdf.joints_) {
      JointInfo j;
      j.name = name;
      j.parentLink = m.linkIndex(joint->parent_link_name);
      j.childLink = m.linkIndex(joint->child_link_name);
      j.T_parent_joint = toIso(joint->parent_to_joint_origin_transform);
      Vec3 axis(joint->axis.x, joint->axis.y, joint->axis.z);
      switch (joint->type) {
        case urdf::Joint::REVOLUTE:
          j.type = JointInfo::Type::kRevolute;
          break;
        case urdf::Joint::CONTINUOUS:
          j.type = JointInfo::Type::kContinuous;
          break;
        case urdf::Joint::PRISMATIC:
          j.type = JointInfo::Type::kPrismatic;
          break;
        case urdf::Joint::FIXED:
          j.type = JointInfo::Type::kFixed;
          break;
        default:
          throw Error(urdfName + ": joint " + name +
                      ": floating and planar joints are not supported");
      }
      if (j.type != JointInfo::Type::kFixed) {
        if (axis.norm() < 1e-9) throw Error(urdfName + ": joint " + name + ": zero axis");
        j.axis = axis.normalized();
        if (j.type == JointInfo::Type::kContinuous) {
          j.lower = -M_PI;
          j.upper = M_PI;
        } else {
          if (!joint->limits) throw Error(urdfName + ": joint " + name + ": missing <limit>");
          j.lower = joint->limits->lower;
          j.upper = joint->limits->upper;
          if (!(j.lower <= j.upper))
            throw Error(urdfName + ": joint " + name + ": limit lower > upper");
        }
        if (joint->limits) j.velocity = joint->limits->velocity;
      }
      m.joints_.push_back(j);
    }
    std::sort(m.joints_.begin(), m.joints_.end(),
              [](const JointInfo& a, const JointInfo& b) { return a.name < b.name; });
    for (int ji = 0; ji < int(m.joints_.size()); ++ji) {
      JointInfo& j = m.joints_[ji];
      if (m.links_[j.childLink].parentJoint >= 0 || j.childLink == j.parentLink)
        throw Error(urdfName + ": link '" + m.links_[j.childLink].name +
                    "' is the child of two joints, or of its own joint: not a tree");
      m.links_[j.childLink].parentJoint = ji;
      if (j.type != JointInfo::Type::kFixed) {
        j.variable = int(m.variableJoint_.size());
        m.variableJoint_.push_back(ji);
      }
    }
    // No loops: from every link the walk up its parents ends within the link count (the walks
    // below, the chain and the topological order, rely on it).
    const int nLinks = int(m.links_.size());
    for (int l = 0; l < nLinks; ++l) {
      int steps = 0;
      for (int link = l; m.links_[link].parentJoint >= 0;
           link = m.joints_[m.links_[link].parentJoint].parentLink)
        if (++steps > nLinks)
          throw Error(urdfName + ": the joints form a loop through link '" + m.links_[l].name +
                      "': not a tree");
    }
    m.rootLink_ = m.linkIndex(urdf.getRoot()->name);
    // Topological order: a joint after the joint of its parent link.
    std::function<void(int)> visit = [&](int link) {
      for (int ji = 0; ji < int(m.joints_.size()); ++ji)
        if (m.joints_[ji].parentLink == link) {
          m.jointOrder_.push_back(ji);
          visit(m.joints_[ji].childLink);
        }
    };
    visit(m.rootLink_);
    // URDF mimic tags (the config's couplings below override them).
    for (const auto& [name, joint] : urdf.joints_)
      if (joint->mimic) {
        JointInfo& j = m.joints_[m.jointIndex(name)];
        int leader = m.variableIndex(joint->mimic->joint_name);
        if (leader < 0 || j.variable < 0)
          throw Error(urdfName + ": joint " + name + ": mimics unknown or fixed joint '" +
                      joint->mimic->joint_name + "'");
        j.mimicOf = leader;
        j.mimicMultiplier = joint->mimic->multiplier;
        j.mimicOffset = joint->mimic->offset;
      }
  }

  int needLink(const Json& obj, const std::string& key, const std::string& where) const {
    std::string n = requireString(obj, key, where);
    int i = m.linkIndex(n);
    if (i < 0) throw Error(where + "." + key + ": no link named '" + n + "' in " + urdfName);
    return i;
  }
  int needVariable(const Json& obj, const std::string& key, const std::string& where) const {
    std::string n = requireString(obj, key, where);
    int ji = m.jointIndex(n);
    if (ji < 0) throw Error(where + "." + key + ": no joint named '" + n + "' in " + urdfName);
    if (m.joints_[ji].variable < 0)
      throw Error(where + "." + key + ": joint '" + n + "' is fixed, it cannot be driven");
    return m.joints_[ji].variable;
  }

  // The arm: the chain base_link → tip_link (KDL), its driven variables.
  void armChain() {
    m.baseLink_ = needLink(cfg, "base_link", cfgName);
    m.tipLink_ = needLink(cfg, "tip_link", cfgName);
    // Chain base → tip: walk up from the tip.
    std::vector<int> chainJoints;
    for (int link = m.tipLink_; link != m.baseLink_;) {
      int ji = m.links_[link].parentJoint;
      if (ji < 0)
        throw Error(cfgName + ": tip_link '" + m.links_[m.tipLink_].name +
                    "' is not below base_link '" + m.links_[m.baseLink_].name + "' in " + urdfName +
                    ": the chain does not connect");
      chainJoints.push_back(ji);
      link = m.joints_[ji].parentLink;
    }
    std::reverse(chainJoints.begin(), chainJoints.end());
    m.chain_ = std::make_shared<KDL::Chain>();
    for (int ji : chainJoints) {
      const JointInfo& j = m.joints_[ji];
      KDL::Frame F = toKdl(j.T_parent_joint);
      KDL::Vector axis = F.M * KDL::Vector(j.axis.x(), j.axis.y(), j.axis.z());
      KDL::Joint kj(j.name + "_fixed", KDL::Joint::Fixed);
      if (j.type == JointInfo::Type::kPrismatic)
        kj = KDL::Joint(j.name, F.p, axis, KDL::Joint::TransAxis);
      else if (j.type != JointInfo::Type::kFixed)
        kj = KDL::Joint(j.name, F.p, axis, KDL::Joint::RotAxis);
      m.chain_->addSegment(KDL::Segment(m.links_[j.childLink].name, kj, F));
      if (j.variable >= 0) {
        if (j.mimicOf >= 0)
          throw Error(cfgName + ": arm joint '" + j.name + "' mimics another joint; not supported");
        m.armVariables_.push_back(j.variable);
      }
    }
    if (m.armVariables_.empty())
      throw Error(cfgName + ": the chain base_link → tip_link has no joints");
  }

  // Joint speed limits and the home state.
  void speedsAndHome() {
    if (cfg.contains("joint_speeds_rad_s")) {
      const Json& s = cfg["joint_speeds_rad_s"];
      if (!s.is_object()) throw Error(cfgName + ": joint_speeds_rad_s: expected an object");
      for (const auto& [name, v] : s.items()) {
        int ji = m.jointIndex(name);
        if (ji < 0)
          throw Error(cfgName + ": joint_speeds_rad_s." + name + ": no such joint in " + urdfName);
        if (!v.is_number() || !(v.get<double>() > 0))
          throw Error(cfgName + ": joint_speeds_rad_s." + name + ": expected a positive number");
        m.joints_[ji].velocity = v.get<double>();
      }
    }
    for (int v : m.armVariables_)
      if (!(m.variable(v).velocity > 0))
        throw Error(cfgName + ": arm joint '" + m.variable(v).name +
                    "' has no speed limit (URDF <limit velocity> or joint_speeds_rad_s)");
    m.homeValues_.resize(m.variableJoint_.size());
    for (int v = 0; v < m.variableCount(); ++v) {
      const JointInfo& j = m.variable(v);
      m.homeValues_[v] = std::clamp(0.0, j.lower, j.upper);
    }
    if (cfg.contains("home")) {
      const Json& h = cfg["home"];
      if (!h.is_object()) throw Error(cfgName + ": home: expected an object of joint values");
      for (const auto& [name, v] : h.items()) {
        int var = m.variableIndex(name);
        if (var < 0)
          throw Error(cfgName + ": home." + name + ": no such movable joint in " + urdfName);
        if (!v.is_number()) throw Error(cfgName + ": home." + name + ": expected a number");
        m.homeValues_[var] = v.get<double>();
      }
    }
  }

  // The hand: links, couplings, fingers (with the links that move with each), spread joint,
  // grasp offset.
  void handPart() {
    const Json& hand = requireField(cfg, "hand", cfgName);
    const std::string hw = cfgName + ": hand";
    const Json& hl = requireField(hand, "links", hw);
    if (!hl.is_array() || hl.empty())
      throw Error(hw + ".links: expected a non-empty array of link names");
    for (size_t i = 0; i < hl.size(); ++i) {
      if (!hl[i].is_string())
        throw Error(hw + ".links[" + std::to_string(i) + "]: expected a string");
      int li = m.linkIndex(hl[i].get<std::string>());
      if (li < 0)
        throw Error(hw + ".links[" + std::to_string(i) + "]: no link named '" +
                    hl[i].get<std::string>() + "' in " + urdfName);
      m.handLinks_.push_back(li);
    }
    if (hand.contains("couplings")) {
      const Json& cs = hand["couplings"];
      if (!cs.is_array()) throw Error(hw + ".couplings: expected an array");
      for (size_t i = 0; i < cs.size(); ++i) {
        const std::string cw = hw + ".couplings[" + std::to_string(i) + "]";
        int v = needVariable(cs[i], "joint", cw), leader = needVariable(cs[i], "follows", cw);
        JointInfo& j = m.joints_[m.variableJoint_[v]];
        j.mimicOf = leader;
        j.mimicMultiplier = requireNumber(cs[i], "multiplier", cw);
        j.mimicOffset = requireNumber(cs[i], "offset", cw);
      }
    }
    const Json& fs = requireField(hand, "fingers", hw);
    if (!fs.is_array() || fs.empty()) throw Error(hw + ".fingers: expected a non-empty array");
    for (size_t i = 0; i < fs.size(); ++i) {
      const std::string fw = hw + ".fingers[" + std::to_string(i) + "]";
      FingerInfo f;
      f.variable = needVariable(fs[i], "joint", fw);
      f.open = requireNumber(fs[i], "open", fw);
      f.closed = requireNumber(fs[i], "closed", fw);
      const JointInfo& j = m.variable(f.variable);
      for (double val : {f.open, f.closed})
        if (val < j.lower - 1e-9 || val > j.upper + 1e-9)
          throw Error(fw + ": open/closed value outside the joint's limits [" +
                      std::to_string(j.lower) + ", " + std::to_string(j.upper) + "] in " +
                      urdfName);
      // Links that move with the finger: below the finger joint or any joint that follows it.
      std::set<int> moving;
      for (int ji = 0; ji < int(m.joints_.size()); ++ji) {
        const JointInfo& jj = m.joints_[ji];
        if (jj.variable == f.variable || jj.mimicOf == f.variable) {
          std::function<void(int)> collect = [&](int link) {
            moving.insert(link);
            for (const JointInfo& c : m.joints_)
              if (c.parentLink == link) collect(c.childLink);
          };
          collect(jj.childLink);
        }
      }
      for (int li : moving)
        if (std::find(m.handLinks_.begin(), m.handLinks_.end(), li) != m.handLinks_.end())
          f.links.push_back(li);
      if (f.links.empty()) throw Error(fw + ": no hand link moves with joint '" + j.name + "'");
      m.fingers_.push_back(f);
    }
    if (hand.contains("spread_joint")) m.spreadVariable_ = needVariable(hand, "spread_joint", hw);
    if (hand.contains("grasp_offset_m")) {
      m.graspOffset_ = requireNumber(hand, "grasp_offset_m", hw);
      if (!(m.graspOffset_ > 0 && m.graspOffset_ < 1))
        throw Error(hw + ".grasp_offset_m: must be in (0, 1) m");
    }
  }

  // camera.colour: {"intrinsics": {width, height, fx, fy, cx, cy}, "T_depth_colour": 16 row-major
  // numbers, the colour camera's optical frame in the depth camera's, "light_at_camera": bool};
  // any may be left out.
  void colourCamera(const Json& c, const std::string& where) {
    if (!c.is_object()) throw Error(where + ": expected an object (intrinsics, T_depth_colour)");
    for (const auto& [key, value] : c.items())
      if (key != "intrinsics" && key != "T_depth_colour" && key != "light_at_camera")
        throw Error(where + ": unknown field \"" + key + "\"");
    if (c.contains("light_at_camera")) {
      if (!c["light_at_camera"].is_boolean())
        throw Error(where + ".light_at_camera: expected true or false");
      m.camera_.colour.light_at_camera = c["light_at_camera"].get<bool>();
    }
    if (c.contains("intrinsics"))
      m.camera_.colour.intrinsics = readIntrinsics(c["intrinsics"], where + ".intrinsics");
    if (c.contains("T_depth_colour"))
      m.camera_.colour.T_D_RGB =
          readRowMajorPose(c["T_depth_colour"], where + ".T_depth_colour", 1e-3);
  }

  // Where the robot stands: the camera's pan-tilt mount, the table, links next to the base.
  void workcell() {
    const Json& cam = requireField(cfg, "camera", cfgName);
    const std::string camw = cfgName + ": camera";
    m.camera_.panTilt_B = readVec3(cam, "pan_tilt_xyz", camw);
    m.camera_.lookAt_B = readVec3(cam, "look_at_xyz", camw);
    std::tie(m.camera_.panMin, m.camera_.panMax) =
        readRangeDeg(cam, "pan_range_deg", camw, {-M_PI, M_PI});
    std::tie(m.camera_.tiltMin, m.camera_.tiltMax) =
        readRangeDeg(cam, "tilt_range_deg", camw, {-M_PI / 2, M_PI / 2});
    if (!m.camera_.aimAt(m.camera_.lookAt_B))
      throw Error(camw + ".look_at_xyz: outside the pan/tilt range of the camera");
    if (cam.contains("colour")) colourCamera(cam["colour"], camw + ".colour");
    const Json& table = requireField(cfg, "table", cfgName);
    m.table_.center_B = readVec3(table, "center_xyz", cfgName + ": table");
    m.table_.size = readVec3(table, "size_xyz", cfgName + ": table");
    if (!(m.table_.size.array() > 0).all())
      throw Error(cfgName + ": table.size_xyz: must be positive");
    if (cfg.contains("base_adjacent_links")) {
      const Json& a = cfg["base_adjacent_links"];
      if (!a.is_array())
        throw Error(cfgName + ": base_adjacent_links: expected an array of link names");
      for (size_t i = 0; i < a.size(); ++i) {
        if (!a[i].is_string() || m.linkIndex(a[i].get<std::string>()) < 0)
          throw Error(cfgName + ": base_adjacent_links[" + std::to_string(i) +
                      "]: no such link in " + urdfName);
        m.baseAdjacent_.push_back(m.linkIndex(a[i].get<std::string>()));
      }
    }
  }
};

RobotModel RobotModel::load(const fs::path& configPath, const fs::path& urdfOverride) {
  const std::string cfgName = configPath.string();
  Json cfg = readJsonFile(configPath);
  if (!cfg.is_object()) throw Error(cfgName + ": expected a JSON object");
  static const std::set<std::string> known = {
      "urdf",   "base_link", "tip_link",           "hand", "joint_speeds_rad_s", "home",
      "camera", "table",     "base_adjacent_links"};
  for (const auto& [key, value] : cfg.items())
    if (!known.count(key)) throw Error(cfgName + ": unknown field \"" + key + "\"");
  fs::path urdfPath = urdfOverride;
  if (urdfPath.empty()) {
    urdfPath = requireString(cfg, "urdf", cfgName);
    if (urdfPath.is_relative()) urdfPath = configPath.parent_path() / urdfPath;
  }
  const std::string urdfName = urdfPath.string();
  std::string xml = readTextFile(urdfPath);
  // TinyXML (under urdfdom) reads past the end of the text after a truncated multi-byte UTF-8
  // sequence (found by fuzzing): the text must be valid UTF-8 before it gets there.
  if (const size_t bad = invalidUtf8At(xml); bad != std::string::npos)
    throw Error(urdfName + ": not valid UTF-8 text (byte " + std::to_string(bad) + ")");
  urdf::ModelInterfaceSharedPtr urdf = urdf::parseURDF(xml);
  if (!urdf) throw Error(urdfName + ": malformed URDF (urdfdom could not parse it; see above)");

  RobotModel m;
  m.name_ = urdf->getName();
  RobotModelLoader loader{m, cfg, cfgName, urdfName, urdfPath};
  loader.urdfModel(*urdf);
  loader.armChain();
  loader.speedsAndHome();
  loader.handPart();
  loader.workcell();
  return m;
}

int RobotModel::linkIndex(const std::string& n) const {
  for (int i = 0; i < int(links_.size()); ++i)
    if (links_[i].name == n) return i;
  return -1;
}

int RobotModel::jointIndex(const std::string& n) const {
  for (int i = 0; i < int(joints_.size()); ++i)
    if (joints_[i].name == n) return i;
  return -1;
}

int RobotModel::variableIndex(const std::string& joint) const {
  int j = jointIndex(joint);
  return j < 0 ? -1 : joints_[j].variable;
}

Eigen::VectorXd RobotModel::armLower() const {
  Eigen::VectorXd v(armDof());
  for (int i = 0; i < armDof(); ++i) v[i] = variable(armVariables_[i]).lower;
  return v;
}
Eigen::VectorXd RobotModel::armUpper() const {
  Eigen::VectorXd v(armDof());
  for (int i = 0; i < armDof(); ++i) v[i] = variable(armVariables_[i]).upper;
  return v;
}
Eigen::VectorXd RobotModel::armVelocity() const {
  Eigen::VectorXd v(armDof());
  for (int i = 0; i < armDof(); ++i) v[i] = variable(armVariables_[i]).velocity;
  return v;
}

JointVector RobotModel::home() const {
  JointVector q =
      Eigen::Map<const Eigen::VectorXd>(homeValues_.data(), Eigen::Index(homeValues_.size()));
  applyCouplings(&q);
  return q;
}

void RobotModel::applyCouplings(JointVector* q) const {
  for (const JointInfo& j : joints_)
    if (j.variable >= 0 && j.mimicOf >= 0)
      (*q)[j.variable] = j.mimicMultiplier * (*q)[j.mimicOf] + j.mimicOffset;
}

JointVector RobotModel::withArm(const JointVector& q, const Eigen::VectorXd& arm) const {
  JointVector out = q;
  for (int i = 0; i < armDof(); ++i) out[armVariables_[i]] = arm[i];
  return out;
}

JointVector RobotModel::withFingersOpen(const JointVector& q) const {
  JointVector out = q;
  for (const FingerInfo& f : fingers_) out[f.variable] = f.open;
  applyCouplings(&out);
  return out;
}

JointVector RobotModel::openHand(double spread) const {
  JointVector q = home();
  if (spreadVariable_ >= 0) q[spreadVariable_] = spread;
  return withFingersOpen(q);
}

JointVector RobotModel::preshapedHand(double spread, double fraction) const {
  JointVector q = openHand(spread);
  for (const FingerInfo& f : fingers_) q[f.variable] = f.open + fraction * (f.closed - f.open);
  applyCouplings(&q);
  return q;
}

std::vector<bool> RobotModel::closingFingers(const JointVector& q) const {
  bool partly = false;
  for (const FingerInfo& f : fingers_) partly = partly || q[f.variable] != f.open;
  std::vector<bool> closing(fingers_.size(), true);
  for (size_t k = 0; k < fingers_.size(); ++k)
    closing[k] = !partly || q[fingers_[k].variable] != fingers_[k].open;
  return closing;
}

int RobotModel::fingerOfLink(int link) const {
  for (size_t k = 0; k < fingers_.size(); ++k)
    if (std::find(fingers_[k].links.begin(), fingers_[k].links.end(), link) !=
        fingers_[k].links.end())
      return int(k);
  return -1;
}

double RobotModel::palmFaceZ() const {
  double top = 0;
  for (const Primitive& p : links_[size_t(tipLink_)].collision)
    top = std::max(top, p.toMesh().bounds().max.z());
  return top;
}

Eigen::VectorXd RobotModel::arm(const JointVector& q) const {
  Eigen::VectorXd a(armDof());
  for (int i = 0; i < armDof(); ++i) a[i] = q[armVariables_[i]];
  return a;
}

bool RobotModel::withinLimits(const JointVector& q, double tol) const {
  for (int v = 0; v < variableCount(); ++v)
    if (q[v] < variable(v).lower - tol || q[v] > variable(v).upper + tol) return false;
  return true;
}

std::vector<Iso3> RobotModel::linkPoses(const JointVector& qIn) const {
  INHAND_CHECK(qIn.size() == variableCount(), "joint vector size != variable count");
  JointVector q = qIn;
  applyCouplings(&q);
  std::vector<Iso3> T(links_.size(), Iso3::Identity());
  for (int ji : jointOrder_) {
    const JointInfo& j = joints_[ji];
    Iso3 motion = Iso3::Identity();
    if (j.variable >= 0) {
      double v = q[j.variable];
      if (j.type == JointInfo::Type::kPrismatic)
        motion.translation() = v * j.axis;
      else
        motion.linear() = Eigen::AngleAxisd(v, j.axis).toRotationMatrix();
    }
    T[j.childLink] = T[j.parentLink] * j.T_parent_joint * motion;
  }
  if (baseLink_ != rootLink_) {
    Iso3 inv = T[baseLink_].inverse();
    for (Iso3& t : T) t = inv * t;
  }
  return T;
}

Iso3 RobotModel::tipPose(const JointVector& q) const { return linkPoses(q)[tipLink_]; }

namespace {
// Adds to tau what f_B at p_B on link `link` puts on the joints between it and the root.
void addPointForce(const std::vector<LinkInfo>& links, const std::vector<JointInfo>& joints,
                   const std::vector<Iso3>& T, int link, const Vec3& p_B, const Vec3& f_B,
                   JointVector* tau) {
  for (int ji = links[size_t(link)].parentJoint; ji >= 0;
       ji = links[size_t(joints[size_t(ji)].parentLink)].parentJoint) {
    const JointInfo& j = joints[size_t(ji)];
    if (j.variable < 0 || j.mimicOf >= 0) continue;
    const Iso3 T_B_joint = T[size_t(j.parentLink)] * j.T_parent_joint;
    const Vec3 a = T_B_joint.linear() * j.axis;
    (*tau)[j.variable] += j.type == JointInfo::Type::kPrismatic
                              ? a.dot(f_B)
                              : a.dot((p_B - T_B_joint.translation()).cross(f_B));
  }
}
}  // namespace

JointVector RobotModel::gravityTorques(const JointVector& q, const Vec3& g_B) const {
  const std::vector<Iso3> T = linkPoses(q);
  JointVector tau = JointVector::Zero(variableCount());
  // Each link's weight acts on every joint between it and the root.
  for (size_t l = 0; l < links_.size(); ++l)
    if (links_[l].mass > 0)
      addPointForce(links_, joints_, T, int(l), T[l] * links_[l].com, links_[l].mass * g_B, &tau);
  return tau;
}

std::vector<std::pair<std::string, double>> RobotModel::handJointValues(
    const JointVector& q) const {
  std::vector<std::pair<std::string, double>> out;
  for (int v = 0; v < variableCount() && v < int(q.size()); ++v)
    if (std::find(armVariables_.begin(), armVariables_.end(), v) == armVariables_.end())
      out.emplace_back(variable(v).name, q[v]);
  return out;
}

JointVector RobotModel::pointForceTorques(const JointVector& q, int link, const Vec3& p_B,
                                          const Vec3& f_B) const {
  JointVector tau = JointVector::Zero(variableCount());
  if (link >= 0 && link < int(links_.size()))
    addPointForce(links_, joints_, linkPoses(q), link, p_B, f_B, &tau);
  return tau;
}

double trajectoryTime(const RobotModel& model, const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  Eigen::VectorXd v = model.armVelocity();
  return ((b - a).cwiseAbs().array() / v.array()).maxCoeff();
}

JointVector armOffsetsFromPalmError(const RobotModel& model, const JointVector& q,
                                    const Iso3& palmError) {
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  auto twist = [](const Iso3& T) {  // rotation vector, translation
    const Eigen::AngleAxisd aa(T.linear());
    Vec6 x;
    x.head<3>() = aa.angle() * aa.axis();
    x.tail<3>() = T.translation();
    return x;
  };
  const std::vector<int>& arm = model.armVariables();
  const Eigen::Index n = Eigen::Index(arm.size());
  JointVector e = JointVector::Zero(q.size());
  const Iso3 target = model.tipPose(q) * palmError;
  for (int it = 0; it < 5; ++it) {
    const Iso3 T = model.tipPose(q + e);
    const Vec6 r = twist(T.inverse() * target);
    if (r.norm() < 1e-12) break;
    Eigen::MatrixXd J(6, n);
    for (Eigen::Index k = 0; k < n; ++k) {
      JointVector d = q + e;
      d[arm[size_t(k)]] += 1e-6;
      J.col(k) = twist(T.inverse() * model.tipPose(d)) / 1e-6;
    }
    const Eigen::MatrixXd A = J.transpose() * J + 1e-4 * Eigen::MatrixXd::Identity(n, n);
    const Eigen::VectorXd step = A.ldlt().solve(J.transpose() * r);
    for (Eigen::Index k = 0; k < n; ++k) e[arm[size_t(k)]] += step[k];
  }
  return e;
}

}  // namespace inhand
