#include "inhand/robot/ik.h"

#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/jntarray.hpp>

#include "inhand/core/error.h"
#include "inhand/core/parallel.h"

namespace inhand {

std::string IkOptions::validate() const {
  if (random_restarts < 0) return "random_restarts must be >= 0";
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (!(position_tolerance_m > 0)) return "position_tolerance_m must be > 0";
  if (!(orientation_tolerance_rad > 0)) return "orientation_tolerance_rad must be > 0";
  return {};
}

std::pair<double, double> poseError(const Iso3& a, const Iso3& b) {
  double dp = (a.translation() - b.translation()).norm();
  double dr = Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
  return {dp, std::abs(dr)};
}

namespace {
KDL::Frame toKdlFrame(const Iso3& T) {
  const Mat3& R = T.linear();
  return KDL::Frame(KDL::Rotation(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0),
                                  R(2, 1), R(2, 2)),
                    KDL::Vector(T.translation().x(), T.translation().y(), T.translation().z()));
}
Iso3 fromKdlFrame(const KDL::Frame& F) {
  Iso3 T = Iso3::Identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = F.M(r, c);
  T.translation() = Vec3(F.p.x(), F.p.y(), F.p.z());
  return T;
}
}  // namespace

IkSolver::IkSolver(const RobotModel& model, const IkOptions& options)
    : model_(&model), options_(options) {
  std::string p = options.validate();
  if (!p.empty()) throw Error("IK options: " + p);
  Eigen::Matrix<double, 6, 1> L;
  L << 1, 1, 1, 0.5, 0.5, 0.5;  // position (m) vs orientation (rad) weights
  // Our own copy of the chain: KDL's Joint::pose caches its last angle in mutable members, so a
  // chain shared between threads is a data race (it made batch IK answers vary from run to run).
  chain_ = std::make_unique<KDL::Chain>(model.chain());
  lma_ =
      std::make_unique<KDL::ChainIkSolverPos_LMA>(*chain_, L, 1e-12, options.max_iterations, 1e-15);
  fk_ = std::make_unique<KDL::ChainFkSolverPos_recursive>(*chain_);
  lower_ = model.armLower();
  upper_ = model.armUpper();
}

IkSolver::~IkSolver() = default;
IkSolver::IkSolver(IkSolver&&) noexcept = default;

Iso3 IkSolver::fk(const Eigen::VectorXd& arm) const {
  KDL::JntArray q(static_cast<unsigned>(arm.size()));
  q.data = arm;
  KDL::Frame F;
  fk_->JntToCart(q, F);
  return fromKdlFrame(F);
}

bool IkSolver::attempt(const Iso3& target, const Eigen::VectorXd& seed, Eigen::VectorXd* out) {
  const int n = int(seed.size());
  KDL::JntArray qin(static_cast<unsigned>(n)), qout(static_cast<unsigned>(n));
  qin.data = seed;
  lma_->CartToJnt(qin, toKdlFrame(target), qout);
  Eigen::VectorXd q = qout.data;
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(q[i])) return false;
    const JointInfo& j = model_->variable(model_->armVariables()[i]);
    if (j.type != JointInfo::Type::kPrismatic) {
      // Wrap into the limits where a 2π shift allows it.
      while (q[i] > upper_[i] + 1e-12 && q[i] - 2 * M_PI >= lower_[i] - 1e-12) q[i] -= 2 * M_PI;
      while (q[i] < lower_[i] - 1e-12 && q[i] + 2 * M_PI <= upper_[i] + 1e-12) q[i] += 2 * M_PI;
      if (j.type == JointInfo::Type::kContinuous) q[i] = std::remainder(q[i], 2 * M_PI);
    }
    if (q[i] < lower_[i] || q[i] > upper_[i]) return false;
  }
  auto [dp, dr] = poseError(fk(q), target);
  if (dp > options_.position_tolerance_m || dr > options_.orientation_tolerance_rad) return false;
  *out = q;
  return true;
}

std::optional<Eigen::VectorXd> IkSolver::solve(const Iso3& target, const Eigen::VectorXd& seedArm,
                                               Rng* rng) {
  INHAND_CHECK(seedArm.size() == model_->armDof(), "IK seed size != arm DOF");
  Eigen::VectorXd q;
  if (attempt(target, seedArm.cwiseMax(lower_).cwiseMin(upper_), &q)) return q;
  std::uniform_real_distribution<double> U(0.0, 1.0);
  Eigen::VectorXd s(seedArm.size());
  for (int r = 0; r < options_.random_restarts; ++r) {
    for (int i = 0; i < s.size(); ++i) s[i] = lower_[i] + U(*rng) * (upper_[i] - lower_[i]);
    if (attempt(target, s, &q)) return q;
  }
  return std::nullopt;
}

std::vector<std::optional<Eigen::VectorXd>> solveIkBatch(const RobotModel& model,
                                                         const std::vector<Iso3>& targets,
                                                         const Eigen::VectorXd& seedArm,
                                                         uint64_t seed, const IkOptions& options) {
  std::vector<std::optional<Eigen::VectorXd>> out(targets.size());
  // A fresh solver per target: KDL's LMA solver also carries state from one CartToJnt call to the
  // next, so reusing one per thread made answers depend on scheduling.
  parallelFor(0, int(targets.size()), [&](int i) {
    Rng rng = makeRng(seed, uint64_t(i));
    IkSolver solver(model, options);
    out[i] = solver.solve(targets[i], seedArm, &rng);
  });
  return out;
}

}  // namespace inhand
