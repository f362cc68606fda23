#include "avatar/avatar_render.h"

#include <torch/torch.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>

#include <Eigen/Geometry>

#include "avatar/drive_remedy.h"
#include "avatar/gan_avatar/avatar_io.h"
#include "avatar/model_folder.h"
#include "avatar/gaussian_style/blendshapes.h"
#include "avatar/gaussian_style/trainer.h"
#include "avatar/model_table.h"
#include "avatar/torch_runtime.h"
#include "avatar/train/device.h"
#include "avatar/train/tensor_image.h"
#include "capture/capture_io.h"
#include "core/image_io.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/options.h"
#include "core/video_writer.h"

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

// A trained avatar ready to draw, whichever model it is. The drawing
// function points into the struct, which therefore stays where it was made.
struct DrawableAvatar {
  DrawableAvatar() = default;
  DrawableAvatar(const DrawableAvatar&) = delete;
  DrawableAvatar& operator=(const DrawableAvatar&) = delete;

  GaussianStyleAvatar gaussian;
  GanAvatar gan;
  GaussianBlendshapes blendshapes;
  FaceModel model;
  DatasetOptions loading;  // how `data` was read (and a driving workspace is)
  AvatarDataset data;      // its workspace's views, held out as in training
  double background = 1;   // the grey behind the head
  // (condition [E + 9], camera) -> [3, H, W] on the CPU, in [0, 1].
  std::function<torch::Tensor(const torch::Tensor&, const SplatCamera&)> draw;
};

// The model in `model_dir` ("": the workspace's model trained last), its
// dataset at `resolution` (0: as trained; images only when asked for).
// gaussian-style draws over `background`; gan-avatar over its own grey.
Status LoadDrawableAvatar(const fs::path& workspace, fs::path model_dir, const std::string& face_model,
                          torch::Device device, int resolution, bool images, double background, DrawableAvatar* a) {
  if (model_dir.empty()) model_dir = LatestModelFolder(workspace);
  if (model_dir.empty()) model_dir = kGaussianStyle.Dir(workspace);
  a->loading.images = images;
  if (IsGanAvatarFolder(model_dir)) {
    // The gan-avatar model: the tracked expression through its mapping.
    HF_RETURN_IF_ERROR(LoadGanAvatar(model_dir, device, &a->gan));
    HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &a->model));
    // Held out as in training; the views at the output's size unless asked otherwise.
    a->loading = a->gan.trained;
    a->loading.images = images;
    a->loading.resolution = resolution > 0 ? resolution : std::max(a->gan.out_width, a->gan.out_height);
    a->loading.min_train_frames = 1;
    HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, a->model, a->loading, &a->data).WithContext("render"));
    a->background = a->gan.background;
    a->draw = [a](const torch::Tensor& condition, const SplatCamera& camera) { return a->gan.Draw(condition, camera); };
    return Status::Ok();
  }
  if (IsBlendshapeFolder(model_dir)) {
    // Gaussian blendshapes (export --formats blendshapes): the tracked
    // expression's weighted sum, RGB splats.
    HF_RETURN_IF_ERROR(ReadGaussianBlendshapes(model_dir, &a->blendshapes, &a->loading).WithContext("render"));
    HF_RETURN_IF_ERROR(FaceModel::Load(face_model, &a->model));
    a->loading.images = images;
    if (resolution > 0) a->loading.resolution = resolution;
    a->loading.min_train_frames = 1;
    HF_RETURN_IF_ERROR(LoadAvatarDataset(workspace, a->model, a->loading, &a->data).WithContext("render"));
    if (int64_t(a->data.expression_names.size()) != a->blendshapes.offsets.size(0))
      return Status::DataError("render: the blendshapes in " + model_dir.string() + " have " +
                               std::to_string(a->blendshapes.offsets.size(0)) + " expressions, the workspace's tracking " +
                               std::to_string(a->data.expression_names.size()));
    a->blendshapes.neutral = a->blendshapes.neutral.to(device);
    a->blendshapes.offsets = a->blendshapes.offsets.to(device);
    a->blendshapes.opacities = a->blendshapes.opacities.to(device);
    a->background = background;
    const torch::Tensor grey = torch::full({3}, background, torch::TensorOptions().device(device));
    const int64_t k = a->blendshapes.offsets.size(0);
    a->draw = [a, grey, k](const torch::Tensor& condition, const SplatCamera& camera) {
      torch::NoGradGuard no_grad;
      return RenderRgb(PoseBlendshapes(a->blendshapes, condition.slice(0, 0, k)), camera, grey).clamp(0, 1).cpu();
    };
    return Status::Ok();
  }
  HF_RETURN_IF_ERROR(LoadTrained(workspace, model_dir, face_model, device, resolution, &a->loading, &a->gaussian,
                                 &a->model, &a->data));
  a->background = background;
  const torch::Tensor grey = torch::full({3}, background, torch::TensorOptions().device(device));
  a->draw = [a, grey](const torch::Tensor& condition, const SplatCamera& camera) {
    torch::NoGradGuard no_grad;
    GaussianStyleAvatar& g = a->gaussian;
    return g.Draw(g.Pose(a->data, condition, 0, g.deform), camera, grey).clamp(0, 1).cpu();
  };
  return Status::Ok();
}

