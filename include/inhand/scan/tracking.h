#pragma once
// Tracking the hand in depth frames (paper §II and its reference [6], Krainin et al., IJRR 2011):
// the arm's joint encoders put the hand centimetres from where it is (cable stretch), so each
// in-hand frame's camera pose relative to the hand is refined by aligning the frame with what is
// known to be rigid with the palm: the hand's own surface at the reported finger joints and the
// object's observed surface so far. Point-to-plane ICP with projective data association: each
// model point is projected into the image at the current estimate and paired with the measured
// point at that pixel; pairs farther apart in depth than a gate that shrinks from gate_m to
// final_gate_m are left out, as are points facing away from the camera.
#include <string>
#include <vector>

#include "inhand/core/options.h"
#include "inhand/geometry/triangle_mesh.h"
#include "inhand/sensor/depth_camera.h"
#include "inhand/sensor/depth_image.h"

namespace inhand {

struct TrackingOptions {
  bool enabled = true;          // off: frames are fused with the reported poses
  int iterations = 30;          // ICP iterations per frame
  double gate_m = 0.06;         // depth gate of the first iteration, m
  double final_gate_m = 0.008;  // … shrinking geometrically to this, m
  int min_inliers = 150;        // fewer pairs at the end: the frame is rejected (not fused)
  // A final point-to-plane RMS above this many times the sensor's axial σ at the palm's depth
  // (the residual of a right alignment is the sensor's noise): rejected.
  double max_rms_ratio = 1.2;
  double max_correction_m = 0.12;  // a correction moving the palm farther: rejected, m
  // A frame whose correction differs from the last tracked frame's of the grasp by more than
  // this, and as much again per radian the joints moved since (the palm's shift plus 10 cm times
  // its turn), is not fused, unless the frame before was refused for a jump to within as much of
  // it (the arm's error does not jump; a wrong alignment does). 0: no check.
  double max_jump_m = 0.01;
  double prior = 0.002;        // pull towards the reported pose, relative to the data's curvature
  double object_weight = 0.3;  // the model's points against the hand's
  double hand_spacing_m = 0.004;  // spacing of the hand's surface samples, m
  int max_object_points = 400;    // the object's observed surface, subsampled to this
  // The frames' corrections filtered over time (a Kalman filter on the palm-frame correction, a
  // random walk): each frame's alignment is a measurement with the information of its point
  // pairs; the correction may change by drift_m/drift_rad per radian the arm's joints move and
  // by frame_drift_m/frame_drift_rad per frame. false: each frame is fused with its own
  // alignment.
  bool filter = false;
  double drift_m = 0.05, drift_rad = 0.05;                // per radian of joint motion
  double frame_drift_m = 0.0001, frame_drift_rad = 5e-4;  // per frame
  // The point pairs' information is scaled by this: their errors are not independent (the
  // model's own error, projective association), a pair counts as this fraction of one.
  double pair_information = 0.1;
  // After each pick-up, the object's pose in the hand from the first frame of it held
  // (ScanSession::registerHeldObject): the model so far aligned with the frame; false: the grasp
  // as the robot reports it. Off in this struct; a scan's config (ScanConfig, physics on by
  // default) turns it on with sim.physics unless it sets it (setPhysics).
  bool in_hand = false;
  // What a pick-up's frame must show before the palm's error there is carried to the pick: the
  // correction's squared Mahalanobis distance under its alignment's information (times
  // pair_information) above this. 16.81: χ² with 6 degrees of freedom at 99 %, a correction the
  // frame's noise alone gives once in a hundred (an exact arm's lift frame would otherwise move
  // the object in the hand by a millimetre or two for the rest of the grasp).
  double in_hand_significance = 16.81;
  // Slip (ScanSession::addFrame): every in-hand frame, the model alone is aligned with the frame
  // from where the grasp holds it (the robot's pixels hidden). A correction that moves the model's
  // surface by more than slip_m (RMS along its normals: what a depth frame can tell), is
  // significant (in_hand_significance), and that the frame bears out clearly better than the
  // held pose, in two frames in a row, means the object moved in the hand: the grasp is
  // corrected, and no frame is fused until one shows the object at rest in the hand again.
  // false: the grasp stays as it began.
  bool slip_check = true;
  double slip_m = 0.002;
  int slip_points = 1500;     // the model's observed surface, subsampled to this for it
  double slip_gate_m = 0.03;  // its first iteration's depth gate, m
  // Creep: a significant correction that moves the model's surface by more than creep_m (and at
  // most twice slip_m) but is not a slip, that the frame bears out better than the held pose (a
  // residual 15 % smaller, not clearly more seen through), shown alike (within slip_m) by every
  // frame while the camera turns about the object by creep_turn_deg and no slip goes on, is
  // followed: the grasp is corrected and the frame fused there. An object that creeps in the
  // hand under a motion's accelerations (a millimetre or so per view, in physics) otherwise stays
  // where the grasp began while the frames fused there smear the model along with it, so that a
  // slow creep never adds up to a slip against that model. The turn tells creep from an
  // alignment that slides on a coarse or one-sided model: that slide changes with where the
  // camera looks from. 0: not followed.
  double creep_m = 0.0005;
  double creep_turn_deg = 10;

