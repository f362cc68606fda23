// A training pack: an AvatarDataset and the resolved options of the run it is
// for, in one .safetensors file, so that a machine with LibTorch alone (a GPU
// server without COLMAP, Ceres, OpenCV or the face model) trains from it with
// `headforge-train` exactly as `headforge train` would on the workspace.
//
// Tensors: identity_vertices, expression_basis, triangles, and per view k
// view.K.image (U8 [3, H, W]), view.K.mask (U8 [1, H, W], 0 or 255),
// view.K.condition (F32) and view.K.uv_map (U8, when the view has one). The
// header's metadata "headforge_pack" is a JSON document: "options" (the
// caller's), "dataset" (sizes, held-out split, expression names, mesh parts)
// and "views" (each view's frame, time, camera name, intrinsics and pose,
// region boxes and flags).
#pragma once

#include <nlohmann/json.hpp>

#include "avatar/train/dataset.h"
#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// Images and masks are stored as the 8-bit values they were read from
// (ImageFromBytes gives back the same floats).
Status WriteDatasetPack(const AvatarDataset& data, const nlohmann::json& options, const fs::path& path);
// A clear error for a file that is not a pack, is damaged, or is of another version.
Status ReadDatasetPack(const fs::path& path, AvatarDataset* data, nlohmann::json* options);

}  // namespace headforge
