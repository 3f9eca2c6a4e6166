#pragma once
// The load an arm carries, from the joint torques it reports while holding still (a WAM reports
// them; so does the simulator): each reading, less what the model's own links (URDF masses)
// explain, is the torque of the payload's weight m·g acting at its centre of mass c (palm
// frame), linear in m and m·c; readings at several palm orientations give c in all three
// directions, one gives m and c across gravity only.
#include <optional>
#include <vector>

#include "inhand/robot/robot_model.h"

namespace inhand {

struct PayloadEstimate {
  double mass_kg = 0;
  double sigma_kg = 0;        // its standard deviation (from the fit's residual torques)
  Vec3 com = Vec3::Zero();    // centre of mass in the readings' frame F (see add)
  bool com_observed = false;  // every direction of com determined (else least-norm)
  int readings = 0;
  double residual_nm = 0;  // RMS joint-torque residual of the fit
};

// Readings of the joint torques taken in a row at one rest (the arm holding still): their mean
// and their scatter, Σ over readings and arm joints of (τ − mean)² (Welford's update). A robot's
// torques are noisy; a rest of N readings (a WAM reports 500 a second) weighs with 1/√N the
// noise of one.
class TorqueSamples {
 public:
  void add(const JointVector& tau, const std::vector<int>& joints);
  const JointVector& mean() const { return mean_; }
  double scatter_nm2() const { return scatter_; }
  int count() const { return count_; }

 private:
  JointVector mean_;
  double scatter_ = 0;
  int count_ = 0;
};

class RobotInterface;
// `readings` readings of the arm's joint torques (RobotInterface::jointTorques) in a row, the
// robot holding still; nullopt for a robot that reports none.
std::optional<TorqueSamples> torquesAtRest(RobotInterface& robot, int readings);

// The load one rest's torques show at q, as a point mass at c_B (base frame): the mean torques
// less the links' own weight, projected on those of a unit mass there (least squares in one
// unknown), and the standard deviation of that from the readings' scatter. kg may be negative (the
// noise, or a model that misses the links' weight); nullopt where no arm torque depends on c_B.
struct Weighing {
  double kg = 0;
  double sigma_kg = 0;
};
std::optional<Weighing> weighAt(const RobotModel& model, const JointVector& q,
                                const TorqueSamples& rest, const Vec3& c_B);

class PayloadEstimator {
 public:
  explicit PayloadEstimator(const RobotModel& model, const Vec3& g_B = Vec3(0, 0, -9.81));
  // One reading at rest: the joints and the driven joints' torques the robot reports (the arm's
  // joints are used). The centre of mass is estimated in a frame F held by the palm at
  // T_palm_F (the palm's own by default; the object's, T_O_palm⁻¹, pools readings of several
  // grasps).
  void add(const JointVector& q, const JointVector& tau, const Iso3& T_palm_F = Iso3::Identity());
  // The same for `samples` readings held at q, given as their mean torques and their scatter
  // (TorqueSamples): the same fit and σ as adding each reading in turn.
  void add(const JointVector& q, const JointVector& mean_tau, const Iso3& T_palm_F, int samples,
           double scatter_nm2);
  // The least-squares fit; nullopt before any reading.
  std::optional<PayloadEstimate> estimate() const;
  int readings() const { return readings_; }

 private:
  const RobotModel* model_;
  Vec3 g_;
  Eigen::Matrix4d AtA_ = Eigen::Matrix4d::Zero();
  Eigen::Vector4d Atb_ = Eigen::Vector4d::Zero();
  double btb_ = 0;
  int rows_ = 0, readings_ = 0;
};

}  // namespace inhand
