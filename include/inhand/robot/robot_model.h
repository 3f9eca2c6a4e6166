#pragma once
// A robot loaded from a URDF (urdfdom) and a small JSON robot config: every link's collision
// geometry, forward kinematics of every link, the arm chain (base_link → tip_link) as a KDL chain
// for IK, joint limits and speeds, the hand's links, fingers and joint couplings, and where the
// camera and table are. Nothing here is specific to one robot: everything comes from the files.
//
// Model/data split (Pinocchio style): RobotModel is immutable after load and safe to share
// between threads; per-call state (IK solvers, joint vectors) lives with the caller.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "inhand/geometry/triangle_mesh.h"
#include "inhand/sensor/depth_camera.h"

namespace KDL {
class Chain;
}

namespace inhand {

// Joint values for every movable (non-fixed) joint of the URDF, in RobotModel::variables() order.
using JointVector = Eigen::VectorXd;

struct Primitive {
  enum class Type { kBox, kCylinder, kSphere, kMesh } type = Type::kBox;
  Vec3 size = Vec3::Zero();  // box: edges; cylinder: (radius, radius, length) along z;
                             // sphere: (radius, radius, radius)
  Iso3 T_link_geom = Iso3::Identity();
  std::shared_ptr<const TriangleMesh> mesh;  // kMesh only, in the geometry frame (scaled)

  TriangleMesh toMesh() const;              // in the link frame
  bool contains(const Vec3& p_link) const;  // exact for box, cylinder, sphere; parity for meshes
};

struct LinkInfo {
  std::string name;
  int parentJoint = -1;  // index into joints(); -1 for the URDF root
  std::vector<Primitive> collision;
  double mass = 0;          // kg, from the URDF's <inertial> (0 without one)
  Vec3 com = Vec3::Zero();  // centre of mass in the link frame, m
};

struct JointInfo {
  enum class Type { kFixed, kRevolute, kContinuous, kPrismatic } type = Type::kFixed;
  std::string name;
  int parentLink = -1, childLink = -1;
  Iso3 T_parent_joint = Iso3::Identity();
  Vec3 axis = Vec3::UnitZ();    // in the joint frame, unit
  double lower = 0, upper = 0;  // rad or m
  double velocity = 0;          // max speed, rad/s or m/s (config overrides the URDF)
  int variable = -1;            // index in JointVector; -1 for fixed joints
  int mimicOf = -1;             // variable this joint follows (q = m·q_leader + offset), or -1
  double mimicMultiplier = 1, mimicOffset = 0;
};

struct FingerInfo {
  int variable = -1;  // the finger's driven joint
  double open = 0, closed = 0;
  std::vector<int> links;  // links that move with this finger
};

struct CameraMount {
  Vec3 panTilt_B = Vec3::Zero();  // pan-tilt unit centre in the base frame, m
  double panMin = -M_PI, panMax = M_PI, tiltMin = -M_PI / 2, tiltMax = M_PI / 2;  // rad
  Vec3 lookAt_B = Vec3(0.6, 0, 0.5);  // nominal point where objects are presented, m
  // The colour camera beside the depth camera: its intrinsics and its pose in the depth camera's
  // optical frame (config camera.colour; a Kinect-class default). Whether it is on is the
  // scan's choice (sim.colour.enabled), not the robot's.
  ColourCameraOptions colour;
  // Camera pose looking at `target_B` (optical frame), or nullopt when pan/tilt cannot aim there.
  std::optional<Iso3> aimAt(const Vec3& target_B) const;
};

struct TableInfo {
  Vec3 center_B = Vec3::Zero();
  Vec3 size = Vec3::Zero();  // a box; its top is center.z + size.z/2
  double topZ() const { return center_B.z() + 0.5 * size.z(); }
};

class RobotModel {
 public:
  // Loads the robot config (JSON) and the URDF it names (or `urdf_override` when given). Throws
  // Error naming the file and field: unknown links or joints, a chain that does not connect, a
  // field of the wrong type, a URDF urdfdom cannot parse.
  static RobotModel load(const std::filesystem::path& config,
                         const std::filesystem::path& urdf_override = {});

  const std::string& name() const { return name_; }
  const std::vector<LinkInfo>& links() const { return links_; }
  const std::vector<JointInfo>& joints() const { return joints_; }
  int variableCount() const { return int(variableJoint_.size()); }
  const JointInfo& variable(int v) const { return joints_[variableJoint_[v]]; }
  int linkIndex(const std::string& name) const;   // -1 when absent
  int jointIndex(const std::string& name) const;  // -1 when absent
  int variableIndex(const std::string& joint) const;

  int baseLink() const { return baseLink_; }
  int tipLink() const { return tipLink_; }
  // Arm chain base → tip: the driven variables in chain order.
  const std::vector<int>& armVariables() const { return armVariables_; }
  int armDof() const { return int(armVariables_.size()); }
  const KDL::Chain& chain() const { return *chain_; }
  Eigen::VectorXd armLower() const;
  Eigen::VectorXd armUpper() const;
  Eigen::VectorXd armVelocity() const;

