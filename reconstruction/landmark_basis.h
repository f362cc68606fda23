// The 68 detector landmarks as linear functions of the face model's identity
// and expression coefficients, which is all tracking needs of the model:
//   X_i(alpha, beta) = base_i + identity_i alpha + expression_i beta   (metres)
// Each landmark is attached to the closest point of the model's surface
// (barycentric coordinates in one triangle, plus the small offset from the
// surface the detector's embedding has), so it moves with the mesh.
#pragma once

#include <Eigen/Core>

#include <vector>

#include "calibration/landmark_embedding.h"
#include "core/face_model.h"
#include "core/status.h"

namespace headforge {

struct LandmarkBasis {
  int num_identity = 0, num_expressions = 0;
  Eigen::Matrix3Xd base;  // [3, 68] head frame at alpha = 0, beta = 0
  // Per landmark: [3, K] and [3, E] blocks.
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> identity, expression;
  // Where each landmark sits: triangle and barycentric coordinates.
  std::vector<int> triangle;
  std::vector<Eigen::Vector3d> barycentric;

  int size() const { return static_cast<int>(base.cols()); }
  Eigen::Vector3d Point(int i, const Eigen::VectorXd& alpha, const Eigen::VectorXd& beta) const;
};

// `points` are the detector's 68 landmarks on the mean face (an embedding, or
// the model's landmark vertices); `identity_modes` how many identity modes to
// keep (at most the model's). Landmarks attach to the closest surface point
// among the triangles of the model's "face" region (the whole mesh when the
// model has no regions).
Status BuildLandmarkBasis(const FaceModel& model, const std::vector<Eigen::Vector3d>& points,
                          int identity_modes, LandmarkBasis* basis);

// The basis of an embedding's points over every direction, with its identity
// columns in place of the surface's when it has them (modes beyond them keep
// the surface's).
Status BuildLandmarkBasis(const FaceModel& model, const LandmarkEmbedding& embedding, int identity_modes,
                          LandmarkBasis* basis);

// The bases of a view-dependent embedding: one per grid node, blended for a
// camera's direction. The blend of linear functions is the linear function of
// the blended points, so a view sees the embedding's points for its direction.
struct ViewLandmarkBases {
  LandmarkBasis any_view;            // from the embedding's points over every direction
  LandmarkEmbedding embedding;       // its grid
  std::vector<LandmarkBasis> nodes;  // empty: the embedding is not view-dependent

  // The basis for a camera whose centre lies in direction `toward_camera`
  // from the head's origin (head frame).
  LandmarkBasis ForDirection(const Eigen::Vector3d& toward_camera) const;
};
// An embedding's identity columns, when it has them, apply to `any_view`
// (the grid's nodes ride on the surface).
Status BuildViewLandmarkBases(const FaceModel& model, const LandmarkEmbedding& embedding, int identity_modes,
                              ViewLandmarkBases* bases);

// How the detector's points move with the subject's identity. A detector
// places a point by the face's look, not by a vertex, so on a wider jaw or a
// longer nose its points slide over the surface rather than ride on it. From
// each subject's measured points, per landmark
//   P_s = c + (S + D) alpha_s,
// where S is how the surface point the landmark is attached to moves with
// identity and D what the detector adds, fitted by ridge regression that pulls
// D toward zero with a weight lambda chosen by leave-one-out error.
struct SubjectLandmarks {
  Eigen::VectorXd alpha;                // identity coefficients (standard deviations)
  std::vector<Eigen::Vector3d> points;  // 68 head-frame points
  std::vector<int> seen;                // renders each point was found on; below min_seen it is left out
};
struct IdentityFitReport {
  double lambda = 0;
  // Leave-one-out prediction error of a subject's points (metres; median over
  // every point of every subject): with the fitted D, and with D = 0.
  double loo_median = 0, loo_median_surface = 0;
  int subjects = 0;
};
// `surface` is the basis built from the subjects' average points (its
// identity blocks give S; at least `modes` columns). The result holds the
// points c and the identity blocks S + D with `modes` columns.
Status FitIdentityLandmarks(const LandmarkBasis& surface, const std::vector<SubjectLandmarks>& subjects, int modes,
                            int min_seen, LandmarkEmbedding* embedding, IdentityFitReport* report);

// Renders `subjects` random subjects (identity coefficients drawn from the
// model's prior over 20 modes, varied skin and light), measures each one's
// points (MeasureSubjectLandmarks) and fits FitIdentityLandmarks.
Status MeasureIdentityLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                        const std::string& landmark_model, int threads, int subjects,
                                        LandmarkEmbedding* embedding, IdentityFitReport* report);

}  // namespace headforge
