// mesh_utils.h's surface samples and the triangle check: Eigen alone (no
// OpenMesh), so that a LibTorch-only build samples the avatar's starting
// Gaussians too.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "reconstruction/mesh_utils.h"

namespace headforge {

Status CheckTriangleIndices(const Eigen::Matrix3Xi& triangles, int num_vertices, const std::string& what) {
  if (triangles.cols() == 0) return Status::Ok();
  if (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices)
    return Status::InvalidArgument(what + ": a triangle names a vertex outside [0, " +
                                   std::to_string(num_vertices) + ")");
  return Status::Ok();
}

Status SampleSurface(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles, int count,
                     uint64_t seed, SurfaceSamples* samples) {
  if (count < 0) return Status::InvalidArgument("surface sampling: negative sample count");
  HF_RETURN_IF_ERROR(CheckTriangleIndices(triangles, static_cast<int>(vertices.cols()), "surface sampling"));
  const Eigen::Index num_triangles = triangles.cols();
  std::vector<double> cumulative(num_triangles);
  double total = 0;
  for (Eigen::Index t = 0; t < num_triangles; ++t) {
    const Eigen::Vector3d a = vertices.col(triangles(0, t)).cast<double>();
    const Eigen::Vector3d b = vertices.col(triangles(1, t)).cast<double>();
    const Eigen::Vector3d c = vertices.col(triangles(2, t)).cast<double>();
    const double area = 0.5 * (b - a).cross(c - a).norm();
    if (!std::isfinite(area))
      return Status::DataError("surface sampling: triangle " + std::to_string(t) + " has a non-finite vertex");
    total += area;
    cumulative[t] = total;
  }
  if (!(total > 0)) return Status::DataError("surface sampling: the mesh has no area");

  // The first triangle whose cumulative area reaches the total: the last one
  // with a positive area, for a draw that rounds up to the total.
  const Eigen::Index last =
      std::lower_bound(cumulative.begin(), cumulative.end(), total) - cumulative.begin();
  // 53 random bits -> [0, 1), the same on every standard library (the
  // standard distributions are not specified bit for bit).
  std::mt19937_64 engine(seed);
  const double kUnit = std::ldexp(1.0, -53);
  auto uniform = [&]() { return static_cast<double>(engine() >> 11) * kUnit; };

  samples->triangles.resize(count);
  samples->barycentric.resize(3, count);
  for (int s = 0; s < count; ++s) {
    // upper_bound skips zero-area triangles: their cumulative value equals
    // the one before them, which is already greater than the draw.
    const double r = uniform() * total;
    Eigen::Index t = std::upper_bound(cumulative.begin(), cumulative.end(), r) - cumulative.begin();
    if (t > last) t = last;
    const double root = std::sqrt(uniform());
    const double r2 = uniform();
    samples->triangles[s] = static_cast<int>(t);
    samples->barycentric.col(s) = Eigen::Vector3d(1.0 - root, root * (1.0 - r2), root * r2).cast<float>();
  }
  return Status::Ok();
}

Eigen::Matrix3Xf SamplePositions(const SurfaceSamples& samples, const Eigen::Matrix3Xf& vertices,
                                 const Eigen::Matrix3Xi& triangles) {
  HF_CHECK(samples.barycentric.cols() == samples.triangles.size());
  Eigen::Matrix3Xf positions(3, samples.size());
  for (int s = 0; s < samples.size(); ++s) {
    const int t = samples.triangles[s];
    HF_CHECK(t >= 0 && t < triangles.cols());
    const Eigen::Vector3f w = samples.barycentric.col(s);
    positions.col(s) = w[0] * vertices.col(triangles(0, t)) + w[1] * vertices.col(triangles(1, t)) +
                       w[2] * vertices.col(triangles(2, t));
  }
  return positions;
}

Status SampleUVs(const SurfaceSamples& samples, const Eigen::Matrix2Xf& uv_coords,
                 const Eigen::Matrix3Xi& uv_triangles, Eigen::Matrix2Xf* uvs) {
  if (uv_coords.cols() == 0 || uv_triangles.cols() == 0)
    return Status::InvalidArgument("sample UVs: the mesh has no texture coordinates");
  if (samples.barycentric.cols() != samples.triangles.size())
    return Status::InvalidArgument("sample UVs: triangle and barycentric counts differ");
  HF_RETURN_IF_ERROR(CheckTriangleIndices(uv_triangles, static_cast<int>(uv_coords.cols()), "sample UVs"));
  uvs->resize(2, samples.size());
  for (int s = 0; s < samples.size(); ++s) {
    const int t = samples.triangles[s];
    if (t < 0 || t >= uv_triangles.cols())
      return Status::InvalidArgument("sample UVs: sample " + std::to_string(s) + " lies on triangle " +
                                     std::to_string(t) + ", beyond the " +
                                     std::to_string(uv_triangles.cols()) + " UV triangles");
    const Eigen::Vector3f w = samples.barycentric.col(s);
    uvs->col(s) = w[0] * uv_coords.col(uv_triangles(0, t)) + w[1] * uv_coords.col(uv_triangles(1, t)) +
                  w[2] * uv_coords.col(uv_triangles(2, t));
  }
  return Status::Ok();
}

}  // namespace headforge
