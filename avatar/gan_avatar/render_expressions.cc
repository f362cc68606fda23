// Renders of the generator tracked (render_expressions.h).
#include "avatar/gan_avatar/render_expressions.h"

#include <torch/torch.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>

#include "avatar/train/tensor_image.h"
#include "calibration/landmark_embedding.h"
#include "capture/landmarks.h"
#include "core/interrupt.h"
#include "core/log.h"
#include "reconstruction/landmark_basis.h"
#include "reconstruction/tracker.h"

namespace headforge {

namespace {

// The box dlib's landmark model expects (its HOG detector's framing: square,
// from the brows to about the chin) round where `points` (the 68 landmarks,
// pixels) are.
cv::Rect2f LandmarkModelBox(const std::array<Eigen::Vector2d, 68>& points) {
  double x0 = 1e9, x1 = -1e9, y0 = 1e9;
  for (int i = ibug::kJawFirst; i <= ibug::kJawLast; ++i) {
    x0 = std::min(x0, points[size_t(i)].x());
    x1 = std::max(x1, points[size_t(i)].x());
  }
  for (int i = ibug::kBrowFirst; i <= ibug::kBrowLast; ++i) y0 = std::min(y0, points[size_t(i)].y());
  const double y1 = points[ibug::kChin].y();
  const double side = std::max(x1 - x0, y1 - y0);
  const double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
  return cv::Rect2f(float(cx - side / 2), float(cy - side / 2), float(side), float(side));
}

}  // namespace

Status EstimateRenderExpressions(GanGenerator& generator, const SplatCamera& camera, int out_width, int out_height,
                                 const FaceModel& model, const TrackingFile& tracking,
                                 const RenderExpressionOptions& options, at::Generator& random, Progress* progress,
                                 RenderExpressions* out) {
  std::unique_ptr<LandmarkPredictor> predictor;
  HF_RETURN_IF_ERROR(LandmarkPredictor::Load(options.landmark_model, &predictor));
  const std::string embedding =
      tracking.landmark_embedding.empty() ? DefaultLandmarkEmbedding() : tracking.landmark_embedding;
  LandmarkBasis basis;
  HF_RETURN_IF_ERROR(
      BuildLandmarkBasis(model, LoadLandmarkEmbedding(model, embedding), tracking.identity_modes, &basis));
  // The camera at the landmark image's size, for the tracker and for the box.
  const double scale = double(options.landmark_size) / std::max(out_width, out_height);
  const int big_w = int(std::lround(out_width * scale)), big_h = int(std::lround(out_height * scale));
  const SplatCamera big = camera.Downscaled(double(camera.width) / big_w);
  TrackingCamera tc;
  tc.fx = big.fx;
  tc.fy = big.fy;
  tc.cx = big.cx;
  tc.cy = big.cy;
  const Eigen::Isometry3d cam_from_head = CameraPose(big);
  tc.rotation = cam_from_head.linear();
  tc.translation = cam_from_head.translation();
  std::array<Eigen::Vector2d, 68> projected;
  const Eigen::VectorXd neutral = Eigen::VectorXd::Zero(basis.num_expressions);
  for (int i = 0; i < 68; ++i) projected[size_t(i)] = tc.Pixel(basis.Point(i, tracking.identity, neutral));
  const cv::Rect2f box = LandmarkModelBox(projected);

  torch::NoGradGuard no_grad;
  const torch::Device device = generator->parameters().front().device();
  std::vector<torch::Tensor> ws, images;
  std::vector<TrackingView> views;
  progress->Start("train: gan-avatar expressions of renders", options.samples);
  const int64_t batch = 8;
  for (int64_t first = 0; first < options.samples; first += batch) {
    const int64_t n = std::min<int64_t>(batch, options.samples - first);
    const torch::Tensor z = torch::randn({n, generator->options().z_dim}, random).to(device);
    const torch::Tensor w = generator->Map(z);
    const torch::Tensor rendered =
        generator->Render(w, std::vector<SplatCamera>(size_t(n), camera), out_width, out_height, options.background,
                          nullptr)
            .image.clamp(0, 1)
            .cpu();
    for (int64_t k = 0; k < n; ++k) {
      cv::Mat bgr;
      cv::resize(TensorToImage(rendered[k]), bgr, cv::Size(big_w, big_h), 0, 0, cv::INTER_CUBIC);
      const Landmarks68 points = predictor->Predict(bgr, box);
      TrackingView view;
      view.frame = int(first + k);
      view.camera = tc;
      std::array<Eigen::Vector2d, 68> found;
      for (int i = 0; i < 68; ++i) found[size_t(i)] = {points[size_t(i)].x, points[size_t(i)].y};
      view.landmarks = found;
      views.push_back(view);
      ws.push_back(w[k].cpu());
      images.push_back(rendered[k]);
      progress->Advance();
    }
    if (InterruptRequested()) {
      progress->Finish("interrupted");
      return Status::Interrupted("train: stopped while rendering the expression mapping's samples; the GAN is kept: "
                                 "run the same command again to go on from it");
    }
  }
  progress->Finish(std::to_string(options.samples) + " renders");
  // Every render one frame: the camera carries the (fixed) head, the
  // identity is shared, nothing ties one render to the next.
  TrackOptions fit;
  fit.identity_modes = tracking.identity_modes;
  fit.fixed_head = true;
  fit.rotation_smoothness = fit.translation_smoothness = fit.expression_smoothness = 0;
  fit.threads = options.threads;
  TrackResult result;
  HF_RETURN_IF_ERROR(TrackSequence(basis, views, options.samples, fit, &result).WithContext("tracking the renders"));
  // Renders the tracker flagged (a large residual: a render the landmark
  // model reads poorly) are kept and counted: the mapping learns from them
  // what the tracker can say. Only renders without a fit are left out.
  std::vector<int64_t> kept;
  std::vector<torch::Tensor> expressions;
  int flagged = 0;
  for (const TrackedFrame& f : result.frames) {
    if (f.interpolated) continue;
    flagged += f.low_confidence ? 1 : 0;
    kept.push_back(f.frame);
    expressions.push_back(torch::from_blob(const_cast<double*>(f.expression.data()), {f.expression.size()},
                                           torch::kFloat64)
                              .to(torch::kFloat32)
                              .clone());
  }
  out->rendered = options.samples;
  out->median_residual_px = result.median_residual_px;
  if (kept.empty())
    return Status::DataError("the tracker found no expression in any of the " + std::to_string(options.samples) +
                             " renders of the GAN (median landmark residual " +
                             std::to_string(result.median_residual_px) +
                             " px); train the GAN longer (--steps, --max-minutes) or at a larger --resolution");
  const torch::Tensor index = torch::tensor(kept, torch::kLong);
  out->w = torch::stack(ws).index_select(0, index);
  out->images = torch::stack(images).index_select(0, index);
  out->expressions = torch::stack(expressions);
  out->flagged = flagged;
  HF_LOG(Info) << "train: gan-avatar: " << kept.size() << " of " << options.samples << " renders tracked, " << flagged
               << " of them flagged (median landmark residual " << result.median_residual_px << " px at " << big_w
               << "x" << big_h << ")";
  return Status::Ok();
}

}  // namespace headforge
