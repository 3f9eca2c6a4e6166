#pragma once
// Inverse kinematics of the arm chain for a 6-D target, from the given seed, then from seeded
// random restarts. Two solvers:
//  - kDampedLeastSquares (default): our own Levenberg–Marquardt on the chain compiled from the
//    URDF into fixed-size Eigen (no heap, 6×6 normal equations, adaptive damping, joint limits
//    enforced every step by ±2π wrapping then clamping). Tens of times faster than KDL's solver.
//  - kKdlLma: KDL's ChainIkSolverPos_LMA, kept as the reference; it ignores joint limits, so
//    revolute solutions are wrapped by ±2π into the limits where possible, else rejected.
// Every returned solution is verified by KDL's forward kinematics (independent of the solver).
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "inhand/core/enum_names.h"
#include "inhand/core/random.h"
#include "inhand/robot/robot_model.h"

namespace KDL {
class Chain;
class ChainIkSolverPos_LMA;
class ChainFkSolverPos_recursive;
}  // namespace KDL

namespace inhand {

enum class IkMethod { kDampedLeastSquares, kKdlLma };
inline constexpr EnumNames<IkMethod, 2> kIkMethodNames = {{IkMethod::kDampedLeastSquares, "dls"},
                                                          {IkMethod::kKdlLma, "kdl_lma"}};
const char* ikMethodName(IkMethod m);                      // dls, kdl_lma
bool parseIkMethod(const std::string& name, IkMethod* m);  // false for an unknown name

struct IkOptions {
  int random_restarts = 40;                 // attempts from random seeds after the given seed fails
  int max_iterations = 300;                 // solver iterations per attempt
  double position_tolerance_m = 1e-5;       // accepted position error, m
  double orientation_tolerance_rad = 1e-4;  // accepted orientation error, rad
  IkMethod method = IkMethod::kDampedLeastSquares;
  std::string validate() const;
};

struct CompiledChain;  // the arm chain as fixed-size Eigen data (ik.cc)

// Not thread-safe (it owns KDL solver state and its own copy of the chain): use one per thread.
// Cheap to construct.
class IkSolver {
 public:
  IkSolver(const RobotModel& model, const IkOptions& options = {});
  ~IkSolver();
  IkSolver(IkSolver&&) noexcept;

  // Arm joint values (armDof(), chain order) putting the tip at T_B_tip, or nullopt.
  std::optional<Eigen::VectorXd> solve(const Iso3& T_B_tip, const Eigen::VectorXd& seedArm,
                                       Rng* rng);
  // Tip pose of arm values by KDL forward kinematics (a second, independent FK).
  Iso3 fk(const Eigen::VectorXd& arm) const;
  // Tip pose by the compiled chain the damped-least-squares solver iterates on.
  Iso3 compiledFk(const Eigen::VectorXd& arm) const;

 private:
  bool attempt(const Iso3& target, const Eigen::VectorXd& seed, Eigen::VectorXd* out);
  bool solveDls(const Iso3& target, const Eigen::VectorXd& seed, Eigen::VectorXd* out) const;
  bool solveKdl(const Iso3& target, const Eigen::VectorXd& seed, Eigen::VectorXd* out);
  const RobotModel* model_;
  IkOptions options_;
  std::unique_ptr<KDL::Chain> chain_;  // declared before the solvers that refer to it
  std::unique_ptr<KDL::ChainIkSolverPos_LMA> lma_;
  std::unique_ptr<KDL::ChainFkSolverPos_recursive> fk_;
  std::shared_ptr<const CompiledChain> compiled_;
  Eigen::VectorXd lower_, upper_;
  std::vector<JointInfo::Type> types_;  // per arm joint
};

// Solves many targets on both cores (one solver per thread); result i for target i. Each target
// gets its own random stream from (seed, i), so results do not depend on scheduling.
std::vector<std::optional<Eigen::VectorXd>> solveIkBatch(const RobotModel& model,
                                                         const std::vector<Iso3>& targets,
                                                         const Eigen::VectorXd& seedArm,
                                                         uint64_t seed,
                                                         const IkOptions& options = {});

// Position and orientation error between two poses (m, rad).
std::pair<double, double> poseError(const Iso3& a, const Iso3& b);

}  // namespace inhand
