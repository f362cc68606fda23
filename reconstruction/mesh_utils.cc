// OpenMesh's property vectors default-construct points whose coordinates are
// left uninitialised (then overwritten); GCC 12 flags the copy inside the
// standard library headers, so the warning is silenced for those headers only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <vector>

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>
#pragma GCC diagnostic pop

#include "reconstruction/mesh_utils.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace headforge {

struct HalfEdgeNormals::Mesh {
  OpenMesh::TriMesh_ArrayKernelT<> connectivity;
  // OpenMesh vertex index -> our vertex index; beyond num_vertices_ come the
  // duplicated corners of the triangles OpenMesh refused.
  std::vector<int> source;
};

HalfEdgeNormals::HalfEdgeNormals() = default;
HalfEdgeNormals::~HalfEdgeNormals() = default;
HalfEdgeNormals::HalfEdgeNormals(HalfEdgeNormals&&) noexcept = default;
HalfEdgeNormals& HalfEdgeNormals::operator=(HalfEdgeNormals&&) noexcept = default;

namespace {

Status CheckTriangles(const Eigen::Matrix3Xi& triangles, int num_vertices, const std::string& what) {
  if (triangles.cols() == 0) return Status::Ok();
  if (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices)
    return Status::InvalidArgument(what + ": a triangle names a vertex outside [0, " +
                                   std::to_string(num_vertices) + ")");
  return Status::Ok();
}

// Restores OpenMesh's error stream when it goes out of scope.
class QuietOpenMesh {
 public:
  QuietOpenMesh() : was_enabled_(omerr().is_enabled()) { omerr().disable(); }
  ~QuietOpenMesh() {
    if (was_enabled_) omerr().enable();
  }

 private:
  bool was_enabled_;
};

}  // namespace

Status HalfEdgeNormals::Init(int num_vertices, const Eigen::Matrix3Xi& triangles) {
  mesh_.reset();
  num_vertices_ = 0;
  if (num_vertices < 0) return Status::InvalidArgument("vertex normals: negative vertex count");
  HF_RETURN_IF_ERROR(CheckTriangles(triangles, num_vertices, "vertex normals"));
  auto mesh = std::make_unique<Mesh>();
  auto& om = mesh->connectivity;
  using Point = OpenMesh::TriMesh_ArrayKernelT<>::Point;
  om.reserve(num_vertices, 3 * triangles.cols(), triangles.cols());
  std::vector<OpenMesh::VertexHandle> handles(num_vertices);
  for (int i = 0; i < num_vertices; ++i) {
    handles[i] = om.add_vertex(Point(0, 0, 0));
    mesh->source.push_back(i);
  }
  // OpenMesh logs each face it refuses; those are expected and handled here.
  const QuietOpenMesh quiet;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    const int a = triangles(0, t), b = triangles(1, t), c = triangles(2, t);
    if (a == b || b == c || a == c) continue;
    if (om.add_face(handles[a], handles[b], handles[c]).is_valid()) continue;
    // A non-manifold edge or vertex: the triangle goes on its own corners,
    // which Compute() folds back onto the shared vertices.
    OpenMesh::VertexHandle corners[3];
    for (int k = 0; k < 3; ++k) {
      corners[k] = om.add_vertex(Point(0, 0, 0));
      mesh->source.push_back(triangles(k, t));
    }
    om.add_face(corners[0], corners[1], corners[2]);
  }
  mesh_ = std::move(mesh);
  num_vertices_ = num_vertices;
  return Status::Ok();
}

Status HalfEdgeNormals::Compute(const Eigen::Matrix3Xf& vertices, Eigen::Matrix3Xf* normals) {
  if (!mesh_) return Status::InvalidArgument("vertex normals: Init() has not succeeded");
  if (vertices.cols() != num_vertices_)
    return Status::InvalidArgument("vertex normals: " + std::to_string(vertices.cols()) +
                                   " vertices given, the mesh has " + std::to_string(num_vertices_));
  auto& om = mesh_->connectivity;
  using Point = OpenMesh::TriMesh_ArrayKernelT<>::Point;
  using Normal = OpenMesh::TriMesh_ArrayKernelT<>::Normal;
  for (size_t i = 0; i < mesh_->source.size(); ++i) {
    const auto p = vertices.col(mesh_->source[i]);
    om.set_point(OpenMesh::VertexHandle(static_cast<int>(i)), Point(p.x(), p.y(), p.z()));
  }
  // Each sector normal is the cross product of the corner's two edges: the
  // face normal scaled by twice the face area, hence the area weighting.
  Eigen::Matrix3Xd sum = Eigen::Matrix3Xd::Zero(3, num_vertices_);
  for (const auto vh : om.vertices()) {
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (const auto in : om.vih_range(vh)) {
      if (om.is_boundary(in)) continue;
      Normal sector;
      om.calc_sector_normal(in, sector);
      n += Eigen::Vector3d(sector[0], sector[1], sector[2]);
    }
    sum.col(mesh_->source[vh.idx()]) += n;
  }
  normals->resize(3, num_vertices_);
  for (int i = 0; i < num_vertices_; ++i) {
    const double length = sum.col(i).norm();
    normals->col(i) = length > 0 ? (sum.col(i) / length).cast<float>().eval() : Eigen::Vector3f::Zero();
  }
  return Status::Ok();
}

Status ComputeVertexNormals(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles,
                            Eigen::Matrix3Xf* normals) {
  HalfEdgeNormals computer;
  HF_RETURN_IF_ERROR(computer.Init(static_cast<int>(vertices.cols()), triangles));
  return computer.Compute(vertices, normals);
}

Status SampleSurface(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles, int count,
                     uint64_t seed, SurfaceSamples* samples) {
  if (count < 0) return Status::InvalidArgument("surface sampling: negative sample count");
  HF_RETURN_IF_ERROR(CheckTriangles(triangles, static_cast<int>(vertices.cols()), "surface sampling"));
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
  HF_RETURN_IF_ERROR(CheckTriangles(uv_triangles, static_cast<int>(uv_coords.cols()), "sample UVs"));
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
