#include "inhand/robot/reachability.h"

#include <cmath>

#include "inhand/core/error.h"
#include "inhand/core/pose.h"
#include "inhand/robot/collision.h"

namespace inhand {

std::string ReachabilityOptions::validate() const {
  if (!(range_m > 0)) return "range_m must be > 0";
  if (directions < 1) return "directions must be >= 1";
  if (rolls < 1) return "rolls must be >= 1";
  if (grid < 1) return "grid must be >= 1";
  std::string p = ik.validate();
  return p.empty() ? "" : "ik." + p;
}

Iso3 presentationPalmPose(const Vec3& object_B, const Vec3& camera_B, const Vec3& dir_O,
                          double roll, double offset) {
  Vec3 w = (object_B - camera_B).normalized();
  Mat3 align = Eigen::Quaterniond::FromTwoVectors(dir_O.normalized(), w).toRotationMatrix();
  Iso3 T_B_O = Iso3::Identity();
  T_B_O.linear() = Eigen::AngleAxisd(roll, w).toRotationMatrix() * align;
  T_B_O.translation() = object_B;
  Iso3 T_palm_O = Iso3(Eigen::Translation3d(0, 0, offset));
  return T_B_O * T_palm_O.inverse();
}

std::vector<ReachabilityCell> reachabilityMap(const RobotModel& model,
                                              const ReachabilityOptions& o) {
  std::string p = o.validate();
  if (!p.empty()) throw Error("reachability options: " + p);
  const CameraMount& cam = model.camera();
  Vec3 d0 = cam.lookAt_B - cam.panTilt_B;
  double pan0 = std::atan2(d0.y(), d0.x()), tilt0 = std::atan2(-d0.z(), std::hypot(d0.x(), d0.y()));
  const std::vector<Vec3> dirs = fibonacciSphere(o.directions);
  const Eigen::VectorXd seedArm = model.arm(model.home());
  CollisionChecker checker(model);
  std::vector<ReachabilityCell> cells;
  for (int iy = 0; iy < o.grid; ++iy)
    for (int ix = 0; ix < o.grid; ++ix) {
      ReachabilityCell c;
      double step = o.grid_step_deg * M_PI / 180, mid = 0.5 * (o.grid - 1);
      double pan = pan0 + (ix - mid) * step, tilt = tilt0 + (iy - mid) * step;
      c.pan_deg = pan * 180 / M_PI;
      c.tilt_deg = tilt * 180 / M_PI;
      Vec3 d(std::cos(tilt) * std::cos(pan), std::cos(tilt) * std::sin(pan), -std::sin(tilt));
      c.object_B = cam.panTilt_B + o.range_m * d;
      c.total = o.directions;
      auto T_B_C = cam.aimAt(c.object_B);
      if (!T_B_C) {
        c.aimable = false;
        cells.push_back(c);
        continue;
      }
      std::vector<Iso3> targets;
      for (const Vec3& dir : dirs)
        for (int r = 0; r < o.rolls; ++r)
          targets.push_back(presentationPalmPose(c.object_B, cam.panTilt_B, dir,
                                                 2 * M_PI * r / o.rolls, model.graspOffset()));
      auto sols =
          solveIkBatch(model, targets, seedArm, mixSeed(o.seed, uint64_t(cells.size())), o.ik);
      const JointVector home = model.home();
      for (size_t k = 0; k < dirs.size(); ++k)
        for (int r = 0; r < o.rolls; ++r) {
          const auto& s = sols[k * o.rolls + r];
          if (s && !checker.inCollision(model.withArm(home, *s))) {
            ++c.reachable;
            break;
          }
        }
      cells.push_back(c);
    }
  return cells;
}

}  // namespace inhand
