// The capture simulator: renders the face model as a scene describes it and
// writes what ingest accepts (an image folder, or a video, per camera) plus
// masks and ground_truth.json. Only the effects the scene lists are simulated.
#pragma once

#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "capture/appearance.h"
#include "capture/scene.h"
#include "core/face_model.h"
#include "core/fs.h"
#include "core/mesh_renderer.h"
#include "core/progress.h"

namespace headforge {

// The subject's state at one instant.
struct SubjectState {
  Eigen::Isometry3d world_from_head = Eigen::Isometry3d::Identity();
  Eigen::VectorXf expression;  // one weight per model expression, in [0, 1]
};

// One rendered view and its ground truth.
struct SimulatedView {
  cv::Mat image;   // CV_8UC3 BGR, every enabled effect applied (but compression)
  cv::Mat mask;    // CV_8U, 255 where face or hair covers at least half the pixel
  RenderOutput render;  // the last render's buffers (depth, uv, part...), undistorted
  PinholeCamera camera;  // intrinsics (undistorted) and cam_from_world at the frame time
  double k1 = 0.0, k2 = 0.0;  // distortion applied to the image (0 unless lens_distortion)
  std::vector<Eigen::Vector2d> landmarks;  // 68 pixels in the output image
  std::vector<bool> visible;
  std::vector<double> depth;  // camera-frame z of each landmark vertex, metres
};

class Simulator {
 public:
  static Status Create(const Scene& scene, const FaceModel& model, int threads,
                       std::unique_ptr<Simulator>* simulator);

  const Scene& scene() const { return scene_; }
  int num_frames() const { return scene_.FrameCount(); }
  int num_cameras() const;
  std::string CameraName(int camera) const { return "cam" + std::to_string(camera); }
  const Eigen::VectorXf& identity() const { return identity_; }
  const FaceModel& model() const { return model_; }

  double FrameTime(int frame) const { return frame / scene_.fps; }
  SubjectState StateAt(double t) const;
  PinholeCamera CameraAt(int camera, double t) const;
  // The head's vertices in the world frame.
  Eigen::Matrix3Xf WorldVertices(const SubjectState& state) const;

  SimulatedView RenderView(int frame, int camera) const;

 private:
  Simulator(const Scene& scene, const FaceModel& model) : scene_(scene), model_(model) {}
  // The colour and buffers at time(s) `row_times` (one per row band) with an
  // optional larger canvas for distortion.
  RenderOutput RenderAt(int camera, const std::vector<double>& band_times, const PinholeCamera& canvas) const;
  RenderOutput RenderOnce(int camera, double t, const PinholeCamera& canvas) const;
  // RenderView's steps. The time offsets of the row bands (one band without
  // a rolling shutter).
  std::vector<double> BandOffsets() const;
  // The colour on `canvas` over the exposure (motion blur's sub-frame
  // samples, each with its row bands); `middle` gets the middle sample's
  // buffers.
  cv::Mat Expose(int camera, double t, const PinholeCamera& canvas, RenderOutput* middle) const;
  // Exposure and white-balance drift, sensor noise.
  void ApplySensorEffects(int frame, int camera, double t, cv::Mat* colour) const;
  // Ground-truth landmarks (at the time their row was exposed), their depth
  // and visibility, distorted like the image.
  void PlaceLandmarks(int camera, double t, const PinholeCamera& canvas, SimulatedView* view) const;

  Scene scene_;
  const FaceModel& model_;
  int threads_ = 1;
  Eigen::VectorXf identity_;
  Eigen::Matrix3Xf identity_shape_;
  std::vector<int> expression_index_;  // model index per scene expression
  std::vector<const Curve*> expression_curve_;
  HeadAppearance appearance_;
  Mesh head_template_;
  std::vector<Mesh> background_;
  Texture background_texture_[6];
  Mesh occluder_template_;
  Texture occluder_texture_;
};

// Renders the first `max_frames` frames (0: all) of every camera into `out_dir`:
//   cam<i>/<frame>.png (or cam<i>.mp4 with video_compression), masks/cam<i>/<frame>.png,
//   ground_truth.json, scene.toml (a copy of the scene file when given).
Status WriteSimulation(const Simulator& simulator, const fs::path& out_dir, const std::string& scene_text,
                       int max_frames, Progress* progress);

}  // namespace headforge
