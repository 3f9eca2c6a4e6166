#pragma once
// ScanSession: the scan as a state the caller drives (paper §IV). The caller owns the control
// loop (a ROS node, its own driver, the simulator): it moves the robot, captures depth frames and
// hands them to the session; the session keeps the model (the TSDF volume, frame O), fuses each
// frame hand-aware (Fig. 3 c), and says where to look next (Alg. 1) and how to grasp next.
//
//   ScanSession s(robotModel, camera, noise, options, multi, centre_O);
//   s.beginGrasp(T_O_palm, q);                       // the object is in the hand
//   while (auto view = s.nextView(q_now)) {           // Alg. 1 (first: the initial trajectory)
//     for (each frame along view->waypoints) s.addFrame(depth, q, T_B_C);
//     s.finishView();                                 // optional: nextView calls it too
//   }
//   std::vector<GraspCandidate> next = s.planGrasps(T_B_O_rest, q_now).candidates;
//   ... pick up with next[0] ... s.beginGrasp(T_O_palm_achieved, q);
//   ObjectModel m = s.model();  s.save("scan.inhand");
//
// The scan drivers (scanSingleGrasp, scanMultiGrasp, scanFromTable) are thin loops over it.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "inhand/core/json_util.h"
#include "inhand/robot/robot_interface.h"
#include "inhand/scan/types.h"
#include "inhand/sensor/depth_sensor.h"

namespace inhand {

class ScanSession;

// A frame of the object resting on the table before the first pick-up (frame O is its pose
// there, T_B_O), the camera at T_B_C; `hidden` pixels (the robot's, the table's) pair with
// nothing. The finished model is aligned with it again (TableTopOptions::reanchor).
struct TableAnchor {
  DepthImage depth;
  std::vector<uint8_t> hidden;
  Iso3 T_B_C = Iso3::Identity(), T_B_O = Iso3::Identity();
};

// What a driver hands to ScanProgress::checkpoint.
struct ScanCheckpoint {
  const ScanSession* session = nullptr;     // the model, views and counters
  const MultiGraspResult* sofar = nullptr;  // the grasps finished, the table-top record
  int grasp = 0;                            // the grasp whose views are under way (0-based)
  const GraspRecord* current = nullptr;     // its record so far
  Iso3 T_B_O_rest = Iso3::Identity();       // where the object rests between grasps
  Aabb object_box_O;                        // the first grasp's object box (initial trajectory)
  const TableAnchor* anchor = nullptr;      // the table-top frame the model is anchored to
};

// What the caller follows of a scan: log lines, ground truth, each frame, stop requests,
// checkpoints.
struct ScanProgress {
  std::function<void(const std::string&)> log;  // one line per event (may be empty)
  // Ground-truth coverage of a model (set when the object's true mesh is known): recorded in
  // each view's record after its frames.
  std::function<double(const ObjectModel&)> coverage;
  // Each in-hand frame as ScanSession::addFrame handled it, with the joints and the camera pose
  // it was given (may be empty).
  std::function<void(const FrameReport&, const JointVector& q, const Iso3& T_B_C)> frame;
  // Each in-hand frame as given to ScanSession::addFrame, before any check: what a robot
  // delivers, for recording it (`inhand scan --save-frames`). May be empty.
  std::function<void(const ScanSession&, const DepthImage&, const JointVector& q,
                     const Iso3& T_B_C)>
      frame_input;
  // Asked before each step and at every frame: true ends the scan at the next frame with
  // Termination::kInterrupted and the model so far (frames after it are not fused). For a
  // SIGINT handler's flag; may be empty.
  std::function<bool()> interrupted;
  // Called at every point a scan can resume from (scan/checkpoint.h): when a grasp's views begin
  // and after each view. May be empty.
  std::function<void(const ScanCheckpoint&)> checkpoint;
  bool stopRequested() const { return interrupted && interrupted(); }
};

// A view the session chose: move the arm along `waypoints` (joint space, the first is the state
// it was planned from) and add the frames taken on the way.
struct PlannedView {
  bool initial = false;  // from the initial trajectory (not chosen by Alg. 1)
  Vec3 dir_O = Vec3::Zero();
  Iso3 T_O_C = Iso3::Identity();  // the camera pose in the object frame there
  std::vector<JointVector> waypoints;
  double quality = 0, cost_s = 0, score = 0;  // eq. 9, trajectory time, the Alg. 1 score
  int candidates = 0;                         // Alg. 1 candidates scored for it
  double planning_s = 0;
};

// Ranked grasp candidates for the next grasp (planGrasps).
struct GraspPlan {
  std::vector<GraspCandidate> candidates;  // ranked, best first
  int above_threshold = 0;                 // the first this many promise a view above t_q
  double t_q = 0;                          // the threshold (relative rule: scaled by the area)
  double model_area_m2 = 0;                // of the planning model the candidates were ranked on
  GraspGeneration generation;              // every pose tried (candidates moved out)
  double ranking_s = 0;
  double hold_s = 0;  // the hold test (grasp/hold_test.h)
};

class ScanSession {
 public:
  struct Summary {
    Termination termination = Termination::kRunning;
    std::string message;  // why it ended, in words
    int grasps = 0, views = 0, frames = 0;
    int frames_rejected = 0;  // in-hand frames tracking could not align (not fused)
    // In-hand frames refused by options.checks: dropped or empty, joints off the planned path,
    // the object not where the hand holds it; and frames whose non-finite depths were dropped.
    int frames_dropped = 0, frames_off_path = 0, frames_unsupported = 0, frames_repaired = 0;
    int frames_in_free_space = 0;  // depth where the model knows space is empty
    int frames_moving = 0;         // the object moving in the hand (TrackingOptions::slip_check)
    int creeps_followed = 0;       // grasp corrections for creep (TrackingOptions::creep_m)
    std::vector<SlipRecord> slips;
    int view_evaluations = 0, view_refinements = 0;
    double planning_s = 0, fusion_s = 0, tracking_s = 0;
    // Colour (camera.colour): pixels whose colour was fused, and the time it took (in fusion_s).
    long colour_pixels = 0;
    double colour_s = 0;
    // … the colour frames kept (ColourFrames) and the shading fall-off fitted to them, as of the
    // last model() with colour.
    int colour_frames_kept = 0;
    double colour_frames_mb = 0, colour_shading_falloff = 0;
    std::optional<PayloadEstimate> payload;  // from addJointTorques' readings (O frame)
    std::string brief() const;               // one line
    // Copies every count and time of this summary into `result` (the one place that does, so
    // that no counter is left out).
    void copyTo(ScanResult* result) const;
  };

