// The face model's surface fitted to 3D points on the face: the whole head
// frame (rotation, translation and scale) together with the subject's identity.
//
// Landmarks place the head frame a degree or more off and take its scale from
// the mean face, while faces differ in size by some 5% (one standard
// deviation of the model's identity prior). Thousands of points on the skin,
// triangulated from the frames (face_points.h), pin both: the identity modes
// alone imitate a change of pitch or scale closely, but not under their prior
// with this many points (docs/calibration.md). The points are paired with the
// closest point of the model's fitting region (its triangles), and the
// distances are measured in the points' own units: measured in the head
// frame, shrinking the head and the points together would pay and bias the
// scale low by a few percent.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "calibration/similarity.h"
#include "core/face_model.h"
#include "core/status.h"

namespace headforge {

struct SurfaceFitOptions {
  int identity_modes = 20;
  // The points' noise (mm): the Huber scale of the point-to-surface
  // distances, and what one standard deviation of an identity coefficient
  // (unit Gaussian prior) weighs against.
  double noise_mm = 1.0;
  // Points pair with the closest point of the fitting region when within
  // this distance: start_mm at first, shrinking by 15% a round to end_mm.
  double start_mm = 30.0, end_mm = 3.0;
  int rounds = 30;
  // Fewer points on the face: no fit (with a few hundred, the identity modes
  // and the head frame trade off by degrees and percent).
  int min_points = 500;
  // A larger change from the start is refused: the pairing went astray.
  double max_turn_deg = 15.0;
  double max_scale_change = 0.15;
  // Keep the head frame's scale (cameras whose unit is known: a rig file in
  // metres); the identity still fits the face's size.
  bool hold_scale = false;
};

struct SurfaceFitResult {
  int points = 0;        // points paired with the surface in the last round
  double median_mm = 0;  // their median point-to-surface distance
  double turn_deg = 0;   // how far the head frame turned
  Eigen::Vector3d turn_xyz_deg =
      Eigen::Vector3d::Zero();  // that turn about the head frame's x (pitch), y (yaw), z (roll)
  double scale_change = 0;      // fitted scale / starting scale - 1
  Eigen::VectorXd identity;     // the fitted identity coefficients (standard deviations)
};

// Refines `head_from_world` so that the face model's surface, with a fitted
// identity, passes through the `world_points` that lie on the face. The start
// must be within some degrees, millimetres and percent (the pairing starts at
// start_mm). Fails, leaving `head_from_world` as it was, when the model has no
// fitting region, too few points lie on the face, or the change exceeds
// max_turn_deg or max_scale_change.
Status FitFaceSurface(const FaceModel& model, const std::vector<Eigen::Vector3d>& world_points,
                      const SurfaceFitOptions& options, Sim3* head_from_world, SurfaceFitResult* result);

// The same over groups of points, each seen with the head at its own pose (a
// rig's instants): one identity and one scale (the starting frames must share
// it), a rotation and translation per group. More of the face's surface pins
// the identity, and with it each group's frame. The result's turn and scale
// change, and the limits, are those of the first group's frame.
Status FitFaceSurfaceGroups(const FaceModel& model, const std::vector<std::vector<Eigen::Vector3d>>& groups,
                            const SurfaceFitOptions& options, std::vector<Sim3>* head_from_world,
                            SurfaceFitResult* result);

}  // namespace headforge
