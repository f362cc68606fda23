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
  HF_RETURN_IF_ERROR(CheckTriangleIndices(triangles, num_vertices, "vertex normals"));
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

}  // namespace headforge