  // A model in a cube of options.volume_size_m around centre_O (object frame O), voxels of
  // options.voxel_m. Throws Error on invalid options.
  ScanSession(const RobotModel& robot, const DepthCameraOptions& camera,
              const NoiseModelOptions& noise, const ScanOptions& options,
              const MultiGraspOptions& multi, const Vec3& centre_O);
  ~ScanSession();
  ScanSession(ScanSession&&) noexcept;
  ScanSession& operator=(ScanSession&&) = delete;

  const ScanOptions& options() const;
  const MultiGraspOptions& multiOptions() const;
  const RobotModel& robot() const;
  const Vec3& centre() const;
  const DepthCameraOptions& camera() const;
  const NoiseModelOptions& noise() const;
  // Where the pan-tilt points the camera for the views (base frame): the planner's presentation
  // point at options.planner.range_m.
  Iso3 cameraPose() const;
  // Log lines and ground-truth coverage (ScanProgress) for what follows.
  void setProgress(const ScanProgress& progress);
  const ScanProgress& progress() const;
  // Seconds since this session was made (a resumed scan's session counts from its resumption).
  double elapsedSeconds() const;
  void log(const std::string& line) const;  // a line to the progress log (if any)

  // The object is now in the hand: palm at T_O_palm in the object frame, the robot at q.
  // `object_box_O`: where the object is believed to lie, for the arm's clearance on the initial
  // trajectory (empty: a 10 cm cube around the centre). The first grasp of a session starts with
  // the initial trajectory (options.initial_views directions); later grasps go to Alg. 1 at once.
  void beginGrasp(const Iso3& T_O_palm, const JointVector& q, const Aabb& object_box_O = Aabb());
  // The next grasp (or the one just begun) is not confirmed (no frame registered the object in
  // the hand: too few of its points in view after the lift): with tracking on, each of the next
  // `frames` in-hand frames first registers the model so far with the frame from the grasp
  // (registerHeldObject, the robot's pixels hidden), and the first that aligns moves the grasp
  // there before anything is fused. 0 stops it; endGrasp too.
  void confirmGraspOnNextFrames(int frames);
  // The object has left the hand (put down): frames are no longer fused until the next grasp.
  void endGrasp();
  bool holding() const;
  int graspIndex() const;  // 0-based index of the current (or last) grasp, -1 before any
  const Iso3& graspPose() const;
  // The joints of the current (or last) grasp's last in-hand frame whose depths showed the object
  // where the hand holds it (checks.min_support); none before one did. Where an object that fell
  // unnoticed was last seen in the hand.
  const std::optional<JointVector>& lastSeenHeld() const;

