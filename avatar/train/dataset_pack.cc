#include "avatar/train/dataset_pack.h"

#include <torch/torch.h>

#include <string>
#include <utility>

#include "avatar/train/tensor_safetensors.h"
#include "core/safetensors.h"

namespace headforge {
namespace {

constexpr const char* kFormat = "headforge-training-pack";
constexpr int kVersion = 1;

nlohmann::json CameraJson(const SplatCamera& c) {
  return {{"cam_from_world", c.cam_from_world}, {"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx},
          {"cy", c.cy}, {"width", c.width},   {"height", c.height}};
}

SplatCamera CameraFromJson(const nlohmann::json& j) {
  SplatCamera c;
  c.cam_from_world = j.at("cam_from_world").get<std::array<double, 12>>();
  c.fx = j.at("fx").get<double>();
  c.fy = j.at("fy").get<double>();
  c.cx = j.at("cx").get<double>();
  c.cy = j.at("cy").get<double>();
  c.width = j.at("width").get<int>();
  c.height = j.at("height").get<int>();
  return c;
}

// The 8-bit values an image in [0, 1] was made from.
torch::Tensor ToBytes(const torch::Tensor& image) {
  return (image.detach().cpu().to(torch::kFloat32) * 255.0).round().clamp(0, 255).to(torch::kUInt8);
}

}  // namespace

Status WriteDatasetPack(const AvatarDataset& data, const nlohmann::json& options, const fs::path& path) {
  SafeTensorsFile file;
  nlohmann::json parts = nlohmann::json::object();
  for (const auto& [name, range] : data.mesh_parts) parts[name] = {range.first, range.second};
  nlohmann::json doc = {{"options", options},
                        {"dataset",
                         {{"width", data.width},
                          {"height", data.height},
                          {"num_frames", data.num_frames},
                          {"first_test_frame", data.first_test_frame},
                          {"holdout_every", data.holdout_every},
                          {"expression_names", data.expression_names},
                          {"mesh_parts", parts}}}};
  // Only when set: a pack of any other capture reads as it was written before.
  if (data.one_state) doc["dataset"]["one_state"] = true;
  file.tensors.push_back(ToSafeTensor("identity_vertices", data.identity_vertices));
  file.tensors.push_back(ToSafeTensor("expression_basis", data.expression_basis));
  file.tensors.push_back(ToSafeTensor("triangles", data.triangles.to(torch::kInt64)));
  nlohmann::json views = nlohmann::json::array();
  int64_t k = 0;
  for (const auto* split : {&data.train, &data.test}) {
    for (const AvatarView& v : *split) {
      if (!v.image.defined() || !v.mask.defined())
        return Status::InvalidArgument("training pack: view " + std::to_string(k) + " has no image (a dataset "
                                       "read for rendering cannot be packed)");
      const std::string prefix = "view." + std::to_string(k) + ".";
      file.tensors.push_back(ToSafeTensor(prefix + "image", ToBytes(v.image)));
      file.tensors.push_back(ToSafeTensor(prefix + "mask", ToBytes(v.mask)));
      file.tensors.push_back(ToSafeTensor(prefix + "condition", v.condition.to(torch::kFloat32)));
      if (v.uv_map.defined()) file.tensors.push_back(ToSafeTensor(prefix + "uv_map", v.uv_map.to(torch::kUInt8)));
      views.push_back({{"split", split == &data.train ? "train" : "test"},
                       {"frame", v.frame},
                       {"time_s", v.time_s},
                       {"camera", v.camera},
                       {"view", CameraJson(v.view)},
                       {"regions", v.regions},
                       {"has_landmarks", v.has_landmarks},
                       {"unreliable", v.unreliable},
                       {"uv_map", v.uv_map.defined()}});
      if (v.interpolated) views.back()["interpolated"] = true;  // only when set: other packs' bytes as before
      ++k;
    }
  }
  doc["views"] = std::move(views);
  file.metadata["format"] = kFormat;
  file.metadata["version"] = std::to_string(kVersion);
  file.metadata["headforge_pack"] = doc.dump();
  return WriteSafetensors(path, file).WithContext("training pack");
}

Status ReadDatasetPack(const fs::path& path, AvatarDataset* data, nlohmann::json* options) {
  SafeTensorsFile file;
  HF_RETURN_IF_ERROR(ReadSafetensors(path, &file).WithContext("training pack"));
  const auto format = file.metadata.find("format");
  if (format == file.metadata.end() || format->second != kFormat || !file.metadata.count("headforge_pack"))
    return Status::DataError(path.string() + " is a .safetensors file but not a training pack; write one with "
                             "headforge pack --workspace W --out " + path.filename().string());
  if (file.metadata["version"] != std::to_string(kVersion))
    return Status::DataError(path.string() + " is a version " + file.metadata["version"] +
                             " training pack; this build reads version " + std::to_string(kVersion) +
                             ": write it again with this version's headforge pack");
  const Status damaged = Status::DataError(path.string() + " is a damaged training pack; write it again");
  AvatarDataset out;
  try {
    const nlohmann::json doc = nlohmann::json::parse(file.metadata["headforge_pack"]);
    const nlohmann::json& d = doc.at("dataset");
    out.width = d.at("width").get<int>();
    out.height = d.at("height").get<int>();
    out.num_frames = d.at("num_frames").get<int>();
    out.first_test_frame = d.at("first_test_frame").get<int>();
    out.holdout_every = d.value("holdout_every", 0);
    out.one_state = d.value("one_state", false);
    out.expression_names = d.at("expression_names").get<std::vector<std::string>>();
    for (const auto& [name, range] : d.at("mesh_parts").items())
      out.mesh_parts[name] = {range.at(0).get<int>(), range.at(1).get<int>()};
    const auto tensor = [&](const std::string& name, torch::Tensor* t) {
      const SafeTensor* s = file.Find(name);
      return s != nullptr && FromSafeTensor(*s, t);
    };
    if (!tensor("identity_vertices", &out.identity_vertices) || !tensor("expression_basis", &out.expression_basis) ||
        !tensor("triangles", &out.triangles))
      return damaged;
    int64_t k = 0;
    for (const nlohmann::json& j : doc.at("views")) {
      AvatarView v;
      v.frame = j.at("frame").get<int>();
      v.time_s = j.at("time_s").get<double>();
      v.camera = j.at("camera").get<std::string>();
      v.view = CameraFromJson(j.at("view"));
      v.regions = j.at("regions").get<std::array<std::array<float, 4>, 3>>();
      v.has_landmarks = j.at("has_landmarks").get<bool>();
      v.unreliable = j.at("unreliable").get<bool>();
      v.interpolated = j.value("interpolated", false);
      const std::string prefix = "view." + std::to_string(k++) + ".";
      torch::Tensor image, mask;
      if (!tensor(prefix + "image", &image) || !tensor(prefix + "mask", &mask) ||
          !tensor(prefix + "condition", &v.condition) || image.dim() != 3 || image.size(0) != 3 ||
          image.size(1) != v.view.height || image.size(2) != v.view.width || mask.dim() != 3 ||
          !mask.sizes().slice(1).equals(image.sizes().slice(1)))
        return damaged;
      if (j.at("uv_map").get<bool>() && !tensor(prefix + "uv_map", &v.uv_map)) return damaged;
      v.image = ImageFromBytes(image);
      v.mask = ImageFromBytes(mask);
      (j.at("split").get<std::string>() == "train" ? out.train : out.test).push_back(std::move(v));
    }
    *options = doc.at("options");
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path.string() + " is a damaged training pack (" + e.what() + "); write it again");
  }
  AttachViewVertices(&out);
  *data = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
