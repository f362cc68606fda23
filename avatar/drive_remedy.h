// Cross-identity driving's remedies: another person's take carries its own
// neutral and its own range of expression weights, which pose the avatar
// in expressions it never showed in training (the main cause of artefacts
// when one face drives another). Two remedies, applied in order:
// - relative: each of the driver's weights taken relative to the driver's
//   own neutral (a low percentile of that weight over its take) and
//   re-based on the avatar's training mean, clamped to [0, 1];
// - span: then projected onto the affine span of the avatar's training
//   expressions (their mean plus the principal components that cover a
//   fraction of their variance), clamped to [0, 1] again.
// Weights are plain vectors (one entry per expression); torch-free.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/status.h"

namespace headforge {

enum class DriveRemedy {
  kNone,           // the driver's weights as tracked
  kRelative,       // driver - driver's neutral + avatar's training mean
  kRelativeSpan,   // relative, then onto the span of the avatar's training expressions
};

// "none", "relative", "relative+span".
Status ParseDriveRemedy(const std::string& name, DriveRemedy* remedy);
std::string DriveRemedyName(DriveRemedy remedy);

struct DriveRemedyOptions {
  // The driver's neutral, per weight: this percentile (0-100) of the weight
  // over the driver's take. A weight rests at its neutral and moves away
  // from it in one direction (weights are >= 0), so a low percentile finds
  // the rest whether the weight is used often (jawOpen in speech, whose
  // median is an open mouth) or rarely, and a few low tracker outliers do
  // not set it as the minimum would.
  double neutral_percentile = 10;
  // The span: principal components of the avatar's training expressions
  // covering this fraction of their variance.
  double span_variance = 0.99;
  Status Check() const;
};

// Per weight, `percentile` (0-100, linear between order statistics) over the frames.
Eigen::VectorXd PercentileWeights(const std::vector<Eigen::VectorXd>& frames, double percentile);

// The affine span of a set of weight vectors: their mean and an orthonormal
// basis [E, K] of their principal components covering `variance` of the total.
struct ExpressionSpan {
  Eigen::VectorXd mean;
  Eigen::MatrixXd basis;
  // The least-squares nearest point of the span (not clamped).
  Eigen::VectorXd Project(const Eigen::VectorXd& weights) const;
};
ExpressionSpan FitExpressionSpan(const std::vector<Eigen::VectorXd>& frames, double variance);

// The driver's take (`driver`, one vector per frame, its whole take) with the
// remedy applied, in the same order, against the avatar's training frames'
// weights (`avatar`). InvalidArgument when sizes disagree or either is empty.
Status ApplyDriveRemedy(DriveRemedy remedy, const DriveRemedyOptions& options,
                        const std::vector<Eigen::VectorXd>& avatar, std::vector<Eigen::VectorXd>* driver);

}  // namespace headforge
