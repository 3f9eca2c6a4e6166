#pragma once
// What the scan needs from a robot arm, real or simulated. A driver for a real arm implements this
// (joint states from the controller, trajectory execution); `sim` implements it for the simulator.
#include <functional>
#include <vector>

#include "inhand/robot/robot_model.h"

namespace inhand {

class RobotInterface {
 public:
  virtual ~RobotInterface() = default;
  virtual const RobotModel& model() const = 0;
  // The joint state the robot reports now.
  virtual JointVector joints() const = 0;
  // Moves through the joint-space waypoints (the first is the current state), calling `on_state`
  // with the reported joints at each sensor frame time along the way (and once at the end).
  virtual void execute(const std::vector<JointVector>& waypoints,
                       const std::function<void(const JointVector&)>& on_state) = 0;
};

}  // namespace inhand