  // A depth frame taken from T_B_C (camera in the robot base frame) with the robot at q, the
  // object in the hand: fused with T_O_C = T_O_palm · T_palm_B(q) · T_B_C; the robot's own
  // pixels only carve (§IV), and with HandMode::kCarveAndEmpty the voxels inside the robot are
  // emptied (Fig. 3 c). Counts toward the current view. Throws when no grasp is active or the
  // image does not match the camera.
  FrameReport addFrame(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C);
  // The colour image taken with the next frame added (addFrame, addFrameOfObjectAt), by the
  // colour camera of the session's DepthCameraOptions (camera.colour): where that frame is
  // fused, its colours are too (integrateColour), and model() carries per-vertex colour. An
  // empty image, or a camera without colour, adds none.
  void setColourOfNextFrame(RgbImage colour);
  // The camera pose (base frame) that aligns a frame taken from T_B_C, the robot at q, with the
  // hand at q and the object held at T_O_palm (its model so far): options.tracking; T_B_C itself
  // when tracking is off, nullopt when the frame cannot be aligned. addFrame uses it.
  std::optional<Iso3> trackedCameraPose(const DepthImage& depth, const JointVector& q,
                                        const Iso3& T_B_C, const Iso3& T_O_palm,
                                        TrackResult* result = nullptr);
  // The object's pose in the hand after a pick-up, from a frame of it held: the arm's error
  // where it grasped can put the object centimetres from where the reported joints say. The
  // model so far (its observed surface) is aligned with the frame (alignBodyToDepth; the robot's
  // pixels, `robot_mask`, may hide it), starting from the grasp as reported (`T_O_palm`), the
  // camera at T_B_C relative to the palm at q (as tracked). Returns the grasp that aligns it, or
  // nullopt when the alignment fails its checks (`result->reason`).
  std::optional<Iso3> registerHeldObject(const DepthImage& depth,
                                         const std::vector<uint8_t>& robot_mask,
                                         const JointVector& q, const Iso3& T_B_C,
                                         const Iso3& T_O_palm, TrackResult* result = nullptr);
  // The object resting on the table, from a frame of it (camera at T_B_C; `hidden`: pixels that
  // pair with nothing, the robot's and the table's): the model so far (its observed surface)
  // aligned with the frame from each of `starts` (T_B_O), on both cores. Each start's aligned
  // pose T_B_O (nullopt where the alignment failed its checks) and result, in order. `in_hand`:
  // the object is held (the frame's pixels the model does not cover pull it too:
  // alignBodyToDepth).
  std::vector<std::pair<std::optional<Iso3>, TrackResult>> registerObjectAt(
      const DepthImage& depth, const std::vector<uint8_t>& hidden, const Iso3& T_B_C,
      const std::vector<Iso3>& starts, bool in_hand = false);

  // A depth frame of the object lying at T_B_O (not in the hand, e.g. on the table): the robot's
  // pixels and those set in `carve` (same size as the image; may be null) only carve. With
  // carve_includes_robot the caller's mask already has the robot's pixels (robotPixelMask, no
  // table): they are not rendered again.
  FrameReport addFrameOfObjectAt(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C,
                                 const Iso3& T_B_O, const std::vector<uint8_t>* carve = nullptr,
                                 bool carve_includes_robot = false);

  // The next view with the robot at q_now: while the first grasp's initial trajectory lasts, its
  // next reachable direction; then Alg. 1 on the model so far. nullopt: this grasp's views are
  // done (summary().termination: no_view_above_threshold, max_views or no_reachable_view). Frames
  // added after it count toward it.
  std::optional<PlannedView> nextView(const JointVector& q_now);
  // Closes the current view's record with the model's figures after its frames (nextView and
  // planGrasps call it when the caller has not). Returns the record.
  const ViewRecord& finishView();
  const std::vector<ViewRecord>& views() const;
  const std::vector<int>& viewGrasps() const;  // the grasp index of each view

  // Grasp candidates on the model so far with the object resting at T_B_O_rest and the robot at
  // q_now, ranked by the best view Alg. 1 finds with the hand there (eq. 9, the ranking planner),
  // the first `above_threshold` of them above its t_q. Sets the termination when none is; when
  // not even a view with no hand reaches t_q (ViewPlanner::graspQualityBound) it does so without
  // generating candidates (an empty plan).
  GraspPlan planGrasps(const Iso3& T_B_O_rest, const JointVector& q_now);
  // The best of them, or nullopt.
  std::optional<GraspCandidate> nextGrasp(const Iso3& T_B_O_rest, const JointVector& q_now);

