#include "reconstruction/landmark_basis.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "core/log.h"
#include "core/mesh_renderer.h"
#include "core/statistics.h"

namespace headforge {
Eigen::Vector3d LandmarkBasis::Point(int i, const Eigen::VectorXd& alpha,
                                     const Eigen::VectorXd& beta) const {
  Eigen::Vector3d p = base.col(i);
  if (alpha.size() > 0) p += identity[i].leftCols(alpha.size()) * alpha;
  if (beta.size() > 0) p += expression[i].leftCols(beta.size()) * beta;
  return p;
}

Status BuildLandmarkBasis(const FaceModel& model, const std::vector<Eigen::Vector3d>& points,
                          int identity_modes, LandmarkBasis* basis) {
  if (points.empty()) return Status::InvalidArgument("landmark basis: no landmark points");
  if (identity_modes < 0) return Status::InvalidArgument("landmark basis: identity_modes must be >= 0");
  const Eigen::Matrix3Xf mean = model.Vertices(Eigen::VectorXf(), Eigen::VectorXf());
  const Eigen::Matrix3Xi& tris = model.triangles();
  int first = 0, last = model.num_triangles() - 1;
  if (const FaceModel::Region* face = model.FindRegion("face")) {
    first = face->first_triangle;
    last = face->last_triangle;
  }
  const int k = std::min(identity_modes, model.num_identity());
  const int e = model.num_expressions();
  LandmarkBasis out;
  out.num_identity = k;
  out.num_expressions = e;
  out.base.resize(3, int(points.size()));
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d& p = points[i];
    double best = std::numeric_limits<double>::infinity();
    int best_t = -1;
    Eigen::Vector3d best_bary;
    for (int t = first; t <= last; ++t) {
      const Eigen::Vector3d a = mean.col(tris(0, t)).cast<double>();
      const Eigen::Vector3d b = mean.col(tris(1, t)).cast<double>();
      const Eigen::Vector3d c = mean.col(tris(2, t)).cast<double>();
      // Cheap rejection: the triangle's bounding sphere is farther than the best.
      const Eigen::Vector3d centre = (a + b + c) / 3.0;
      const double radius = std::max({(a - centre).norm(), (b - centre).norm(), (c - centre).norm()});
      const double lower = std::max(0.0, (p - centre).norm() - radius);
      if (lower * lower >= best) continue;
      const Eigen::Vector3d bary = ClosestBarycentric(p, a, b, c);
      const double d = (p - (bary[0] * a + bary[1] * b + bary[2] * c)).squaredNorm();
      if (d < best) {
        best = d;
        best_t = t;
        best_bary = bary;
      }
    }
    if (best_t < 0) return Status::DataError("landmark basis: the model has no triangles to attach landmarks to");
    out.triangle.push_back(best_t);
    out.barycentric.push_back(best_bary);
    out.base.col(int(i)) = p;  // the surface point plus its offset: the embedded point itself
    Eigen::Matrix<double, 3, Eigen::Dynamic> id = Eigen::MatrixXd::Zero(3, k);
    Eigen::Matrix<double, 3, Eigen::Dynamic> ex = Eigen::MatrixXd::Zero(3, e);
    for (int corner = 0; corner < 3; ++corner) {
      const int v = tris(corner, best_t);
      const double w = best_bary[corner];
      if (k > 0) id += w * model.identity_basis().block(3 * v, 0, 3, k).cast<double>();
      if (e > 0) ex += w * model.expression_basis().block(3 * v, 0, 3, e).cast<double>();
    }
    out.identity.push_back(id);
    out.expression.push_back(ex);
  }
  *basis = std::move(out);
  return Status::Ok();
}

Status BuildLandmarkBasis(const FaceModel& model, const LandmarkEmbedding& embedding, int identity_modes,
                          LandmarkBasis* basis) {
  LandmarkBasis out;
  HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, embedding.points, identity_modes, &out));
  if (!embedding.identity.empty()) {
    if (int(embedding.identity.size()) != out.size())
      return Status::DataError("landmark basis: the embedding's identity columns do not match its points");
    const int k = std::min(out.num_identity, int(embedding.identity[0].cols()));
    for (int i = 0; i < out.size(); ++i) out.identity[i].leftCols(k) = embedding.identity[i].leftCols(k);
  }
  *basis = std::move(out);
  return Status::Ok();
}

