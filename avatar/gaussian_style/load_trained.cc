// LoadTrained (trainer.h): a trained avatar with its workspace's views, for
// render, export and the benches (the full build's; it reads the workspace).
#include <torch/torch.h>

#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_table.h"

namespace headforge {

Status LoadTrained(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                   torch::Device device, int resolution, DatasetOptions* loading, GaussianStyleAvatar* avatar,
                   TrainOptions* trained, FaceModel* model, AvatarDataset* data) {
  HF_RETURN_IF_ERROR(LoadAvatar(model_dir, device, avatar, trained));
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, model));
  loading->resolution = resolution > 0 ? resolution : trained->data.resolution;
  loading->min_train_frames = 1;
  loading->holdout = trained->data.holdout;
  loading->holdout_order = trained->data.holdout_order;
  loading->mask = trained->MaskFor(kGaussianStyle);
  loading->mask_hair = trained->data.mask_hair;
  loading->mask_skin = trained->data.mask_skin;
  HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, *model, *loading, data).WithContext("render"));
  if (trained->gaussian_style.mesh_riding)
    avatar->neutral = ComputeTriangleFrames(data->identity_vertices, data->triangles).To(device);
  return Status::Ok();
}

}  // namespace headforge
