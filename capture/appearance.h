// Procedural appearance for simulated captures: textures in the face model's
// UV space with detail enough for feature matching (multi-scale noise, pores,
// freckles, lips, brows, a hair cap, irises), and textured backgrounds.
//
// Head textures are "solid" textures baked into UV space: each texel is
// coloured from the 3D point of the identity shape it maps to, so features sit
// where they belong on the head whatever the UV layout.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "capture/scene.h"
#include "core/face_model.h"
#include "core/mesh_renderer.h"

namespace headforge {

struct HeadAppearance {
  Texture skin;          // UDIM tiles 0 (face) and 1 (head and neck): u in [0, 2]
  cv::Mat skin_parts;    // CV_8U Part per skin texel (face or hair)
  Texture eye;           // the eyeballs' tile
  Eigen::Vector3f teeth, gums, mouth, socket;  // BGR constants for the mouth and eye sockets
};

// Bakes the head textures for the identity shape `shape` ([3, N], neutral expression).
HeadAppearance MakeHeadAppearance(const FaceModel& model, const Eigen::Matrix3Xf& shape, const Scene& scene);

// The head as a renderable mesh (materials per region; transparent eye shells
// and eyelash cards hidden). Vertices and normals are filled per frame.
Mesh MakeHeadMesh(const FaceModel& model, const HeadAppearance& appearance);

// A wall, backdrop or occluder texture: noise plus random shapes (BGR, [0, 1]).
Texture MakePatternTexture(int size, uint64_t seed, const Eigen::Vector3f& base_rgb);

}  // namespace headforge
