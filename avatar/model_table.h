// The avatar models HeadForge makes, one entry each: the only place a
// model's name and folder are spelled. Two kinds: the models `train` trains
// (kAvatarModels, in WORKSPACE/models/) and the models `export` makes from a
// trained one (kExportedModels, in WORKSPACE/export/); `render --model NAME`
// draws either. No LibTorch here: pipelines/ and export/ read it. Adding a
// model is an entry here, its folder beside gaussian_style/ and gan_avatar/,
// and its branch where train, render and export dispatch on the entry.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "core/fs.h"

namespace headforge {

struct AvatarModel {
  std::string_view name;          // --model, config.json's "model", the weights' metadata
  std::string_view folder;        // WORKSPACE/models/<folder>, or WORKSPACE/export/<folder> for an exported one
  std::string_view summary;       // one line for --help and the docs
  std::string_view default_mask;  // what --mask auto trains it with: "mesh" or "ingest"
  std::string_view export_format = {};  // exported models: the `export --formats` name that makes it; "" if trained
  std::string_view made_from = {};      // exported models: the trained model's name they are made from
  std::string_view marker = "config.json";  // the file in Dir() that says the model is there

  std::string Name() const { return std::string(name); }
  bool Trained() const { return export_format.empty(); }
  fs::path Dir(const fs::path& workspace) const {
    return workspace / (Trained() ? "models" : "export") / std::string(folder);
  }
  bool Is(std::string_view other) const { return other == name; }
  // Whether `workspace` holds the model (its marker file in Dir()).
  bool In(const fs::path& workspace) const {
    std::error_code ec;
    return fs::is_regular_file(Dir(workspace) / std::string(marker), ec);
  }
  // The command that makes it in `workspace`, for a message.
  std::string MadeBy(const fs::path& workspace) const {
    return Trained() ? "headforge train --workspace " + workspace.string() + " --model " + Name()
                     : "headforge export --workspace " + workspace.string() + " --formats " + std::string(export_format);
  }
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
inline constexpr AvatarModel kGaussianBlendshapes{
    "gaussian-blendshapes", "blendshapes",
    "linear Gaussian blendshapes distilled from a trained gaussian-style avatar: for every Gaussian a neutral "
    "state and one offset per tracked expression, posed by a weighted sum (any engine can draw them)",
    "mesh", "blendshapes", kGaussianStyle.name, "blendshapes.json"};
// What `train --model` trains.
inline constexpr AvatarModel kAvatarModels[] = {kGaussianStyle, kGanAvatar};
// What `export` makes from a trained model; `render --model` draws these too.
inline constexpr AvatarModel kExportedModels[] = {kGaussianBlendshapes};

// The trained model called `name`, or null.
inline const AvatarModel* FindAvatarModel(std::string_view name) {
  for (const AvatarModel& m : kAvatarModels)
    if (m.name == name) return &m;
  return nullptr;
}

// Every model, the trained ones first, then the exported ones.
inline std::vector<const AvatarModel*> AllAvatarModels() {
  std::vector<const AvatarModel*> all;
  for (const AvatarModel& m : kAvatarModels) all.push_back(&m);
  for (const AvatarModel& m : kExportedModels) all.push_back(&m);
  return all;
}

// Any model called `name`, trained or exported, or null.
inline const AvatarModel* FindAnyAvatarModel(std::string_view name) {
  for (const AvatarModel* m : AllAvatarModels())
    if (m->name == name) return m;
  return nullptr;
}

// "gaussian-style or gan-avatar": the trained models' names for a message
// (with the exported ones too: "gaussian-style, gan-avatar or gaussian-blendshapes").
inline std::string AvatarModelNames(bool exported = false) {
  std::vector<const AvatarModel*> named;
  for (const AvatarModel* m : AllAvatarModels())
    if (exported || m->Trained()) named.push_back(m);
  std::string out;
  for (size_t i = 0; i < named.size(); ++i) {
    if (i > 0) out += i + 1 == named.size() ? " or " : ", ";
    out += named[i]->name;
  }
  return out;
}

}  // namespace headforge
