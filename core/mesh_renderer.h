// The mesh renderer: a CPU triangle rasterizer with a z-buffer, perspective-
// correct attribute interpolation and supersampled antialiasing. Besides colour
// it renders per-pixel UV coordinates, depth, normals, part labels and triangle
// ids, which the simulator, the tracker's overlays and the UV-conditioned
// discriminator all use.
//
// Cameras follow OpenCV (+x right, +y down, +z forward); a pixel's centre is
// at integer coordinates, so the pinhole maps x_cam to fx x/z + cx.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace headforge {

struct PinholeCamera {
  double fx = 500, fy = 500, cx = 255.5, cy = 255.5;  // pixels
  int width = 512, height = 512;
  Eigen::Isometry3d cam_from_world = Eigen::Isometry3d::Identity();

  // Pixel position (and camera-frame depth) of a world point.
  Eigen::Vector2d Project(const Eigen::Vector3d& world, double* depth = nullptr) const;
  Eigen::Vector3d Centre() const { return cam_from_world.inverse().translation(); }
};

// A camera at `eye` looking at `target`, image "up" toward `up` (world).
Eigen::Isometry3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                         const Eigen::Vector3d& up = Eigen::Vector3d::UnitY());

// An RGB texture (CV_32FC3, values in [0, 1]) sampled bilinearly, repeating.
struct Texture {
  cv::Mat image;
  Eigen::Vector3f Sample(float u, float v) const;  // u right, v up (v = 0 is the bottom row)
};

// Part labels written to RenderOutput::part.
enum Part : uint8_t { kPartBackground = 0, kPartFace = 1, kPartHair = 2, kPartOccluder = 3 };

struct Material {
  const Texture* texture = nullptr;  // nullptr: the constant colour
  Eigen::Vector3f colour = Eigen::Vector3f(0.5f, 0.5f, 0.5f);  // BGR, [0, 1]
  float u_offset = 0.0f;             // subtracted from u before sampling (UDIM tiles)
  float u_scale = 1.0f, v_scale = 1.0f;
  uint8_t part = kPartFace;
  // Optional per-texel part labels (CV_8U, same size as the texture).
  const cv::Mat* part_map = nullptr;
  bool lit = true;  // shaded by the light when lighting is on
};

struct Mesh {
  Eigen::Matrix3Xf vertices;      // [3, N] world coordinates, metres
  Eigen::Matrix3Xi triangles;     // [3, T]
  Eigen::Matrix3Xf normals;       // [3, N] vertex normals (empty: flat shading)
  Eigen::Matrix2Xf uvs;           // [2, U] (may be empty)
  Eigen::Matrix3Xi uv_triangles;  // [3, T] indices into uvs (empty: uvs per vertex)
  std::vector<int16_t> material;  // per triangle; -1 hides it. Empty: material 0.
  std::vector<Material> materials;
};

// A planar quad origin, origin + du, origin + du + dv, origin + dv (two
// triangles) with UVs (0,0) (1,0) (1,1) (0,1), drawn with `material`.
Mesh MakeQuad(const Eigen::Vector3f& origin, const Eigen::Vector3f& du, const Eigen::Vector3f& dv,
              const Material& material);

// Area-weighted vertex normals.
Eigen::Matrix3Xf VertexNormals(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles);

// Barycentric coordinates of the point of triangle (a, b, c) closest to p
// (the region tests of Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                   const Eigen::Vector3d& c);

struct Lighting {
  bool enabled = false;
  Eigen::Vector3f direction = Eigen::Vector3f(0, 0, 1);  // toward the light, world frame
  float ambient = 0.35f, diffuse = 0.75f;
};

struct RenderOptions {
  int supersample = 3;  // samples per pixel side; odd, so one sample sits at the centre
  Eigen::Vector3f background = Eigen::Vector3f(0, 0, 0);  // BGR colour where nothing is drawn
  Lighting lighting;
  float near = 0.01f;  // near plane, metres
  int threads = 0;     // 0: all hardware threads
};

struct RenderOutput {
  cv::Mat color;     // CV_32FC3 BGR [0, 1], antialiased
  cv::Mat depth;     // CV_32F camera z in metres at the pixel centre, 0 where empty
  cv::Mat uv;        // CV_32FC2 at the pixel centre
  cv::Mat normal;    // CV_32FC3 world-frame unit normal at the pixel centre
  cv::Mat part;      // CV_8U Part at the pixel centre
  cv::Mat triangle;  // CV_32S (mesh << 24 | triangle) at the pixel centre, -1 where empty
  cv::Mat coverage;  // CV_32F fraction of a pixel's samples on face or hair
};

// Where a texel of a texture lies on a mesh: its triangle (-1: none) and
// barycentric coordinates.
struct TexelHit {
  int triangle = -1;
  Eigen::Vector3f bary = Eigen::Vector3f::Zero();
};

// Rasterises the UV triangles `triangles` (columns of `uv_triangles`, whose
// entries index `texel_coords`, given in texel units: x right, y down, texel
// centres at integers) into a map of `size` texels; triangles overlap their
// edges a little so no texel along a seam between two is missed.
std::vector<TexelHit> RasteriseTexels(const Eigen::Matrix2Xf& texel_coords, const Eigen::Matrix3Xi& uv_triangles,
                                      const std::vector<int>& triangles, cv::Size size);

// Fills the texels of `image` not set in `filled` (CV_8U) from their set
// neighbours, `iterations` texels deep, so bilinear lookups along UV seams do
// not pick up the empty colour; `filled` grows accordingly.
void PadSeams(cv::Mat* image, cv::Mat* filled, int iterations);

// Renders `meshes` (drawn with one shared z-buffer) through `camera`.
void RenderMeshes(const std::vector<const Mesh*>& meshes, const PinholeCamera& camera,
                  const RenderOptions& options, RenderOutput* output);

}  // namespace headforge