  template <class V, class S>
  static void fields(V& v, S& o) {
    v.boolean("enabled", o.enabled, "off: frames fused with the poses the robot reports");
    v.integer("iterations", o.iterations, "ICP iterations per frame", Range::closed(1, 200));
    v.num("gate_m", o.gate_m, "depth gate of the first iteration, m", Range::open(0, 1));
    v.num("final_gate_m", o.final_gate_m, "… shrinking to this (at most gate_m), m",
          Range::open(0, 1));
    v.integer("min_inliers", o.min_inliers, "fewer aligned points: the frame is not fused",
              Range::atLeast(6));
    v.num("max_rms_ratio", o.max_rms_ratio,
          "a final residual above this many sensor σ: the frame is not fused", Range::above(0));
    v.num("max_correction_m", o.max_correction_m,
          "a correction moving the palm farther: the frame is not fused, m", Range::above(0));
    v.num("max_jump_m", o.max_jump_m,
          "a correction farther from the last tracked frame's (and as much again per radian "
          "the joints moved; the palm's shift plus 10 cm times its turn): not fused unless the "
          "next frame agrees, m; 0: no check",
          Range::atLeast(0));
    v.num("prior", o.prior, "pull towards the reported pose, relative to the data's curvature",
          Range::closedOpen(0, 1));
    v.num("object_weight", o.object_weight, "the model's points against the hand's",
          Range::closed(0, 1));
    v.num("hand_spacing_m", o.hand_spacing_m, "spacing of the hand's surface samples, m",
          Range::closedOpen(0.001, 0.05));
    v.integer("max_object_points", o.max_object_points,
              "the model's observed surface, subsampled to this many points", Range::atLeast(0));
    v.boolean("filter", o.filter,
              "corrections Kalman-filtered over frames (a random walk); off: each frame's own");
    v.num("drift_m", o.drift_m, "the correction's drift per radian of joint motion, m",
          Range::atLeast(0));
    v.num("drift_rad", o.drift_rad, "… and of its rotation, rad", Range::atLeast(0));
    v.num("frame_drift_m", o.frame_drift_m, "the correction's drift per frame, m", Range::above(0));
    v.num("frame_drift_rad", o.frame_drift_rad, "… and of its rotation, rad", Range::above(0));
    v.num("pair_information", o.pair_information,
          "each aligned point pair counts as this fraction of an independent measurement",
          Range::openClosed(0, 1));
    v.boolean("in_hand", o.in_hand,
              "after each pick-up the object's pose in the hand from a frame (the model aligned "
              "with it); off: as the robot reports it (default: as sim.physics.enabled, unless "
              "given)");
    v.num("in_hand_significance", o.in_hand_significance,
          "a pick-up's palm error is carried to the grasp only when its squared Mahalanobis "
          "distance exceeds this (χ²(6) at 99 %)",
          Range::atLeast(0));
    v.boolean("slip_check", o.slip_check,
              "each in-hand frame, the model alone aligned with it: the object's slip in the hand "
              "found, the grasp corrected, frames not fused while it moves");
    v.num("slip_m", o.slip_m,
          "a significant correction moving the model's surface farther (RMS along its normals) "
          "is a slip, m",
          Range::open(0, 0.1));
    v.integer("slip_points", o.slip_points,
              "the model's observed surface, subsampled to this many points for it",
              Range::atLeast(0));
    v.num("slip_gate_m", o.slip_gate_m, "its first iteration's depth gate, m", Range::open(0, 1));
    v.num("creep_m", o.creep_m,
          "a significant correction moving the model's surface farther (at most 2 slip_m), not "
          "a slip, better borne out, alike in every frame while the camera turns by "
          "creep_turn_deg: the grasp follows it, m; 0: off",
          Range::closedOpen(0, 0.1));
    v.num("creep_turn_deg", o.creep_turn_deg,
          "… the camera's turn about the object (in the hand's frame) over which the frames "
          "show the creep alike, deg",
          Range::closed(0, 90));
  }
  std::string validate() const;
};

// Why an alignment was refused: too few points aligned, the camera sees through the aligned
// points, the residual too large, the correction too large.
enum class TrackRefusal { kNone, kTooFewPoints, kSeesThrough, kResidual, kCorrection };
// "", "too_few_points", "sees_through", "residual", "correction".
const char* trackRefusalName(TrackRefusal r);

struct TrackResult {
  bool ok = false;
  // The correction ΔT in the camera frame: T_C_palm = ΔT · T_C_palm(predicted).
  Iso3 correction = Iso3::Identity();
  int inliers = 0;
  int see_through = 0;  // visible points the camera sees through (measured well behind them)
  int hand_inliers = 0, hand_see_through = 0;  // of those, the hand's
  double rms_m = 0;
  // The information (inverse covariance) of the correction's parameters about the predicted palm,
  // camera frame (rotation vector, then translation): the final pairs' normal equations over the
  // residual's variance (max(rms, σ/2)²).
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  TrackRefusal refusal = TrackRefusal::kNone;  // why not ok
  std::string reason;                          // … in words, with the figure
};

// Aligns `points_palm` (surface points with outward normals in the palm frame) with the depth
// frame, starting from each of `starts` (corrections: the reported pose, the previous frame's)
// and keeping the best; the palm predicted at T_C_palm in the camera frame. Only points in front
// of the model's other points are paired (`occluders_palm`, e.g. the object's whole model, hide
// what lies behind them, as the points do each other). A result whose visible points the camera
// sees through (measured more than 1.5 cm behind them) for more than a tenth of its pairs is not
// ok: a wrong alignment, not an arm error.
// `hand_palm` are the hand's points (exact geometry), `object_palm` the model's (weighted by
// options.object_weight; the model can be wrong where it was seen little); the best result is
// chosen by the hand's fit. `sigma_m`: the sensor's axial noise at the palm's depth.
TrackResult alignToDepth(const DepthImage& depth, const CameraIntrinsics& K,
                         const std::vector<SurfacePoint>& hand_palm,
                         const std::vector<SurfacePoint>& object_palm,
                         const std::vector<Vec3>& occluders_palm, const Iso3& T_C_palm,
                         const std::vector<Iso3>& starts, double sigma_m,
                         const TrackingOptions& options);

// How far a result's correction lies from no correction in units of its own uncertainty: the
// squared Mahalanobis distance of its parameters (rotation vector, translation of the body
// predicted at T_C_X) under `information` · `pair_information`.
double correctionSignificance(const TrackResult& r, const Iso3& T_C_X, double pair_information);

// The chamfer distance in pixels (a 3×3 mask: 1 along rows and columns, √2 diagonally; two
// passes) from each pixel of `window` (of an image `width` pixels wide) to the nearest pixel of
// it where `zero` is set, over paths within the window; 1e9 where it has none. Row-major,
// window-sized. Within a whole-image window it is the image's distance; within a smaller one, a
// distance shorter than the window's margin around the pixel is the image's too.
std::vector<float> chamferDistance(const std::vector<uint8_t>& zero, int width,
                                   const PixelRect& window);

// How alignBodyToDepth uses the uncovered pixels' pull (below).
enum class UncoveredPull {
  kOff,
  // In every iteration from the start: the slip check, whose start is where the hand held the
  // body (the refinement below left the mug of Faults.AnObjectThatSlipsIsFoundAndTheGraspCorrected
  // 5.7 mm off after its slip, against 1.4 mm).
  kFromStart,
  // As a refinement from where the alignment without it converged, kept when it converges and
  // the frame does not contradict it more (it sees through more points than that alignment by
  // over 1 % of its pairs, at least 3, or pairs fewer by over 5 %, at least 15: where the model
  // lacks a part of the body, that part's pixels drag the points over them): a body looked for
  // from where the hand planned to hold it, which may be a centimetre off.
  kAfterConverging,
};

// What alignBodyToDepth's outline makes of a pixel without depth (below).
enum class NoDepthPixels {
  // Not the body: the body on the table, whose outline against an empty background is where
  // depth ends (Session.AnObjectThatTippedIsFoundAgainOnTheTable), and the slip check, which
  // compares frames of the same held body with each other.
  kOutside,
  // Unknown, inside the outline: a held body registered from where the hand planned to hold it.
  // A depth camera returns nothing at grazing incidence and in its projector's shadow, both at
  // the body's edges (a standing can's top face seen edge-on), and counted as outside such
  // pixels pulled the points out of them: the body slid along what the frame left free
  // (Tracking.PixelsWithoutDepthDoNotPullAHeldBodysOutline).
  kUnknown,
};

// Aligns a rigid body's surface points (`points_X`, with outward normals, in its frame X) with
// the depth frame, from X at T_C_X: the object's model with its pose in the hand unknown after a
// pick-up. `hidden` (empty, or one per pixel): pixels of something in front that may hide the
// body (the robot's); they pair with nothing. Point-to-plane pairs as alignToDepth (same gates
// and checks, every point weighted alike), and an outline term: projective association alone
// slides a body sideways slowly and stops where a face seen head-on fits (anywhere in its own
// plane), so a point that projects where the frame shows neither the body (depths within 5 cm
// of its own) nor a hidden pixel (nor, with `no_depth` kUnknown, a pixel without depth) is pulled
// by its image distance to the nearest one.
// `pull` (a held body, its outline against the robot and the background): the outline
// the other way too, a pixel at the body's depths within the final gate of it that no point of
// the body covers (none within 1.5 times their spacing) pulls the nearest point towards it (a
// body whose far end projects onto hidden pixels and whose near end falls short of the frame's
// has nothing else pulling it along); from a start a centimetre off, the pixels uncovered there
// drew the points the wrong way (UncoveredPull::kAfterConverging: a flat hammer pushed 9 mm in the
// hand was not found). Not on the table: it broke the re-find of a tipped box
// (Session.AnObjectThatTippedIsFoundAgainOnTheTable: every start failed). The correction:
// T_C_X = correction · T_C_X(given).
TrackResult alignBodyToDepth(const DepthImage& depth, const std::vector<uint8_t>& hidden,
                             const CameraIntrinsics& K, const std::vector<SurfacePoint>& points_X,
                             const std::vector<Vec3>& occluders_X, const Iso3& T_C_X,
                             double sigma_m, const TrackingOptions& options,
                             UncoveredPull pull = UncoveredPull::kOff,
                             NoDepthPixels no_depth = NoDepthPixels::kOutside);

}  // namespace inhand