Eigen::VectorXd ExpressionWeights(const torch::Tensor& condition, int64_t expressions) {
  const torch::Tensor w = condition.slice(0, 0, expressions).to(torch::kCPU, torch::kFloat64).contiguous();
  return Eigen::Map<const Eigen::VectorXd>(w.data_ptr<double>(), expressions);
}

// The driver's weights with options.drive_remedy applied, one tensor a
// frame (left empty without a remedy): its neutral from its whole take
// (one view a frame), re-based on the mean (and span) of the avatar's
// training frames.
Status RemedyDriving(const AvatarRenderOptions& options, const AvatarDataset& own,
                     const std::map<int, const AvatarView*>& driver, int64_t expressions,
                     std::map<int, torch::Tensor>* remedied) {
  DriveRemedy remedy = DriveRemedy::kNone;
  HF_RETURN_IF_ERROR(ParseDriveRemedy(options.drive_remedy, &remedy).WithContext("render --drive-remedy"));
  if (remedy == DriveRemedy::kNone) return Status::Ok();
  if (options.drive.empty())
    return Status::InvalidArgument("render: --drive-remedy re-bases another workspace's expressions; give --drive");
  std::vector<Eigen::VectorXd> training, take;
  for (const AvatarView& v : own.train) training.push_back(ExpressionWeights(v.condition, expressions));
  for (const auto& [frame, view] : driver) take.push_back(ExpressionWeights(view->condition, expressions));
  DriveRemedyOptions remedy_options;
  remedy_options.neutral_percentile = options.drive_neutral_percentile;
  remedy_options.span_variance = options.drive_span_variance;
  HF_RETURN_IF_ERROR(ApplyDriveRemedy(remedy, remedy_options, training, &take).WithContext("render"));
  size_t i = 0;
  for (const auto& [frame, view] : driver) {
    const Eigen::VectorXd& w = take[i++];
    remedied->emplace(frame, torch::from_blob(const_cast<double*>(w.data()), {expressions}, torch::kFloat64).clone()
                                 .to(view->condition.options()));
  }
  return Status::Ok();
}

}  // namespace

std::string RenderFileName(const AvatarRenderOptions& options, int frame, int orbit_step) {
  auto number = [](const char* format, double value) {
    char text[32];
    std::snprintf(text, sizeof(text), format, value + 0.0);  // + 0.0: -0 reads as +0
    return std::string(text);
  };
  char text[32];
  std::snprintf(text, sizeof(text), "frame_%06d", frame);
  std::string name = text;
  if (!options.drive.empty()) name += "_driven";
  if (!options.drive.empty() && options.drive_remedy != "none") name += "_" + options.drive_remedy;
  if (options.side_by_side) name += "_side_by_side";
  // Renders from another camera sit beside the frame's own without replacing them.
  if (options.yaw_deg != 0 || options.pitch_deg != 0)
    name += "_yaw" + number("%+g", options.yaw_deg) + "_pitch" + number("%+g", options.pitch_deg);
  if (options.orbit_deg > 0) {
    const int digits = std::max(3, int(std::to_string(std::max(0, options.orbit_steps - 1)).size()));
    std::snprintf(text, sizeof(text), "_%0*d", digits, orbit_step);
    name += "_orbit" + number("%g", options.orbit_deg) + text;
  }
  return name + ".png";
}