LandmarkBasis ViewLandmarkBases::ForDirection(const Eigen::Vector3d& toward_camera) const {
  if (nodes.empty()) return any_view;
  LandmarkBasis out;
  double heaviest = 0;
  for (const auto& [node, weight] : embedding.NodeWeights(toward_camera)) {
    const LandmarkBasis& b = nodes[node];
    if (out.size() == 0) {
      out = b;
      out.base *= weight;
      for (int i = 0; i < out.size(); ++i) {
        out.identity[i] *= weight;
        out.expression[i] *= weight;
      }
    } else {
      out.base += weight * b.base;
      for (int i = 0; i < out.size(); ++i) {
        out.identity[i] += weight * b.identity[i];
        out.expression[i] += weight * b.expression[i];
      }
    }
    if (weight > heaviest) {  // the surface attachment of the nearest node
      heaviest = weight;
      out.triangle = b.triangle;
      out.barycentric = b.barycentric;
    }
  }
  return out;
}

Status BuildViewLandmarkBases(const FaceModel& model, const LandmarkEmbedding& embedding, int identity_modes,
                              ViewLandmarkBases* bases) {
  ViewLandmarkBases out;
  out.embedding = embedding;
  HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, embedding, identity_modes, &out.any_view));
  for (const auto& points : embedding.nodes) {
    out.nodes.emplace_back();
    HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, points, identity_modes, &out.nodes.back()));
  }
  *bases = std::move(out);
  return Status::Ok();
}

namespace {

// One landmark's ridge fit of r_s = c + D alpha_s (r: the point less the
// surface's motion). Returns the [K+1, 3] coefficients (c on the first row)
// and appends each subject's leave-one-out error (metres) to `loo`.
// lambda < 0: D = 0.
Eigen::MatrixXd FitOneLandmark(const Eigen::MatrixXd& a, const Eigen::MatrixXd& r, double lambda,
                               std::vector<double>* loo) {
  const int n = int(a.rows()), k1 = int(a.cols());
  Eigen::MatrixXd x = Eigen::MatrixXd::Zero(k1, 3);
  Eigen::VectorXd leverage(n);
  if (lambda < 0) {
    x.row(0) = r.colwise().mean();
    leverage.setConstant(1.0 / n);
  } else {
    Eigen::MatrixXd m = a.transpose() * a;
    m.diagonal().tail(k1 - 1).array() += lambda;
    const Eigen::LDLT<Eigen::MatrixXd> solve(m);
    x = solve.solve(a.transpose() * r);
    const Eigen::MatrixXd mia = solve.solve(a.transpose());  // [K+1, n]
    for (int i = 0; i < n; ++i) leverage[i] = a.row(i).dot(mia.col(i));
  }
  const Eigen::MatrixXd e = r - a * x;
  for (int i = 0; i < n; ++i) loo->push_back(e.row(i).norm() / std::max(1e-9, 1.0 - leverage[i]));
  return x;
}

}  // namespace

