#include "calibration/similarity.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <random>

namespace headforge {

Sim3 Sim3::Inverse() const {
  Sim3 inv;
  inv.scale = 1.0 / scale;
  inv.rotation = rotation.transpose();
  inv.translation = -inv.scale * (inv.rotation * translation);
  return inv;
}

Eigen::Matrix4d Sim3::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = scale * rotation;
  m.topRightCorner<3, 1>() = translation;
  return m;
}

const char* SimilarityQualityName(SimilarityQuality q) {
  switch (q) {
    case SimilarityQuality::kGood: return "good";
    case SimilarityQuality::kPlanar: return "planar";
    case SimilarityQuality::kReflection: return "reflection";
    case SimilarityQuality::kDegenerate: return "degenerate";
  }
  return "degenerate";
}

namespace {

// Centroid and RMS distance from it.
void Normalisation(const Eigen::Matrix3Xd& p, Eigen::Vector3d* centre, double* spread) {
  *centre = p.rowwise().mean();
  *spread = std::sqrt((p.colwise() - *centre).squaredNorm() / std::max<Eigen::Index>(1, p.cols()));
}

}  // namespace

SimilarityResult EstimateSimilarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& tgt) {
  SimilarityResult r;
  const Eigen::Index n = src.cols();
  if (n != tgt.cols()) {
    r.message = "source and target differ in size";
    return r;
  }
  if (n < 3) {
    r.message = "need at least 3 point pairs, got " + std::to_string(n);
    return r;
  }
  if (!src.allFinite() || !tgt.allFinite()) {
    r.message = "non-finite coordinates";
    return r;
  }
  Eigen::Vector3d cs, ct;
  double ss, st;
  Normalisation(src, &cs, &ss);
  Normalisation(tgt, &ct, &st);
  if (!(ss > 0) || !(st > 0)) {
    r.message = "all points coincide";
    return r;
  }
  const Eigen::Matrix3Xd a = (src.colwise() - cs) / ss;  // unit RMS spread
  const Eigen::Matrix3Xd b = (tgt.colwise() - ct) / st;
  // Shape of the source: its singular values tell collinear and coplanar sets.
  const Eigen::JacobiSVD<Eigen::Matrix3Xd> shape(a, Eigen::ComputeThinU);
  const Eigen::Vector3d sv = shape.singularValues() / shape.singularValues()[0];
  constexpr double kCollinear = 1e-6, kPlanar = 1e-3;
  if (sv[1] < kCollinear) {
    r.message = "points are collinear (or duplicates): rotation about their line is undetermined";
    return r;
  }
  const Eigen::Matrix3d sigma = b * a.transpose() / static_cast<double>(n);
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d& u = svd.matrixU();
  const Eigen::Matrix3d& v = svd.matrixV();
  Eigen::Vector3d d(1, 1, 1);
  const bool reflected = (u * v.transpose()).determinant() < 0;
  if (reflected) d[2] = -1;
  // With coplanar points the smallest singular value is ~0 and its sign is
  // arbitrary: Umeyama's rule then chooses the proper rotation.
  const Eigen::Matrix3d rotation = u * d.asDiagonal() * v.transpose();
  const double variance_a = a.squaredNorm() / static_cast<double>(n);  // = 1 by construction
  const double scale_n = svd.singularValues().dot(d) / variance_a;
  if (!(scale_n > 0) || !std::isfinite(scale_n)) {
    r.message = "no positive scale fits (points in no consistent correspondence)";
    return r;
  }
  // Undo the normalisation: x_t = st * (s_n R (x_s - cs) / ss) + ct.
  r.tgt_from_src.rotation = rotation;
  r.tgt_from_src.scale = scale_n * st / ss;
  r.tgt_from_src.translation = ct - r.tgt_from_src.scale * (rotation * cs);
  double sum = 0;
  for (Eigen::Index i = 0; i < n; ++i) sum += (tgt.col(i) - r.tgt_from_src * src.col(i)).squaredNorm();
  r.rms = std::sqrt(sum / static_cast<double>(n));
  r.ok = true;
  r.inliers.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) r.inliers[i] = static_cast<int>(i);
  // A planar configuration cannot tell a reflection from a rotation: flag only
  // genuine reflections (the flipped direction is one the points span).
  if (reflected && sv[2] >= kPlanar) {
    r.quality = SimilarityQuality::kReflection;
    r.message = "the point sets are mirror images; the best proper rotation was returned";
  } else if (sv[2] < kPlanar) {
    r.quality = SimilarityQuality::kPlanar;
    r.message = "source points are nearly coplanar";
  } else {
    r.quality = SimilarityQuality::kGood;
  }
  return r;
}

SimilarityResult EstimateSimilarityRansac(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& tgt,
                                          const RansacOptions& options) {
  const int n = static_cast<int>(src.cols());
  SimilarityResult best;
  if (n < 3 || n != tgt.cols()) return EstimateSimilarity(src, tgt);
  std::mt19937_64 rng(options.seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  const double threshold2 = options.inlier_threshold * options.inlier_threshold;
  std::vector<int> best_inliers;
  int iterations = options.max_iterations;
  for (int it = 0; it < iterations; ++it) {
    int i = pick(rng), j = pick(rng), k = pick(rng);
    if (i == j || j == k || i == k) continue;
    Eigen::Matrix3Xd s(3, 3), t(3, 3);
    s << src.col(i), src.col(j), src.col(k);
    t << tgt.col(i), tgt.col(j), tgt.col(k);
    const SimilarityResult m = EstimateSimilarity(s, t);
    if (!m.ok) continue;
    std::vector<int> inliers;
    for (int p = 0; p < n; ++p)
      if ((tgt.col(p) - m.tgt_from_src * src.col(p)).squaredNorm() < threshold2) inliers.push_back(p);
    if (inliers.size() > best_inliers.size()) {
      best_inliers = inliers;
      // Adaptive stopping: enough iterations to draw one all-inlier sample.
      const double w = static_cast<double>(inliers.size()) / n;
      const double denom = std::log(std::max(1e-12, 1.0 - w * w * w));
      if (denom < 0)
        iterations = std::min(options.max_iterations,
                              static_cast<int>(std::ceil(std::log(1.0 - options.confidence) / denom)) + 1);
    }
  }
  if (static_cast<int>(best_inliers.size()) < std::max(3, options.min_inliers)) {
    best.message = "no consensus: fewer than " + std::to_string(std::max(3, options.min_inliers)) +
                   " pairs agree within " + std::to_string(options.inlier_threshold);
    return best;
  }
  // Refit on the inliers, then once more on the inliers of the refit.
  for (int round = 0; round < 2; ++round) {
    Eigen::Matrix3Xd s(3, best_inliers.size()), t(3, best_inliers.size());
    for (size_t q = 0; q < best_inliers.size(); ++q) {
      s.col(q) = src.col(best_inliers[q]);
      t.col(q) = tgt.col(best_inliers[q]);
    }
    SimilarityResult fit = EstimateSimilarity(s, t);
    if (!fit.ok) return fit;
    std::vector<int> inliers;
    for (int p = 0; p < n; ++p)
      if ((tgt.col(p) - fit.tgt_from_src * src.col(p)).squaredNorm() < threshold2) inliers.push_back(p);
    fit.inliers = best_inliers;
    best = fit;
    if (inliers == best_inliers || static_cast<int>(inliers.size()) < 3) break;
    best_inliers = inliers;
  }
  return best;
}

}  // namespace headforge