Status RenderAvatarFrames(const fs::path& workspace, const std::string& face_model, const AvatarRenderOptions& options,
                          const fs::path& out_dir, Progress* progress, AvatarRenderSummary* summary) {
  UseTensorThreads();
  torch::Device device = torch::kCPU;
  HF_RETURN_IF_ERROR(ParseDevice("render", options.device, &device));
  if ((options.side_by_side || options.held_out) && !options.drive.empty())
    return Status::InvalidArgument("render: --side-by-side and --held-out show the avatar's own frames; leave out --drive");
  if (options.orbit_deg < 0 || options.orbit_deg > 180 || options.orbit_steps < 2)
    return Status::InvalidArgument("render: --orbit takes a yaw in (0, 180] degrees and at least 2 steps");
  const fs::path model_dir = options.model;  // empty: the model trained last
  DrawableAvatar avatar;
  HF_RETURN_IF_ERROR(LoadDrawableAvatar(workspace, model_dir, face_model, device, options.resolution,
                                        options.side_by_side, options.background, &avatar));
  const AvatarDataset& own = avatar.data;
  const FaceModel& model = avatar.model;
  DatasetOptions loading = avatar.loading;
  AvatarDataset drive;
  const auto& draw = avatar.draw;
  const std::vector<const AvatarView*> own_views = AllViews(own);
  std::vector<const AvatarView*> drivers = own_views;
  if (!options.drive.empty()) {
    loading.images = false;
    HF_RETURN_IF_ERROR(LoadAvatarDataset(options.drive, model, loading, &drive).WithContext("render --drive"));
    drivers = AllViews(drive);
  }
  std::map<int, const AvatarView*> by_frame;
  for (const AvatarView* v : drivers) by_frame.emplace(v->frame, v);
  const int64_t expressions = int64_t(own.expression_names.size());
  std::map<int, torch::Tensor> remedied;  // frame -> the driver's expression weights, remedied
  HF_RETURN_IF_ERROR(RemedyDriving(options, own, by_frame, expressions, &remedied));
  std::vector<int> frames;
  if (!options.frames.empty() && !by_frame.empty())
    HF_RETURN_IF_ERROR(
        ParseFrameList(options.frames, by_frame.rbegin()->first + 1, &frames).WithContext("render --frames"));
  if (frames.empty())
    for (const auto& [frame, view] : by_frame)
      if (!options.held_out || own.HeldOut(frame)) frames.push_back(frame);
  // An orbit: one frame, the camera swung from 0 to +orbit, to -orbit and
  // back to 0; at 180, turned once all the way round.
  std::vector<double> yaws(frames.size(), options.yaw_deg);
  if (options.orbit_deg > 0) {
    frames.assign(size_t(options.orbit_steps), frames.empty() ? 0 : frames.front());
    yaws.clear();
    for (int i = 0; i < options.orbit_steps; ++i) {
      const double turn = double(i) / options.orbit_steps;
      yaws.push_back(options.yaw_deg + (options.orbit_deg >= 180 ? 360 * turn : options.orbit_deg * std::sin(2 * M_PI * turn)));
    }
  }
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  VideoFileWriter video;
  double posing = 0;
  progress->Start("render", int64_t(frames.size()));
  for (size_t i = 0; i < frames.size(); ++i) {
    const int frame = frames[i];
    const auto found = by_frame.find(frame);
    if (found == by_frame.end())
      return Status::InvalidArgument("render: no frame " + std::to_string(frame) + " (the frames run 0-" +
                                     std::to_string(by_frame.rbegin()->first) + ")");
    const AvatarView& driver = *found->second;
    // Driven by another capture: its expressions, this avatar's first camera and head pose.
    const AvatarView& own_view = options.drive.empty() ? driver : *own_views.front();
    torch::Tensor condition = own_view.condition.clone();
    const auto remedy = remedied.find(frame);
    condition.slice(0, 0, expressions)
        .copy_(remedy != remedied.end() ? remedy->second : driver.condition.slice(0, 0, expressions));
    const SplatCamera camera = OrbitCamera(own_view.view, yaws[i], options.pitch_deg);
    const auto start = std::chrono::steady_clock::now();
    torch::Tensor render = draw(condition, camera);
    posing += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (options.side_by_side)
      render = ComparisonStrip(render, driver.image, driver.mask, avatar.background);
    const cv::Mat image = TensorToImage(render);
    if (options.video) {
      if (!video.IsOpen()) {
        const fs::path path = out_dir / options.video_name;
        HF_RETURN_IF_ERROR(video.Open(path, options.fps, image.size()).WithContext("render"));
        summary->files.push_back(path.filename().string());
      }
      HF_RETURN_IF_ERROR(video.Write(image));
    } else {
      const std::string name = RenderFileName(options, frame, int(i));
      HF_RETURN_IF_ERROR(WriteImageAtomic(out_dir / name, image));
      summary->files.push_back(name);
    }
    progress->Advance();
  }
  HF_RETURN_IF_ERROR(video.Close().WithContext("render"));
  progress->Finish();
  summary->frames = int(frames.size());
  summary->seconds_per_frame = frames.empty() ? 0 : posing / frames.size();
  return Status::Ok();
}

