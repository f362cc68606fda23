// LoadTrained (trainer.h): a trained avatar with its workspace's views, for
// render, export and the benches (the full build's; it reads the workspace).
#include <torch/torch.h>

#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_table.h"

namespace headforge {

Status LoadTrained(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                   torch::Device device, int resolution, DatasetOptions* loading, GaussianStyleAvatar* avatar,
                   FaceModel* model, AvatarDataset* data) {
  DatasetOptions trained;
  HF_RETURN_IF_ERROR(LoadAvatar(model_dir, device, avatar, &trained));
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, model));
  // The frames held out as training held them out; not its held-out
  // cameras (--holdout-cameras), which this loading has never taken.
  loading->resolution = resolution > 0 ? resolution : trained.resolution;
  loading->min_train_frames = 1;
  loading->holdout = trained.holdout;
  loading->holdout_order = trained.holdout_order;
  loading->mask = trained.mask;
  loading->auto_mask = std::string(kGaussianStyle.default_mask);
  loading->mask_hair = trained.mask_hair;
  loading->mask_skin = trained.mask_skin;
  HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, *model, *loading, data).WithContext("render"));
  if (avatar->model->options().mesh_riding)
    avatar->neutral = ComputeTriangleFrames(data->identity_vertices, data->triangles).To(device);
  return Status::Ok();
}

}  // namespace headforge
