#pragma once
// The load an arm carries, from the joint torques it reports while holding still (a WAM reports
// them; so does the simulator): each reading, less what the model's own links (URDF masses)
// explain, is the torque of the payload's weight m·g acting at its centre of mass c (palm
// frame), linear in m and m·c; readings at several palm orientations give c in all three
// directions, one gives m and c across gravity only.
#include <optional>

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

class PayloadEstimator {
 public:
  explicit PayloadEstimator(const RobotModel& model, const Vec3& g_B = Vec3(0, 0, -9.81));
  // One reading at rest: the joints and the driven joints' torques the robot reports (the arm's
  // joints are used). The centre of mass is estimated in a frame F held by the palm at
  // T_palm_F (the palm's own by default; the object's, T_O_palm⁻¹, pools readings of several
  // grasps).
  void add(const JointVector& q, const JointVector& tau, const Iso3& T_palm_F = Iso3::Identity());
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