namespace {

Eigen::Isometry3d IsometryFromJson(const nlohmann::json& rows) {
  Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) m.matrix()(i, j) = rows.at(i).at(j).get<double>();
  return m;
}

// Azimuth (toward +x) and elevation (toward +y) of a camera's centre round the origin, degrees.
std::pair<double, double> AzimuthElevation(const Eigen::Isometry3d& cam_from_world) {
  const Eigen::Vector3d c = cam_from_world.inverse().translation();
  return {std::atan2(c.x(), c.z()) * 180 / M_PI, std::asin(c.y() / c.norm()) * 180 / M_PI};
}

// The workspace's view of `camera` at `time_s` (within `tolerance` s), held
// out or trained on, or null.
const AvatarView* FindView(const AvatarDataset& data, const std::string& camera, double time_s, double tolerance) {
  for (const auto* split : {&data.test, &data.train})
    for (const AvatarView& v : *split)
      if (v.camera == camera && std::abs(v.time_s - time_s) <= tolerance) return &v;
  return nullptr;
}

// `view`'s lens (at the training size of the workspace's frame of
// `camera_name`, which may be a crop of the source) as a lens of the
// source's whole frame at `whole`'s size (the truth's lens there):
// training pixel p_t = (p_source + 0.5 - crop_x0) * crop_scale * s - 0.5,
// s the training size over the frame's.
Status LensOnWholeFrame(const IngestedCapture& capture, const SplatCamera& view, const std::string& camera_name,
                        const SplatCamera& whole, SplatCamera* out) {
  const IngestedCamera* cam = capture.FindCamera(camera_name);
  if (!cam || cam->width <= 0 || cam->source_width <= 0 || !cam->fixed_crop)
    return Status::DataError("novel views: the workspace's camera " + camera_name +
                             " has no one crop of its source to carry its lens through (ingest with --crop "
                             "sequence or none to score it against a simulation)");
  const double a = cam->crop_scale * double(view.width) / cam->width;                     // source -> training
  const double l = double(whole.width) / cam->source_width;                               // source -> whole
  *out = whole;
  out->fx = view.fx * l / a;
  out->fy = view.fy * l / a;
  out->cx = ((view.cx + 0.5) / a + cam->crop_x0) * l - 0.5;
  out->cy = ((view.cy + 0.5) / a + cam->crop_y0) * l - 0.5;
  return Status::Ok();
}

}  // namespace

