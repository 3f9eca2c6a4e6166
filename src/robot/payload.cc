#include "inhand/robot/payload.h"

#include "inhand/robot/robot_interface.h"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace inhand {

PayloadEstimator::PayloadEstimator(const RobotModel& model, const Vec3& g_B)
    : model_(&model), g_(g_B) {}

void TorqueSamples::add(const JointVector& tau, const std::vector<int>& joints) {
  if (count_ == 0) mean_ = JointVector::Zero(tau.size());
  ++count_;
  for (int v : joints) {
    const double d = tau[v] - mean_[v];
    mean_[v] += d / count_;
    scatter_ += d * (tau[v] - mean_[v]);
  }
}

std::optional<TorqueSamples> torquesAtRest(RobotInterface& robot, int readings) {
  TorqueSamples rest;
  for (int i = 0; i < readings; ++i) {
    const std::optional<JointVector> tau = robot.jointTorques();
    if (!tau) return std::nullopt;
    rest.add(*tau, robot.model().armVariables());
  }
  if (rest.count() == 0) return std::nullopt;
  return rest;
}

std::optional<Weighing> weighAt(const RobotModel& model, const JointVector& q,
                                const TorqueSamples& rest, const Vec3& c_B) {
  if (rest.count() == 0 || rest.mean().size() != q.size()) return std::nullopt;
  const JointVector unit = model.pointForceTorques(q, model.tipLink(), c_B, Vec3(0, 0, -9.81));
  const JointVector load = rest.mean() - model.gravityTorques(q);
  double num = 0, den = 0;
  for (int v : model.armVariables()) {
    num += unit[v] * load[v];
    den += unit[v] * unit[v];
  }
  if (!(den > 0)) return std::nullopt;
  // One reading's variance per joint, from the scatter about the means; the means' is 1/count of
  // it, and the projection's 1/den of theirs.
  const double joints = double(model.armVariables().size());
  const double n = double(rest.count());
  const double perReading = n > 1 ? rest.scatter_nm2() / ((n - 1) * joints) : 0.0;
  return Weighing{num / den, std::sqrt(perReading / n / den)};
}

void PayloadEstimator::add(const JointVector& q, const JointVector& tau, const Iso3& T_palm_F) {
  add(q, tau, T_palm_F, 1, 0.0);
}

void PayloadEstimator::add(const JointVector& q, const JointVector& tau, const Iso3& T_palm_F,
                           int samples, double scatter_nm2) {
  if (samples < 1) return;
  const RobotModel& m = *model_;
  const int tip = m.tipLink();
  const Iso3 T_B_palm = m.tipPose(q) * T_palm_F;
  // Unknowns x = (m, m·c): the weight at the palm's origin, and its moment per unit m·c along
  // each palm axis.
  const JointVector own = m.gravityTorques(q, g_);
  const JointVector a0 = m.pointForceTorques(q, tip, T_B_palm.translation(), g_);
  JointVector ak[3];
  for (int k = 0; k < 3; ++k)
    ak[k] = m.pointForceTorques(q, tip, T_B_palm.translation() + T_B_palm.linear().col(k), g_) - a0;
  for (int v : m.armVariables()) {
    const Eigen::Vector4d row(a0[v], ak[0][v], ak[1][v], ak[2][v]);
    const double b = tau[v] - own[v];
    // Each of the `samples` readings is a row; their residuals about their mean add the scatter.
    AtA_ += samples * (row * row.transpose());
    Atb_ += samples * (row * b);
    btb_ += samples * b * b;
    rows_ += samples;
  }
  btb_ += std::max(0.0, scatter_nm2);
  readings_ += samples;
}

std::optional<PayloadEstimate> PayloadEstimator::estimate() const {
  if (readings_ == 0) return std::nullopt;
  // A pseudo-inverse of the normal equations: directions of m·c that no reading constrains
  // (along gravity when the palm never turned) are left at zero.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(AtA_);
  const double top = std::max(es.eigenvalues().maxCoeff(), 1e-300);
  Eigen::Matrix4d inv = Eigen::Matrix4d::Zero();
  int rank = 0;
  for (int i = 0; i < 4; ++i)
    if (es.eigenvalues()[i] > 1e-8 * top) {
      inv += es.eigenvectors().col(i) * es.eigenvectors().col(i).transpose() / es.eigenvalues()[i];
      ++rank;
    }
  const Eigen::Vector4d x = inv * Atb_;
  PayloadEstimate e;
  e.readings = readings_;
  e.mass_kg = x[0];
  e.com_observed = rank == 4;
  e.com = std::abs(x[0]) > 1e-9 ? Vec3(x.tail<3>() / x[0]) : Vec3::Zero();
  const double rss = std::max(0.0, btb_ - 2 * x.dot(Atb_) + x.dot(AtA_ * x));
  const int dof = std::max(1, rows_ - rank);
  e.residual_nm = std::sqrt(rss / std::max(1, rows_));
  e.sigma_kg = std::sqrt(rss / dof * std::max(0.0, inv(0, 0)));
  return e;
}

}  // namespace inhand
