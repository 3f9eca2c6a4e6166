#include "inhand/robot/ik.h"

#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/jntarray.hpp>

#include <Eigen/Cholesky>

#include "inhand/core/error.h"
#include "inhand/core/internal/parallel.h"

namespace inhand {

const char* ikMethodName(IkMethod m) { return enumName(kIkMethodNames, m); }

bool parseIkMethod(const std::string& name, IkMethod* m) {
  return enumFromName(kIkMethodNames, name, m);
}

std::string IkOptions::validate() const {
  if (random_restarts < 0) return "random_restarts must be >= 0";
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (!(position_tolerance_m > 0)) return "position_tolerance_m must be > 0";
  if (!(orientation_tolerance_rad > 0)) return "orientation_tolerance_rad must be > 0";
  if (method != IkMethod::kDampedLeastSquares && method != IkMethod::kKdlLma)
    return "method must be dls or kdl_lma";
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

// One entry per KDL segment: the joint (a rotation by q about `axis` through `origin`, or a
// translation by q along `axis`, both in the segment's parent frame), then the fixed frame to the
// segment's tip. Built from the same KDL chain the reference solver uses.
struct CompiledChain {
  static constexpr int kMaxDof = 16;
  using VecQ = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxDof, 1>;
  using Jac = Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, kMaxDof>;
  enum class Kind { kFixed, kRevolute, kPrismatic };
  struct Segment {
    Kind kind = Kind::kFixed;
    Vec3 axis = Vec3::UnitZ(), origin = Vec3::Zero();
    Iso3 tip = Iso3::Identity();
  };
  std::vector<Segment> segments;
  int dof = 0;

  explicit CompiledChain(const KDL::Chain& chain) {
    for (unsigned k = 0; k < chain.getNrOfSegments(); ++k) {
      const KDL::Segment& s = chain.getSegment(k);
      const KDL::Joint& j = s.getJoint();
      Segment out;
      if (j.getType() == KDL::Joint::RotAxis) out.kind = Kind::kRevolute;
      if (j.getType() == KDL::Joint::TransAxis) out.kind = Kind::kPrismatic;
      INHAND_CHECK(out.kind != Kind::kFixed || j.getType() == KDL::Joint::Fixed,
                   "IK: unsupported KDL joint type in the arm chain");
      const KDL::Vector a = j.JointAxis(), o = j.JointOrigin();
      out.axis = Vec3(a.x(), a.y(), a.z()).normalized();
      out.origin = Vec3(o.x(), o.y(), o.z());
      out.tip = fromKdlFrame(s.getFrameToTip());
      if (out.kind != Kind::kFixed) ++dof;
      segments.push_back(out);
    }
    INHAND_CHECK(dof <= kMaxDof, "IK: more than 16 arm joints");
  }

  // Tip pose at q and, if J is given, the geometric Jacobian in the base frame (rows: linear
  // velocity of the tip origin, angular velocity).
  Iso3 fk(const double* q, Jac* J) const {
    Iso3 T = Iso3::Identity();
    Vec3 axes[kMaxDof], pivots[kMaxDof];
    bool revolute[kMaxDof];
    int v = 0;
    for (const Segment& s : segments) {
      if (s.kind == Kind::kRevolute) {
        axes[v] = T.linear() * s.axis;
        pivots[v] = T * s.origin;
        revolute[v] = true;
        const Mat3 R = Eigen::AngleAxisd(q[v], s.axis).toRotationMatrix();
        Iso3 Tj = Iso3::Identity();
        Tj.linear() = R;
        Tj.translation() = s.origin - R * s.origin;
        T = T * Tj;
        ++v;
      } else if (s.kind == Kind::kPrismatic) {
        axes[v] = T.linear() * s.axis;
        revolute[v] = false;
        T.translation() += T.linear() * (s.axis * q[v]);
        ++v;
      }
      T = T * s.tip;
    }
    if (J) {
      J->resize(6, dof);
      const Vec3 p = T.translation();
      for (int i = 0; i < dof; ++i) {
        if (revolute[i]) {
          J->col(i).head<3>() = axes[i].cross(p - pivots[i]);
          J->col(i).tail<3>() = axes[i];
        } else {
          J->col(i).head<3>() = axes[i];
          J->col(i).tail<3>().setZero();
        }
      }
    }
    return T;
  }
};

namespace {
// Pose error as a 6-vector in the base frame: position, then the rotation vector taking the
// current orientation to the target's.
Eigen::Matrix<double, 6, 1> twistError(const Iso3& T, const Iso3& target) {
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = target.translation() - T.translation();
  const Eigen::AngleAxisd aa(Mat3(target.linear() * T.linear().transpose()));
  e.tail<3>() = aa.angle() * aa.axis();
  return e;
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
  if (options.method == IkMethod::kKdlLma)
    lma_ = std::make_unique<KDL::ChainIkSolverPos_LMA>(*chain_, L, 1e-12, options.max_iterations,
                                                       1e-15);
  fk_ = std::make_unique<KDL::ChainFkSolverPos_recursive>(*chain_);
  compiled_ = std::make_shared<const CompiledChain>(*chain_);
  INHAND_CHECK(compiled_->dof == model.armDof(), "IK: chain DOF != arm DOF");
  lower_ = model.armLower();
  upper_ = model.armUpper();
  for (int v : model.armVariables()) types_.push_back(model.variable(v).type);
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

Iso3 IkSolver::compiledFk(const Eigen::VectorXd& arm) const {
  INHAND_CHECK(arm.size() == compiled_->dof, "IK: arm vector size != arm DOF");
  return compiled_->fk(arm.data(), nullptr);
}

bool IkSolver::solveDls(const Iso3& target, const Eigen::VectorXd& seed,
                        Eigen::VectorXd* out) const {
  using VecQ = CompiledChain::VecQ;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  const CompiledChain& chain = *compiled_;
  const int n = chain.dof;
  // Weights: metres against radians, as for the reference solver.
  Vec6 L;
  L << 1, 1, 1, 0.5, 0.5, 0.5;
  // Limits are enforced every step: a revolute joint is first moved by ±2π towards its range
  // (continuous joints are wrapped into (−π, π]), then clamped.
  auto project = [&](VecQ& q) {
    for (int i = 0; i < n; ++i) {
      if (types_[size_t(i)] == JointInfo::Type::kContinuous) {
        q[i] = std::remainder(q[i], 2 * M_PI);
        continue;
      }
      if (types_[size_t(i)] == JointInfo::Type::kRevolute) {
        while (q[i] > upper_[i] && q[i] - 2 * M_PI >= lower_[i]) q[i] -= 2 * M_PI;
        while (q[i] < lower_[i] && q[i] + 2 * M_PI <= upper_[i]) q[i] += 2 * M_PI;
      }
      q[i] = std::clamp(q[i], lower_[i], upper_[i]);
    }
  };
  const double tolP = 0.1 * options_.position_tolerance_m;
  const double tolR = 0.1 * options_.orientation_tolerance_rad;
  VecQ q = seed;
  project(q);
  CompiledChain::Jac J;
  Vec6 e = twistError(chain.fk(q.data(), &J), target);
  double E = (L.cwiseProduct(e)).squaredNorm();
  double lambda = 1e-3;
  double Ewindow = E;  // the error kWindow iterations ago
  constexpr int kWindow = 15;
  for (int it = 0; it < options_.max_iterations; ++it) {
    if (e.head<3>().norm() < tolP && e.tail<3>().norm() < tolR) {
      *out = q;
      return true;
    }
    // Less than halving the error over kWindow iterations: crawling along a joint limit towards
    // a minimum that is not a solution, or an unreachable target (measured on Alg. 1's targets:
    // such attempts used to run to the iteration limit). A random restart does better.
    if (it > 0 && it % kWindow == 0) {
      if (E > 0.5 * Ewindow) return false;
      Ewindow = E;
    }
    // Levenberg–Marquardt step on the weighted problem: dq = Jwᵀ (Jw Jwᵀ + λI)⁻¹ ew.
    const CompiledChain::Jac Jw = L.asDiagonal() * J;
    Eigen::Matrix<double, 6, 6> A = Jw * Jw.transpose();
    A.diagonal().array() += lambda;
    const Vec6 y = A.llt().solve(L.cwiseProduct(e));
    VecQ qn = q + Jw.transpose() * y;
    project(qn);
    CompiledChain::Jac Jn;
    const Vec6 en = twistError(chain.fk(qn.data(), &Jn), target);
    const double En = (L.cwiseProduct(en)).squaredNorm();
    if (En < E) {
      q = qn;
      J = Jn;
      e = en;
      E = En;
      lambda = std::max(lambda * 0.3, 1e-12);
    } else {
      lambda *= 10;
      if (lambda > 1e8) return false;
    }
  }
  return false;
}

bool IkSolver::solveKdl(const Iso3& target, const Eigen::VectorXd& seed, Eigen::VectorXd* out) {
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
  *out = q;
  return true;
}

bool IkSolver::attempt(const Iso3& target, const Eigen::VectorXd& seed, Eigen::VectorXd* out) {
  Eigen::VectorXd q;
  const bool found = options_.method == IkMethod::kKdlLma ? solveKdl(target, seed, &q)
                                                          : solveDls(target, seed, &q);
  if (!found) return false;
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
  if (options.method == IkMethod::kKdlLma) {
    // A fresh solver per target: KDL's LMA solver carries state from one CartToJnt call to the
    // next, so reusing one per thread made answers depend on scheduling.
    parallelFor(0, int(targets.size()), [&](int i) {
      Rng rng = makeRng(seed, uint64_t(i));
      IkSolver solver(model, options);
      out[i] = solver.solve(targets[i], seedArm, &rng);
    });
    return out;
  }
  // The damped-least-squares solver keeps no state between solves: one solver per chunk.
  tbb::parallel_for(tbb::blocked_range<int>(0, int(targets.size()), 16),
                    [&](const tbb::blocked_range<int>& r) {
                      IkSolver solver(model, options);
                      for (int i = r.begin(); i != r.end(); ++i) {
                        Rng rng = makeRng(seed, uint64_t(i));
                        out[i] = solver.solve(targets[i], seedArm, &rng);
                      }
                    });
  return out;
}

}  // namespace inhand