Status ScoreNovelViews(const fs::path& workspace, const fs::path& model_dir, const std::string& face_model,
                       const fs::path& truth, const fs::path& write_dir, std::vector<NovelViewScore>* scores) {
  UseTensorThreads();
  torch::NoGradGuard no_grad;
  DrawableAvatar avatar;
  HF_RETURN_IF_ERROR(LoadDrawableAvatar(workspace, model_dir, face_model, torch::kCPU, 0, false, 0.5, &avatar));
  const AvatarDataset& data = avatar.data;
  const DatasetOptions& loading = avatar.loading;
  nlohmann::json gt;
  HF_RETURN_IF_ERROR(ReadJson(truth / "ground_truth.json", &gt));
  if (data.test.empty()) return Status::DataError("novel views: the workspace has no held-out frames");
  if (!write_dir.empty()) HF_RETURN_IF_ERROR(EnsureDirectory(write_dir));
  const std::string trained_on = data.test.front().camera;
  const torch::Tensor background = torch::full({3}, avatar.background);
  IngestedCapture capture;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace, &capture));
  std::vector<NovelViewScore> out;
  std::vector<std::vector<ViewScores>> per_camera, per_camera_truth_lens;
  try {
    const double fps = gt.at("fps").get<double>();
    const nlohmann::json& frames = gt.at("frames");
    const nlohmann::json& cameras = gt.at("cameras");
    // Each truth camera's intrinsics at the training resolution.
    std::vector<SplatCamera> lenses;
    for (const nlohmann::json& cam : cameras) {
      const double scale = double(loading.resolution) / std::max(cam.at("width").get<int>(), cam.at("height").get<int>());
      SplatCamera lens;
      lens.width = int(std::lround(cam.at("width").get<int>() * scale));
      lens.height = int(std::lround(cam.at("height").get<int>() * scale));
      lens.fx = cam.at("fx").get<double>() * scale;
      lens.fy = cam.at("fy").get<double>() * scale;
      lens.cx = (cam.at("cx").get<double>() + 0.5) * scale - 0.5;
      lens.cy = (cam.at("cy").get<double>() + 0.5) * scale - 0.5;
      lenses.push_back(lens);
      out.emplace_back();
      out.back().camera = cam.at("name").get<std::string>();
    }
    per_camera.resize(lenses.size());
    per_camera_truth_lens.resize(lenses.size());
    for (const AvatarView& view : data.test) {
      if (view.camera != trained_on) continue;
      const int index = int(std::lround(view.time_s * fps));
      if (index < 0 || index >= int(frames.size()) ||
          std::abs(frames[size_t(index)].at("time_s").get<double>() - view.time_s) > 0.5 / fps)
        return Status::DataError("novel views: " + truth.string() + " has no frame at " + std::to_string(view.time_s) +
                                 " s; simulate the scene the workspace came from");
      const nlohmann::json& views = frames[size_t(index)].at("views");
      if (!views.contains(trained_on))
        return Status::DataError("novel views: " + truth.string() + " has no camera " + trained_on +
                                 ", the camera the avatar was trained on");
      // The head frame in truth's world, through the training camera.
      const Eigen::Isometry3d training_camera = IsometryFromJson(views.at(trained_on).at("cam_from_world"));
      const Eigen::Isometry3d world_from_head = training_camera.inverse() * CameraPose(view.view);
      const auto [azimuth0, elevation0] = AzimuthElevation(training_camera);
      char file[32];
      std::snprintf(file, sizeof(file), "%06d.png", index);
      for (size_t k = 0; k < lenses.size(); ++k) {
        const nlohmann::json& cam = cameras[k];
        const Eigen::Isometry3d novel = IsometryFromJson(views.at(out[k].camera).at("cam_from_world"));
        const auto [azimuth, elevation] = AzimuthElevation(novel);
        out[k].yaw_deg = azimuth - azimuth0;
        out[k].pitch_deg = elevation - elevation0;
        // A camera the workspace calibrated at this instant through its own
        // calibration (where align's scale is off, the truth's placement
        // relative to the training camera would put it at another distance),
        // its lens carried onto the truth's whole frame; any other through
        // the truth's lens and pose, relative to the training camera.
        SplatCamera camera = lenses[k];
        const AvatarView* own = FindView(data, out[k].camera, view.time_s, 0.5 / fps);
        if (own) {
          HF_RETURN_IF_ERROR(LensOnWholeFrame(capture, own->view, out[k].camera, lenses[k], &camera));
          SetCameraPose(CameraPose(own->view), &camera);
        } else {
          SetCameraPose(novel * world_from_head, &camera);
        }
        const torch::Tensor render = avatar.draw(view.condition, camera);
        const fs::path image_path = truth / cam.at("input").get<std::string>() / file;
        const fs::path mask_path = truth / "masks" / out[k].camera / file;
        cv::Mat image = cv::imread(image_path.string(), cv::IMREAD_COLOR);
        cv::Mat mask = cv::imread(mask_path.string(), cv::IMREAD_GRAYSCALE);
        if (image.empty() || mask.empty())
          return Status::DataError("novel views: cannot read " + image_path.string() + " or its mask");
        cv::resize(image, image, cv::Size(camera.width, camera.height), 0, 0, cv::INTER_AREA);
        cv::resize(mask, mask, cv::Size(camera.width, camera.height), 0, 0, cv::INTER_AREA);
        const torch::Tensor target = ImageToTensor(image), cover = MaskToTensor(mask);
        per_camera[k].push_back(ScoreRender(render, target, cover, background));
        if (own) {
          SplatCamera truth_lens = lenses[k];
          SetCameraPose(CameraPose(own->view), &truth_lens);
          per_camera_truth_lens[k].push_back(
              ScoreRender(avatar.draw(view.condition, truth_lens), target, cover, background));
        }
        if (!write_dir.empty())
          HF_RETURN_IF_ERROR(WriteImageAtomic(write_dir / (out[k].camera + "_" + file),
                                              TensorToImage(ComparisonStrip(render, target, cover, avatar.background))));
      }
    }
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError("novel views: " + (truth / "ground_truth.json").string() + " is damaged: " + e.what());
  }
  for (size_t k = 0; k < out.size(); ++k) {
    const ViewScores mean = MeanScores(per_camera[k]);
    out[k].views = int(per_camera[k].size());
    out[k].psnr_masked = mean.psnr_masked;
    out[k].ssim_masked = mean.ssim_masked;
    out[k].psnr_full = mean.psnr_full;
    out[k].calibrated = !per_camera_truth_lens[k].empty();
    const ViewScores through_truth = MeanScores(per_camera_truth_lens[k]);
    out[k].truth_lens_psnr_masked = through_truth.psnr_masked;
    out[k].truth_lens_ssim_masked = through_truth.ssim_masked;
  }
  *scores = std::move(out);
  return Status::Ok();
}

