#include "avatar/train/dataset.h"

#include <torch/torch.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "avatar/train/tensor_image.h"
#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

// The frame and its mask, lens distortion removed, resized to `size`.
Status ReadView(const IngestedCapture& capture, const IngestedCamera& cam, const CameraIntrinsics& lens, int frame,
                cv::Size size, cv::Mat* image, cv::Mat* mask) {
  HF_RETURN_IF_ERROR(ReadUndistortedFrame(capture, cam.name, lens, frame, image, mask));
  if (image->size() != size) {
    cv::resize(*image, *image, size, 0, 0, cv::INTER_AREA);
    cv::resize(*mask, *mask, size, 0, 0, cv::INTER_AREA);
  }
  return Status::Ok();
}

// Boxes round the eyes and the mouth, grown by a third and at least 6 px.
void RegionBoxes(const Landmarks68& points, const CameraIntrinsics& lens, double scale, AvatarView* view) {
  const std::array<std::pair<int, int>, 3> ranges = {{{36, 41}, {42, 47}, {48, 67}}};
  for (size_t r = 0; r < 3; ++r) {
    double x0 = 1e30, y0 = 1e30, x1 = -1e30, y1 = -1e30;
    for (int i = ranges[r].first; i <= ranges[r].second; ++i) {
      const Eigen::Vector2d p = lens.Undistort(Eigen::Vector2d(points[i].x, points[i].y));
      const double x = (p.x() + 0.5) * scale - 0.5, y = (p.y() + 0.5) * scale - 0.5;
      x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
    }
    const double grow_x = std::max(3.0, (x1 - x0) / 6), grow_y = std::max(3.0, (y1 - y0) / 6);
    view->regions[r] = {float(x0 - grow_x), float(y0 - grow_y), float(x1 + grow_x), float(y1 + grow_y)};
  }
  view->has_landmarks = true;
}

}  // namespace

torch::Tensor AvatarDataset::Vertices(const torch::Tensor& expression) const {
  return identity_vertices + torch::matmul(expression_basis, expression.to(expression_basis.dtype())).view({-1, 3});
}

torch::Tensor PoseCondition(const double rotation[9], const double translation[3]) {
  // Row-major rotation: its first two columns, then the translation.
  return torch::tensor({rotation[0], rotation[3], rotation[6], rotation[1], rotation[4], rotation[7], translation[0],
                        translation[1], translation[2]},
                       torch::kFloat32);
}

SplatCamera OrbitCamera(const SplatCamera& camera, double yaw_deg, double pitch_deg) {
  const double yaw = yaw_deg * M_PI / 180, pitch = pitch_deg * M_PI / 180;
  // world_from_cam' = O world_from_cam, so cam_from_world' = cam_from_world O^T,
  // with O turning +z toward +x (yaw) and toward +y (pitch).
  const Eigen::Matrix3d o = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  // Turning the camera about the origin keeps its translation.
  Eigen::Isometry3d turned = CameraPose(camera);
  turned.linear() = turned.linear() * o.transpose();
  SplatCamera out = camera;
  SetCameraPose(turned, &out);
  return out;
}

