// The face model's surface fitted to a reconstruction's 3D points on the face:
// refines the head frame's yaw, which landmarks see worst. A landmark detector
// reads a turned, unshaded head as nearly frontal, so a rotation from
// landmarks alone can sit degrees off in yaw; the points that structure from
// motion triangulates on the skin do not depend on the detector. The face's
// shape is fitted with them (the face model's identity modes under a Gaussian
// prior), because a subject's face is not the mean face.
//
// Only yaw is refined, with the translation. The identity modes imitate a
// change of pitch (about 90% on the face), roll (60%) and scale (over 99%)
// closely enough that the surface cannot tell such a turned or larger head from
// another face (docs/tracking.md); yaw they imitate least (25%). Pitch, roll
// and scale stay as given. (Freeing roll as well turned four orbits' head
// frames by 0.1-3 deg either way, depending on the prior.)
#pragma once

#include <vector>

#include <Eigen/Core>

#include "calibration/similarity.h"
#include "core/face_model.h"
#include "core/status.h"

namespace headforge {

struct SurfaceFitOptions {
  int identity_modes = 20;
  // The identity's unit Gaussian prior, as the squared point-to-surface
  // distance (mm^2) that one standard deviation of a coefficient costs.
  double identity_prior_mm2 = 3.0;
  double robust_mm = 1.0;  // Huber scale of the point-to-surface distances
  // Points pair with the nearest vertex of the model's fitting region when
  // within this distance: start_mm at first, shrinking by 15% a round to end_mm.
  double start_mm = 12.0, end_mm = 3.0;
  int rounds = 30;
  // Fewer points on the face: no fit. With some 30 points, 20 identity modes
  // and the turn trade off freely (3-9 deg off on a small orbit).
  int min_points = 100;
  double max_turn_deg = 10.0;  // a larger turn is refused: the pairing went astray
};

struct SurfaceFitResult {
  int points = 0;                 // points paired with the surface in the last round
  double median_mm = 0;           // their median point-to-surface distance
  double yaw_deg = 0;             // how far the head frame turned about its vertical axis
  Eigen::VectorXd identity;       // the fitted identity coefficients (standard deviations)
};

// Refines `head_from_world` (its rotation about the head frame's vertical axis
// and its translation) so that the face model's surface, with a fitted
// identity, passes through the `world_points` that lie on the face. The
// starting alignment must be within some degrees and millimetres (the pairing
// starts at start_mm). Fails, leaving `head_from_world` as it was, when the
// model has no fitting region, too few points lie on the face, or the turn
// exceeds max_turn_deg.
Status FitFaceSurface(const FaceModel& model, const std::vector<Eigen::Vector3d>& world_points,
                      const SurfaceFitOptions& options, Sim3* head_from_world, SurfaceFitResult* result);

}  // namespace headforge