namespace {

// `other`'s capture lines up with `own`'s: the same cameras, frame sizes and
// crops of the source (so a mask of one is a mask of the other's frame).
Status CheckSameCrop(const IngestedCapture& own, const IngestedCapture& other, const fs::path& other_dir) {
  for (const IngestedCamera& a : own.cameras) {
    const IngestedCamera* b = other.FindCamera(a.name);
    if (!b) return Status::InvalidArgument("--score-masks: " + other_dir.string() + " has no camera " + a.name);
    const bool same = a.width == b->width && a.height == b->height && a.source_width == b->source_width &&
                      a.source_height == b->source_height && std::abs(a.crop_x0 - b->crop_x0) < 1e-3 &&
                      std::abs(a.crop_y0 - b->crop_y0) < 1e-3 && std::abs(a.crop_scale / b->crop_scale - 1) < 1e-6;
    if (!same)
      return Status::InvalidArgument("--score-masks: " + other_dir.string() + "'s " + a.name +
                                     " was ingested with another crop or size than this workspace's (" +
                                     std::to_string(b->width) + "x" + std::to_string(b->height) + " against " +
                                     std::to_string(a.width) + "x" + std::to_string(a.height) +
                                     "): ingest the same video with the same --crop and --resolution");
  }
  return Status::Ok();
}

}  // namespace