Status FitIdentityLandmarks(const LandmarkBasis& surface, const std::vector<SubjectLandmarks>& subjects, int modes,
                            int min_seen, LandmarkEmbedding* embedding, IdentityFitReport* report) {
  if (modes <= 0) return Status::InvalidArgument("identity landmarks: modes must be positive");
  if (surface.num_identity < modes)
    return Status::InvalidArgument("identity landmarks: the surface basis has fewer identity modes than asked for");
  const int num_points = surface.size();
  for (const SubjectLandmarks& s : subjects) {
    if (s.alpha.size() < modes || int(s.points.size()) != num_points || int(s.seen.size()) != num_points)
      return Status::InvalidArgument("identity landmarks: every subject needs " + std::to_string(modes) +
                                     " coefficients and " + std::to_string(num_points) + " points");
  }
  constexpr int kMinSubjects = 8;
  // Per landmark: the subjects that saw it, as design rows [1, alpha] and
  // points less the surface's motion.
  std::vector<Eigen::MatrixXd> designs(num_points), targets(num_points);
  for (int i = 0; i < num_points; ++i) {
    std::vector<int> used;
    for (int s = 0; s < int(subjects.size()); ++s)
      if (subjects[s].seen[i] >= min_seen) used.push_back(s);
    if (int(used.size()) < kMinSubjects) {
      return Status::DataError("identity landmarks: landmark " + std::to_string(i) + " was found on " +
                               std::to_string(used.size()) + " subjects; at least " + std::to_string(kMinSubjects) +
                               " are needed");
    }
    Eigen::MatrixXd a(used.size(), modes + 1), r(used.size(), 3);
    for (size_t u = 0; u < used.size(); ++u) {
      const SubjectLandmarks& s = subjects[used[u]];
      a(u, 0) = 1;
      a.row(u).tail(modes) = s.alpha.head(modes).transpose();
      r.row(u) = (s.points[i] - surface.identity[i].leftCols(modes) * s.alpha.head(modes)).transpose();
    }
    designs[i] = std::move(a);
    targets[i] = std::move(r);
  }
  // One lambda for every landmark, the one whose held-out predictions are best.
  IdentityFitReport out;
  out.subjects = int(subjects.size());
  std::vector<double> loo;
  for (int i = 0; i < num_points; ++i) FitOneLandmark(designs[i], targets[i], -1, &loo);
  out.loo_median_surface = Median(loo);
  double best = std::numeric_limits<double>::infinity();
  for (double lambda : {1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0}) {
    loo.clear();
    for (int i = 0; i < num_points; ++i) FitOneLandmark(designs[i], targets[i], lambda, &loo);
    const double m = Median(loo);
    if (m < best) {
      best = m;
      out.lambda = lambda;
    }
  }
  out.loo_median = best;
  LandmarkEmbedding result;
  for (int i = 0; i < num_points; ++i) {
    std::vector<double> unused;
    const Eigen::MatrixXd x = FitOneLandmark(designs[i], targets[i], out.lambda, &unused);
    result.points.push_back(x.row(0).transpose());
    result.identity.push_back(surface.identity[i].leftCols(modes) + x.bottomRows(modes).transpose());
  }
  *embedding = std::move(result);
  if (report) *report = out;
  return Status::Ok();
}

Status MeasureIdentityLandmarkEmbedding(const FaceModel& model, const FaceDetectorOptions& detector,
                                        const std::string& landmark_model, int threads, int num_subjects,
                                        LandmarkEmbedding* embedding, IdentityFitReport* report) {
  const int modes = std::min(20, model.num_identity());
  if (modes == 0) return Status::DataError("identity landmarks: the face model has no identity modes");
  if (num_subjects < 10) return Status::InvalidArgument("identity landmarks: measure at least 10 subjects");
  std::vector<SubjectLandmarks> subjects;
  for (int s = 0; s < num_subjects; ++s) {
    // Subject s: its own draw of identity, skin between fair and dark, and a
    // key light somewhere above and in front.
    std::mt19937_64 rng(1000 + uint64_t(s));
    std::normal_distribution<double> normal;
    std::uniform_real_distribution<double> uniform;
    SubjectLook look;
    look.alpha.resize(modes);
    for (int m = 0; m < modes; ++m) look.alpha[m] = normal(rng);
    const double t = uniform(rng);
    look.skin = (1 - t) * Eigen::Vector3d(0.88, 0.70, 0.60) + t * Eigen::Vector3d(0.42, 0.28, 0.20);
    look.light = Eigen::Vector3d(-0.6 + 1.2 * uniform(rng), 0.1 + 0.6 * uniform(rng), 0.9);
    look.ambient = 0.35 + 0.2 * uniform(rng);
    look.diffuse = 0.6 + 0.2 * uniform(rng);
    SubjectLandmarks subject;
    subject.alpha = look.alpha;
    HF_RETURN_IF_ERROR(
        MeasureSubjectLandmarks(model, detector, landmark_model, threads, look, &subject.points, &subject.seen));
    subjects.push_back(std::move(subject));
    HF_LOG(Info) << "embed-landmarks: subject " << s + 1 << " of " << num_subjects << " measured";
  }
  // The surface points the landmarks attach to: the subjects' average points.
  std::vector<Eigen::Vector3d> average(68, Eigen::Vector3d::Zero());
  const std::vector<int>& ibug = model.landmarks_ibug68();
  for (int i = 0; i < 68; ++i) {
    int n = 0;
    for (const SubjectLandmarks& s : subjects) {
      if (s.seen[i] == 0) continue;
      average[i] += s.points[i];
      ++n;
    }
    average[i] = n > 0 ? Eigen::Vector3d(average[i] / n) : Eigen::Vector3d(model.neutral().col(ibug[i]).cast<double>());
  }
  LandmarkBasis surface;
  HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, average, modes, &surface));
  constexpr int kMinSeen = 10;  // of 60 renders
  return FitIdentityLandmarks(surface, subjects, modes, kMinSeen, embedding, report);
}

}  // namespace headforge
