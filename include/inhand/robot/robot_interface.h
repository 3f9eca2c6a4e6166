#pragma once
// What the scan needs from a robot arm, real or simulated. A driver for a real arm implements this
// (joint states from the controller, trajectory execution); `sim` implements it for the simulator.
#include <chrono>
#include <functional>
#include <optional>
#include <thread>
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

  // Re-grasping (§IV). putDown: returns the held object to its resting pose on the table and
  // lets go. pickUp: grasps it there, aiming for the palm at T_O_palm with the joints q (the arm
  // at the pick configuration, fingers closed to contact), and holds it; returns the grasp as
  // achieved (palm pose in the object frame, as the arm's joints imply it), or nullopt. With
  // TrackingOptions::in_hand the scan then registers the object's model to the frame after the
  // lift (ScanSession::registerHeldObject): an arm that misses its target by centimetres grasps
  // the object that far from where its joints say. A driver that cannot re-grasp returns false /
  // nullopt (the scan then ends after its first grasp).
  virtual bool putDown() { return false; }
  // The driven joints' torques (N·m; N for prismatic joints) the robot reports now, holding
  // still, gravity's included (a WAM reports them): the object's weight is estimated from them
  // (PayloadEstimator). Each call is a new reading (a driver returns its controller's next one:
  // a WAM's come at 500 Hz); a scan reads ScanOptions::torque_readings of them at each rest.
  // nullopt for a robot that reports none.
  virtual std::optional<JointVector> jointTorques() { return std::nullopt; }
  // Holds still for `seconds`, the arm and the hand as they are: after a lift the scan waits so
  // and looks again, to see whether the object stays where the hand holds it. A real arm's
  // controller holds its position while the time passes (the default sleeps); the simulator
  // steps its physics.
  virtual void holdStill(double seconds) {
    if (seconds > 0) std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  }
  virtual std::optional<Iso3> pickUp(const Iso3& /*T_O_palm*/, const JointVector& /*q*/) {
    return std::nullopt;
  }
};

}  // namespace inhand
