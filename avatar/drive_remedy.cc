#include "avatar/drive_remedy.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>

namespace headforge {

Status ParseDriveRemedy(const std::string& name, DriveRemedy* remedy) {
  for (DriveRemedy r : {DriveRemedy::kNone, DriveRemedy::kRelative, DriveRemedy::kRelativeSpan})
    if (name == DriveRemedyName(r)) {
      *remedy = r;
      return Status::Ok();
    }
  return Status::InvalidArgument("unknown drive remedy '" + name + "' (none, relative or relative+span)");
}

std::string DriveRemedyName(DriveRemedy remedy) {
  switch (remedy) {
    case DriveRemedy::kRelative: return "relative";
    case DriveRemedy::kRelativeSpan: return "relative+span";
    default: return "none";
  }
}

Status DriveRemedyOptions::Check() const {
  if (!(neutral_percentile >= 0 && neutral_percentile <= 100))
    return Status::InvalidArgument("drive remedy: the neutral percentile must be in [0, 100]");
  if (!(span_variance > 0 && span_variance <= 1))
    return Status::InvalidArgument("drive remedy: the span's variance fraction must be in (0, 1]");
  return Status::Ok();
}

Eigen::VectorXd PercentileWeights(const std::vector<Eigen::VectorXd>& frames, double percentile) {
  if (frames.empty()) return Eigen::VectorXd();
  const Eigen::Index n = frames.front().size();
  Eigen::VectorXd out(n);
  std::vector<double> values(frames.size());
  const double at = std::clamp(percentile, 0.0, 100.0) / 100 * double(frames.size() - 1);
  const size_t below = size_t(std::floor(at));
  const size_t above = std::min(below + 1, frames.size() - 1);
  for (Eigen::Index k = 0; k < n; ++k) {
    for (size_t f = 0; f < frames.size(); ++f) values[f] = frames[f][k];
    std::sort(values.begin(), values.end());
    out[k] = values[below] + (at - double(below)) * (values[above] - values[below]);
  }
  return out;
}

Eigen::VectorXd ExpressionSpan::Project(const Eigen::VectorXd& weights) const {
  return mean + basis * (basis.transpose() * (weights - mean));
}

ExpressionSpan FitExpressionSpan(const std::vector<Eigen::VectorXd>& frames, double variance) {
  ExpressionSpan span;
  if (frames.empty()) return span;
  const Eigen::Index n = frames.front().size();
  span.mean = Eigen::VectorXd::Zero(n);
  for (const Eigen::VectorXd& f : frames) span.mean += f;
  span.mean /= double(frames.size());
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(n, n);
  for (const Eigen::VectorXd& f : frames) covariance += (f - span.mean) * (f - span.mean).transpose();
  // Eigenvalues ascending: the largest last.
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(covariance);
  const Eigen::VectorXd values = eigen.eigenvalues().cwiseMax(0.0);
  const double total = values.sum();
  Eigen::Index kept = 0;
  for (double covered = 0; kept < n && total > 0 && covered < variance * total * (1 - 1e-12); ++kept)
    covered += values[n - 1 - kept];
  span.basis = eigen.eigenvectors().rightCols(kept).rowwise().reverse();
  return span;
}

Status ApplyDriveRemedy(DriveRemedy remedy, const DriveRemedyOptions& options,
                        const std::vector<Eigen::VectorXd>& avatar, std::vector<Eigen::VectorXd>* driver) {
  if (remedy == DriveRemedy::kNone) return Status::Ok();
  HF_RETURN_IF_ERROR(options.Check());
  if (avatar.empty() || driver->empty())
    return Status::InvalidArgument("drive remedy: needs the avatar's training expressions and the driver's take");
  const Eigen::Index n = avatar.front().size();
  for (const auto* set : {&avatar, static_cast<const std::vector<Eigen::VectorXd>*>(driver)})
    for (const Eigen::VectorXd& w : *set)
      if (w.size() != n)
        return Status::InvalidArgument("drive remedy: the avatar and the driver have different expression counts");
  const ExpressionSpan span = FitExpressionSpan(avatar, options.span_variance);
  const Eigen::VectorXd shift = span.mean - PercentileWeights(*driver, options.neutral_percentile);
  for (Eigen::VectorXd& w : *driver) {
    w = (w + shift).cwiseMax(0.0).cwiseMin(1.0);
    if (remedy == DriveRemedy::kRelativeSpan) w = span.Project(w).cwiseMax(0.0).cwiseMin(1.0);
  }
  return Status::Ok();
}

}  // namespace headforge
