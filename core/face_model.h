// A morphable face model in the Basel layout ("statismo" HDF5): the MIT-licensed
// ICT-FaceKit model shipped in ../shared/data, or a user's BFM 2017/2019 file.
//
//   vertices = shape_mean + B_id diag(sqrt(var_id)) alpha
//            + expr_mean  + B_ex diag(sqrt(var_ex)) beta
//
// with alpha ~ N(0, I) (identity) and beta in [0, 1] (ICT blendshape weights;
// for BFM, expression PCA coefficients). Head frame: metres, +y up, the face
// looks toward +z. ICT extensions (UVs, iBUG-68 landmark vertices, regions,
// vertex masks) are optional: a plain BFM file loads without them.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "core/status.h"

namespace headforge {

class FaceModel {
 public:
  // [first vertex, last vertex, first triangle, last triangle], inclusive.
  struct Region {
    int first_vertex = 0, last_vertex = -1, first_triangle = 0, last_triangle = -1;
    bool ContainsTriangle(int t) const { return t >= first_triangle && t <= last_triangle; }
    bool ContainsVertex(int v) const { return v >= first_vertex && v <= last_vertex; }
  };

  static Status Load(const std::string& path, FaceModel* model);

  int num_vertices() const { return static_cast<int>(neutral_.cols()); }
  int num_triangles() const { return static_cast<int>(triangles_.cols()); }
  int num_identity() const { return static_cast<int>(identity_basis_.cols()); }
  int num_expressions() const { return static_cast<int>(expression_basis_.cols()); }

  // Vertices [3, N] in metres. `alpha` may hold fewer than num_identity()
  // coefficients (the rest are zero); `beta` likewise.
  Eigen::Matrix3Xf Vertices(const Eigen::VectorXf& alpha, const Eigen::VectorXf& beta) const;
  // The identity-only shape (no expression).
  Eigen::Matrix3Xf Identity(const Eigen::VectorXf& alpha) const;
  // Adds the expression offsets to an identity shape.
  void AddExpression(const Eigen::VectorXf& beta, Eigen::Matrix3Xf* vertices) const;

  // The bases behind Identity() and AddExpression(): [3N, K] and [3N, E],
  // columns already scaled by sqrt(variance); row 3v + d is vertex v, axis d.
  const Eigen::MatrixXf& identity_basis() const { return identity_basis_; }
  const Eigen::MatrixXf& expression_basis() const { return expression_basis_; }
  const Eigen::Matrix3Xf& neutral() const { return neutral_; }  // representer points [3, N]
  const Eigen::Matrix3Xi& triangles() const { return triangles_; }  // [3, T]
  const std::vector<std::string>& expression_names() const { return expression_names_; }
  // Index of a named expression, -1 if absent.
  int ExpressionIndex(const std::string& name) const;

  bool has_uv() const { return uv_coords_.cols() > 0; }
  const Eigen::Matrix2Xf& uv_coords() const { return uv_coords_; }       // [2, U]
  const Eigen::Matrix3Xi& uv_triangles() const { return uv_triangles_; }  // [3, T]
  const std::vector<int>& landmarks_ibug68() const { return landmarks_; }  // 68 vertex indices
  const std::vector<int>& rigid_landmarks() const { return rigid_landmarks_; }
  const std::vector<int>& rigid_vertices() const { return rigid_vertices_; }
  const std::vector<int>& fitting_vertices() const { return fitting_vertices_; }
  const std::map<std::string, Region>& regions() const { return regions_; }
  // nullptr if the model has no such region.
  const Region* FindRegion(const std::string& name) const;

  const std::string& path() const { return path_; }

 private:
  std::string path_;
  Eigen::Matrix3Xf neutral_;
  Eigen::Matrix3Xi triangles_;
  Eigen::VectorXf shape_mean_;           // [3N]
  Eigen::MatrixXf identity_basis_;       // [3N, K], columns scaled by sqrt(variance)
  Eigen::VectorXf expression_mean_;      // [3N]
  Eigen::MatrixXf expression_basis_;     // [3N, E], columns scaled by sqrt(variance)
  std::vector<std::string> expression_names_;
  Eigen::Matrix2Xf uv_coords_;
  Eigen::Matrix3Xi uv_triangles_;
  std::vector<int> landmarks_, rigid_landmarks_, rigid_vertices_, fitting_vertices_;
  std::map<std::string, Region> regions_;
};

}  // namespace headforge
