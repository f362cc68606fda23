#include "reconstruction/landmark_basis.h"

#include <limits>

namespace headforge {
namespace {

// Barycentric coordinates of the point of triangle (a, b, c) closest to p
// (the region tests of Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                   const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {1 - v - w, v, w};
}

}  // namespace

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
  HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, embedding.points, identity_modes, &out.any_view));
  for (const auto& points : embedding.nodes) {
    out.nodes.emplace_back();
    HF_RETURN_IF_ERROR(BuildLandmarkBasis(model, points, identity_modes, &out.nodes.back()));
  }
  *bases = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