Status ScoreHeldOutRegions(const fs::path& workspace, const std::string& face_model, const RegionScoreOptions& options,
                           std::vector<RegionScore>* scores) {
  if (options.band_px < 0) return Status::InvalidArgument("--band must be 0 or more pixels");
  IngestedCapture own, other;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace, &own));
  const fs::path masks_dir = options.masks_from.empty() ? workspace : fs::path(options.masks_from);
  if (!options.masks_from.empty()) {
    HF_RETURN_IF_ERROR(ReadIngestedCapture(masks_dir, &other).WithContext("--score-masks"));
    HF_RETURN_IF_ERROR(CheckSameCrop(own, other, masks_dir));
  }
  UseTensorThreads();
  torch::NoGradGuard no_grad;
  DrawableAvatar avatar;
  HF_RETURN_IF_ERROR(LoadDrawableAvatar(workspace, options.model, face_model, torch::kCPU, 0, true, 0.5, &avatar));
  const AvatarDataset& data = avatar.data;
  if (data.test.empty()) return Status::DataError("score regions: the workspace has no held-out frames");
  const IngestedCapture& reference = options.masks_from.empty() ? own : other;
  if (!options.write_dir.empty()) HF_RETURN_IF_ERROR(EnsureDirectory(options.write_dir));
  const std::string whose = options.masks_from.empty() ? "its masks" : "the masks of " + masks_dir.filename().string();
  std::vector<std::string> names = {"the workspace's masks (eval.json's figure)", "the face (the 68 landmarks' hull)"};
  if (!options.masks_from.empty()) names.push_back(whose);
  if (options.band_px > 0)
    names.push_back("a band " + std::to_string(options.band_px) + " px each side of the edge of " + whose);
  std::vector<std::vector<ViewScores>> per_region(names.size());
  const torch::Tensor background = torch::full({3}, avatar.background);
  for (const AvatarView& view : data.test) {
    const torch::Tensor render = avatar.draw(view.condition, view.view);
    const cv::Size size(view.view.width, view.view.height);
    // The reference masks at the training size, and the frame shown through them.
    const fs::path mask_path = reference.MaskPath(view.camera, view.frame);
    cv::Mat mask = cv::imread(mask_path.string(), cv::IMREAD_GRAYSCALE);
    if (mask.empty()) return Status::DataError("score regions: cannot read " + mask_path.string());
    cv::resize(mask, mask, size, 0, 0, cv::INTER_AREA);
    const torch::Tensor cover = MaskToTensor(mask);
    const torch::Tensor shown = view.image * cover + background.view({3, 1, 1}) * (1 - cover);
    std::vector<cv::Mat> regions;
    regions.push_back(cv::Mat());  // the view's own mask, as eval scores it
    const IngestedFrame* frame = own.FindFrame(view.camera, view.frame);
    const IngestedCamera* camera = own.FindCamera(view.camera);
    regions.push_back(frame && camera && frame->landmarks
                          ? LandmarkHullMask(*frame->landmarks, size, double(size.width) / camera->width)
                          : cv::Mat::zeros(size, CV_8U));
    if (!options.masks_from.empty()) regions.push_back(mask >= 128);
    if (options.band_px > 0) {
      const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * options.band_px + 1, 2 * options.band_px + 1});
      cv::Mat inner, outer;
      cv::erode(mask >= 128, inner, disc);
      cv::dilate(mask >= 128, outer, disc);
      regions.push_back(outer & ~inner);
    }
    for (size_t r = 0; r < regions.size(); ++r) {
      if (r == 0) {
        per_region[r].push_back(ScoreRender(render, view.image, view.mask, background));
        continue;
      }
      if (cv::countNonZero(regions[r]) == 0) continue;  // no landmarks: no face to score
      const torch::Tensor where = MaskToTensor(regions[r]);
      per_region[r].push_back(ScoreRender(render, shown, where, background));
      if (!options.write_dir.empty()) {
        char file[64];
        std::snprintf(file, sizeof(file), "%s_%06d_region%zu.png", view.camera.c_str(), view.frame, r);
        // render | the frame within the region | the error there x 4
        const torch::Tensor inside = shown * where + avatar.background * (1 - where);
        const torch::Tensor error = ((render - shown).abs() * 4 * where).clamp(0, 1);
        HF_RETURN_IF_ERROR(
            WriteImageAtomic(fs::path(options.write_dir) / file, TensorToImage(torch::cat({render, inside, error}, 2))));
      }
    }
  }
  scores->clear();
  for (size_t r = 0; r < names.size(); ++r) {
    const ViewScores mean = MeanScores(per_region[r]);
    scores->push_back({names[r], int(per_region[r].size()), mean.psnr_masked, mean.ssim_masked});
  }
  return Status::Ok();
}

}  // namespace headforge