  // The model (S_obj) at full resolution, and at the planning stride (what Alg. 1 sees). Each is
  // extracted once per state of the volume and kept until the volume changes (so, though const,
  // not to be called from two threads at once on one session).
  ObjectModel model() const;
  ObjectModel planningModel() const;
  const TsdfVolume& volume() const;
  // The frames of the object not held (addFrameOfObjectAt) fused with their silhouettes, which
  // volume() only carves (ScanOptions::discontinuities_carve_only_on_table): the first grasp's
  // model reaches the edges seen from above. volume() when there is none (the option off, no
  // such frame, a resumed session, or once a grasp began).
  const TsdfVolume& tableTopVolume() const;
  // Writable access counts as a change of the volume: the kept models are extracted again.
  // Writes through a reference kept across a model() call are not seen by it: call volume()
  // again after writing.
  TsdfVolume& volume();

  // Ends the scan (the caller's reason; the session sets its own when it runs out of views or
  // grasps).
  void finish(Termination termination, const std::string& message = "");
  Summary summary() const;
  // The arm's joint torques (RobotInterface::jointTorques) read at rest with the object held in
  // the current grasp: the readings of every grasp give the object's mass and its centre of
  // mass in O (Summary::payload). Ignored while nothing is held.
  void addJointTorques(const JointVector& q, const JointVector& tau);
  // … a rest's readings in a row at q (their mean and scatter).
  void addJointTorques(const JointVector& q, const TorqueSamples& rest);

  // A checkpoint: the volume, the grasp, the views so far and the counters, written atomically,
  // with the caller's `extra` (e.g. its own loop's state; null: none). load() resumes from it
  // with the same robot, camera and options (the volume's size and voxel must match the file's;
  // the error names the file and what differs) and gives back `extra`.
  void save(const std::filesystem::path& path, const Json& extra = Json()) const;
  static ScanSession load(const std::filesystem::path& path, const RobotModel& robot,
                          const DepthCameraOptions& camera, const NoiseModelOptions& noise,
                          const ScanOptions& options, const MultiGraspOptions& multi,
                          Json* extra = nullptr);

 private:
  struct State;
  std::unique_ptr<State> s_;
  FrameReport fuse(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C,
                   const Iso3& T_O_B, const std::vector<uint8_t>* carve, bool inHand,
                   bool maskRobot, const RgbImage& colour);
  void emptyInsideRobot(const JointVector& q, const Iso3& T_O_B);
  // Tracking's object points from `current` (or a fresh planning model).
  void refreshTrackingModel(const ObjectModel* current = nullptr);
  // The grasp corrected by a slip `moved` (palm frame) that alignment `r` found from the palm at
  // T_C_palm: the palm again from the hand alone, then T_O_palm and the palm-frame points.
  void moveGrasp(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C,
                 const Iso3& T_C_palm, const TrackResult& r, Iso3 moved);
  // confirmGraspOnNextFrames' registration on one frame (camera reported at T_B_C).
  void confirmGrasp(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C);
  // A slip under way ends, at rest in the hand (`settled`) or with the grasp's views; its record
  // is kept when it moved the grasp.
  void closeSlip(bool settled = false);
  // TrackingOptions::slip_check on an in-hand frame (the robot at q, the camera reported at T_B_C,
  // the palm at T_C_palm in the camera frame): why it must not be fused because the object moved
  // in the hand, or "". A slip that two frames bear out moves the grasp (T_O_palm and everything
  // kept in the palm frame).
  std::string followSlip(const DepthImage& depth, const JointVector& q, const Iso3& T_B_C,
                         const Iso3& T_C_palm);
  // TrackingOptions::filter: the frame's alignment `r` (taken with the robot at q, the palm
  // predicted at T_C_palm) through the Kalman filter; r->correction becomes the filtered one.
  void filterCorrection(const JointVector& q, const Iso3& T_C_palm, TrackResult* r);
  static bool modelPointsNeeded(const ScanOptions& o);  // tracking or the frame checks
};

// Drives the current grasp's views with a robot and a sensor: points the camera
// (cameraPose), then for each view the session plans, executes its waypoints, adding every frame
// the robot reports on the way, until nextView says the grasp is done. Calls `after_view` after
// each view (e.g. to write a checkpoint). Ends with kInterrupted when the session's
// progress.interrupted says so (checked before each view and at every frame; the view under way
// keeps the frames fused before). Returns why it ended.
Termination runGraspViews(ScanSession& session, RobotInterface& robot, DepthSensor& sensor,
                          const std::function<void()>& after_view = {});

}  // namespace inhand
