// Mesh utilities on the face model's arrays: vertex normals and random surface
// samples that stay attached to the mesh while it deforms.
//
// Shapes follow core/face_model.h: vertices [3, N] in metres (one column per
// vertex), triangles [3, T] of vertex indices, counter-clockwise seen from
// outside, so the right-hand normal of (v0, v1, v2) points out of the head.
// Per-corner UVs: coordinates [2, U] and UV triangles [3, T], where column t
// of the UV triangles holds the UV index of each corner of triangle t.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>

#include "core/status.h"

namespace headforge {

// InvalidArgument naming `what` when a triangle names a vertex outside [0,
// num_vertices).
Status CheckTriangleIndices(const Eigen::Matrix3Xi& triangles, int num_vertices, const std::string& what);

// Area-weighted unit vertex normals, computed with OpenMesh: each triangle
// adds its (unnormalised) cross product, i.e. its normal times twice its area,
// to its three corners, and the sum is normalised. A vertex that no triangle
// uses, or whose contributions cancel, gets the zero vector. Triangles with a
// repeated vertex are skipped (they have no area); triangles that OpenMesh
// cannot join to its half-edge structure (non-manifold edges or vertices) are
// kept on duplicated corners, so they still contribute.
//
// Builds the half-edge structure once; Compute() then only moves the points,
// which suits a mesh whose vertices change every frame (tracking).
class HalfEdgeNormals {
 public:
  HalfEdgeNormals();
  ~HalfEdgeNormals();
  HalfEdgeNormals(HalfEdgeNormals&&) noexcept;
  HalfEdgeNormals& operator=(HalfEdgeNormals&&) noexcept;

  // InvalidArgument when a triangle names a vertex outside [0, num_vertices).
  Status Init(int num_vertices, const Eigen::Matrix3Xi& triangles);

  // vertices [3, N] with N = num_vertices of Init() -> normals [3, N].
  // InvalidArgument if Init() did not succeed or N differs.
  Status Compute(const Eigen::Matrix3Xf& vertices, Eigen::Matrix3Xf* normals);

  int num_vertices() const { return num_vertices_; }

 private:
  struct Mesh;
  std::unique_ptr<Mesh> mesh_;
  int num_vertices_ = 0;
};

// One-shot form of HalfEdgeNormals: vertices [3, N], triangles [3, T] -> [3, N].
Status ComputeVertexNormals(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles,
                            Eigen::Matrix3Xf* normals);

// Points on a mesh's surface in barycentric form, so they can be re-evaluated
// on any deformation of the same topology (another identity, an expression).
struct SurfaceSamples {
  Eigen::VectorXi triangles;     // [S] triangle index of each sample
  Eigen::Matrix3Xf barycentric;  // [3, S] weights of the triangle's corners 0, 1, 2; >= 0, sum 1

  int size() const { return static_cast<int>(triangles.size()); }
};

// `count` points drawn uniformly over the surface area of the mesh: a triangle
// with probability proportional to its area, then a uniform point inside it
// (corner weights 1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2 for r1, r2
// uniform in [0, 1)). The same seed gives the same samples on every machine
// (the generator is std::mt19937_64 and the mapping to [0, 1) is our own).
// InvalidArgument: negative count, a triangle index out of range.
// DataError: the mesh has no area, or a non-finite vertex.
Status SampleSurface(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles, int count,
                     uint64_t seed, SurfaceSamples* samples);

// Positions [3, S] of the samples on `vertices` [3, N] (any shape of the mesh
// that was sampled; `triangles` as given to SampleSurface).
Eigen::Matrix3Xf SamplePositions(const SurfaceSamples& samples, const Eigen::Matrix3Xf& vertices,
                                 const Eigen::Matrix3Xi& triangles);

// Texture coordinates [2, S] of the samples from per-corner UVs:
// uv_coords [2, U] (FaceModel::uv_coords()), uv_triangles [3, T]
// (FaceModel::uv_triangles()). InvalidArgument: no UVs, a sample's triangle
// beyond uv_triangles, or a UV index outside [0, U).
Status SampleUVs(const SurfaceSamples& samples, const Eigen::Matrix2Xf& uv_coords,
                 const Eigen::Matrix3Xi& uv_triangles, Eigen::Matrix2Xf* uvs);

}  // namespace headforge