Status LoadAvatarDataset(const fs::path& workspace, const FaceModel& model, const DatasetOptions& options,
                         AvatarDataset* dataset) {
  IngestedCapture capture;
  CameraSet cameras;
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTrackedWorkspace(workspace, model, &capture, &cameras, &tracking));
  const int frames = capture.num_frames();
  if (options.resolution < 16) return Status::InvalidArgument("the training resolution must be at least 16 pixels");
  AvatarDataset out;
  out.num_frames = frames;
  const int held = std::max(1, int(std::lround(options.holdout * frames)));
  out.first_test_frame = frames - held;
  if (out.first_test_frame < options.min_train_frames)
    return Status::DataError("the capture has " + std::to_string(frames) + " frames: the model needs at least " +
                             std::to_string(options.min_train_frames) + " to train on besides the " +
                             std::to_string(held) + " held out; ingest a longer video");
  out.expression_names = tracking.expression_names;
  const Eigen::Matrix3Xf identity = model.Identity(tracking.identity.cast<float>());
  out.identity_vertices = torch::from_blob(const_cast<float*>(identity.data()), {identity.cols(), 3}).clone();
  const Eigen::MatrixXf& basis = model.expression_basis();
  // Eigen is column-major: the transpose's buffer is the row-major [3V, E].
  const Eigen::MatrixXf basis_t = basis.transpose();
  out.expression_basis = torch::from_blob(const_cast<float*>(basis_t.data()), {basis.rows(), basis.cols()}).clone();
  const Eigen::Matrix3Xi& tris = model.triangles();
  out.triangles = torch::from_blob(const_cast<int*>(tris.data()), {tris.cols(), 3}, torch::kInt32).to(torch::kInt64);

  for (const std::string& name : options.holdout_cameras) {
    bool known = false;
    for (const IngestedCamera& cam : capture.cameras) known = known || cam.name == name;
    if (!known) return Status::InvalidArgument("no camera " + name + " to hold out (see capture.json's cameras)");
  }
  for (const IngestedCamera& cam : capture.cameras) {
    const bool held_camera = std::find(options.holdout_cameras.begin(), options.holdout_cameras.end(), cam.name) !=
                             options.holdout_cameras.end();
    const CameraIntrinsics* lens = cameras.FindCamera(cam.name);
    if (!lens) return Status::DataError("cameras_head.json has no camera " + cam.name + "; run headforge align again");
    const double scale = double(options.resolution) / std::max(cam.width, cam.height);
    const cv::Size size(int(std::lround(cam.width * scale)), int(std::lround(cam.height * scale)));
    for (const IngestedFrame& f : cam.frames) {
      const CameraView* registered = cameras.FindView(cam.name, f.index);
      if (!registered || !registered->registered) continue;
      const TrackedFrame& tracked = tracking.frames[size_t(f.index)];
      AvatarView view;
      view.frame = f.index;
      view.time_s = f.time_s;
      view.camera = cam.name;
      view.unreliable = tracked.interpolated || tracked.low_confidence;
      if (options.images) {
        cv::Mat image, mask;
        HF_RETURN_IF_ERROR(ReadView(capture, cam, *lens, f.index, size, &image, &mask));
        view.image = ImageToTensor(image);
        view.mask = MaskToTensor(mask);
      }
      const Eigen::Isometry3d cam_from_canonical = registered->cam_from_world * tracked.head_motion;
      const Eigen::Isometry3d pose = cameras.mode == "head-pose" ? cam_from_canonical : tracked.head_motion;
      double rotation[9], translation[3];
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) rotation[3 * i + j] = pose.linear()(i, j);
        translation[i] = pose.translation()[i];
      }
      SetCameraPose(cam_from_canonical, &view.view);
      view.view.fx = lens->fx * scale;
      view.view.fy = (lens->fy > 0 ? lens->fy : lens->fx) * scale;
      view.view.cx = (lens->cx + 0.5) * scale - 0.5;
      view.view.cy = (lens->cy + 0.5) * scale - 0.5;
      view.view.width = size.width;
      view.view.height = size.height;
      const Eigen::VectorXf expression = tracked.expression.cast<float>();
      view.condition = torch::cat({torch::from_blob(const_cast<float*>(expression.data()), {expression.size()}).clone(),
                                   PoseCondition(rotation, translation)});
      if (f.landmarks) RegionBoxes(*f.landmarks, *lens, scale, &view);
      (f.index < out.first_test_frame && !held_camera ? out.train : out.test).push_back(std::move(view));
      out.width = size.width;
      out.height = size.height;
    }
  }
  if (int(out.train.size()) < options.min_train_frames)
    return Status::DataError("only " + std::to_string(out.train.size()) +
                             " registered views to train on (the model needs " + std::to_string(options.min_train_frames) +
                             "); calibrate registered too few frames");
  *dataset = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