  const std::vector<int>& handLinks() const { return handLinks_; }
  const std::vector<FingerInfo>& fingers() const { return fingers_; }
  int spreadVariable() const { return spreadVariable_; }  // -1 when the hand has none
  double graspOffset() const { return graspOffset_; }     // palm-to-object-centre distance, m
  const CameraMount& camera() const { return camera_; }
  const TableInfo& table() const { return table_; }
  const std::vector<int>& baseAdjacentLinks() const { return baseAdjacent_; }

  // All variables at their home values (config "home", else mid-range), couplings applied.
  JointVector home() const;
  // Sets mimic joints from their leaders.
  void applyCouplings(JointVector* q) const;
  JointVector withArm(const JointVector& q, const Eigen::VectorXd& arm) const;
  // q with every finger at its `open` value (spread as in q), couplings applied.
  JointVector withFingersOpen(const JointVector& q) const;
  // home() with the spread joint (hands with one) at `spread` and the fingers open.
  JointVector openHand(double spread = 0.0) const;
  // The hand preshaped for an approach: spread as given, every finger `fraction` of the way
  // from open to closed (0: open), couplings applied; the arm at home.
  JointVector preshapedHand(double spread, double fraction) const;
  // Which fingers (fingers() order) close from the preshape q: every one, except that in a
  // preshape with a finger partly closed, a finger exactly at its `open` value stays open (the
  // third finger of a two-finger pinch, kept out of the way). Kinematic closing, the simulated
  // pick-up and physics all follow it; a robot's driver should too.
  std::vector<bool> closingFingers(const JointVector& q) const;
  // The finger (index into fingers()) that `link` moves with, or -1 (the palm, the arm).
  int fingerOfLink(int link) const;
  // The palm face: the top of the palm (tip) link's collision geometry along palm z, m.
  double palmFaceZ() const;
  Eigen::VectorXd arm(const JointVector& q) const;
  // The hand's joints of q (every variable not of the arm), by URDF name, in variable order.
  std::vector<std::pair<std::string, double>> handJointValues(const JointVector& q) const;
  bool withinLimits(const JointVector& q, double tol = 1e-9) const;

  // T_B_link for every link (base frame), couplings applied to a copy of q.
  std::vector<Iso3> linkPoses(const JointVector& q) const;
  Iso3 tipPose(const JointVector& q) const;
  // The generalised force gravity `g_B` (base frame, m/s²) puts on each driven joint at q from
  // the weights of the links it carries (URDF masses at their centres of mass): N·m for
  // revolute joints, N for prismatic ones; 0 for coupled (mimic) joints and without masses.
  JointVector gravityTorques(const JointVector& q, const Vec3& g_B = Vec3(0, 0, -9.81)) const;
  // The generalised force a force f_B (N, base frame) applied at p_B on `link` puts on each
  // driven joint between that link and the root (as gravityTorques counts a link's weight).
  JointVector pointForceTorques(const JointVector& q, int link, const Vec3& p_B,
                                const Vec3& f_B) const;

 private:
  friend struct RobotModelLoader;
  std::string name_;
  std::vector<LinkInfo> links_;
  std::vector<JointInfo> joints_;
  std::vector<int> jointOrder_;     // joints in topological order (parents first)
  std::vector<int> variableJoint_;  // variable → joint
  std::vector<double> homeValues_;
  int rootLink_ = -1, baseLink_ = -1, tipLink_ = -1;
  std::vector<int> armVariables_;
  std::shared_ptr<KDL::Chain> chain_;
  std::vector<int> handLinks_;
  std::vector<FingerInfo> fingers_;
  int spreadVariable_ = -1;
  double graspOffset_ = 0.1;
  CameraMount camera_;
  TableInfo table_;
  std::vector<int> baseAdjacent_;
};

// Trajectory time (s) of a synchronous joint move from a to b: max_i |Δq_i| / v_i over the arm
// (the paper's cost, Alg. 1 line 7).
double trajectoryTime(const RobotModel& model, const Eigen::VectorXd& armA,
                      const Eigen::VectorXd& armB);

// The arm's joint offsets e (arm variables; the arm truly at q + e while it reports q) that put
// the palm where it was seen at q: tipPose(q + e) = tipPose(q) · palmError. Damped Gauss-Newton
// from zero (five steps, numerical Jacobian): of the offsets that explain the six numbers (a
// seven-joint arm has one more), the smallest. With them the palm's error at another
// configuration q2 is tipPose(q2)⁻¹ · tipPose(q2 + e).
JointVector armOffsetsFromPalmError(const RobotModel& model, const JointVector& q,
                                    const Iso3& palmError);

}  // namespace inhand
