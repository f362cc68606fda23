#include "avatar/avatar_render.h"

#include <torch/torch.h>

#include <opencv2/videoio.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>

#include "avatar/gaussian_style/trainer.h"
#include "avatar/torch_runtime.h"
#include "avatar/train/tensor_image.h"
#include "core/image_io.h"
#include "core/log.h"

namespace headforge {
namespace {

// Every view of a dataset, in frame order (then camera).
std::vector<const AvatarView*> AllViews(const AvatarDataset& data) {
  std::vector<const AvatarView*> views;
  for (const auto* list : {&data.train, &data.test})
    for (const AvatarView& v : *list) views.push_back(&v);
  std::stable_sort(views.begin(), views.end(), [](const AvatarView* a, const AvatarView* b) {
    return a->frame != b->frame ? a->frame < b->frame : a->camera < b->camera;
  });
  return views;
}

}  // namespace

Status RenderAvatarFrames(const fs::path& workspace, const std::string& face_model, const AvatarRenderOptions& options,
                          const fs::path& out_dir, Progress* progress, AvatarRenderSummary* summary) {
  UseTensorThreads();
  torch::Device device = torch::kCPU;
  try {
    device = torch::Device(options.device);
  } catch (const c10::Error&) {
    return Status::InvalidArgument("render: '" + options.device + "' is not a device (cpu or cuda)");
  }
  if (device.is_cuda() && !torch::cuda::is_available())
    return Status::InvalidArgument("render: this build's LibTorch sees no CUDA device; use --device cpu");
  if (options.side_by_side && !options.drive.empty())
    return Status::InvalidArgument("render: --side-by-side shows the avatar's own frames; leave out --drive");
  GaussianStyleAvatar avatar;
  TrainOptions trained;
  HF_RETURN_IF_ERROR(LoadAvatar(workspace / "models" / "gaussian_style", device, &avatar, &trained));
  FaceModel model;
  HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &model));
  DatasetOptions loading;
  loading.resolution = options.resolution > 0 ? options.resolution : trained.resolution;
  loading.images = options.side_by_side;
  loading.min_train_frames = 1;
  AvatarDataset own, drive;
  HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, model, loading, &own).WithContext("render"));
  if (trained.mesh_riding) {
    avatar.neutral = ComputeTriangleFrames(own.identity_vertices, own.triangles);
    TriangleFrames& n = avatar.neutral;
    for (torch::Tensor* t : {&n.origin, &n.rotation, &n.quat, &n.scale}) *t = t->to(device);
  }
  const std::vector<const AvatarView*> own_views = AllViews(own);
  std::vector<const AvatarView*> drivers = own_views;
  if (!options.drive.empty()) {
    loading.images = false;
    HF_RETURN_IF_ERROR(LoadAvatarDataset(options.drive, model, loading, &drive).WithContext("render --drive"));
    drivers = AllViews(drive);
  }
  std::map<int, const AvatarView*> by_frame;
  for (const AvatarView* v : drivers) by_frame.emplace(v->frame, v);
  std::vector<int> frames = options.frames;
  if (frames.empty())
    for (const auto& [frame, view] : by_frame) frames.push_back(frame);
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  const torch::Tensor background = torch::full({3}, options.background, torch::TensorOptions().device(device));
  const int64_t expressions = int64_t(own.expression_names.size());
  cv::VideoWriter video;
  double posing = 0;
  progress->Start("render", int64_t(frames.size()));
  for (int frame : frames) {
    const auto found = by_frame.find(frame);
    if (found == by_frame.end())
      return Status::InvalidArgument("render: no frame " + std::to_string(frame) + " (the frames run 0-" +
                                     std::to_string(by_frame.rbegin()->first) + ")");
    const AvatarView& driver = *found->second;
    // Driven by another capture: its expressions, this avatar's first camera and head pose.
    const AvatarView& own_view = options.drive.empty() ? driver : *own_views.front();
    torch::Tensor condition = own_view.condition.clone();
    condition.slice(0, 0, expressions).copy_(driver.condition.slice(0, 0, expressions));
    const SplatCamera camera = OrbitCamera(own_view.view, options.yaw_deg, options.pitch_deg);
    const auto start = std::chrono::steady_clock::now();
    torch::Tensor render;
    {
      torch::NoGradGuard no_grad;
      render = RenderRgb(avatar.Pose(own, condition, 0, avatar.deform), camera, background).clamp(0, 1).cpu();
    }
    posing += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (options.side_by_side) {
      const torch::Tensor target = driver.image * driver.mask + options.background * (1 - driver.mask);
      render = torch::cat({render, target}, 2);
    }
    const cv::Mat image = TensorToImage(render);
    if (options.video) {
      if (!video.isOpened()) {
        const fs::path path = out_dir / "render.mp4";
        video.open(path.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('m', 'p', '4', 'v'), 25, image.size());
        if (!video.isOpened()) return Status::IoError("render: cannot open " + path.string() + " for writing");
        summary->files.push_back(path.filename().string());
      }
      video.write(image);
    } else {
      char name[48];
      std::snprintf(name, sizeof(name), "frame_%06d.png", frame);
      HF_RETURN_IF_ERROR(WriteImageAtomic(out_dir / name, image));
      summary->files.push_back(name);
    }
    progress->Advance();
  }
  progress->Finish();
  summary->frames = int(frames.size());
  summary->seconds_per_frame = frames.empty() ? 0 : posing / frames.size();
  return Status::Ok();
}

}  // namespace headforge
