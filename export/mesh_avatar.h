// The mesh avatar: the tracked identity's face-model mesh with the model's
// blendshapes as named morph targets, the tracked sequence as an animation
// (morph weights and the head's rotation and translation per frame), and a
// colour texture baked from the frames onto the model's UVs, written as
// glTF 2.0 binary (.glb) that Blender, Unity, Unreal and three.js open.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/face_model.h"
#include "core/fs.h"
#include "core/progress.h"
#include "core/status.h"

namespace headforge {

struct MeshAvatarOptions {
  int texture_size = 512;  // texels per side of the skin's square; the atlas is twice it on each side
  int bake_views = 24;     // views, spread over the capture, whose colours are baked
};

struct MeshAvatar {
  Eigen::Matrix3Xf positions;             // [3, V] the identity without expression, head frame, metres
  Eigen::Matrix2Xf texcoords;             // [2, V] atlas coordinates, glTF's convention (v down)
  Eigen::Matrix3Xi triangles;             // [3, T] into positions
  std::vector<int> source_vertex;         // [V] the face model's vertex each one copies (split at UV seams)
  std::vector<Eigen::Matrix3Xf> targets;  // per blendshape, [3, V] offsets at weight 1
  std::vector<std::string> target_names;  // ARKit-style names
  cv::Mat texture;                        // CV_8UC3 BGR atlas
  cv::Mat texture_seen;                   // CV_8U: 255 where a frame saw the texel, 0 where filled in
  std::vector<double> times;              // per frame, seconds from the first
  std::vector<Eigen::VectorXf> weights;   // per frame, [E] blendshape weights
  // Per frame, the head's pose in the head frame; with head-pose cameras, as
  // the first view's camera (cam_from_world) sees it.
  std::vector<Eigen::Isometry3d> head_motion;
  // A camera for viewers: the first camera at the first frame.
  double yfov = 0.5, aspect = 1;          // radians; width / height
  int width = 512, height = 512;
  Eigen::Isometry3d cam_from_world = Eigen::Isometry3d::Identity();
};

// The ARKit-style name of an ICT-FaceKit blendshape: "_L"/"_R" become
// "Left"/"Right" ("eyeBlink_L" -> "eyeBlinkLeft"); other names stay.
std::string ArkitName(const std::string& name);

// Builds the mesh avatar of a tracked workspace: mesh and morph targets from
// the face model and the tracked identity, the animation from tracking.json,
// the texture from the frames (each texel from the views that see it, blended
// by the cosine of its viewing angle squared, the unseen filled from the seen).
Status BuildMeshAvatar(const fs::path& workspace, const FaceModel& model, const MeshAvatarOptions& options,
                       Progress* progress, MeshAvatar* avatar);

// The avatar's vertices at frame `frame` in the head frame, as a viewer
// playing the glTF animation shows them.
Eigen::Matrix3Xf MeshAvatarVertices(const MeshAvatar& avatar, int frame);

Status WriteMeshAvatarGlb(const fs::path& path, const MeshAvatar& avatar);

}  // namespace headforge
