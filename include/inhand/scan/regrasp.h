#pragma once
// Picking up an object the robot holds an asset of (its model and a grasp set: inhand export),
// lying on the table in a pose nobody told it: the object found by registering the model to a
// frame of the table, a grasp of the set made again where it lies, tried on the model in physics
// (the hold test), and the first that held picked up and lifted. Only the robot and sensor
// interfaces are used, as in a scan.
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "inhand/grasp/grasp.h"
#include "inhand/mesh/extract.h"
#include "inhand/robot/robot_interface.h"
#include "inhand/scan/types.h"
#include "inhand/sensor/depth_sensor.h"
#include "inhand/sensor/noise_model.h"

namespace inhand {

struct RegraspOptions {
  ScanOptions scan;           // the frame checks, the robot's pixels, tracking (registration)
  TableTopOptions table_top;  // the object on the table: aim, plane fit, clustering
  NoiseModelOptions noise;    // the sensor's (registration weighs depth by its σ)
  GraspOptions grasp;         // making the set's grasps again; grasp.hold, the hold test
  // Registration starts: the model's most probable resting orientations × headings about the
  // vertical, over the object's points.
  int orientations = 6;
  int headings = 12;
  double min_support = 0.6;  // the frame must bear out this fraction of the registered model
  // The hold test's pose tolerance (HoldTestOptions::pose_tolerance_m): the found pose is right
  // to about the registration's error; a grasp that holds the model moved this far each way is
  // chosen first.
  double pose_tolerance_m = 0.002;
  std::string validate() const;
};

// What the robot knows of the object: an asset's model (frame O, observed vertices flagged), mass,
// centre of mass and grasp set.
struct KnownObject {
  ObjectModel model_O;
  double mass_kg = 0;
  Vec3 com_O = Vec3::Zero();
  std::vector<KnownGrasp> grasps;
};

struct RegraspResult {
  // Found: where the model was registered, how far the frame bears it out, the alignment's RMS.
  std::optional<Iso3> T_B_O;
  double support = -1, rms_m = 0;
  int starts = 0;  // registrations tried
  // The grasp set: how many, made again here (stable, clear of the table, reachable), held the
  // model in the hold test, and the one tried (its index in the set; -1: none).
  int set = 0, made = 0, held_in_test = 0, chosen = -1;
  std::optional<GraspCandidate> grasp;  // as made here (T_O_palm, hand, arm configurations)
  GraspGeneration generation;           // what became of each grasp of the set
  // The pick-up: the hand closed on something (picked); after the lift, the frame aimed at the
  // hand bore out the model where the hand holds it (in_hand) and where it lay (on_table), −1
  // none in view (the hand hides it); and the load the arm's joint torques show at the known
  // centre of mass (weighed_kg; −1: the robot reports no torques).
  bool picked = false;
  double in_hand = -1, on_table = -1, weighed_kg = -1;
  // The robot's verdict: with torques, a load of half to twice the object's mass (less: not in
  // the hand; more: the frame decides, as without torques); the frame: in_hand > 0.5 and
  // on_table ≤ 0.5.
  bool lifted = false;
  // Why not lifted: object_not_found, not_registered, no_grasp_here, no_contact, empty_hand,
  // not_in_hand; empty when lifted.
  std::string failure;
  double find_s = 0, plan_s = 0, pick_s = 0;
};

// Finds the object on the table near look_at_B, makes the grasps of its set (in the set's order)
// on the model where it was found, tries them on the model in physics at its mass (the hold test
// reorders: those that held first), and picks the object up with the first and lifts it
// (grasp.lift_m). The arm starts from home; `log` gets one line per step.
RegraspResult pickUpKnownObject(RobotInterface& robot, DepthSensor& sensor,
                                const KnownObject& object, const Vec3& look_at_B,
                                const RegraspOptions& options,
                                const std::function<void(const std::string&)>& log = {});

}  // namespace inhand
