// The avatar models HeadForge trains, one entry each: the only place a
// model's name and folder are spelled. No LibTorch here: pipelines/ and
// export/ read it. Adding a model is an entry here, its folder beside
// gaussian_style/ and gan_avatar/, and its branch where train, render and
// export dispatch on the entry.
#pragma once

#include <string>
#include <string_view>

#include "core/fs.h"

namespace headforge {

struct AvatarModel {
  std::string_view name;          // --model, config.json's "model", the weights' metadata
  std::string_view folder;        // WORKSPACE/models/<folder>
  std::string_view summary;       // one line for --help and the docs
  std::string_view default_mask;  // what --mask auto trains it with: "mesh" or "ingest"

  std::string Name() const { return std::string(name); }
  fs::path Dir(const fs::path& workspace) const { return workspace / "models" / std::string(folder); }
  bool Is(std::string_view other) const { return other == name; }
};

inline constexpr AvatarModel kGaussianStyle{
    "gaussian-style", "gaussian_style",
    "3D Gaussians riding the tracked face mesh, a triplane generator and an attention deformation driven by the "
    "tracked expressions (and, with stage 3, a StyleGAN decoder)",
    "mesh"};
inline constexpr AvatarModel kGanAvatar{
    "gan-avatar", "gan_avatar",
    "an EG3D-style 3D GAN trained on the subject's frames and a mapping from tracked expressions to its latents",
    "ingest"};
inline constexpr AvatarModel kAvatarModels[] = {kGaussianStyle, kGanAvatar};

// The entry of `name`, or null.
inline const AvatarModel* FindAvatarModel(std::string_view name) {
  for (const AvatarModel& m : kAvatarModels)
    if (m.name == name) return &m;
  return nullptr;
}

// "gaussian-style or gan-avatar": the names for a message.
inline std::string AvatarModelNames() {
  std::string out;
  for (size_t i = 0; i < std::size(kAvatarModels); ++i) {
    if (i > 0) out += i + 1 == std::size(kAvatarModels) ? " or " : ", ";
    out += kAvatarModels[i].name;
  }
  return out;
}

}  // namespace headforge
